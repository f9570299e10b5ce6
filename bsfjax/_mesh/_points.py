"""Point clouds from meshes: area-uniform samples of a triangle mesh's surface (for tests,
benchmarks and scan-like targets)."""

from __future__ import annotations

import numpy as np

from .._util import BSFError
from ._mesh import Mesh
from ._interop import as_mesh

__all__ = ["sample_surface"]


def sample_surface(mesh: Mesh, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` points drawn uniformly by area from ``mesh``'s triangles, deterministically from
    ``seed``: ``(points (n, 3), face (n,), barycentric (n, 3))``, each point
    ``Σ_c barycentric[:, c] · vertices[faces[face, c]]``."""
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    if mesh.is_point_cloud:
        raise BSFError("sample_surface needs a triangle mesh (a point cloud has no surface)")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise BSFError(f"n must be a positive int, got {n!r}")
    rng = np.random.default_rng(seed)
    area = mesh.face_areas()
    face = rng.choice(area.size, size=int(n), p=area / area.sum())
    r1, r2 = rng.random(int(n)), rng.random(int(n))
    s = np.sqrt(r1)
    bary = np.stack([1.0 - s, s * (1.0 - r2), s * r2], axis=1)
    points = np.einsum("nc,ncd->nd", bary, mesh.vertices[mesh.faces[face]])
    return points, face, bary
