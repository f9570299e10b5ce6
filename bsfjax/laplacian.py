"""Cotangent Laplacian: stiffness ``W`` and diagonal mass ``A`` of a triangle mesh.

The Laplace–Beltrami eigenproblem is discretized as ``W φ = λ A φ`` (paper Eq. 3–4) with

    W_ij = −½ (cot α_ij + cot β_ij)   for an edge (i, j),   W_ii = −Σ_{j≠i} W_ij,

where α_ij, β_ij are the angles opposite the edge (a boundary edge has only one).  ``W`` is
symmetric positive semidefinite with the constants in its kernel.  Assembly is fully vectorized:
one pass over the ``3m`` half-edges, summed by ``scipy.sparse``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .errors import MeshError
from .mesh import Mesh

__all__ = ["laplacian", "cotangent_stiffness", "mass_matrix"]

MASS_TYPES = ("mixed", "barycentric")


def _corner_cotangents(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cotangent of the angle at each corner, ``(m, 3)``, and twice the face areas ``(m,)``.

    Column c holds the corner at ``f[:, c]``, whose opposite edge is ``(f[:, c+1], f[:, c+2])``.
    cot θ = (a·b) / ‖a×b‖ for the two edge vectors a, b leaving the corner.
    """
    P = v[f]  # (m, 3, 3): one gather for all corners
    p0, p1, p2 = P[:, 0], P[:, 1], P[:, 2]
    e0, e1, e2 = p2 - p1, p0 - p2, p1 - p0  # e_c is the edge opposite corner c
    cross = np.cross(e1, e2)
    dbl_area = np.linalg.norm(cross, axis=1)
    safe = np.where(dbl_area > 0, dbl_area, 1.0)
    cots = np.stack(
        [
            -np.einsum("ij,ij->i", e1, e2),  # corner 0: vectors -e2 (to p1) and e1 (to p2)
            -np.einsum("ij,ij->i", e2, e0),
            -np.einsum("ij,ij->i", e0, e1),
        ],
        axis=1,
    ) / safe[:, None]
    cots[dbl_area == 0] = 0.0  # zero-area faces contribute nothing rather than inf
    return cots, dbl_area


def _stiffness(f: np.ndarray, cots: np.ndarray, n: int) -> sp.csr_matrix:
    # corner c weights its opposite edge (f[c+1], f[c+2]) by −½ cot θ_c; one triangle per
    # half-edge, then H + Hᵀ adds the two triangles of an interior edge (cheaper in scipy than
    # summing duplicate COO entries)
    i = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    j = np.concatenate([f[:, 2], f[:, 0], f[:, 1]])
    w = -0.5 * cots.T.ravel()
    H = sp.coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
    off = H + H.T
    return (off - sp.diags(np.asarray(off.sum(axis=1)).ravel())).tocsr()


def cotangent_stiffness(mesh: Mesh) -> sp.csr_matrix:
    """Positive semidefinite cotangent stiffness matrix ``W`` (n × n, CSR, float64)."""
    cots, _ = _corner_cotangents(mesh.vertices, mesh.faces)
    return _stiffness(mesh.faces, cots, mesh.n_vertices)


def _mass(v: np.ndarray, f: np.ndarray, cots: np.ndarray, dbl_area: np.ndarray, n: int,
          kind: str) -> np.ndarray:
    area = 0.5 * dbl_area
    if kind == "barycentric":
        per_corner = np.repeat(area[:, None] / 3.0, 3, axis=1)
    else:
        p = [v[f[:, c]] for c in range(3)]
        sq = np.stack([np.sum((p[(c + 2) % 3] - p[(c + 1) % 3]) ** 2, axis=1) for c in range(3)], 1)
        # Voronoi share of corner c: ⅛ Σ over its two edges of |edge|² cot(opposite corner)
        sc = sq * cots
        vor = (np.roll(sc, -1, axis=1) + np.roll(sc, -2, axis=1)) / 8.0
        obtuse = cots < 0  # cot θ < 0 ⇔ θ > 90°
        any_obtuse = obtuse.any(axis=1, keepdims=True)
        per_corner = np.where(any_obtuse, np.where(obtuse, area[:, None] / 2, area[:, None] / 4), vor)
    return np.bincount(f.ravel(), weights=per_corner.ravel(), minlength=n)


def mass_matrix(mesh: Mesh, kind: str = "mixed") -> sp.csr_matrix:
    """Diagonal (lumped) mass matrix ``A`` (n × n, CSR, float64).

    ``kind="barycentric"``: each triangle gives a third of its area to each corner.
    ``kind="mixed"``: the mixed Voronoi areas of Meyer et al. 2003 — the Voronoi region of the
    corner inside a non-obtuse triangle, ⅛(‖e_ij‖² cot θ_k + ‖e_ik‖² cot θ_j); in an obtuse
    triangle half the area to the obtuse corner and a quarter to each other one.  Both sum to the
    total surface area.
    """
    if kind not in MASS_TYPES:
        raise ValueError(f"mass must be one of {MASS_TYPES}, got {kind!r}")
    cots, dbl_area = _corner_cotangents(mesh.vertices, mesh.faces)
    return sp.diags(_mass(mesh.vertices, mesh.faces, cots, dbl_area, mesh.n_vertices, kind)).tocsr()


def laplacian(mesh: Mesh, mass: str = "mixed", robust: bool = False) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Cotangent stiffness ``W`` and diagonal mass ``A`` of ``mesh`` (both ``scipy.sparse``).

    Args:
        mesh: a :class:`~bsfjax.Mesh`.
        mass: ``"mixed"`` (default; mixed Voronoi, Meyer et al. 2003, libigl's default for
            triangles) or ``"barycentric"``.  Mixed Voronoi areas are the consistent dual areas
            of the cotangent operator on well-shaped meshes and stay positive on obtuse ones.
        robust: use the intrinsic-Delaunay "robust" Laplacian of Sharp & Crane 2020
            (``pip install robust-laplacian``), for non-manifold or badly triangulated meshes.
            Its mass is the lumped intrinsic Voronoi area.

    Returns:
        ``(W, A)``: ``W`` symmetric PSD with ``W·1 = 0``; ``A`` diagonal with positive entries.
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    if robust:
        try:
            import robust_laplacian
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("robust=True needs the robust-laplacian package: "
                              "pip install 'bsfjax[robust]'") from exc
        W, A = robust_laplacian.mesh_laplacian(np.asarray(mesh.vertices), np.asarray(mesh.faces))
        return sp.csr_matrix(W), sp.csr_matrix(A)
    if mass not in MASS_TYPES:
        raise ValueError(f"mass must be one of {MASS_TYPES}, got {mass!r}")
    v, f, n = mesh.vertices, mesh.faces, mesh.n_vertices
    cots, dbl_area = _corner_cotangents(v, f)  # shared by W and A
    W = _stiffness(f, cots, n)
    a = _mass(v, f, cots, dbl_area, n, mass)
    A = sp.diags(a).tocsr()
    bad = a <= 0
    if bad.any():
        where = f"{mesh.name}: " if mesh.name else ""
        raise MeshError(f"{where}{int(bad.sum())} vertices have zero mass "
                        "(unreferenced or only in zero-area faces)")
    return W, A
