r"""The orientation term's operators (Ren et al. 2018), as [`bsfjax.estimate_fmap`][bsfjax.estimate_fmap] uses them.

For a descriptor ``d_q`` the reduced operator ``O^q = Φᵀ W_q Φ`` has
``(W_q g)(i) = Σ_{faces t ∋ i} (|t|/3) ⟨n_t × ∇d_q, ∇g⟩_t`` (per-face gradients of
piecewise-linear functions), the reduced form of g ↦ ⟨n × ∇d_q, ∇g⟩.  It is linear in ``d_q``:

.. math::

    O^q[a, b] = Σ_v d_q(v) Y[v, a, b],\qquad
    Y[v, a, b] = Σ_{\text{corners } (t, c) \text{ at } v} (|t|/3)\, s_a(t)\, (K_t φ_b(t))_c

with ``s_a(t) = Σ_c φ_a(t_c)`` and ``K_t`` of `_Geometry`.  ``Y`` is one scan over the
faces (memory ``n k²``); each estimate then needs one GEMM ``(p, n) @ (n, k²)``.  Entry
``(a, b)`` of ``Y`` involves ``φ_a`` and ``φ_b`` only, so the ``Y`` of ``k`` eigenvectors
holds that of every smaller size as its top-left block: `orientation_bases` scans once
for several estimates of a pair (the 15 starts of [`bsfjax.estimate_map`][bsfjax.estimate_map] without
landmarks: their estimates 1.45–1.75× faster, docs/benchmarks.md).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._util import BSFError, require_triangles
from .._mesh import Mesh
from .._spectral import Spectrum, unit_area_pair

__all__ = ["OrientationBasis", "orientation_bases"]


class _Geometry(NamedTuple):
    """Per-face data of a mesh for the orientation operators.

    On face t with corners c, the piecewise-linear g has ∇g = Σ_c g_c ∇B_c (∇B_c = n × e_c / 2|t|,
    e_c the edge opposite c, counter-clockwise), so for any f

        ⟨n × ∇f, ∇g⟩_t = Σ_{c,c'} f_c K_t[c, c'] g_c',    K_t[c, c'] = ⟨n × ∇B_c, ∇B_c'⟩.
    """

    faces: np.ndarray  # (m, 3) int32
    K: np.ndarray  # (m, 3, 3)
    third_area: np.ndarray  # (m,) |t| / 3


def face_geometry(mesh: Mesh) -> _Geometry:
    v, f = mesh.vertices, mesh.faces
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cross = np.cross(p1 - p0, p2 - p0)
    dbl = np.linalg.norm(cross, axis=1)
    safe = np.where(dbl > 0, dbl, 1.0)
    normals = cross / safe[:, None]
    opp = np.stack([p2 - p1, p0 - p2, p1 - p0], axis=1)  # counter-clockwise
    grad_basis = np.cross(normals[:, None, :], opp) / safe[:, None, None]
    grad_basis[dbl == 0] = 0.0  # degenerate faces carry no gradient
    rotated = np.cross(normals[:, None, :], grad_basis)
    K = np.einsum("tcx,tdx->tcd", rotated, grad_basis)
    return _Geometry(f.astype(np.int32), K, dbl / 6.0)


#: Faces per block when assembling orientation operators (memory ``block × k²``).
_FACE_BLOCK = 2048


class OrientationBasis(NamedTuple):
    """A shape's orientation operators before the descriptors (`orientation_bases`):
    ``Y`` ``(n, k, k)`` of `_orient_basis` for its first ``k`` eigenvectors.  It stands
    in for the shape's `_Geometry`; ``Y`` of fewer eigenvectors is its top-left block, so
    one face scan serves every map size."""

    Y: jax.Array


def _orient_basis(evecs, geom: _Geometry):
    """``Y[v, a, b] = Σ_{corners (t, c) at v} (|t|/3) s_a(t) (K_t φ_b(t))_c`` with
    ``s_a(t) = Σ_c φ_a(t_c)``: one scan over blocks of faces (module doc).
    Entry ``(a, b)`` involves ``φ_a`` and ``φ_b`` only."""
    n, k = evecs.shape
    m = geom.faces.shape[0]
    n_blocks = -(-m // _FACE_BLOCK)
    pad = n_blocks * _FACE_BLOCK - m

    def blocks(x):  # padded faces have zero area and K = 0: they add nothing
        x = jnp.pad(x, [(0, pad)] + [(0, 0)] * (x.ndim - 1))
        return x.reshape(n_blocks, _FACE_BLOCK, *x.shape[1:])

    def one(Y, blk):
        faces, K, third = blk
        phi = evecs[faces]  # (T, 3, k)
        weight = third[:, None] * jnp.sum(phi, axis=1)  # (T, k): (|t|/3) Σ_c φ_a(t_c)
        for c in range(3):  # the three corners of every face of the block
            g = sum(K[:, c, e, None] * phi[:, e, :] for e in range(3))  # (T, k): (K_t φ_b)_c
            Y = Y.at[faces[:, c]].add(weight[:, :, None] * g[:, None, :])
        return Y, None

    Y, _ = jax.lax.scan(one, jnp.zeros((n, k, k), evecs.dtype),
                        (blocks(geom.faces), blocks(geom.K), blocks(geom.third_area)))
    return Y


def _orient_ops(evecs, geom, d):
    """``(p, k, k)`` reduced orientation operators O^q = Φᵀ W_q Φ (module doc).

    O^q[a, b] = Σ_t (|t|/3) (Σ_c φ_a(t_c)) Σ_{c,c'} d_q(t_c) K_t[c, c'] φ_b(t_c'), which is linear
    in d: gather Y[v, a, b] = Σ_{corners (t, c) at v} (|t|/3) s_a(t) (K_t φ_b(t))_c once (a scan
    over face blocks, `_orient_basis`; or the top-left block of a shared
    `OrientationBasis`), then O = dᵀ Y is one GEMM ``(p, n) @ (n, k²)``.
    """
    n, k = evecs.shape
    Y = geom.Y[:, :k, :k] if isinstance(geom, OrientationBasis) else _orient_basis(evecs, geom)
    return (d.T @ Y.reshape(n, k * k)).reshape(-1, k, k)


@jax.jit
def _orient_basis_jit(evecs, geom: _Geometry):
    return OrientationBasis(_orient_basis(evecs, geom))


def orientation_bases(source_spectrum: Spectrum, target_spectrum: Spectrum, source_mesh: Mesh,
                      target_mesh: Mesh, k: int) -> tuple[OrientationBasis, OrientationBasis]:
    """The pair's orientation operators before the descriptors, for
    [`estimate_fmap`][bsfjax.estimate_fmap]'s ``orientation_bases``: one scan over each mesh's faces for several
    estimates of the pair ([`bsfjax.estimate_map`][bsfjax.estimate_map]'s starts), not one per estimate.

    **Arguments:**

    - ``source_spectrum``, ``target_spectrum``: the spectra the estimates will get (as
      [`estimate_fmap`][bsfjax.estimate_fmap] does, they are put at one area first, so the bases match its).
    - ``source_mesh``, ``target_mesh``: their meshes.
    - `k`: eigenvectors of each basis, the largest map size the estimates use (a smaller
      one takes the top-left block).

    **Returns:**

    ``(source basis, target basis)``, each ``Y`` ``(n, k, k)``: ``n k²`` floats.
    """
    dt = jnp.result_type(float)
    source_spectrum, _, target_spectrum, _ = unit_area_pair(source_spectrum, target_spectrum)
    out = []
    for s, mesh, name in ((source_spectrum, source_mesh, "source_mesh"),
                          (target_spectrum, target_mesh, "target_mesh")):
        if not 2 <= k <= s.k:
            raise BSFError(f"k must be in [2, {s.k}] (the spectra's size), got {k!r}")
        if np.ndim(s.evecs) != 2:
            raise BSFError("orientation_bases takes single spectra, not stacks")
        geom = _geometries(mesh, np.shape(s.evecs), name)
        out.append(_orient_basis_jit(jnp.asarray(s.evecs[:, :k], dt), _cast(geom, dt)))
    return out[0], out[1]


def _geometries(mesh, spectrum_shape, name: str):
    """Per-face geometry of one mesh, or stacked for a sequence of meshes (batched)."""
    *batch, n, _ = spectrum_shape
    meshes = [mesh] if not batch else (list(mesh) if isinstance(mesh, (list, tuple)) else [mesh])
    if batch and len(meshes) != batch[0]:
        raise BSFError(f"{name} must be a sequence of {batch[0]} meshes for stacked spectra, got "
                       f"{len(meshes)}")
    for m in meshes:
        if not isinstance(m, Mesh):
            raise BSFError(f"{name} must be a bsfjax.Mesh (or a sequence of them for stacked "
                           f"spectra), got {type(m).__name__}")
        if m.n_vertices != n:
            raise BSFError(f"{name} has {m.n_vertices} vertices but its spectrum has {n}")
        require_triangles(m, "a point cloud has no orientation term: it needs triangles "
                          "(give landmarks instead)")
    if len({m.n_faces for m in meshes}) != 1:
        raise BSFError(f"{name}: stacked meshes must have equal face counts, got "
                       f"{[m.n_faces for m in meshes]}")
    geoms = [face_geometry(m) for m in meshes]
    return geoms[0] if not batch else jax.tree.map(lambda *x: np.stack(x), *geoms)


def _check_bases(bases, source_mesh, target_mesh, w, shapes, ks):
    """``orientation_bases`` of [`estimate_fmap`][bsfjax.estimate_fmap] checked against the pair (evecs
    ``shapes``, map sizes ``ks``)."""
    if source_mesh is not None or target_mesh is not None:
        raise BSFError("give the meshes or their orientation_bases, not both")
    if w[3] == 0:
        raise BSFError("orientation_bases are for the orientation term: weights.orient must be "
                       "> 0")
    if len(shapes[0]) != 2:
        raise BSFError("orientation_bases take single spectra, not stacks")
    ns = (shapes[0][0], shapes[1][0])
    ok = isinstance(bases, tuple) and len(bases) == 2
    for i, name in enumerate(("source", "target")):
        b = bases[i] if ok else None
        if not isinstance(b, OrientationBasis) or b.Y.shape[0] != ns[i] or b.Y.shape[1] < ks[i]:
            raise BSFError(f"orientation_bases must be the pair's bsfjax.orientation_bases; the "
                           f"{name}'s needs {ns[i]} vertices and at least {ks[i]} eigenvectors, "
                           f"got {b.Y.shape[:2] if isinstance(b, OrientationBasis) else b!r}")
    return bases


def _cast(tree, dt):
    """Float arrays in the working dtype (spectra and geometry arrive as float64 numpy),
    indices int32."""
    return jax.tree.map(lambda x: jnp.asarray(
        x, jnp.int32 if np.issubdtype(np.result_type(x), np.integer) else dt), tree)
