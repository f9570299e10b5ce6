"""Least squares (bsfjax.LeastSquares, "lstsq") against numpy float64."""

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
# lstsq
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(120, 60), (40, 90)])
def test_lstsq_matches_numpy_float64(shape):
    """Minimum-norm least squares = numpy.linalg.lstsq, tall and wide rank-deficient frames."""
    B = random_frame(1, *shape)
    F = random_functions(2, 7, shape[0])
    ref = np.linalg.lstsq(B, F.T, rcond=None)[0].T
    with jax.enable_x64(True):
        alpha, info = encode(B, F, "lstsq", return_info=True)
        assert alpha.dtype == jnp.float64
    np.testing.assert_allclose(alpha, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    assert np.all(np.asarray(alpha)[:, 3] == 0)  # empty atom: zero in the minimum-norm solution
    res = np.linalg.norm(F - ref @ B.T, axis=1)
    np.testing.assert_allclose(info.residual, res, rtol=1e-9, atol=1e-12)


def test_lstsq_real_frame(faust):
    B, F = faust["B"], faust["F"]
    ref = np.linalg.lstsq(B, F.T, rcond=None)[0].T
    with jax.enable_x64(True):
        alpha = np.asarray(encode(faust["frame"], F, "lstsq", weights=None))
    np.testing.assert_allclose(alpha, ref, rtol=0, atol=1e-8 * np.abs(ref).max())
    # float32: the approximation (not the ill-determined coefficients) to float32 accuracy
    a32 = encode(faust["frame"], F.astype(np.float32), "lstsq", weights=None)
    assert a32.dtype == jnp.float32
    err = np.linalg.norm((np.asarray(a32, np.float64) - ref) @ B.T, axis=1)
    assert np.all(err <= 1e-4 * np.linalg.norm(F, axis=1))


def test_gram_float64_binary_fast_path_is_exact():
    """0/1 atoms: G is computed by a float32 GEMM (exact integers) — equal to float64 numpy."""
    B = random_frame(32, n=300, q=70)
    W = B * np.linspace(0.5, 1.5, 300)[:, None]  # not 0/1: the float64 GEMM
    with jax.enable_x64(True):
        for X in (B, W):
            G = jax.jit(bsfjax._frame._dense_frame.dense_gram)(jnp.asarray(X))
            assert G.dtype == jnp.float64
            np.testing.assert_allclose(G, X.T @ X, rtol=1e-14, atol=0)


def test_lstsq_rcond_cuts_small_singular_values():
    """rcond = numpy's rcond: directions with s < rcond·s_max are dropped the same way."""
    rng = np.random.default_rng(3)
    U, _ = np.linalg.qr(rng.standard_normal((50, 8)))
    V, _ = np.linalg.qr(rng.standard_normal((8, 8)))
    s = np.array([10, 5, 3, 1, 0.5, 0.1, 0.03, 0.01])
    A = U @ np.diag(s) @ V.T
    f = rng.standard_normal((3, 50))
    with jax.enable_x64(True):
        for rcond in (1e-2, 0.04):  # 0.04·10 = 0.4: drops 0.1, 0.03, 0.01
            ours = encode(A, f, "lstsq", rcond=rcond)
            np.testing.assert_allclose(ours, np.linalg.lstsq(A, f.T, rcond=rcond)[0].T,
                                       atol=1e-10)
