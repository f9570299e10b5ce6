"""The mesh stage: a triangle mesh and its files.

`Mesh` (vertices, triangles, or none: a `PointCloud`, cleaning of unreferenced vertices and degenerate faces, areas,
edges, components), reading and writing mesh files (OFF, PLY, OBJ, STL, ... through meshio,
with fast paths for plain OFF/PLY), segmentation files (`.txt` / `.npy`, SMPL's `.json`,
per-triangle `.seg`), loop subdivision, denoising (Taubin smoothing with a strength from a noise estimate; of point clouds too), a scan's preparation
for its spectrum (`prepare_scan`: main body, then denoised, then its holes closed), quadric decimation (`decimate`: a large
mesh's proxy), the built-in example pair, a point cloud's oriented stand-in surface (`cloud_surface`), and meshes from trimesh, pyFM, open3d or ``(V, F)`` arrays (`as_mesh`).
"""

from ._example import ExamplePair, JOINTS, LABEL_NAMES, POSES, example_mesh, example_pair
from ._label_files import UNASSIGNED_PART, LabelFile, is_face_file, load_labels, read_label_file, save_labels
from ._clean import MeshReport, clean_mesh, mesh_report
from ._graph import edge_graph, graph_from_edges, knn_edges, mesh_edges, n_components
from ._points import sample_surface
from ._components import MainBody, split_main_body, vertex_areas
from ._mesh import FileRows, Mesh, PointCloud
from ._readers import load_mesh
from ._interop import as_mesh, is_mesh_like
from ._mesh_write import save_mesh
from ._subdivision import subdivide
from ._denoise import (as_strength, auto_iterations, denoise, denoise_iterations, mesh_threshold,
                       noise_level, surface_for_map, umbrella_operator)
from ._cloud_surface import CloudSurface, cloud_normals, cloud_surface
from ._holes import HoleFill, boundary_loops, fill_holes
from ._scan import PreparedScan, prepare_scan
from ._decimate import Decimated, decimate

__all__ = [
    "CloudSurface", "Decimated", "decimate", "ExamplePair", "FileRows", "HoleFill", "JOINTS", "LABEL_NAMES", "LabelFile",
    "MainBody", "Mesh", "MeshReport", "POSES", "PointCloud", "PreparedScan", "as_mesh",
    "as_strength", "auto_iterations", "boundary_loops", "clean_mesh", "cloud_normals",
    "cloud_surface", "fill_holes", "is_mesh_like", "mesh_threshold", "surface_for_map",
    "denoise", "denoise_iterations", "edge_graph", "example_mesh", "example_pair",
    "graph_from_edges", "is_face_file", "knn_edges", "load_labels", "load_mesh", "mesh_edges",
    "mesh_report", "n_components", "noise_level", "prepare_scan", "read_label_file", "sample_surface",
    "UNASSIGNED_PART", "save_labels", "save_mesh", "split_main_body", "subdivide",
    "umbrella_operator", "vertex_areas",
]
