"""bsfjax: Binary Sparse Frames in JAX.

Sparse representation and transfer of step functions on manifolds, after S. Melzi,
"Sparse representation of step functions on manifolds", Computers & Graphics 82 (2019).

Pipeline, one module per stage (data flows downwards only)::

    mesh.py        Mesh, load_mesh, save_mesh
    laplacian.py   laplacian -> (W, A)
    spectrum.py    Spectrum, spectrum, spectrum_from_operators, interval_spectrum
"""

from importlib.metadata import PackageNotFoundError, version as _version

from ._errors import BSFError, MeshError
from ._laplacian import laplacian
from ._mesh import Mesh, MeshReport, load_mesh, mesh_report, save_mesh
from ._example import ExamplePair, example_mesh, example_pair
from ._spectrum import Spectrum, interval_spectrum, spectrum, spectrum_from_operators
from ._sampling import farthest_point_sampling
from ._operator import AbstractFrame
from ._sparse_frame import SparseFrame
from ._dense_frame import Frame
from ._frame import build_frame, transfer_frame
from ._frame_tools import adaptive_taus, prune_frame, unique_atoms
from ._coders import AbstractCoder, CodingInfo
from ._lstsq import LeastSquares
from ._omp import OMP, ErrorOMP
from ._lasso import Lasso
from ._encode import CODERS, as_coder, decode, encode
from ._pipeline import PairResult, approximate, stack_spectra, transfer, transfer_pairs
from ._descriptors import hks, wks
from ._fmap import fmap_from_p2p, fmap_to_p2p, icp_refine, nearest_neighbors, zoomout
from ._estimation import FmapWeights, estimate_fmap, fmap_energy
from ._geodesics import geodesic_distances, geodesic_error
from ._metrics import relative_error
from ._indicators import indicators_to_labels, labels_to_indicators, random_indicators
from ._highlevel import LabelTransfer, MapEstimate, estimate_map, transfer_labels, transfer_values

try:
    __version__ = _version("bsfjax")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = [
    "relative_error",
    "random_indicators",
    "labels_to_indicators",
    "indicators_to_labels",
    "PairResult",
    "approximate",
    "stack_spectra",
    "transfer",
    "transfer_pairs",
    "CodingInfo",
    "decode",
    "encode",
    "AbstractCoder",
    "LeastSquares",
    "OMP",
    "ErrorOMP",
    "Lasso",
    "CODERS",
    "as_coder",
    "AbstractFrame",
    "FmapWeights",
    "estimate_fmap",
    "fmap_energy",
    "fmap_from_p2p",
    "fmap_to_p2p",
    "geodesic_distances",
    "geodesic_error",
    "hks",
    "icp_refine",
    "nearest_neighbors",
    "wks",
    "zoomout",
    "ExamplePair",
    "example_mesh",
    "example_pair",
    "BSFError",
    "Frame",
    "SparseFrame",
    "build_frame",
    "farthest_point_sampling",
    "transfer_frame",
    "adaptive_taus",
    "prune_frame",
    "unique_atoms",
    "Mesh",
    "MeshReport",
    "mesh_report",
    "MeshError",
    "Spectrum",
    "interval_spectrum",
    "laplacian",
    "load_mesh",
    "save_mesh",
    "spectrum",
    "spectrum_from_operators",
]
