r"""A point cloud's oriented stand-in surface: normals oriented consistently (Hoppe et al.
1992) and globally outward, and a triangulation by local tangent-plane Delaunay fans, so that
what needs triangles with a consistent orientation (the landmark-free map's orientation term,
its geodesic distortions and orientation agreement) runs on a cloud.

Owner of `cloud_normals` and `cloud_surface`.  The surface's vertices are the cloud's points,
in their order: every per-vertex array (spectra, point maps, labels) stays valid on it.

**Normals.**  Each point's normal is the smallest principal axis of its ``k`` nearest
neighbours (PCA).  Signs are made consistent along the minimum spanning tree of the
symmetrized k-NN graph weighted by ``1 − |n_i · n_j|`` (Hoppe et al. 1992: the tree follows
flat, well-aligned neighbourhoods first), then each connected piece is turned outward: the
signed volume ``Σ_t det(p_a, p_b, p_c) / 6`` of its fans must be positive.

**Fans.**  On each point's tangent plane (the two largest principal axes, right-handed with
the normal) its neighbours' projections are ``q_j``; the point's Voronoi cell among them is
``{x : x · q_j ≤ |q_j|² / 2}``, and ``j`` is a Delaunay neighbour when its half-plane bounds
the cell along an edge of positive length.  Consecutive Delaunay neighbours in angle
(gaps under π) with the point make counter-clockwise triangles, whose normals agree with the
point's.  The fans of all points are merged; a triangle found by several of its corners is
kept once (unordered corners).  On a well-sampled smooth surface the union is close to a
triangulation (Sharp & Crane 2020 build their point-cloud Laplacian on the same local
triangulations): its area is within a few per cent of the surface's.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph

from .._util import BSFError
from ._mesh import Mesh, PointCloud

__all__ = ["cloud_normals", "cloud_surface", "CloudSurface", "SURFACE_NEIGHBORS"]

#: Neighbours per point for the normals and the tangent-plane fans.
SURFACE_NEIGHBORS = 12


class CloudSurface(Mesh):
    """A [`Mesh`][bsfjax.Mesh] made by [`cloud_surface`][bsfjax.cloud_surface] from a point cloud:
    the cloud's points as vertices and its tangent-plane Delaunay fans as triangles.  Its
    triangles overlap a little and may leave small gaps, so its face areas are not the
    cloud's lumped areas: spectra stay on the cloud (the point-cloud Laplacian)."""

    #: (read by the spectrum checks: its triangles' area is not its spectrum's mass)
    from_cloud = True

    @property
    def area(self) -> float:
        """The cloud's area: the lumped area of its point-cloud Laplacian (what its spectrum's
        mass sums to), not the sum of the overlapping triangles' areas (a few per cent more),
        so that distances at unit area (the geodesic distortion) match the spectrum's."""
        cached = self.__dict__.get("_area")
        if cached is None:
            cached = PointCloud(self.vertices).area
            object.__setattr__(self, "_area", cached)
        return cached

    def __repr__(self) -> str:
        name = f", name={self.name!r}" if self.name else ""
        return f"CloudSurface(n_points={self.n_vertices}, n_faces={self.n_faces}{name})"


