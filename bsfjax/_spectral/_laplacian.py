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

from .._util import BSFError, MeshError
from .._mesh import Mesh
from .._mesh import as_mesh

__all__ = ["laplacian", "cotangent_stiffness", "mass_matrix", "POINT_CLOUD_NEIGHBORS"]

MASS_TYPES = ("mixed", "barycentric")

#: Neighbours of each point in the point-cloud Laplacian's local triangulations (robust-laplacian's
#: default), fewer on a cloud with fewer points.
POINT_CLOUD_NEIGHBORS = 30


def _point_cloud_laplacian(mesh: Mesh) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Sharp & Crane 2020's point-cloud Laplacian (robust-laplacian): the intrinsic-Delaunay
    Laplacian of the union of local tangent-plane triangulations (tufted cover) of every point's
    ``POINT_CLOUD_NEIGHBORS`` nearest neighbours, and its lumped (Voronoi) area.  Duplicate
    points are kept: their mollified zero-length edges tie them together with a large weight,
    so their eigenvector values agree and no spurious zero eigenvalue appears."""
    import robust_laplacian

    v = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    where = f"{mesh.name}: " if mesh.name else ""
    if v.shape[0] < 4:
        raise MeshError(f"{where}a point cloud needs at least 4 points for its Laplacian, got "
                        f"{v.shape[0]}")
    nn = min(POINT_CLOUD_NEIGHBORS, v.shape[0] - 1)
    W, A = robust_laplacian.point_cloud_laplacian(v, n_neighbors=nn)
    W, A = sp.csr_matrix(W), sp.csr_matrix(A)
    a = A.diagonal()
    if not (np.isfinite(W.data).all() and np.isfinite(a).all()) or np.any(a <= 0):
        raise MeshError(f"{where}point-cloud Laplacian has {int(np.sum(~(a > 0)))} points with "
                        "zero or undefined area (coplanar or collinear neighbourhoods?)")
    return W, A


def _corner_geometry(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per face: cotangent of each corner's angle ``(3, m)``, twice the area ``(m,)`` and the
    squared length of the edge opposite each corner ``(3, m)`` (corner-major rows).

    Corner c sits at ``f[:, c]``; its opposite edge is e_c = p_{c+2} − p_{c+1}, and
    cot θ_c = −(e_{c+1}·e_{c+2}) / ‖e_{c+1}×e_{c+2}‖ (every pair of edges has the same cross
    norm, twice the area).  Coordinates are handled as separate ``(3, m)`` planes: contiguous
    rows make this several times faster in numpy than ``(m, 3, 3)`` fancy indexing.
    """
    ft = f.T
    X, Y, Z = v[:, 0][ft], v[:, 1][ft], v[:, 2][ft]  # (3 corners, m)
    nxt, prv = [2, 0, 1], [1, 2, 0]
    ex, ey, ez = X[nxt] - X[prv], Y[nxt] - Y[prv], Z[nxt] - Z[prv]  # row c: e_c
    sq = ex * ex + ey * ey + ez * ez
    dots = ex[prv] * ex[nxt] + ey[prv] * ey[nxt] + ez[prv] * ez[nxt]  # row c: e_{c+1}·e_{c+2}
    cx = ey[1] * ez[2] - ez[1] * ey[2]
    cy = ez[1] * ex[2] - ex[1] * ez[2]
    cz = ex[1] * ey[2] - ey[1] * ex[2]
    dbl_area = np.sqrt(cx * cx + cy * cy + cz * cz)
    cots = -dots / np.where(dbl_area > 0, dbl_area, 1.0)
    cots[:, dbl_area == 0] = 0.0  # zero-area faces contribute nothing rather than inf
    return cots, dbl_area, sq


def _stiffness(f: np.ndarray, cots: np.ndarray, n: int) -> sp.csr_matrix:
    # corner c weights its opposite edge (f[c+1], f[c+2]) by −½ cot θ_c; one triangle per
    # half-edge, then H + Hᵀ adds the two triangles of an interior edge (cheaper in scipy than
    # summing duplicate COO entries)
    i = np.concatenate([f[:, 1], f[:, 2], f[:, 0]])
    j = np.concatenate([f[:, 2], f[:, 0], f[:, 1]])
    H = sp.coo_matrix((-0.5 * cots.ravel(), (i, j)), shape=(n, n)).tocsr()
    off = H + H.T
    return (off - sp.diags(np.asarray(off.sum(axis=1)).ravel())).tocsr()


def cotangent_stiffness(mesh: Mesh) -> sp.csr_matrix:
    """Positive semidefinite cotangent stiffness matrix ``W`` (n × n, CSR, float64); of a
    point cloud, the point-cloud Laplacian's (see [`laplacian`][bsfjax.laplacian])."""
    if mesh.is_point_cloud:
        return _point_cloud_laplacian(mesh)[0]
    cots, _, _ = _corner_geometry(mesh.vertices, mesh.faces)
    return _stiffness(mesh.faces, cots, mesh.n_vertices)


