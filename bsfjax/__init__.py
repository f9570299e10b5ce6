"""bsfjax: Binary Sparse Frames in JAX.

Sparse representation and transfer of step functions on manifolds, after S. Melzi,
"Sparse representation of step functions on manifolds", Computers & Graphics 82 (2019).

Pipeline, one module per stage (data flows downwards only)::

    mesh.py        Mesh, load_mesh, save_mesh
    laplacian.py   laplacian -> (W, A)
    spectrum.py    Spectrum, spectrum, spectrum_from_operators, interval_spectrum
"""

from importlib.metadata import PackageNotFoundError, version as _version

from .errors import BSFError, MeshError
from .laplacian import laplacian
from .mesh import Mesh, MeshReport, load_mesh, mesh_report, save_mesh
from .example import ExamplePair, example_mesh, example_pair
from .spectrum import Spectrum, interval_spectrum, spectrum, spectrum_from_operators
from .sampling import farthest_point_sampling
from .sparse_frame import SparseFrame
from .frame import (Frame, adaptive_taus, build_frame, prune_frame, transfer_frame,
                    unique_atoms)
from .coding import CodingInfo, decode, encode
from .pipeline import PairResult, approximate, stack_spectra, transfer, transfer_pairs
from .descriptors import hks, wks
from .fmap import fmap_from_p2p, fmap_to_p2p, icp_refine, nearest_neighbors, zoomout
from .estimation import FmapWeights, estimate_fmap, fmap_energy
from .geodesics import geodesic_distances, geodesic_error
from .metrics import relative_error
from .indicators import indicators_to_labels, labels_to_indicators, random_indicators

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
