"""bsfjax: Binary Sparse Frames in JAX.

Sparse representation and transfer of step functions on manifolds, after S. Melzi,
"Sparse representation of step functions on manifolds", Computers & Graphics 82 (2019).

The public API, by pipeline stage (mesh → spectrum → frame → coefficients → transfer →
metrics, with functional maps feeding the transfer); each stage is one private sub-package,
and docs/architecture.md lists their modules.  `bsfjax.plot` draws figures, `bsfjax.cli` is
the `bsfjax` command, `bsfjax.experiments` reproduces the paper's tables and figures, and
`bsfjax.internal` holds the building blocks below this API.
"""

from ._util import BSFError, MeshError, VERSION

# mesh
from ._mesh import (
    ExamplePair, FileRows, LabelFile, MainBody, Mesh, MeshReport, PointCloud, cloud_normals,
    cloud_surface, denoise,
    denoise_iterations, example_mesh, example_pair, load_labels, load_mesh, mesh_report,
    noise_level, save_labels, save_mesh, split_main_body, PreparedScan, prepare_scan,
    HoleFill, boundary_loops, fill_holes,
    Decimated, decimate,
)
from ._mesh import as_mesh

# operators and spectrum
from ._spectral import (
    Spectrum, interval_spectrum, laplacian, spectrum, spectrum_from_operators, stack_spectra,
)

# sampling
from ._sampling import (
    Subsample, farthest_point_sampling, geodesic_distances, geodesic_error, subsample,
)

# frame
from ._frame import (
    AbstractFrame, Frame, SparseFrame, adaptive_taus, build_frame, prune_frame, transfer_frame,
)

# coding
from ._coding import AbstractCoder, CodingInfo, ErrorOMP, Lasso, LeastSquares, OMP, decode, encode

# transfer
from ._transfer import (
    AbstractMethod, BSF, GeodesicBalls, METHODS, Pair, ProductBasis, PullBack, RefinedPullBack,
    SaturatedHeat, SpectralProjection, TransferResult, stack_pairs, transfer, transfer_pairs,
)

# functional maps
from ._maps import (
    FmapWeights, MapEstimate, MapEstimator, choose_map, estimate_fmap, estimate_map,
    fmap_energy, fmap_from_p2p, fmap_to_p2p, hks, icp_refine, map_coverage, map_distortion,
    mirror_symmetry,
    orientation_agreement, refine_point_maps, wks, zoomout,
)

# mesh-level entry points
from ._pipeline import (
    LabelTransfer, REGIMES, TargetTransfer, face_labels_from_vertices, transfer_collection,
    transfer_face_labels, transfer_labels, transfer_values,
)

# metrics and test functions
from ._metrics import (indicators_to_labels, labels_to_indicators, missing_labels,
                       random_indicators, relative_error)

__version__ = VERSION


def view(source, targets=None, **options):
    """Open the polyscope viewer: [`bsfjax.plot.view`][bsfjax.plot.view] (same arguments),
    imported on the first call, so that ``import bsfjax`` loads neither matplotlib nor
    polyscope.

    **Arguments:**

    - `source`, `targets`, `options`: as [`bsfjax.plot.view`][bsfjax.plot.view].
    """
    from ._plot import view as _view

    return _view(source, targets, **options)


__all__ = [
    "BSFError", "MeshError",
    # mesh
    "Mesh", "FileRows", "MeshReport", "PointCloud", "as_mesh", "view", "cloud_normals", "cloud_surface",
    "load_mesh", "mesh_report", "save_mesh",
    "MainBody", "split_main_body",
    "denoise", "denoise_iterations", "noise_level", "PreparedScan", "prepare_scan",
    "HoleFill", "boundary_loops", "fill_holes",
    "Decimated", "decimate",
    "ExamplePair",
    "example_mesh", "example_pair",
    # operators and spectrum
    "laplacian", "Spectrum", "interval_spectrum", "spectrum", "spectrum_from_operators",
    "stack_spectra",
    # sampling
    "farthest_point_sampling", "subsample", "Subsample", "geodesic_distances", "geodesic_error",
    # frame
    "AbstractFrame", "Frame", "SparseFrame", "build_frame", "transfer_frame", "adaptive_taus",
    "prune_frame",
    # coding
    "AbstractCoder", "CodingInfo", "encode", "decode", "OMP", "ErrorOMP",
    "LeastSquares", "Lasso",
    # transfer
    "METHODS", "AbstractMethod", "BSF", "SpectralProjection", "PullBack", "RefinedPullBack", "ProductBasis",
    "GeodesicBalls", "SaturatedHeat", "Pair", "TransferResult", "transfer",
    "transfer_pairs", "stack_pairs",
    # functional maps
    "hks", "wks", "fmap_from_p2p", "fmap_to_p2p", "icp_refine", "zoomout",
    "refine_point_maps",
    "FmapWeights", "estimate_fmap", "fmap_energy",
    "map_distortion", "orientation_agreement", "map_coverage",
    "choose_map",
    # mesh level
    "MapEstimate", "MapEstimator", "estimate_map", "mirror_symmetry", "LabelTransfer", "REGIMES",
    "transfer_values", "transfer_labels",
    "transfer_face_labels", "face_labels_from_vertices", "transfer_collection", "TargetTransfer",
    # metrics
    "relative_error", "missing_labels", "indicators_to_labels", "labels_to_indicators", "random_indicators",
    "LabelFile", "load_labels", "save_labels",
]
