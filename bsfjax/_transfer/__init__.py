"""Transfer methods (BSF and the paper's baselines) and the engine that runs any of them on one pair or a batch of pairs."""

from ._engine import Pair, TransferResult, stack_pairs, transfer, transfer_pairs
from ._methods import (
    AbstractMethod, BSF, CODER_NAMES, GeodesicBalls, METHODS, PAPER_GAMMA, PAPER_TAUS, Pair,
    ProductBasis, PullBack, RefinedPullBack, SaturatedHeat, SpectralProjection, as_method,
    geodesic_ball_radii, method_name, product_basis, saturate,
)

__all__ = [
    "AbstractMethod", "BSF", "CODER_NAMES", "GeodesicBalls", "METHODS", "PAPER_GAMMA",
    "PAPER_TAUS", "Pair", "Pair", "ProductBasis", "PullBack", "RefinedPullBack",
    "SaturatedHeat", "SpectralProjection", "TransferResult", "as_method", "geodesic_ball_radii",
    "method_name", "product_basis", "saturate", "stack_pairs", "transfer", "transfer_pairs",
]
