"""Denoising a point cloud: the cloud counterparts of `noise_level` and `denoise`'s Taubin
smoothing (`bsfjax._mesh._denoise`), with each point's ``k`` nearest neighbours (symmetrized)
in place of a vertex's one-ring and the PCA normals of `cloud_normals` in place of the
vertex normals, so that one noise level means the same roughness on a mesh and on a cloud.

Owner of `cloud_noise_level`, `cloud_smooth` and `CLOUD_NEIGHBORS`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ._cloud_surface import _frames, _neighbours, _orient

__all__ = ["cloud_noise_level", "cloud_smooth", "CLOUD_NEIGHBORS"]

#: The "one-ring" of a point for the noise level and the smoothing: its 6 nearest neighbours
#: (a triangle mesh's vertex has 6 on average), symmetrized.
CLOUD_NEIGHBORS = 6


def _ring(pts: np.ndarray, k: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """The averaging operator of the symmetrized k-NN graph (row ``i``: the mean of ``i``'s
    neighbours) and the neighbour array ``(n, k)``."""
    n = pts.shape[0]
    k = min(int(k), n - 1)
    nbr = _neighbours(pts, k)
    A = sp.csr_matrix((np.ones(nbr.size), (np.repeat(np.arange(n), k), nbr.ravel())),
                      shape=(n, n))
    A = ((A + A.T) > 0).astype(np.float64)
    deg = np.asarray(A.sum(axis=1)).ravel()
    return sp.diags(1.0 / np.maximum(deg, 1)) @ A, nbr


def cloud_noise_level(points: np.ndarray, k: int = CLOUD_NEIGHBORS) -> float:
    """`noise_level` of a point cloud: each point's offset from the mean of its ``k`` nearest
    neighbours (symmetrized) along its PCA normal (signs made consistent as in
    `cloud_normals`), minus the neighbours' mean of those offsets; the root mean square over
    the mean distance to the ``k`` nearest neighbours."""
    pts = np.asarray(points, np.float64)
    if pts.shape[0] < 4:
        return 0.0
    W, nbr = _ring(pts, k)
    big = _neighbours(pts, min(12, pts.shape[0] - 1))
    normals = _frames(pts, big)[:, :, 0]
    normals = normals * _orient(pts, normals, big)[:, None]
    d = np.einsum("ij,ij->i", pts - W @ pts, normals)
    r = d - W @ d
    h = float(np.linalg.norm(pts[nbr] - pts[:, None], axis=2).mean())
    return float(np.sqrt(np.mean(r**2)) / h) if h > 0 else 0.0


def cloud_smooth(points: np.ndarray, n_iter: int, lam: float, mu: float,
                 k: int = CLOUD_NEIGHBORS) -> np.ndarray:
    """``n_iter`` Taubin λ/μ iterations on the symmetrized k-NN averaging operator
    (``x ← x + λ (W x − x)``, then ``μ``): ``(n, 3)`` smoothed points, in their order."""
    v = np.array(points, dtype=np.float64)
    if n_iter <= 0:
        return v
    W, _ = _ring(v, k)  # the graph of the noisy points, kept for every iteration
    for _ in range(int(n_iter)):
        v = v + lam * (W @ v - v)
        v = v + mu * (W @ v - v)
    return v
