r"""Minimum-norm least squares in a frame (paper Eq. 6): the [`LeastSquares`][bsfjax.LeastSquares] coder.

    α = argmin ‖f − Bα‖_W  of minimum norm  = G⁺ BᵀWf,      G = BᵀWB,

from the eigendecomposition ``G = V Λ Vᵀ``, then one step of iterative refinement against
``B`` itself.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp

from ._coders import AbstractCoder, check_positive
from .._util import BSFError

__all__ = ["LeastSquares"]


class LeastSquares(AbstractCoder):
    """Minimum-norm least squares ``α = B⁺_W f`` (paper Eq. 6).

    The solution is ``α = V Λ⁺ Vᵀ BᵀWf`` from the eigendecomposition ``G = BᵀWB = V Λ Vᵀ``
    (then one step of iterative refinement against ``B``), i.e. numpy's ``lstsq`` computed
    through ``G``; since ``G``'s eigenvalues ``s²`` carry an absolute error ``~eps·s_max²``,
    singular values below ``~√eps·s_max`` cannot be told from zero, hence the default
    ``rcond`` (numpy's own ``max(n, q)·eps`` is below that resolution).  Binary frames are
    often rank deficient (duplicate atoms); the minimum-norm solution is returned.

    **Arguments:**

    - `rcond`: singular values of ``B`` below ``rcond · s_max`` count as zero; ``None``
      (default): ``√(10·eps)`` of the dtype.  In ``[0, 1)``.
    - `weights`: the coding norm (see [`AbstractCoder`][bsfjax.AbstractCoder]).
    """

    rcond: float | None = eqx.field(static=True, default=None)
    name = "lstsq"

    def __check_init__(self):
        if self.rcond is not None:
            r = check_positive("rcond", self.rcond, allow_zero=True)
            if r >= 1:
                raise BSFError(f"rcond must be in [0, 1), got {r}")

    def _options(self, frame, w, lead, m, dtype, host=False):
        return {"rcond": self.rcond}, {}, {}

    @classmethod
    def _solve(cls, frame, F, w, C, fnorm2, static, dyn):
        G = frame.gram(w).astype(C.dtype)
        nonempty = frame.column_norms2(w) > 0
        alpha = lstsq_gram(G, C, lambda a: frame.apply_transpose(F - frame.apply(a), w),
                           nonempty, static["rcond"])
        return alpha, jnp.ones(F.shape[0], bool)


def lstsq_gram(G, C, resid_corr, nonempty, rcond):
    """``α = G⁺ C`` rows, refined once with ``resid_corr(α) = BᵀW(f − Bα)`` rows."""
    dtype = G.dtype
    if rcond is None:
        rcond = math.sqrt(10 * float(jnp.finfo(dtype).eps))
    lam, V = jnp.linalg.eigh(G)
    keep = lam > (rcond * rcond) * lam[-1]  # s_i > rcond·s_max (lam ≥ 0 up to rounding)
    inv = jnp.where(keep, 1.0 / jnp.where(keep, lam, 1.0), 0.0)

    def solve(rhs):  # G⁺ rhs for rows of rhs (m, q)
        return ((rhs @ V) * inv) @ V.T

    alpha = solve(C)
    # One step of iterative refinement with the residual computed against B itself: the
    # normal equations lose accuracy as κ(B)², the refined solution only as κ(B).  The update
    # stays in the range of G⁺, so the solution keeps minimum norm.
    alpha = alpha + solve(resid_corr(alpha))
    # Empty atoms are exactly 0 in the minimum-norm solution; the eigenvectors only get that
    # to rounding, so make it exact (and n_atoms meaningful).
    return jnp.where(nonempty, alpha, 0.0)
