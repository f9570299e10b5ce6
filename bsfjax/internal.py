"""Names that tests, benchmarks and extensions need beyond the public API (lineax's pattern).

Nothing here is covered by the deprecation policy of `bsfjax`'s public names: these are the
building blocks one level below them (mesh helpers, kernels of the frame, tuning constants), kept
importable from one place so that no code outside the package reaches into its private modules.
"""

from ._util import (
    BSFError, BUCKET_FACTORS, MERGE_PADDING, atomic_path, merge_buckets,
    on_one_blas_thread, one_blas_thread, write_text_atomic,
)
from ._mesh import (
    JOINTS, LABEL_NAMES, Mesh, POSES, clean_mesh, edge_graph, example_mesh, example_pair,
    mesh_edges, mesh_report, subdivide,
)
from ._spectral import (
    cotangent_stiffness, has_cholmod, interval_operators, interval_spectrum, mass_matrix,
)
from ._maps import (
    LANDMARK_FREE_STARTS, ORIENTATION_SLACK, ORIENT_WEIGHT, TURN_RADIUS, TURN_SAMPLES,
    ZOOMOUT_SAMPLES, hks_times, refinement_sizes, wks_energies,
)
from ._frame import (
    ADAPTIVE_N_SCALES, decode_host, decode_traced, effective_taus, ell_matmul,
    ell_rmatmul, kernel_mask, pack_lists, sparse_atoms, sparse_gram,
)
from ._transfer import (
    METHODS, geodesic_ball_radii, product_basis,
)
from ._pipeline import (
    REGIMES,
)
from ._plot import (
    label_colour,
)
from ._cli import (
    CLIError, TURN_DOUBT, example_landmarks, format_table, run_demo,
)

__all__ = [
    "ADAPTIVE_N_SCALES", "BSFError", "BUCKET_FACTORS", "CLIError", "JOINTS", "LABEL_NAMES",
    "LANDMARK_FREE_STARTS", "MERGE_PADDING", "METHODS", "Mesh", "ORIENTATION_SLACK",
    "ORIENT_WEIGHT", "POSES", "REGIMES", "TURN_DOUBT", "TURN_RADIUS", "TURN_SAMPLES",
    "ZOOMOUT_SAMPLES", "atomic_path", "clean_mesh", "cotangent_stiffness", "decode_host",
    "decode_traced", "edge_graph", "effective_taus", "ell_matmul", "ell_rmatmul",
    "example_landmarks", "example_mesh", "example_pair", "format_table", "geodesic_ball_radii",
    "has_cholmod", "hks_times", "interval_operators", "interval_spectrum", "kernel_mask",
    "label_colour", "mass_matrix", "merge_buckets", "mesh_edges", "mesh_report",
    "on_one_blas_thread", "one_blas_thread", "pack_lists", "product_basis", "refinement_sizes",
    "run_demo", "sparse_atoms", "sparse_gram", "subdivide", "wks_energies", "write_text_atomic",
]
