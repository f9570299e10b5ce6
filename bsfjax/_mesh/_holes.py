"""Holes of a scan: its boundary loops, and patches that close them for the spectrum only.

Owner of [`boundary_loops`][bsfjax.boundary_loops], [`fill_holes`][bsfjax.fill_holes] and
[`HoleFill`][bsfjax.HoleFill].  A hole changes the Laplace–Beltrami spectrum (a free, Neumann,
boundary where the surface should go on): the eigenfunctions bend around it and the map's
descriptors move.  [`prepare_scan`][bsfjax.prepare_scan] closes each hole with a smooth patch
of new vertices, so that the spectrum is nearly the one of the closed surface, and every value
computed on the filled mesh comes back to the mesh as read without them
([`HoleFill.restrict`][bsfjax.HoleFill.restrict]): the added vertices and triangles come AFTER
the original ones, whose indices, order and coordinates are unchanged.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg

from .._util import MeshError
from ._mesh import Mesh

__all__ = ["HoleFill", "boundary_loops", "fill_holes"]


def boundary_loops(mesh: Mesh) -> list[np.ndarray]:
    """The closed boundary loops of a triangle mesh, longest first.

    A boundary edge is an edge used by exactly one triangle; a loop follows its triangles'
    orientation (edge ``a → b`` of its triangle, then the boundary edge leaving ``b``).  A
    vertex where several loops meet (two holes touching at a corner) splits them; boundary
    edges that close no loop (inconsistent orientation) are left out.

    **Arguments:**

    - `mesh`: a [`Mesh`][bsfjax.Mesh] (a point cloud has no boundary: ``[]``).

    **Returns:** a list of ``(L,)`` int64 arrays of vertex indices, ``L ≥ 3``, each in the
    order of its boundary edges.
    """
    if not isinstance(mesh, Mesh):
        raise MeshError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    f = np.asarray(mesh.faces)
    if f.shape[0] == 0:
        return []
    he = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = np.sort(he, axis=1)
    _, inv, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    bnd = he[count[inv.reshape(-1)] == 1]
    out: dict[int, list[int]] = {}
    for a, b in bnd.tolist():
        out.setdefault(a, []).append(b)
    loops: list[np.ndarray] = []
    for start in list(out):
        while out[start]:
            path, pos, v = [start], {start: 0}, start
            while True:
                if not out.get(v):  # a dead end: inconsistent orientation, no loop
                    break
                w = out[v].pop()
                if w in pos:  # a loop closed: cut it off the path
                    p = pos[w]
                    if len(path) - p >= 3:
                        loops.append(np.asarray(path[p:], np.int64))
                    for u in path[p + 1:]:
                        del pos[u]
                    path, v = path[:p + 1], w
                    if len(path) == 1 and not out[v]:
                        break
                else:
                    pos[w] = len(path)
                    path.append(w)
                    v = w
    loops.sort(key=len, reverse=True)
    return loops


class HoleFill(NamedTuple):
    """A mesh with its holes closed, and the way back; what [`fill_holes`][bsfjax.fill_holes]
    returns.

    **Attributes:**

    - `mesh`: the filled [`Mesh`][bsfjax.Mesh]: the original vertices first (unchanged, in
      order), then the added ones; the original triangles first, then the added ones.
    - `original`: the mesh as given.
    - `loops`: the boundary loops that were filled (vertex indices of ``original``).
    - `nearest`: ``(n_added,)`` per added vertex, the original vertex (of its loop) nearest to
      it: the value an added vertex takes from values on the original vertices.
    - `nearest_face`: ``(n_added_faces,)`` per added triangle, an original triangle on the
      boundary of its patch.
    """

    mesh: Mesh
    original: Mesh
    loops: tuple
    nearest: np.ndarray
    nearest_face: np.ndarray

    @property
    def n_added(self) -> int:
        """Vertices added."""
        return int(self.mesh.n_vertices - self.original.n_vertices)

    @property
    def n_added_faces(self) -> int:
        """Triangles added."""
        return int(self.mesh.n_faces - self.original.n_faces)

    def restrict(self, values, *, faces: bool = False) -> np.ndarray:
        """Values on the filled mesh (first axis: its vertices, or triangles with ``faces``) on
        the original mesh: the added rows dropped."""
        v = np.asarray(values)
        n, n0 = ((self.mesh.n_faces, self.original.n_faces) if faces else
                 (self.mesh.n_vertices, self.original.n_vertices))
        if v.shape[:1] != (n,):
            raise MeshError(f"values must have one row per {'triangle' if faces else 'vertex'} "
                            f"of the filled mesh ({n}), got shape {v.shape}")
        return v[:n0]

    def extend(self, values, *, faces: bool = False) -> np.ndarray:
        """Values on the original mesh (first axis: its vertices, or triangles with ``faces``)
        on the filled mesh: an added vertex (triangle) takes the value of ``nearest``
        (``nearest_face``)."""
        v = np.asarray(values)
        n0 = self.original.n_faces if faces else self.original.n_vertices
        if v.shape[:1] != (n0,):
            raise MeshError(f"values must have one row per original "
                            f"{'triangle' if faces else 'vertex'} ({n0}), got shape {v.shape}")
        return np.concatenate([v, v[self.nearest_face if faces else self.nearest]])


def _ring_patch(n_loop: int, n_rings: int, first: int):
    """The connectivity of a patch of concentric rings closing a loop of ``n_loop`` vertices
    (local ids ``0 … n_loop-1``, in the loop's order): ring ``j`` (``1 … n_rings-1``) has
    about ``n_loop (n_rings - j) / n_rings`` vertices (at least 3), and a centre vertex closes
    the innermost ring.  New vertices are numbered from ``first``; returns (the number of new
    vertices, their ring parameters ``(s, t)`` (``s``: ring / n_rings, ``t`` in ``[0, 1)``:
    place along the ring), triangles in global-local ids).  The triangles are oriented against
    the loop (its edge ``a → b`` appears as ``b → a``), so the patch continues the surface's
    orientation."""
    outer = list(range(n_loop))  # local ids of the loop; new vertices: first + i
    st, tris = [], []
    nxt = first
    for j in range(1, n_rings):
        n_j = max(3, int(round(n_loop * (n_rings - j) / n_rings)))
        if n_j >= len(outer) and j > 1:
            n_j = len(outer) - 1
        if n_j < 3:
            break
        inner = list(range(nxt, nxt + n_j))
        st += [(j / n_rings, m / n_j) for m in range(n_j)]
        nxt += n_j
        tris += _zip(outer, inner)
        outer = inner
    if len(outer) == 3 and nxt == first:  # a triangle hole: one triangle
        tris.append([outer[2], outer[1], outer[0]])
    else:  # a centre vertex closes the innermost ring
        c = nxt
        st.append((1.0, 0.0))
        nxt += 1
        tris += [[outer[(i + 1) % len(outer)], outer[i], c] for i in range(len(outer))]
    return nxt - first, st, tris


def _zip(a: list, b: list) -> list:
    """Triangles joining closed ring ``a`` to the closed ring ``b`` inside it (both in the same
    direction, ``b[0]`` next to ``a[0]``), oriented against ``a``'s edges."""
    na, nb, i, j, tris = len(a), len(b), 0, 0, []
    while i < na or j < nb:
        if j >= nb or (i < na and (i + 1) / na <= (j + 1) / nb):
            tris.append([a[(i + 1) % na], a[i % na], b[j % nb]])
            i += 1
        else:
            tris.append([a[i % na], b[j % nb], b[(j + 1) % nb]])
            j += 1
    return tris


def _fair(vertices: np.ndarray, faces: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Positions of the ``free`` vertices that minimise the bi-Laplacian (thin-plate) energy
    ``‖L x‖²`` of the uniform graph Laplacian ``L`` with the other vertices fixed: the
    solution of ``(L²)_{UU} x_U = −(L²)_{UK} x_K`` (a smooth patch, tangent to the surface
    around the hole)."""
    n = vertices.shape[0]
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    a = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    a = ((a + a.T) > 0).astype(np.float64)
    deg = np.asarray(a.sum(axis=1)).ravel()
    lap = (sp.diags(deg) - a).tocsr()
    # only the rows near the patch matter: the free vertices, their 2-ring
    near = np.zeros(n, bool)
    near[free] = True
    for _ in range(2):
        near |= (a @ near.astype(np.float64)) > 0
    rows = lap[np.flatnonzero(near)]
    m = (rows.T @ rows).tocsr()
    fixed = np.setdiff1d(np.arange(n), free)
    rhs = -(m[free][:, fixed] @ vertices[fixed])
    out = vertices.copy()
    out[free] = np.column_stack([scipy.sparse.linalg.spsolve(m[free][:, free].tocsc(), rhs[:, d])
                                 for d in range(3)])
    return out


def fill_holes(mesh: Mesh, max_share: float | None = None) -> HoleFill:
    """Close the holes of ``mesh`` with smooth patches of new vertices.

    Each boundary loop ([`boundary_loops`][bsfjax.boundary_loops]) of ``L`` vertices is closed
    by ``R = max(1, round(ρ / h))`` concentric rings (``ρ``: the loop's mean distance to its
    centroid, ``h``: its mean edge length) of about ``L (R − j) / R`` vertices each and a
    centre vertex, joined ring to ring by triangles of matching orientation; the new vertices
    are then placed by thin-plate fairing (``min ‖L x‖²`` for the uniform graph Laplacian
    ``L``, the original vertices fixed), so the patch continues the surface smoothly.  The
    original vertices and triangles keep their indices; the new ones come after them.

    **Arguments:**

    - `mesh`: a [`Mesh`][bsfjax.Mesh] (a point cloud, or a closed mesh, comes back as it is).
    - `max_share`: fill only loops whose patch would be small: ``π ρ²`` at most this share of
      the mesh's area (``None``: every loop).

    **Returns:** a [`HoleFill`][bsfjax.HoleFill].
    """
    loops = boundary_loops(mesh)
    v0 = np.asarray(mesh.vertices)
    if max_share is not None:
        if not max_share > 0:
            raise MeshError(f"max_share must be positive, got {max_share}")
        total = mesh.area
        loops = [lp for lp in loops
                 if np.pi * np.mean(np.linalg.norm(v0[lp] - v0[lp].mean(axis=0), axis=1)) ** 2
                 <= max_share * total]
    if not loops:
        return HoleFill(mesh, mesh, (), np.zeros(0, np.int64), np.zeros(0, np.int64))
    n0 = mesh.n_vertices
    new_pos, new_faces, nearest, patch_of = [], [], [], []
    nxt = n0
    for lp in loops:
        p = v0[lp]
        centre = p.mean(axis=0)
        h = float(np.linalg.norm(p - np.roll(p, -1, axis=0), axis=1).mean())
        rho = float(np.linalg.norm(p - centre, axis=1).mean())
        n_rings = max(1, int(round(rho / max(h, 1e-300))))
        n_new, st, tris = _ring_patch(len(lp), n_rings, nxt)
        for s, t in st:  # a start: between the loop and its centroid (fairing moves it)
            q = p[int(np.floor(t * len(lp))) % len(lp)]
            new_pos.append((1 - s) * q + s * centre)
        lookup = np.concatenate([lp, np.arange(nxt, nxt + n_new)])
        tris = np.asarray(tris, np.int64)
        local = np.where(tris < len(lp), tris, tris - nxt + len(lp))
        new_faces.append(lookup[local])
        patch_of.append((lp, nxt, n_new, len(tris)))
        nxt += n_new
    verts = np.concatenate([v0, np.asarray(new_pos).reshape(-1, 3)])
    faces = np.concatenate([np.asarray(mesh.faces)] + new_faces)
    free = np.arange(n0, nxt)
    if free.size:
        verts = _fair(verts, faces, free)
    from scipy.spatial import cKDTree

    nearest, nearest_face = [], []
    f0 = np.asarray(mesh.faces)
    # the original triangle of each boundary edge a → b: looked up by the key a·n + b
    he = np.concatenate([f0[:, [0, 1]], f0[:, [1, 2]], f0[:, [2, 0]]])
    keys = he[:, 0] * n0 + he[:, 1]
    order = np.argsort(keys)
    face_of = np.tile(np.arange(f0.shape[0]), 3)[order]
    for i, (lp, start, n_new, n_tris) in enumerate(patch_of):
        if n_new:
            nearest.append(lp[cKDTree(verts[lp]).query(verts[start:start + n_new])[1]])
        # the added triangles: the original triangle of the boundary edge nearest to them
        edge_faces = face_of[np.searchsorted(keys[order], lp * n0 + np.roll(lp, -1))]
        mids = verts[f0[edge_faces]].mean(axis=1)
        nearest_face.append(edge_faces[cKDTree(mids).query(
            verts[new_faces[i]].mean(axis=1))[1]])
    filled = Mesh(verts, faces, name=mesh.name)
    return HoleFill(filled, mesh, tuple(loops),
                    np.concatenate(nearest) if nearest else np.zeros(0, np.int64),
                    np.concatenate(nearest_face))
