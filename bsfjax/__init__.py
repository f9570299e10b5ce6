"""bsfjax: Binary Sparse Frames in JAX.

Sparse representation and transfer of step functions on manifolds, after S. Melzi,
"Sparse representation of step functions on manifolds", Computers & Graphics 82 (2019).

The public names are grouped by pipeline stage, in the order data flows through them: mesh,
operators and spectrum, sampling, frame, coding, transfer, functional maps, mesh level,
metrics; plus the modules ``bsfjax.experiments`` (the paper's tables and figures),
``bsfjax.plot`` and ``bsfjax.cli``.  The API reference (``docs/api/``) has one page per
stage; ``docs/architecture.md`` maps the private sub-package behind each stage and their
layers.  ``bsfjax.internal`` holds the names one level below, for tests and benchmarks.
"""

# the ``bsfjax`` command handles Ctrl-C from here on, before the heavy imports below (a no-op
# when bsfjax is imported as a library; see _signals)
from ._util import install_sigint_handler

install_sigint_handler()

from ._util import VERSION, BSFError, MeshError

# mesh
from ._mesh import Mesh, MeshReport, load_mesh, mesh_report
from ._mesh import save_mesh
from ._mesh import ExamplePair, example_mesh, example_pair

# operators and spectrum
from ._spectral import laplacian
from ._spectral import Spectrum, interval_spectrum, spectrum, spectrum_from_operators, stack_spectra

# sampling
from ._sampling import Subsample, farthest_point_sampling, subsample
from ._sampling import geodesic_distances, geodesic_error

# frame
from ._frame import AbstractFrame
from ._frame import Frame
from ._frame import SparseFrame
from ._frame import build_frame, transfer_frame
from ._frame import adaptive_taus, prune_frame

# coding
from ._coding import AbstractCoder, CodingInfo
from ._coding import LeastSquares
from ._coding import OMP, ErrorOMP
from ._coding import Lasso
from ._coding import decode, encode

# transfer
from ._transfer import BSF, METHODS, AbstractMethod, GeodesicBalls, Pair, ProductBasis, PullBack, RefinedPullBack, SaturatedHeat, SpectralProjection
from ._transfer import TransferResult, stack_pairs, transfer, transfer_pairs

# functional maps
from ._maps import hks, wks
from ._maps import fmap_from_p2p, fmap_to_p2p, icp_refine, zoomout
from ._maps import refine_point_maps
from ._maps import FmapWeights, estimate_fmap, fmap_energy
from ._maps import choose_map, map_distortion, orientation_agreement

# mesh-level entry points
from ._maps import MapEstimate, estimate_map, mirror_symmetry
from ._pipeline import REGIMES, LabelTransfer, transfer_labels, transfer_values
from ._pipeline import face_labels_from_vertices, transfer_face_labels
from ._pipeline import TargetTransfer, transfer_collection

# metrics and test functions
from ._metrics import relative_error
from ._metrics import indicators_to_labels, labels_to_indicators, random_indicators
from ._mesh import LabelFile, load_labels, save_labels

__version__ = VERSION

__all__ = [
    "BSFError", "MeshError",
    # mesh
    "Mesh", "MeshReport", "load_mesh", "mesh_report", "save_mesh", "ExamplePair",
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
    "map_distortion", "orientation_agreement",
    "choose_map",
    # mesh level
    "MapEstimate", "estimate_map", "mirror_symmetry", "LabelTransfer", "REGIMES",
    "transfer_values", "transfer_labels",
    "transfer_face_labels", "face_labels_from_vertices", "transfer_collection", "TargetTransfer",
    # metrics
    "relative_error", "indicators_to_labels", "labels_to_indicators", "random_indicators",
    "LabelFile", "load_labels", "save_labels",
]
