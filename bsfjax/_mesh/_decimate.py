"""A coarse stand-in for a large mesh: quadric decimation, and the vertex correspondences
between the two.

Owner of [`decimate`][bsfjax.decimate] and [`Decimated`][bsfjax.Decimated]: the landmark-free
map of a mesh of hundreds of thousands of vertices is chosen on such a proxy of a few thousand
(`bsfjax.MapEstimator`'s ``proxy_above``), where its 15 starts, geodesic distortions and turn
check cost seconds, and carried back to the whole mesh through the correspondences.
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from .._util import BSFError, check_int, require_triangles
from ._components import split_main_body
from ._mesh import Mesh

__all__ = ["Decimated", "decimate"]


class Decimated(NamedTuple):
    """A mesh and its decimated proxy; what [`decimate`][bsfjax.decimate] returns.

    **Attributes:**

    - `mesh`: the proxy, one connected component (the largest by area of the decimated mesh).
    - `to_proxy`: ``(n,)`` per vertex of the mesh, the nearest proxy vertex (Euclidean).
    - `from_proxy`: ``(n_proxy,)`` per proxy vertex, the nearest vertex of the mesh.
    """

    mesh: Mesh
    to_proxy: np.ndarray
    from_proxy: np.ndarray


def decimate(mesh: Mesh, n_vertices: int) -> Decimated:
    r"""Decimate ``mesh`` to about ``n_vertices`` vertices by quadric edge collapses (Garland &
    Heckbert 1997, ``fast_simplification``), keep the largest connected component by area, and
    match the vertices of the two meshes by nearest neighbours.

    Each collapse merges an edge's two vertices into the point of least quadric error (the sum
    of squared distances to the planes of the triangles around them), so the proxy keeps the
    shape's large-scale geometry, and with it the first Laplace–Beltrami eigenfunctions, at a
    fraction of its vertices.  The number of triangles asked for follows Euler's formula:
    ``F ≈ 2 n_vertices + (F₀ − 2 V₀)`` (holes and boundaries keep their share).

    **Arguments:**

    - `mesh`: a triangle [`Mesh`][bsfjax.Mesh] (not a point cloud).
    - `n_vertices`: the proxy's vertex count, about (at least 4).  A mesh with no more
      vertices is copied as it is (its own proxy).

    **Returns:** a [`Decimated`][bsfjax.Decimated].
    """
    require_triangles(mesh, "a point cloud cannot be decimated: decimation collapses edges "
                      "of triangles")
    n_vertices = check_int(n_vertices, "n_vertices", 4)
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    if mesh.n_vertices <= n_vertices:
        ident = np.arange(mesh.n_vertices)
        return Decimated(Mesh(v, f, name=mesh.name), ident, ident)
    try:
        import fast_simplification
    except ImportError:  # pragma: no cover - a core dependency
        raise BSFError("decimation needs fast_simplification (pip install "
                       "fast-simplification)") from None
    count = max(2 * n_vertices + (f.shape[0] - 2 * v.shape[0]), 4)
    # (writable copies: the extension refuses the mesh's read-only arrays)
    pv, pf = fast_simplification.simplify(np.array(v, order="C"), np.array(f, np.int32, order="C"),
                                          target_count=count)
    pv, pf = np.asarray(pv, np.float64), np.asarray(pf, np.int64)
    # collapses may leave repeated indices, unused points and (rarely) pieces: the largest one
    pf = pf[(pf[:, 0] != pf[:, 1]) & (pf[:, 1] != pf[:, 2]) & (pf[:, 0] != pf[:, 2])]
    used = np.zeros(pv.shape[0], bool)
    used[pf.ravel()] = True
    pv, pf = pv[used], (np.cumsum(used) - 1)[pf]
    proxy = Mesh(pv, pf, name=f"{mesh.name or 'mesh'} decimated")
    proxy = Mesh(proxy.vertices, proxy.faces[proxy.face_areas() > 0], name=proxy.name)
    with warnings.catch_warnings():  # (a piece left out of a proxy is no news to the user)
        warnings.simplefilter("ignore")
        body = split_main_body(proxy)
    proxy = Mesh(body.mesh.vertices, body.mesh.faces, name=proxy.name)
    pv = np.asarray(proxy.vertices, np.float64)
    return Decimated(proxy, cKDTree(pv).query(v)[1].astype(np.int64),
                     cKDTree(v).query(pv)[1].astype(np.int64))
