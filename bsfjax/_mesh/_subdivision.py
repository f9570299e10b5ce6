"""Mesh refinement: Loop and midpoint subdivision (vectorized, sparse).

Used to make large test meshes from real ones (e.g. the TOSCA cat at ~111K and ~445K vertices).
Each scheme maps ``(n, m)`` to ``(n + e, 4m)`` with ``e`` the number of edges; new vertex
``n + j`` sits on edge ``j`` of `mesh_edges`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._util import BSFError, require_triangles
from ._graph import mesh_edges
from ._mesh import Mesh
from ._interop import as_mesh

__all__ = ["subdivide"]


def _loop_weights(n: int, faces: np.ndarray, edges: np.ndarray, face_edges: np.ndarray) -> sp.csr_matrix:
    """Sparse ``(n + e, n)`` matrix of Loop's stencils (Loop 1987; boundary rules of Hoppe et al.)."""
    e = edges.shape[0]
    m = faces.shape[0]
    # faces per edge: 2 interior, 1 boundary
    edge_face_count = np.bincount(face_edges.ravel(), minlength=e)
    if edge_face_count.max() > 2:
        raise BSFError("Loop subdivision needs a manifold mesh: some edge has more than 2 faces")
    boundary_edge = edge_face_count == 1
    # opposite vertex of each (face, edge slot): slot 0 (v0v1) ↔ v2, slot 1 ↔ v0, slot 2 ↔ v1
    opp = faces[:, [2, 0, 1]]
    rows, cols, vals = [], [], []
    # odd (edge) vertices
    ends = edges
    w_end = np.where(boundary_edge, 0.5, 3.0 / 8.0)
    rows += [n + np.arange(e)] * 2
    cols += [ends[:, 0], ends[:, 1]]
    vals += [w_end, w_end]
    fe = face_edges.ravel()
    interior_slot = ~boundary_edge[fe]
    rows.append(n + fe[interior_slot])
    cols.append(opp.ravel()[interior_slot])
    vals.append(np.full(interior_slot.sum(), 1.0 / 8.0))
    # even (old) vertices
    adj = sp.csr_matrix((np.ones(2 * e), (np.concatenate([ends[:, 0], ends[:, 1]]),
                                          np.concatenate([ends[:, 1], ends[:, 0]]))), shape=(n, n))
    valence = np.asarray(adj.sum(axis=1)).ravel()
    on_boundary = np.zeros(n, bool)
    on_boundary[ends[boundary_edge].ravel()] = True
    val = np.maximum(valence, 1)
    beta = (5.0 / 8.0 - (3.0 / 8.0 + 0.25 * np.cos(2 * np.pi / val)) ** 2) / val
    # interior vertices: (1 − nβ) v + β Σ neighbours
    inner = ~on_boundary
    ai, aj = adj.nonzero()
    keep = inner[ai]
    rows += [ai[keep], np.flatnonzero(inner)]
    cols += [aj[keep], np.flatnonzero(inner)]
    vals += [beta[ai[keep]], (1 - valence * beta)[inner]]
    # boundary vertices: ¾ v + ⅛ (its two boundary neighbours)
    bi = np.flatnonzero(on_boundary)
    be = ends[boundary_edge]
    rows += [bi, be[:, 0], be[:, 1]]
    cols += [bi, be[:, 1], be[:, 0]]
    vals += [np.full(bi.size, 0.75), np.full(be.shape[0], 0.125), np.full(be.shape[0], 0.125)]
    del m
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n + e, n))


def subdivide(mesh: Mesh, scheme: str = "loop", levels: int = 1) -> Mesh:
    """Subdivide ``mesh`` ``levels`` times: every triangle becomes four.

    ``scheme="loop"`` smooths (Loop 1987; boundary curves by the cubic B-spline rule),
    ``"midpoint"`` keeps the geometry (new vertices at edge midpoints).  Vertex ``i < n`` of the
    result is the (moved, for Loop) vertex ``i`` of the input, so per-vertex correspondences of
    the coarse mesh carry over to the first ``n`` vertices.
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    require_triangles(mesh, "a point cloud cannot be subdivided: subdivision splits triangles")
    if scheme not in ("loop", "midpoint"):
        raise BSFError(f"scheme must be 'loop' or 'midpoint', got {scheme!r}")
    if not isinstance(levels, (int, np.integer)) or levels < 0:
        raise BSFError(f"levels must be a non-negative integer, got {levels!r}")
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    for _ in range(levels):
        n = v.shape[0]
        edges, fe = mesh_edges(f)
        if scheme == "loop":
            v = _loop_weights(n, f, edges, fe) @ v
        else:
            v = np.concatenate([v, 0.5 * (v[edges[:, 0]] + v[edges[:, 1]])])
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        ab, bc, ca = n + fe[:, 0], n + fe[:, 1], n + fe[:, 2]
        f = np.concatenate([np.stack(t, 1) for t in ([a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca])])
    return Mesh(v, f, name=mesh.name)
