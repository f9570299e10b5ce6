"""Coefficients of step functions in a frame: `f ≈ B α`.

Coders are small objects whose options are their fields: minimum-norm least squares (paper
Eq. 6), OMP with at most `S` atoms (Eq. 9), OMP to an error bound (Eq. 8), and the ℓ1-relaxed
problem (Lasso, jaxopt proximal gradient).  Each is written against the frame operator and
batched over functions; `encode` / `decode` are the entry points.
"""

from ._coders import AbstractCoder, CodingInfo
from ._encode import CODERS, as_coder, decode, encode
from ._lasso import Lasso
from ._lstsq import LeastSquares
from ._omp import ErrorOMP, OMP

__all__ = [
    "AbstractCoder", "CODERS", "CodingInfo", "ErrorOMP", "Lasso", "LeastSquares", "OMP",
    "as_coder", "decode", "encode",
]
