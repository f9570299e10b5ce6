"""bsfjax: Binary Sparse Frames in JAX.

Sparse representation and transfer of step functions on manifolds, after S. Melzi,
"Sparse representation of step functions on manifolds", Computers & Graphics 82 (2019).

The public names, grouped by pipeline stage (data flows downwards only; one private module
owns each step, see ``docs/architecture.md``)::

    mesh        Mesh, load_mesh, save_mesh, mesh_report, example_pair   _mesh, _mesh_write, _example
                load_labels, save_labels (segmentation files, SMPL's .json)   _label_files
    operators   laplacian -> (W, A)                                           _laplacian
    spectrum    Spectrum, spectrum, spectrum_from_operators                   _spectrum
    sampling    farthest_point_sampling, subsample, geodesic_distances        _sampling, _geodesics
    frame       Frame, SparseFrame, build_frame, transfer_frame, ...          _frame, ...
    coding      OMP, ErrorOMP, LeastSquares, Lasso, encode, decode            _coding, ...
    transfer    METHODS, BSF, ..., Pair, transfer, transfer_pairs             _methods, _transfer
    maps        wks, hks, estimate_fmap, zoomout, fmap_to_p2p                 _fmap, _estimation, ...
                orientation_bases (the orientation term's face scan, shared)   _orientation
                map_distortion, orientation_agreement, choose_map             _distortion
                estimate_map, mirror_symmetry (mesh to mesh)                  _map_estimate
    mesh level  transfer_values, transfer_labels                              _highlevel
                transfer_face_labels, face_label_shares (labels per triangle) _face_labels
    collection  transfer_collection (one source to many targets, batched)    _collection
    metrics     relative_error, labels_to_indicators, random_indicators       _metrics, _indicators
    experiments bsfjax.experiments (the paper's tables and figures), bsfjax.plot, bsfjax.cli
"""

# the ``bsfjax`` command handles Ctrl-C from here on, before the heavy imports below (a no-op
# when bsfjax is imported as a library; see _signals)
from ._util import install_sigint_handler

install_sigint_handler()

from importlib.metadata import PackageNotFoundError, version as _version

from ._util import BSFError, MeshError

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
from ._frame import adaptive_taus, prune_frame, unique_atoms

# coding
from ._coding import AbstractCoder, CodingInfo
from ._coding import LeastSquares
from ._coding import OMP, ErrorOMP
from ._coding import Lasso
from ._coding import CODERS, as_coder, decode, encode

# transfer
from ._transfer import BSF, METHODS, AbstractMethod, GeodesicBalls, Pair, ProductBasis, PullBack, RefinedPullBack, SaturatedHeat, SpectralProjection, as_method
from ._transfer import TransferResult, stack_pairs, transfer, transfer_pairs

# functional maps
from ._maps import hks, wks
from ._maps import fmap_from_p2p, fmap_to_p2p, icp_refine, nearest_neighbors, zoomout
from ._maps import refine_point_maps
from ._maps import FmapWeights, estimate_fmap, fmap_energy
from ._maps import OrientationBasis, orientation_bases
from ._maps import choose_map, map_distortion, orientation_agreement

# mesh-level entry points
from ._maps import MapEstimate, estimate_map, mirror_symmetry
from ._pipeline import REGIMES, LabelTransfer, transfer_labels, transfer_values
from ._pipeline import FaceShares, decide_face_labels, face_label_shares, face_labels_from_vertices, face_scores, transfer_face_labels
from ._pipeline import TargetTransfer, size_bucket, transfer_collection

# metrics and test functions
from ._metrics import relative_error
from ._metrics import indicators_to_labels, labels_to_indicators, random_indicators
from ._mesh import LabelFile, is_face_file, load_labels, save_labels

try:
    __version__ = _version("bsfjax")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

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
    "unique_atoms",
    # coding
    "AbstractCoder", "CodingInfo", "CODERS", "as_coder", "encode", "decode", "OMP", "ErrorOMP",
    "LeastSquares", "Lasso",
    # transfer
    "METHODS", "AbstractMethod", "BSF", "SpectralProjection", "PullBack", "RefinedPullBack", "ProductBasis",
    "GeodesicBalls", "SaturatedHeat", "as_method", "Pair", "TransferResult", "transfer",
    "transfer_pairs", "stack_pairs",
    # functional maps
    "hks", "wks", "fmap_from_p2p", "fmap_to_p2p", "icp_refine", "nearest_neighbors", "zoomout",
    "refine_point_maps",
    "FmapWeights", "estimate_fmap", "fmap_energy", "OrientationBasis", "orientation_bases",
    "map_distortion", "orientation_agreement",
    "choose_map",
    # mesh level
    "MapEstimate", "estimate_map", "mirror_symmetry", "LabelTransfer", "REGIMES",
    "transfer_values", "transfer_labels",
    "transfer_face_labels", "face_label_shares", "face_scores", "decide_face_labels",
    "FaceShares", "face_labels_from_vertices", "transfer_collection", "TargetTransfer",
    "size_bucket",
    # metrics
    "relative_error", "indicators_to_labels", "labels_to_indicators", "random_indicators",
    "LabelFile", "load_labels", "save_labels", "is_face_file",
]
