"""Triangle meshes: the immutable [`Mesh`][bsfjax.Mesh] container and its validation.

This is the first stage of the pipeline (mesh → spectrum → frame → coefficients → transfer →
metrics) and depends on nothing else in bsfjax.

Owner of the [`Mesh`][bsfjax.Mesh] class and its validation (`MAX_COORDINATE`); its graph
helpers live in `bsfjax._mesh._graph`, cleaning and defect reports in `bsfjax._mesh._clean`,
the file readers and [`load_mesh`][bsfjax.load_mesh] in `bsfjax._mesh._readers`.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from .._util import MeshError

__all__ = ["FileRows", "Mesh", "MeshError", "MAX_COORDINATE", "PointCloud"]


#: Largest accepted ``|coordinate|``.  Face areas are norms of cross products of edges, whose
#: squares grow as ``|x|⁴`` (up to ``192 |x|⁴``): below 10⁷⁵ they stay finite in float64.
MAX_COORDINATE = 1e75


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


class FileRows(NamedTuple):
    """What a reader dropped from a mesh file (``Mesh.file_rows``): enough to give every output
    the file's own rows and to write the mesh back as the file had it.

    **Attributes:**

    - `n_rows`: vertex rows of the file.
    - `dropped_vertices`: ``(n_rows − n, 3)`` coordinates of the rows without a vertex, in
      row order.
    - `n_faces`: triangles of the file (after polygons were fan-triangulated).
    - `face_ids`: ``(m,)`` the file triangle of each kept triangle, or ``None`` when all kept.
    - `dropped_faces`: ``(n_faces − m, 3)`` the dropped triangles, as file rows.
    """

    n_rows: int
    dropped_vertices: np.ndarray
    n_faces: int
    face_ids: np.ndarray | None
    dropped_faces: np.ndarray


@dataclasses.dataclass(frozen=True, eq=False)
class Mesh:
    """An immutable triangle mesh.

    **Attributes:**

    - `vertices`: ``(n, 3)`` float64 coordinates (read-only array).
    - `faces`: ``(m, 3)`` int64 vertex indices of the triangles (read-only array).
    - `vertex_ids`: ``(n,)`` int64 index of each vertex in the file it was read from, or
      ``None`` when vertex ``i`` is row ``i`` of the source.  ``load_mesh`` drops
      unreferenced vertices; per-vertex data indexed like the file (labels, ground-truth
      correspondences) is brought onto the mesh with ``data[mesh.vertex_ids]``, or with
      [`from_file_rows`][bsfjax.Mesh.from_file_rows].
    - `name`: where the mesh came from (a path), for error messages.
    - `file_rows`: a [`FileRows`][bsfjax.FileRows] record of what the reader dropped (the file's
      row and triangle counts, the dropped rows), or ``None`` when nothing was dropped.

    **File rows.** The rows of a user's file are the numbering a user sees: the command line
    reads and writes every per-vertex (per-triangle) file in the file's row order, through
    [`to_file_rows`][bsfjax.Mesh.to_file_rows] (mesh → file, ``−1`` / NaN on the rows without a
    vertex), [`from_file_rows`][bsfjax.Mesh.from_file_rows] (file → mesh) and
    [`file_row_index`][bsfjax.Mesh.file_row_index] (row numbers, e.g. landmarks → vertex
    indices).  The Python API on meshes and spectra numbers the mesh's own vertices.

    The constructor validates its input and raises [`MeshError`][bsfjax.MeshError] on NaN/inf, complex or
    overflowing (``|x| > MAX_COORDINATE``) coordinates, ragged or wrongly shaped arrays,
    non-integer, out-of-range or negative face indices and empty meshes.  It does not clean:
    degenerate faces, isolated or duplicate vertices and non-manifold edges are counted by
    [`mesh_report`][bsfjax.mesh_report] and removed or reported by `clean_mesh` / [`load_mesh`][bsfjax.load_mesh].
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_ids: np.ndarray | None = None
    name: str | None = None
    file_rows: FileRows | None = None

    _POINTS = False  # (a class attribute, not a field) a PointCloud: zero faces are its form

    def __post_init__(self):
        where = f"{self.name}: " if self.name else ""
        try:
            v = np.asarray(self.vertices)
        except (TypeError, ValueError) as exc:  # ragged nested lists, objects numpy rejects
            raise MeshError(f"{where}vertices must be an (n, 3) array of numbers ({exc})") from None
        try:
            f = np.asarray(self.faces)
        except (TypeError, ValueError) as exc:
            raise MeshError(f"{where}faces must be an (m, 3) array of vertex indices ({exc})") \
                from None
        if v.ndim != 2 or v.shape[1] != 3:
            raise MeshError(f"{where}vertices must have shape (n, 3), got {v.shape}")
        if v.shape[0] == 0:
            raise MeshError(f"{where}mesh is empty (0 vertices)")
        if not np.issubdtype(v.dtype, np.number) or np.issubdtype(v.dtype, np.complexfloating):
            raise MeshError(f"{where}vertices must be real numbers, got dtype {v.dtype}")
        v = v.astype(np.float64)
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            raise MeshError(
                f"{where}{int(bad.sum())} vertices have NaN or infinite coordinates "
                f"(first: vertex {int(np.flatnonzero(bad)[0])})"
            )
        big = float(np.abs(v).max())
        if big > MAX_COORDINATE:
            raise MeshError(f"{where}coordinates up to {big:.3g} overflow the geometry "
                            f"(squared lengths, areas); the limit is {MAX_COORDINATE:.0e}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise MeshError(f"{where}faces must have shape (m, 3), got {f.shape}")
        if f.shape[0] == 0 and not self._POINTS:
            raise MeshError(f"{where}mesh has no faces (a point cloud is a bsfjax.PointCloud)")
        if not np.issubdtype(f.dtype, np.integer):
            if np.issubdtype(f.dtype, np.floating) and np.all(np.mod(f, 1) == 0):
                f = f.astype(np.int64)
            else:
                raise MeshError(f"{where}faces must be integer indices, got dtype {f.dtype}")
        f = f.astype(np.int64)
        lo, hi = (int(f.min()), int(f.max())) if f.size else (0, 0)
        if lo < 0 or hi >= v.shape[0]:
            raise MeshError(
                f"{where}face indices out of range: found [{lo}, {hi}] for {v.shape[0]} vertices"
            )
        object.__setattr__(self, "vertices", _readonly(v))
        object.__setattr__(self, "faces", _readonly(f))
        if self.vertex_ids is not None:
            ids = np.asarray(self.vertex_ids)
            if not np.issubdtype(ids.dtype, np.integer):
                raise MeshError(f"{where}vertex_ids must be integer row indices, got dtype "
                                f"{ids.dtype}")
            ids = ids.astype(np.int64)
            if ids.shape != (v.shape[0],):
                raise MeshError(f"{where}vertex_ids must have shape ({v.shape[0]},), got {ids.shape}")
            object.__setattr__(self, "vertex_ids", _readonly(ids))

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def is_point_cloud(self) -> bool:
        """``True`` for a [`PointCloud`][bsfjax.PointCloud]: points without triangles."""
        return self._POINTS

    def face_areas(self) -> np.ndarray:
        """``(m,)`` triangle areas ½‖(v₁−v₀)×(v₂−v₀)‖."""
        v = self.vertices
        e1 = v[self.faces[:, 1]] - v[self.faces[:, 0]]
        e2 = v[self.faces[:, 2]] - v[self.faces[:, 0]]
        return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)

    @property
    def area(self) -> float:
        """Total surface area."""
        return float(self.face_areas().sum())

    @property
    def n_file_rows(self) -> int:
        """Vertex rows of the file the mesh was read from (``n_vertices`` when none dropped)."""
        if self.file_rows is not None:
            return int(self.file_rows.n_rows)
        return self.n_vertices if self.vertex_ids is None else int(self.vertex_ids.max()) + 1

    @property
    def n_file_faces(self) -> int:
        """Triangles of the file the mesh was read from (``n_faces`` when none dropped)."""
        return self.n_faces if self.file_rows is None else int(self.file_rows.n_faces)

    @property
    def dropped_rows(self) -> int:
        """Vertex rows of the file that carry no vertex of the mesh (unreferenced vertices)."""
        return self.n_file_rows - self.n_vertices

    @property
    def dropped_faces(self) -> int:
        """Triangles of the file that the reader dropped (zero area)."""
        return self.n_file_faces - self.n_faces

    def _ids(self, faces: bool) -> np.ndarray | None:
        if faces:
            return None if self.file_rows is None else self.file_rows.face_ids
        if self.vertex_ids is None and self.n_file_rows != self.n_vertices:
            return np.arange(self.n_vertices)
        return self.vertex_ids

    def to_file_rows(self, values, fill=None, *, faces: bool = False) -> np.ndarray:
        """Per-vertex ``values`` (first axis ``n_vertices``) in the rows of the mesh's file.

        **Arguments:**

        - `values`: ``(n, ...)`` array, one entry per vertex (per triangle with ``faces``).
        - `fill`: the value of the rows without a vertex (default ``-1`` for integers, NaN
          otherwise; integers filled with NaN become floats).
        - `faces`: ``values`` are per triangle: the result has ``n_file_faces`` rows.

        **Returns:**

        ``(n_file_rows, ...)`` (``(n_file_faces, ...)``): row ``r`` holds the value of the vertex
        read from row ``r``.  The inverse of [`from_file_rows`][bsfjax.Mesh.from_file_rows].
        """
        v = np.asarray(values)
        n, n_file = (self.n_faces, self.n_file_faces) if faces else (self.n_vertices,
                                                                      self.n_file_rows)
        if v.shape[:1] != (n,):
            raise MeshError(f"values must have one row per mesh {'triangle' if faces else 'vertex'} "
                            f"({n}), got shape {v.shape}")
        ids = self._ids(faces)
        if ids is None or n_file == n:
            return v.copy()
        integer = np.issubdtype(v.dtype, np.integer) or v.dtype == np.bool_
        if fill is None:
            fill = -1 if integer else np.nan
        dtype = np.float64 if integer and not float(fill).is_integer() else v.dtype
        out = np.full((n_file,) + v.shape[1:], fill, dtype=dtype)
        out[ids] = v
        return out

    def from_file_rows(self, values, *, faces: bool = False) -> np.ndarray:
        """``values`` given per row of the mesh's file (first axis ``n_file_rows``; with
        ``faces``, ``n_file_faces``) on the mesh's vertices (triangles): the rows without a
        vertex are left out.  The inverse of [`to_file_rows`][bsfjax.Mesh.to_file_rows]."""
        v = np.asarray(values)
        n_file = self.n_file_faces if faces else self.n_file_rows
        if v.shape[:1] != (n_file,):
            raise MeshError(f"values must have one row per file {'triangle' if faces else 'row'} "
                            f"({n_file}), got shape {v.shape}")
        ids = self._ids(faces)
        return v.copy() if ids is None else v[ids]

    def file_row_index(self, rows, what: str = "rows") -> np.ndarray:
        """The mesh vertices of file rows ``rows`` (e.g. landmarks given as file rows).

        Raises [`MeshError`][bsfjax.MeshError] naming the first row out of range or without a
        vertex (a row the reader dropped); ``what`` names the input in the message.
        """
        r = np.asarray(rows, dtype=np.int64).reshape(-1)
        n_file = self.n_file_rows
        bad = (r < 0) | (r >= n_file)
        if bad.any():
            raise MeshError(f"{what}: row {int(r[bad][0])} is out of range [0, {n_file})")
        ids = self._ids(False)
        if ids is None:
            return r
        inv = np.full(n_file, -1, np.int64)
        inv[ids] = np.arange(self.n_vertices)
        out = inv[r]
        if (out < 0).any():
            where = f" of {self.name}" if self.name else ""
            raise MeshError(f"{what}: row {int(r[out < 0][0])}{where} is an unreferenced vertex "
                            "(no triangle uses it): it has no place on the surface")
        return out

    def file_mesh(self) -> "Mesh":
        """The mesh as its file has it: every vertex row and every triangle in file order,
        dropped ones included (for writing per-row data back next to the file's geometry)."""
        if self.file_rows is None and self.vertex_ids is None:
            return self
        fr = self.file_rows
        ids = self._ids(False)
        v = np.zeros((self.n_file_rows, 3))
        v[ids] = self.vertices
        f_kept = ids[self.faces]
        if fr is None:
            return Mesh(v, f_kept, name=self.name)
        v[np.setdiff1d(np.arange(fr.n_rows), ids)] = fr.dropped_vertices
        f = np.zeros((fr.n_faces, 3), np.int64)
        fids = np.arange(self.n_faces) if fr.face_ids is None else fr.face_ids
        f[fids] = f_kept
        f[np.setdiff1d(np.arange(fr.n_faces), fids)] = fr.dropped_faces
        return Mesh(v, f, name=self.name)

    def to_trimesh(self):
        """The mesh as a ``trimesh.Trimesh`` (same vertices and triangles, in order; nothing
        merged: ``process=False``; a point cloud: a ``trimesh.PointCloud``); needs trimesh
        (``pip install trimesh``)."""
        try:
            import trimesh
        except ImportError:
            raise MeshError("Mesh.to_trimesh needs trimesh: pip install trimesh") from None
        if self.is_point_cloud:
            return trimesh.PointCloud(np.array(self.vertices))
        return trimesh.Trimesh(vertices=np.array(self.vertices), faces=np.array(self.faces),
                               process=False)

    def __repr__(self) -> str:
        name = f", name={self.name!r}" if self.name else ""
        return f"Mesh(n_vertices={self.n_vertices}, n_faces={self.n_faces}{name})"


