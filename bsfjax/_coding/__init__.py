"""Coefficients: the coders (least squares, OMP, error-bounded OMP, Lasso) written against the frame operator, and `encode` / `decode`."""

from ._coders import AbstractCoder, CodingInfo
from ._encode import CODERS, as_coder, decode, encode
from ._lasso import Lasso
from ._lstsq import LeastSquares
from ._omp import ErrorOMP, OMP

__all__ = [
    "AbstractCoder", "CODERS", "CodingInfo", "ErrorOMP", "Lasso", "LeastSquares", "OMP",
    "as_coder", "decode", "encode",
]
