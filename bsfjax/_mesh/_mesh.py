"""Triangle meshes: the immutable [`Mesh`][bsfjax.Mesh] container and its validation.

This is the first stage of the pipeline (mesh → spectrum → frame → coefficients → transfer →
metrics) and depends on nothing else in bsfjax.

Owner of the [`Mesh`][bsfjax.Mesh] class and its validation (`MAX_COORDINATE`); its graph
helpers live in `bsfjax._mesh._graph`, cleaning and defect reports in `bsfjax._mesh._clean`,
the file readers and [`load_mesh`][bsfjax.load_mesh] in `bsfjax._mesh._readers`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._util import MeshError

__all__ = ["Mesh", "MeshError", "MAX_COORDINATE", "PointCloud"]


#: Largest accepted ``|coordinate|``.  Face areas are norms of cross products of edges, whose
#: squares grow as ``|x|⁴`` (up to ``192 |x|⁴``): below 10⁷⁵ they stay finite in float64.
MAX_COORDINATE = 1e75


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class Mesh:
    """An immutable triangle mesh.

    **Attributes:**

    - `vertices`: ``(n, 3)`` float64 coordinates (read-only array).
    - `faces`: ``(m, 3)`` int64 vertex indices of the triangles (read-only array).
    - `vertex_ids`: ``(n,)`` int64 index of each vertex in the file it was read from, or
      ``None`` when vertex ``i`` is row ``i`` of the source.  ``load_mesh`` drops
      unreferenced vertices; per-vertex data indexed like the file (labels, ground-truth
      correspondences) is brought onto the mesh with ``data[mesh.vertex_ids]``.
    - `name`: where the mesh came from (a path), for error messages.

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
