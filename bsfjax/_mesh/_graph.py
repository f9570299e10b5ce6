"""Graph helpers of a triangle mesh: edges, weighted edge graphs and connected components. Owner
of `mesh_edges` (the unique undirected edges and each face's edges), `graph_from_edges` and
`edge_graph` (sparse weighted graphs, for Dijkstra), `n_components`, and of a point cloud's
stand-in for edges, `knn_edges` (its symmetrized k-nearest-neighbour graph).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph

from ._mesh import Mesh

__all__ = ["mesh_edges", "graph_from_edges", "edge_graph", "n_components", "knn_edges",
           "KNN_NEIGHBORS"]

#: Neighbours per point of a point cloud's graph (geodesics by Dijkstra, components).  On 15K
#: points sampled from a FAUST body, 8 neighbours keep the body one component.
KNN_NEIGHBORS = 8


def knn_edges(points: np.ndarray, k: int = KNN_NEIGHBORS) -> np.ndarray:
    """Unique undirected edges ``(e, 2)`` (sorted pairs, lexicographic order) joining every
    point to its ``k`` nearest other points (the symmetrized k-NN graph of a point cloud)."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, np.float64)
    n = pts.shape[0]
    k = min(int(k), n - 1)
    if k < 1:
        return np.zeros((0, 2), np.int64)
    _, idx = cKDTree(pts).query(pts, k=k + 1)
    rows = np.repeat(np.arange(n), k + 1)
    cols = idx.ravel()
    keep = rows != cols  # (a duplicate point may come first: any self pair is dropped)
    lo, hi = np.minimum(rows, cols)[keep], np.maximum(rows, cols)[keep]
    keys = np.unique(lo.astype(np.int64) * n + hi)
    return np.stack([keys // n, keys % n], axis=1)


def mesh_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges ``(e, 2)`` (sorted pairs, lexicographic order) and, per face,
    the index of its edges ``(m, 3)`` in the order (v0v1, v1v2, v2v0)."""
    faces = np.asarray(faces, dtype=np.int64)
    if faces.size == 0:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3), np.int64)
    half = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    lo, hi = half.min(axis=1), half.max(axis=1)
    # one int64 key per sorted pair (lo·n + hi sorts like the pair): a 1-D unique is several
    # times faster than np.unique(..., axis=0) on rows
    n = int(hi.max()) + 1
    keys, inv = np.unique(lo * n + hi, return_inverse=True)
    edges = np.stack([keys // n, keys % n], axis=1)
    return edges, inv.reshape(3, -1).T


def graph_from_edges(n: int, edges: np.ndarray, weights: np.ndarray) -> sp.csr_matrix:
    """Symmetric ``(n, n)`` sparse graph with ``weights`` on ``edges`` (both directions).

    scipy's csgraph reads an explicit 0 as "no edge", so zero weights (duplicate vertices) are
    raised to the smallest positive float: their endpoints stay connected at distance ~0.
    """
    w = np.maximum(np.asarray(weights, dtype=np.float64), np.finfo(np.float64).tiny)
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    return sp.csr_matrix((np.concatenate([w, w]), (rows, cols)), shape=(n, n))


def _edges(mesh: "Mesh") -> np.ndarray:
    """A mesh's unique edges; a point cloud's k-NN edges."""
    if mesh.is_point_cloud:
        return knn_edges(mesh.vertices)
    return mesh_edges(mesh.faces)[0]


def edge_graph(mesh: "Mesh") -> sp.csr_matrix:
    """The mesh's edge graph weighted by edge length (for Dijkstra), ``(n, n)`` CSR; of a
    point cloud, its symmetrized k-nearest-neighbour graph (`knn_edges`)."""
    e = _edges(mesh)
    lengths = np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    return graph_from_edges(mesh.n_vertices, e, lengths)


def n_components(mesh: "Mesh", edges: np.ndarray | None = None) -> int:
    """Connected components of the mesh's edge graph (an isolated vertex is one of its own);
    ``edges`` from `mesh_edges` if already at hand.  A point cloud's: of its k-NN graph."""
    if edges is None and mesh.is_point_cloud:
        e = knn_edges(mesh.vertices)
    elif edges is None:  # the faces' half-edges as they are: no de-duplication needed here
        f = np.asarray(mesh.faces, dtype=np.int64)
        e = np.stack([f.ravel(), np.roll(f, -1, axis=1).ravel()], axis=1)
    else:
        e = edges
    g = sp.coo_matrix((np.ones(len(e), np.int32), (e[:, 0], e[:, 1])),
                      shape=(mesh.n_vertices,) * 2).tocsr()
    return int(scipy.sparse.csgraph.connected_components(g, directed=False)[0])
