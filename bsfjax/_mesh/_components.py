"""A scan's connected components: its main body and the rest (scanner debris, a detached hand).

Owner of [`split_main_body`][bsfjax.split_main_body] and of [`MainBody`][bsfjax.MainBody]:
the spectrum, the map and the transfer run on the main body alone (one zero eigenvalue), and
the vertices of the other components take the value of the nearest main-body vertex when it is
near enough, else ``-1`` / NaN.
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph

from .._util import MeshError
from ._graph import mesh_edges
from ._mesh import FileRows, Mesh
from ._interop import as_mesh

__all__ = ["MainBody", "MIN_SHARE", "REACH", "split_main_body", "vertex_areas"]

#: A component other than the largest that holds at least this share of the area is not
#: debris: it is still left out of the map (labelled from the nearest surface), with a warning.
MIN_SHARE = 0.05
#: How far (in mean edge lengths of the main body) a vertex of another component may be from
#: the main body's nearest vertex and still take its value.
REACH = 4.0


def vertex_areas(mesh: Mesh) -> np.ndarray:
    """``(n,)`` barycentric vertex areas: a third of the area of every incident triangle
    (zero on a vertex no triangle uses)."""
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    third = np.repeat(mesh.face_areas() / 3.0, 3)
    return np.bincount(mesh.faces.ravel(), weights=third, minlength=mesh.n_vertices)


class MainBody(NamedTuple):
    """A mesh split into its main body (the largest connected component by area) and the rest;
    what [`split_main_body`][bsfjax.split_main_body] returns.

    **Attributes:**

    - `mesh`: the main body, a [`Mesh`][bsfjax.Mesh] of the same file: its ``vertex_ids`` are
      rows of the whole mesh's file, so [`from_file_rows`][bsfjax.Mesh.from_file_rows] and
      [`file_row_index`][bsfjax.Mesh.file_row_index] (landmarks) read the file's rows onto it.
    - `whole`: the mesh as given.
    - `vertices`: ``(n_body,)`` the vertex of ``whole`` of each main-body vertex.
    - `faces`: ``(m_body,)`` the triangle of ``whole`` of each main-body triangle.
    - `nearest`: ``(n_other,)`` per vertex of ``other``, the nearest main-body vertex when it
      lies within ``reach``, else ``-1``.
    - `other`: ``(n_other,)`` the vertices of ``whole`` in the other components.
    - `n_other_components`: how many other components.
    - `reach`: the distance bound (``REACH`` mean edge lengths of the main body).
    """

    mesh: Mesh
    whole: Mesh
    vertices: np.ndarray
    faces: np.ndarray
    other: np.ndarray
    nearest: np.ndarray
    n_other_components: int
    reach: float

    @property
    def n_labelled(self) -> int:
        """Vertices of the other components near enough to the main body to take a value."""
        return int(np.sum(self.nearest >= 0))

    @property
    def n_unassigned(self) -> int:
        """Vertices of the other components too far from the main body: ``-1`` / NaN."""
        return int(self.other.size - self.n_labelled)

    def summary(self) -> str:
        """One line: ``N vertices in K other components: M labelled from the nearest surface,
        R unassigned``."""
        return (f"{self.other.size} vertices in {self.n_other_components} other components: "
                f"{self.n_labelled} labelled from the nearest surface, {self.n_unassigned} "
                "unassigned")

    def to_whole(self, values, fill=None, *, faces: bool = False) -> np.ndarray:
        """Values on the main body (first axis: its vertices, or triangles with ``faces``) on
        the whole mesh: a vertex of another component takes the value of the nearest main-body
        vertex within ``reach``, else ``fill`` (default ``-1`` for integers, NaN otherwise); a
        triangle of another component, that of the main-body triangle whose centroid is
        nearest to its own centroid, within ``reach``."""
        v = np.asarray(values)
        n = self.mesh.n_faces if faces else self.mesh.n_vertices
        if v.shape[:1] != (n,):
            raise MeshError(f"values must have one row per main-body "
                            f"{'triangle' if faces else 'vertex'} ({n}), got shape {v.shape}")
        integer = np.issubdtype(v.dtype, np.integer) or v.dtype == np.bool_
        if fill is None:
            fill = -1 if integer else np.nan
        dtype = np.float64 if integer and not float(fill).is_integer() else v.dtype
        n_whole = self.whole.n_faces if faces else self.whole.n_vertices
        out = np.full((n_whole,) + v.shape[1:], fill, dtype=dtype)
        out[self.faces if faces else self.vertices] = v
        if faces:
            rest = np.setdiff1d(np.arange(n_whole), self.faces)
            near = _nearest(self.mesh.vertices[self.mesh.faces].mean(axis=1),
                            self.whole.vertices[self.whole.faces[rest]].mean(axis=1), self.reach)
        else:
            rest, near = self.other, self.nearest
        ok = near >= 0
        out[rest[ok]] = v[near[ok]]
        return out

    def index(self, vertices, what: str = "vertices") -> np.ndarray:
        """The main-body vertices of vertices of ``whole``; raises
        [`MeshError`][bsfjax.MeshError] for one on another component."""
        inv = np.full(self.whole.n_vertices, -1, np.int64)
        inv[self.vertices] = np.arange(self.vertices.size)
        out = inv[np.asarray(vertices, np.int64)]
        if (out < 0).any():
            bad = int(np.asarray(vertices).reshape(-1)[np.flatnonzero(out.reshape(-1) < 0)[0]])
            raise MeshError(f"{what}: vertex {bad} is not on the main body (the largest "
                            "connected component): only the main body is matched")
        return out


def _nearest(body_points: np.ndarray, points: np.ndarray, reach: float) -> np.ndarray:
    if points.shape[0] == 0:
        return np.zeros(0, np.int64)
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(body_points).query(points)
    return np.where(dist <= reach, idx, -1).astype(np.int64)


def _components(mesh: Mesh) -> np.ndarray:
    f = mesh.faces
    e = np.stack([f.ravel(), np.roll(f, -1, axis=1).ravel()], axis=1)
    g = sp.coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])),
                      shape=(mesh.n_vertices,) * 2).tocsr()
    return scipy.sparse.csgraph.connected_components(g, directed=False)[1]


def split_main_body(mesh: Mesh, min_share: float = MIN_SHARE, reach: float = REACH) -> MainBody:
    """Split ``mesh`` into its main body and the rest.

    **Arguments:**

    - `mesh`: a [`Mesh`][bsfjax.Mesh] (a [`PointCloud`][bsfjax.PointCloud] is returned whole).
    - `min_share`: the rule for *small*: the main body is the largest connected component by
      area, and every other component is left out of the map; one holding at least this
      share of the total area (default 5 %) is not debris, and a warning says it is left out.
    - `reach`: the distance bound in mean edge lengths of the main body (default 4): a vertex
      of another component within it of the main body's nearest vertex takes that vertex's
      value (label), a farther one is left unassigned (``-1`` / NaN).

    **Returns:**

    A [`MainBody`][bsfjax.MainBody]; with one component (or a point cloud) its ``mesh`` is
    ``mesh`` itself and nothing is left out.
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    if not isinstance(mesh, Mesh):
        raise MeshError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    n = mesh.n_vertices
    whole = (mesh, mesh, np.arange(n), np.arange(mesh.n_faces), np.zeros(0, np.int64),
             np.zeros(0, np.int64), 0, 0.0)
    if mesh.is_point_cloud:
        return MainBody(*whole)
    comp = _components(mesh)
    n_comp = int(comp.max()) + 1
    if n_comp == 1:
        return MainBody(*whole)
    area = np.bincount(comp[mesh.faces[:, 0]], weights=mesh.face_areas(), minlength=n_comp)
    main = int(np.argmax(area))
    total = float(area.sum())
    big = [c for c in range(n_comp) if c != main and area[c] >= min_share * total]
    if big:
        where = f"{mesh.name}: " if mesh.name else ""
        warnings.warn(f"{where}{len(big)} connected components besides the largest hold "
                      f"{area[big].sum() / total:.0%} of the area: only the largest is matched, "
                      "the others are labelled from its nearest surface", stacklevel=2)
    keep = np.flatnonzero(comp == main)
    kept_faces = np.flatnonzero(comp[mesh.faces[:, 0]] == main)
    new = np.full(n, -1, np.int64)
    new[keep] = np.arange(keep.size)
    faces = new[mesh.faces[kept_faces]]
    rows = mesh.vertex_ids if mesh.vertex_ids is not None else np.arange(n)
    frows = (mesh.file_rows.face_ids if mesh.file_rows is not None
             and mesh.file_rows.face_ids is not None else np.arange(mesh.n_faces))
    fm = mesh.file_mesh()
    body_rows, body_frows = rows[keep], frows[kept_faces]
    file_rows = FileRows(
        n_rows=mesh.n_file_rows,
        dropped_vertices=fm.vertices[np.setdiff1d(np.arange(mesh.n_file_rows), body_rows)],
        n_faces=mesh.n_file_faces, face_ids=body_frows,
        dropped_faces=fm.faces[np.setdiff1d(np.arange(mesh.n_file_faces), body_frows)])
    body = Mesh(mesh.vertices[keep], faces, vertex_ids=body_rows, name=mesh.name,
                file_rows=file_rows)
    edges = mesh_edges(faces)[0]
    mean_edge = float(np.linalg.norm(body.vertices[edges[:, 0]] - body.vertices[edges[:, 1]],
                                     axis=1).mean())
    other = np.flatnonzero(comp != main)
    bound = reach * mean_edge
    return MainBody(body, mesh, keep, kept_faces, other,
                    _nearest(body.vertices, mesh.vertices[other], bound), n_comp - 1, bound)