class PointCloud(Mesh):
    """Points without triangles (a scan saved as points): a [`Mesh`][bsfjax.Mesh] with zero
    faces, so that every function that takes a mesh takes it.

    ``PointCloud(points)`` with ``points`` an ``(n, 3)`` array; [`load_mesh`][bsfjax.load_mesh]
    returns one for a file with vertices and no faces (PLY, OBJ, OFF, ``.xyz``).  Every point
    keeps its row: nothing is dropped, merged or reordered (duplicate points included), so
    ``vertex_ids`` is ``None``.  `faces` is an empty ``(0, 3)`` array, `is_point_cloud` is
    ``True``, `area` is the lumped area of the point-cloud Laplacian.

    What changes for a point cloud: [`laplacian`][bsfjax.laplacian] and
    [`spectrum`][bsfjax.spectrum] use the point-cloud Laplacian of Sharp & Crane 2020
    (robust-laplacian's ``point_cloud_laplacian``; its mass is a lumped area per point);
    geodesic distances and ``"geodesic"`` farthest point sampling run Dijkstra on the
    symmetrized k-nearest-neighbour graph (`bsfjax.internal.edge_graph`).  What
    needs triangles refuses with a line that says so: the landmark-free map (its orientation
    term), per-triangle labels, the heat method, subdivision.
    """

    _POINTS = True

    def __init__(self, vertices, faces=None, vertex_ids=None, name: str | None = None):
        if faces is not None and np.asarray(faces).size:
            raise MeshError(f"{name + ': ' if name else ''}a PointCloud has no faces; "
                            "use bsfjax.Mesh for a triangle mesh")
        super().__init__(vertices, np.zeros((0, 3), np.int64), vertex_ids, name)

    @property
    def points(self) -> np.ndarray:
        """The ``(n, 3)`` coordinates (the same array as `vertices`)."""
        return self.vertices

    @property
    def area(self) -> float:
        """The total lumped area of the point-cloud Laplacian (Sharp & Crane 2020)."""
        import robust_laplacian

        return float(robust_laplacian.point_cloud_laplacian(np.asarray(self.vertices))[1].sum())

    def __repr__(self) -> str:
        name = f", name={self.name!r}" if self.name else ""
        return f"PointCloud(n_points={self.n_vertices}{name})"