def _mass(f: np.ndarray, cots: np.ndarray, dbl_area: np.ndarray, sq: np.ndarray, n: int,
          kind: str) -> np.ndarray:
    area = 0.5 * dbl_area
    if kind == "barycentric":
        per_corner = np.broadcast_to(area / 3.0, (3, area.size))
    else:
        # Voronoi share of corner c: ⅛ Σ over its two edges of |edge|² cot(opposite corner)
        sc = sq * cots
        vor = (sc[[1, 2, 0]] + sc[[2, 0, 1]]) / 8.0
        obtuse = cots < 0  # cot θ < 0 ⇔ θ > 90°
        per_corner = np.where(obtuse.any(axis=0), np.where(obtuse, area / 2, area / 4), vor)
    return np.bincount(f.T.ravel(), weights=per_corner.ravel(), minlength=n)


def mass_matrix(mesh: Mesh, kind: str = "mixed") -> sp.csr_matrix:
    """Diagonal (lumped) mass matrix ``A`` (n × n, CSR, float64).

    ``kind="barycentric"``: each triangle gives a third of its area to each corner.
    ``kind="mixed"``: the mixed Voronoi areas of Meyer et al. 2003 — the Voronoi region of the
    corner inside a non-obtuse triangle, ⅛(‖e_ij‖² cot θ_k + ‖e_ik‖² cot θ_j); in an obtuse
    triangle half the area to the obtuse corner and a quarter to each other one.  Both sum to the
    total surface area.
    """
    if kind not in MASS_TYPES:
        raise BSFError(f"mass must be one of {MASS_TYPES}, got {kind!r}")
    if mesh.is_point_cloud:
        return _point_cloud_laplacian(mesh)[1]
    cots, dbl_area, sq = _corner_geometry(mesh.vertices, mesh.faces)
    return sp.diags(_mass(mesh.faces, cots, dbl_area, sq, mesh.n_vertices, kind)).tocsr()


def laplacian(mesh: Mesh, mass: str = "mixed", robust: bool = False) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Cotangent stiffness ``W`` and diagonal mass ``A`` of ``mesh`` (both ``scipy.sparse``).

    **Arguments:**

    - `mesh`: a [`Mesh`][bsfjax.Mesh].
    - `mass`: ``"mixed"`` (default; mixed Voronoi, Meyer et al. 2003, libigl's default for
      triangles) or ``"barycentric"``.  Mixed Voronoi areas are the consistent dual areas
      of the cotangent operator on well-shaped meshes and stay positive on obtuse ones.
    - `robust`: use the intrinsic-Delaunay "robust" Laplacian of Sharp & Crane 2020
      (``pip install robust-laplacian``), for non-manifold or badly triangulated meshes.
      Its mass is the lumped intrinsic Voronoi area.

    A [`PointCloud`][bsfjax.PointCloud] gets the point-cloud Laplacian of Sharp & Crane 2020
    (robust-laplacian's ``point_cloud_laplacian``, 30 neighbours per point), whatever `mass`
    and `robust` say: ``A`` is each point's lumped area, so everything downstream of the
    spectrum treats the cloud like a mesh.

    **Returns:**

    ``(W, A)``: ``W`` symmetric PSD with ``W·1 = 0``; ``A`` diagonal with positive entries.
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    if not isinstance(mesh, Mesh):
        raise MeshError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    if mesh.is_point_cloud:
        if mass not in MASS_TYPES:
            raise BSFError(f"mass must be one of {MASS_TYPES}, got {mass!r}")
        return _point_cloud_laplacian(mesh)
    if robust:
        try:
            import robust_laplacian
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("robust=True needs the robust-laplacian package: "
                              "pip install 'bsfjax[robust]'") from exc
        W, A = robust_laplacian.mesh_laplacian(np.asarray(mesh.vertices), np.asarray(mesh.faces))
        W, A = sp.csr_matrix(W), sp.csr_matrix(A)
        a = A.diagonal()
        if not (np.isfinite(W.data).all() and np.isfinite(a).all()) or np.any(a <= 0):
            where = f"{mesh.name}: " if mesh.name else ""
            raise MeshError(f"{where}robust Laplacian has {int(np.sum(~(a > 0)))} vertices with "
                            "zero or undefined mass (unreferenced or only in zero-area faces)")
        return W, A
    if mass not in MASS_TYPES:
        raise BSFError(f"mass must be one of {MASS_TYPES}, got {mass!r}")
    v, f, n = mesh.vertices, mesh.faces, mesh.n_vertices
    cots, dbl_area, sq = _corner_geometry(v, f)  # shared by W and A
    W = _stiffness(f, cots, n)
    a = _mass(f, cots, dbl_area, sq, n, mass)
    A = sp.diags(a).tocsr()
    bad = ~(a > 0)  # also catches NaN
    where = f"{mesh.name}: " if mesh.name else ""
    if not np.isfinite(W.data).all():  # needle-thin faces: cotangents beyond float64
        raise MeshError(f"{where}cotangent weights overflow (nearly degenerate faces); "
                        "use laplacian(..., robust=True)")
    if bad.any():
        raise MeshError(f"{where}{int(bad.sum())} vertices have zero mass "
                        "(unreferenced or only in zero-area faces; bsfjax._mesh.clean_mesh "
                        "removes them)")
    return W, A
