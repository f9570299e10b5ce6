"""The lasso (bsfjax.Lasso) against scikit-learn's objective and the KKT conditions."""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from sklearn.linear_model import Lasso, orthogonal_mp, orthogonal_mp_gram

import bsfjax
from bsfjax import BSFError, Frame, decode, encode

from .conftest import data_path  # noqa: F401
from .coding_common import (METHODS, as_frame, faust, fold_duplicate, lasso_objective,  # noqa: F401
                            random_frame, random_functions, sk_omp)


# --------------------------------------------------------------------------------------------
# Lasso
# --------------------------------------------------------------------------------------------


def _sk_lasso(B, f, lam_abs):
    n = B.shape[0]
    return Lasso(alpha=lam_abs / n, fit_intercept=False, tol=1e-12,
                 max_iter=200000).fit(B, f).coef_


@pytest.mark.parametrize("lam", [0.003, 0.05, 0.3])
def test_lasso_reaches_sklearn_objective(lam):
    B = random_frame(14, n=80, q=50)
    F = random_functions(15, 4, 80)
    with jax.enable_x64(True):
        alpha, info = encode(B, F, "lasso", lam=lam, return_info=True)  # default tol/maxiter
        tight = np.asarray(encode(B, F, "lasso", lam=lam, tol=1e-9, maxiter=50000))
    alpha = np.asarray(alpha)
    assert np.all(info.converged)
    for i, f in enumerate(F):
        lam_abs = lam * np.abs(B.T @ f).max()
        ref = lasso_objective(B, f, _sk_lasso(B, f, lam_abs), lam_abs)
        assert lasso_objective(B, f, alpha[i], lam_abs) <= ref * (1 + 1e-4)
        # KKT: |bⱼᵀr| ≤ λ everywhere, = λ·sign(αⱼ) on the support
        g = B.T @ (f - B @ tight[i])
        assert np.all(np.abs(g) <= lam_abs * (1 + 1e-4))
        on = tight[i] != 0
        assert on.sum() >= 3
        np.testing.assert_allclose(g[on], lam_abs * np.sign(tight[i][on]), rtol=1e-4)


def test_lasso_faust_objective(faust):
    B, F, lam = faust["B"], faust["F"][:6], 0.01
    with jax.enable_x64(True):
        alpha = np.asarray(encode(faust["frame"], F, "lasso", lam=lam, weights=None))
    a32 = np.asarray(encode(faust["frame"], F.astype(np.float32), "lasso", lam=lam,
                            weights=None), np.float64)
    for i, f in enumerate(F):
        lam_abs = lam * np.abs(B.T @ f).max()
        ref = lasso_objective(B, f, _sk_lasso(B, f, lam_abs), lam_abs)
        assert lasso_objective(B, f, alpha[i], lam_abs) <= ref * (1 + 1e-4)
        assert lasso_objective(B, f, a32[i], lam_abs) <= ref * (1 + 1e-3)


def test_lasso_warm_start_and_large_lambda():
    B = random_frame(16, n=80, q=50)
    F = random_functions(17, 3, 80)
    with jax.enable_x64(True):
        sol = encode(B, F, "lasso", lam=0.02, tol=1e-9)
        warm, info_w = encode(B, F, "lasso", lam=0.02, init=sol, maxiter=2, tol=1e-6,
                              return_info=True)
        _, info_c = encode(B, F, "lasso", lam=0.02, maxiter=2, tol=1e-6, return_info=True)
        zero = encode(B, F, "lasso", lam=1.0)
    assert np.all(info_w.converged) and not np.any(info_c.converged)
    np.testing.assert_allclose(warm, sol, atol=1e-7)
    assert np.all(np.asarray(zero) == 0)
