"""The mesh stage: `Mesh`, reading and writing mesh files and segmentation files, the built-in example pair."""

from ._example import ExamplePair, JOINTS, LABEL_NAMES, POSES, example_mesh, example_pair
from ._label_files import LabelFile, is_face_file, load_labels, read_label_file, save_labels
from ._mesh import (
    Mesh, MeshReport, clean_mesh, edge_graph, graph_from_edges, load_mesh, mesh_edges,
    mesh_report, n_components,
)
from ._mesh_write import save_mesh
from ._subdivision import subdivide

__all__ = [
    "ExamplePair", "JOINTS", "LABEL_NAMES", "LabelFile", "Mesh", "MeshReport", "POSES",
    "clean_mesh", "edge_graph", "example_mesh", "example_pair", "graph_from_edges",
    "is_face_file", "load_labels", "load_mesh", "mesh_edges", "mesh_report", "n_components",
    "read_label_file", "save_labels", "save_mesh", "subdivide",
]