def _points(cloud) -> np.ndarray:
    pts = np.asarray(cloud.vertices if isinstance(cloud, Mesh) else cloud, np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise BSFError(f"a point cloud must be (n, 3) points, got shape {pts.shape}")
    if pts.shape[0] < 4:
        raise BSFError(f"a point cloud's surface needs at least 4 points, got {pts.shape[0]}")
    return pts


def _neighbours(pts: np.ndarray, k: int) -> np.ndarray:
    """``(n, k)`` the ``k`` nearest other points of each point (a duplicate point may be one)."""
    from scipy.spatial import cKDTree

    _, idx = cKDTree(pts).query(pts, k=k + 1)
    n = pts.shape[0]
    self_col = idx == np.arange(n)[:, None]
    # drop each point itself (or, for a duplicate found first, the last column)
    drop = np.where(self_col.any(axis=1), self_col.argmax(axis=1), k)
    keep = np.ones_like(idx, bool)
    keep[np.arange(n), drop] = False
    return idx[keep].reshape(n, k)


def _frames(pts: np.ndarray, nbr: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` principal axes of each point's neighbourhood (itself included), columns
    in increasing variance: column 0 is the (unoriented) normal."""
    local = np.concatenate([pts[:, None], pts[nbr]], axis=1)
    local = local - local.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local)
    return np.linalg.eigh(cov)[1]


def _orient(pts, normals, nbr) -> np.ndarray:
    """Signs ``±1`` making neighbouring normals agree: propagation along the minimum spanning
    tree of the k-NN graph weighted by ``1 − |n_i · n_j|`` (Hoppe et al. 1992), from each
    component's point of largest x."""
    n, k = nbr.shape
    rows = np.repeat(np.arange(n), k)
    cols = nbr.ravel()
    w = 1.0 - np.abs(np.einsum("ij,ij->i", normals[rows], normals[cols])) + 1e-9
    g = sp.csr_matrix((w, (rows, cols)), shape=(n, n))
    g = g.maximum(g.T)
    tree = csgraph.minimum_spanning_tree(g)
    tree = tree + tree.T
    n_comp, comp = csgraph.connected_components(tree, directed=False)
    sign = np.ones(n)
    for c in range(n_comp):
        members = np.flatnonzero(comp == c)
        root = members[np.argmax(pts[members, 0])]
        order, pred = csgraph.breadth_first_order(tree, root, directed=False)
        for i in order[1:]:  # parents come first in breadth-first order
            p = pred[i]
            sign[i] = sign[p] if normals[i] @ normals[p] >= 0 else -sign[p]
    return sign


def _fans(pts, frames, nbr) -> np.ndarray:
    """Counter-clockwise triangles (about each point's oriented normal, ``frames[:, :, 0]``)
    of each point's tangent-plane Delaunay fan: ``(m, 3)`` with each point first."""
    n, k = nbr.shape
    e1, e2 = frames[:, :, 2], frames[:, :, 1]
    e2 = np.cross(frames[:, :, 0], e1)  # right-handed with the oriented normal
    d = pts[nbr] - pts[:, None]
    q = np.stack([np.einsum("nkx,nx->nk", d, e1), np.einsum("nkx,nx->nk", d, e2)], axis=-1)
    qq = np.einsum("nkx,nkx->nk", q, q)
    perp = np.stack([-q[..., 1], q[..., 0]], axis=-1)
    # edge of the cell on line j: x = q_j / 2 + t perp_j, bounded by every other half-plane l:
    # t (perp_j · q_l) <= (|q_l|² − q_j · q_l) / 2
    a = np.einsum("njx,nlx->njl", perp, q)
    b = 0.5 * (qq[:, None, :] - np.einsum("njx,nlx->njl", q, q))
    eye = np.eye(k, dtype=bool)[None]
    tiny = 1e-12 * np.maximum(qq.max(axis=1), 1e-300)[:, None, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = b / a
    hi = np.where((a > tiny) & ~eye, t, np.inf).min(axis=2)
    lo = np.where((a < -tiny) & ~eye, t, -np.inf).max(axis=2)
    # a half-plane parallel to line j that excludes it altogether (b < 0) empties the edge
    cut = ((np.abs(a) <= tiny) & (b < 0) & ~eye).any(axis=2)
    scale = np.sqrt(qq.max(axis=1))[:, None]
    active = (hi - lo > 1e-9 * scale) & ~cut & (qq > 0)
    ang = np.where(active, np.arctan2(q[..., 1], q[..., 0]), np.inf)
    order = np.argsort(ang, axis=1)
    ang_s = np.take_along_axis(ang, order, axis=1)
    idx_s = np.take_along_axis(nbr, order, axis=1)
    count = active.sum(axis=1)
    tris = []
    for step in range(k):  # pairs (step, step + 1) of the sorted active neighbours, cyclic
        nxt = np.where(step + 1 < count, step + 1, 0)
        has = (step < count) & (count >= 2)
        a0 = ang_s[np.arange(n), np.minimum(step, k - 1)]
        a1 = ang_s[np.arange(n), nxt]
        gap = np.where(nxt > step, a1 - a0, a1 + 2 * np.pi - a0)
        ok = has & (gap > 0) & (gap < np.pi)
        rows = np.flatnonzero(ok)
        tris.append(np.stack([rows, idx_s[rows, step], idx_s[rows, nxt[rows]]], axis=1))
    return np.concatenate(tris) if tris else np.zeros((0, 3), np.int64)


def _dedupe(tris: np.ndarray) -> np.ndarray:
    """Each triangle once (unordered corners; the first orientation found), without
    degenerate ones (a repeated corner)."""
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])]
    key = np.sort(tris, axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    return tris[np.sort(first)]


def _volume(pts, tris) -> np.ndarray:
    """Per triangle ``det(p_a, p_b, p_c) / 6`` (about the centroid of the points)."""
    c = pts - pts.mean(axis=0)
    return np.einsum("ij,ij->i", c[tris[:, 0]], np.cross(c[tris[:, 1]], c[tris[:, 2]])) / 6.0


def _oriented(pts: np.ndarray, k: int):
    """(frames with oriented normal in column 0, neighbours, fan triangles)."""
    n = pts.shape[0]
    k = min(int(k), n - 1)
    nbr = _neighbours(pts, k)
    frames = _frames(pts, nbr)
    sign = _orient(pts, frames[:, :, 0], nbr)
    frames = frames.copy()
    frames[:, :, 0] *= sign[:, None]
    tris = _fans(pts, frames, nbr)
    # each connected piece outward: the signed volume of its fans positive
    n_comp, comp = csgraph.connected_components(
        sp.csr_matrix((np.ones(nbr.size), (np.repeat(np.arange(n), k), nbr.ravel())),
                      shape=(n, n)), directed=False)
    vol = np.bincount(comp[tris[:, 0]], _volume(pts, tris), minlength=n_comp)
    flip = vol[comp] < 0
    if flip.any():
        frames[flip, :, 0] *= -1
        tris = _fans(pts, frames, nbr)
    return frames, nbr, tris


def cloud_normals(cloud, k: int = SURFACE_NEIGHBORS) -> np.ndarray:
    """Unit normals of a point cloud, consistently oriented and outward: ``(n, 3)``.

    Each point's normal is the smallest principal axis of it and its ``k`` nearest neighbours;
    signs agree along the minimum spanning tree of the k-NN graph weighted by
    ``1 − |n_i · n_j|`` (Hoppe et al. 1992), and each connected piece points outward (the signed
    volume of its [`cloud_surface`][bsfjax.cloud_surface] triangles is positive).

    **Arguments:**

    - `cloud`: a [`PointCloud`][bsfjax.PointCloud] (or any [`Mesh`][bsfjax.Mesh]: its
      vertices) or ``(n, 3)`` points, at least 4.
    - `k`: neighbours per point (default 12).
    """
    pts = _points(cloud)
    return _oriented(pts, k)[0][:, :, 0].copy()


def cloud_surface(cloud, k: int = SURFACE_NEIGHBORS) -> CloudSurface:
    r"""A triangulation of a point cloud whose vertices are its points (same order) and whose
    triangles are consistently oriented outward: what the landmark-free map needs of a cloud
    (its orientation term, geodesic distortions and orientation agreement).

    Each point's ``k`` nearest neighbours are projected on its tangent plane (PCA); the point's
    Delaunay neighbours among them (those whose bisector bounds its Voronoi cell) make a fan of
    counter-clockwise triangles about its normal, oriented as in
    [`cloud_normals`][bsfjax.cloud_normals]; the fans of all points are merged, each triangle
    once.  A point in no triangle (a duplicate point) gets one with its two nearest other
    points, so that every point is joined to the rest.  ``bsfjax transfer`` and
    [`transfer_collection`][bsfjax.transfer_collection] give it to the estimator for a cloud
    without landmarks; in Python pass it as ``source_mesh`` / ``target_mesh`` of
    [`estimate_map`][bsfjax.estimate_map] and keep the spectrum on the cloud.

    **Arguments:**

    - `cloud`: a [`PointCloud`][bsfjax.PointCloud] or ``(n, 3)`` points, at least 4.
    - `k`: neighbours per point (default 12).

    **Returns:** a `CloudSurface` (a [`Mesh`][bsfjax.Mesh]) with the cloud's name.
    """
    pts = _points(cloud)
    k = min(int(k), pts.shape[0] - 1)
    if k < 3:
        raise BSFError(f"k must be at least 3 neighbours, got {k}")
    frames, nbr, tris = _oriented(pts, k)
    tris = _dedupe(tris)
    lone = np.setdiff1d(np.arange(pts.shape[0]), tris.ravel())
    if lone.size:  # (duplicates: the first two other neighbours)
        extra = np.stack([lone, nbr[lone, 0], nbr[lone, 1]], axis=1)
        tris = np.concatenate([tris, extra])
    name = getattr(cloud, "name", None)
    return CloudSurface(pts, tris.astype(np.int64), name=name)

