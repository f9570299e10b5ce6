"""Names that tests, benchmarks and extensions need beyond the public API (lineax's pattern).

Nothing here is covered by the deprecation policy of `bsfjax`'s public names: these are the
building blocks one level below them (mesh helpers, kernels of the frame, tuning constants), kept
importable from one place so that no code outside the package reaches into its private modules.
"""

from ._util import (
    BUCKET_FACTORS, MERGE_PADDING, atomic_path, merge_buckets, on_one_blas_thread,
    one_blas_thread, size_bucket, write_text_atomic,
)
from ._mesh import (
    CloudSurface, JOINTS, LABEL_NAMES, POSES, auto_iterations, clean_mesh, edge_graph, is_face_file,
    mesh_threshold, surface_for_map,
    knn_edges, mesh_edges, sample_surface, subdivide, vertex_areas,
)
from ._spectral import (
    cotangent_stiffness, has_cholmod, interval_operators, mass_matrix,
)
from ._maps import (
    GUIDE_WEIGHT, OrientationBasis, estimate_size, guided_zoomout, hks_times, landmark_geodesics,
    nearest_neighbors, orientation_bases, refinement_sizes, wks_energies,
)
from ._frame import (
    ADAPTIVE_N_SCALES, DENSE_BUDGET_BYTES, decode_host, decode_traced, effective_taus,
    ell_matmul, ell_rmatmul, kernel_mask, pack_lists, sparse_atoms, sparse_gram, unique_atoms,
)
from ._coding import (
    CODERS, as_coder,
)
from ._transfer import (
    CLOUD_DESCRIPTOR_WEIGHT, as_method, geodesic_ball_radii, method_for_shapes, product_basis,
)
from ._pipeline import (
    FaceShares, decide_face_labels, face_label_shares, face_scores,
)
from ._plot import (
    label_colour,
)
from ._util import available_memory, check_path_clashes
from ._maps import check_fmap_memory
from ._pipeline import capped_batch
from ._cli import (
    CLIError, TURN_DOUBT, example_landmarks, format_table, run_demo,
)

__all__ = [
    "ADAPTIVE_N_SCALES", "BUCKET_FACTORS", "CLIError", "CODERS", "DENSE_BUDGET_BYTES",
    "FaceShares", "JOINTS", "LABEL_NAMES", "MERGE_PADDING", "OrientationBasis", "POSES",
    "TURN_DOUBT", "as_coder", "as_method", "atomic_path", "auto_iterations", "clean_mesh",
    "cotangent_stiffness", "decide_face_labels", "decode_host", "decode_traced", "edge_graph",
    "effective_taus", "ell_matmul", "ell_rmatmul", "example_landmarks", "face_label_shares",
    "face_scores", "format_table", "geodesic_ball_radii", "has_cholmod", "hks_times",
    "interval_operators", "is_face_file", "kernel_mask", "knn_edges", "label_colour",
    "mass_matrix", "merge_buckets", "mesh_edges", "nearest_neighbors", "on_one_blas_thread",
    "one_blas_thread", "orientation_bases", "pack_lists", "product_basis", "refinement_sizes",
    "run_demo", "sample_surface", "size_bucket", "sparse_atoms", "sparse_gram", "subdivide",
    "unique_atoms", "vertex_areas", "wks_energies", "write_text_atomic",
    "GUIDE_WEIGHT", "estimate_size", "guided_zoomout", "landmark_geodesics",
]
__all__ += ["CLOUD_DESCRIPTOR_WEIGHT", "CloudSurface", "method_for_shapes", "mesh_threshold",
            "surface_for_map"]
__all__ += ["available_memory", "capped_batch", "check_fmap_memory", "check_path_clashes"]
