"""The arrays a target sends to the batched stages: its spectrum, ZoomOut samples, point map
or landmarks, and face geometry, padded to its size bucket and cast to the working dtype."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._maps import face_geometry
from .._mesh import Mesh


def pad_rows(x: np.ndarray, n: int) -> np.ndarray:
    pad = n - x.shape[0]
    return x if pad == 0 else np.concatenate([x, np.zeros((pad,) + x.shape[1:], x.dtype)])


def geometry_arrays(mesh: Mesh, m_b: int) -> dict:
    g = face_geometry(mesh)
    return {"faces": pad_rows(g.faces, m_b), "K": pad_rows(g.K, m_b),
            "third_area": pad_rows(g.third_area, m_b)}


def item_arrays(t, n_b: int, m_b: int, s_b: int) -> dict:
    """Target ``t``'s arrays (a `_Target`), padded to ``n_b`` vertices, ``m_b`` faces and
    ``s_b`` samples."""
    s = t.spectrum
    out = {"evals": np.asarray(s.evals), "evecs": pad_rows(np.asarray(s.evecs), n_b),
           "mass": pad_rows(np.asarray(s.mass), n_b)}
    if t.samples is not None:
        out["zo_indices"] = pad_rows(t.samples.indices, s_b)
        out["zo_cells"] = pad_rows(t.samples.cells, n_b)
    if t.p2p is not None:  # (padded vertices: zero mass, any source vertex)
        out["p2p"] = pad_rows(np.asarray(t.p2p, np.int32), n_b)
    if t.landmarks is not None:  # the source's: in its operators (source_ops)
        out["landmarks_target"] = np.asarray(t.landmarks[1], np.int32)
        if t.guide is not None:  # ZoomOut's landmark distances (bsfjax._maps._guide)
            out["guide_source"], out["guide_target"] = t.guide[0], pad_rows(t.guide[1], n_b)
    else:
        out.update(geometry_arrays(t.mesh, m_b))
    return out


def cast_tree(tree):
    dt = jax.dtypes.canonicalize_dtype(jnp.float64)
    return jax.tree.map(lambda x: np.asarray(x, np.int32 if np.issubdtype(np.asarray(x).dtype,
                                                                          np.integer) else dt),
                        tree)
