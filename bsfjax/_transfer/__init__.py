"""Transfer methods and the one engine that runs them.

A method (`AbstractMethod`) prepares a pair of spectra and a set of functions once and carries
them through any functional map: the paper's BSF with any coder, its competitors (spectral
projection, pull-back, product basis, geodesic balls, saturated heat), and the pull-back through
a refined map (`refined`, the default for labels).  `transfer` runs one pair, `transfer_pairs`
a stack of pairs under `vmap`.
"""

from ._engine import TransferResult, stack_pairs, transfer, transfer_pairs
from ._baselines import (
    GeodesicBalls, ProductBasis, PullBack, SaturatedHeat, SpectralProjection,
    geodesic_ball_radii, product_basis, saturate,
)
from ._bsf import AbstractMethod, BSF, PAPER_GAMMA, PAPER_TAUS, Pair
from ._methods import CODER_NAMES, METHODS, as_method, method_name
from ._refined import RefinedPullBack
from ._cloud_method import CLOUD_DESCRIPTOR_WEIGHT, method_for_shapes

__all__ = [
    "AbstractMethod", "BSF", "CLOUD_DESCRIPTOR_WEIGHT", "CODER_NAMES", "GeodesicBalls", "METHODS", "PAPER_GAMMA",
    "PAPER_TAUS", "Pair", "ProductBasis", "PullBack", "RefinedPullBack",
    "SaturatedHeat", "SpectralProjection", "TransferResult", "as_method", "geodesic_ball_radii",
    "method_for_shapes", "method_name", "product_basis", "saturate", "stack_pairs", "transfer", "transfer_pairs",
]
