"""Mesh hygiene: defect reports and cleaning. Owner of `MeshReport` / `mesh_report` (counting a
mesh's defects), the warnings about the defects that are kept, and `clean_mesh`, which builds a
[`Mesh`][bsfjax.Mesh] from raw arrays, dropping zero-area faces and unreferenced vertices (the
last step of every reader).
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np

from .._util import MeshError
from ._graph import mesh_edges, n_components
from ._mesh import FileRows, Mesh
from ._interop import as_mesh

__all__ = ["MeshReport", "mesh_report", "clean_mesh"]


class MeshReport(NamedTuple):
    """What [`mesh_report`][bsfjax.mesh_report] counts on a mesh (every field an ``int``).

    **Attributes:**

    - `n_vertices`, `n_faces`: sizes.
    - `degenerate_faces`: faces with a repeated vertex index or zero area.
    - `duplicate_faces`: faces whose vertex set equals that of an earlier face.
    - `duplicate_vertices`: vertices with exactly the coordinates of an earlier vertex.
    - `isolated_vertices`: vertices that no face references.
    - `non_manifold_edges`: edges shared by more than two faces.
    - `boundary_edges`: edges of a single face.
    - `components`: connected components of the face graph (isolated vertices count as
      components of their own).
    """

    n_vertices: int
    n_faces: int
    degenerate_faces: int
    duplicate_faces: int
    duplicate_vertices: int
    isolated_vertices: int
    non_manifold_edges: int
    boundary_edges: int
    components: int


def _row_keys(a: np.ndarray) -> np.ndarray:
    """One opaque scalar per row (equal rows ⇔ equal keys), for fast 1-D ``np.unique``."""
    a = np.ascontiguousarray(a)
    return a.view(np.dtype((np.void, a.dtype.itemsize * a.shape[1]))).ravel()


def mesh_report(mesh: "Mesh") -> MeshReport:
    """Count the defects of ``mesh`` that the pipeline handles but a user should know about.

    ``load_mesh`` removes degenerate faces and isolated vertices and warns about duplicate
    vertices and non-manifold edges; [`bsfjax.spectrum`][bsfjax.spectrum] warns about several components.
    Cost: a few sorts of the ``(m, 3)`` faces and ``(n, 3)`` vertices.

    A [`PointCloud`][bsfjax.PointCloud] has no faces, so no face defects, no isolated
    points and no edges to be non-manifold or on a boundary (all 0); its duplicate points are
    counted, and its components are those of its k-nearest-neighbour graph.
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    if not isinstance(mesh, Mesh):
        raise MeshError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    f = mesh.faces
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    degenerate = int(np.sum(repeated | (mesh.face_areas() == 0)))
    dup_faces = f.shape[0] - np.unique(_row_keys(np.sort(f, axis=1))).shape[0]
    dup_verts = mesh.n_vertices - np.unique(_row_keys(mesh.vertices + 0.0)).shape[0]  # −0 → +0
    used = np.full(mesh.n_vertices, mesh.is_point_cloud)
    used[f.ravel()] = True
    edges, face_edges = mesh_edges(f)
    per_edge = np.bincount(face_edges.ravel(), minlength=len(edges))
    return MeshReport(
        n_vertices=mesh.n_vertices, n_faces=mesh.n_faces, degenerate_faces=degenerate,
        duplicate_faces=int(dup_faces), duplicate_vertices=int(dup_verts),
        isolated_vertices=int((~used).sum()), non_manifold_edges=int(np.sum(per_edge > 2)),
        boundary_edges=int(np.sum(per_edge == 1)),
        components=n_components(mesh, None if mesh.is_point_cloud else edges))


def _warn_defects(mesh: "Mesh", stacklevel: int) -> None:
    """Warn (with counts) about the kept defects: duplicate vertices, non-manifold edges."""
    where = f"{mesh.name}: " if mesh.name else ""
    rep = mesh_report(mesh)
    if rep.duplicate_vertices:
        warnings.warn(f"{where}{rep.duplicate_vertices} duplicate vertices (same coordinates as "
                      "another vertex; kept: faces on either copy are not connected there)",
                      stacklevel=stacklevel + 1)
    if rep.non_manifold_edges:
        warnings.warn(f"{where}{rep.non_manifold_edges} non-manifold edges (shared by more than "
                      "two faces; kept: the cotangent Laplacian sums every face, "
                      "laplacian(..., robust=True) is better suited)", stacklevel=stacklevel + 1)


def clean_mesh(vertices: np.ndarray, faces: np.ndarray, name: str | None = None,
               area_tol: float = 0.0) -> Mesh:
    """Build a [`Mesh`][bsfjax.Mesh], dropping zero-area faces and unreferenced vertices with a warning.

    Duplicate vertices and non-manifold edges are kept, with a warning that counts them
    (see [`mesh_report`][bsfjax.mesh_report]).

    A face is degenerate when two of its indices coincide or its area is ``<= area_tol`` times the
    mean face area.  Vertices no face references are removed; ``Mesh.vertex_ids`` records the
    original index of every kept vertex and ``Mesh.file_rows`` what was dropped, so that
    [`Mesh.to_file_rows`][bsfjax.Mesh.to_file_rows] gives per-vertex results the rows of the input.
    """
    where = f"{name}: " if name else ""
    probe = Mesh(vertices, faces, name=name)  # validates shapes, finiteness, indices
    v, f = probe.vertices, probe.faces
    areas = probe.face_areas()
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    degenerate = repeated | (areas <= area_tol * max(areas.mean(), np.finfo(float).tiny))
    if degenerate.any():
        warnings.warn(f"{where}removed {int(degenerate.sum())} zero-area faces", stacklevel=3)
        f = f[~degenerate]
        if f.shape[0] == 0:
            raise MeshError(f"{where}every face has zero area")
    used = np.zeros(v.shape[0], dtype=bool)
    used[f.ravel()] = True
    if not used.all():
        rows = np.flatnonzero(~used)
        shown = ", ".join(map(str, rows[:5])) + (", ..." if rows.size > 5 else "")
        warnings.warn(
            f"{where}removed {rows.size} unreferenced vertices (file rows {shown}: no triangle "
            "uses them; per-vertex files keep their rows, -1 or NaN there)",
            stacklevel=3,
        )
    if degenerate.any() or not used.all():
        rows = FileRows(n_rows=v.shape[0], dropped_vertices=v[~used], n_faces=probe.n_faces,
                        face_ids=np.flatnonzero(~degenerate) if degenerate.any() else None,
                        dropped_faces=probe.faces[degenerate])
        remap = np.cumsum(used) - 1
        mesh = Mesh(v[used], remap[f], vertex_ids=None if used.all() else np.flatnonzero(used),
                    name=name, file_rows=rows)
    else:
        mesh = Mesh(v, f, name=name)
    _warn_defects(mesh, stacklevel=3)
    return mesh
