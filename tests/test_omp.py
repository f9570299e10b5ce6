"""OMP and error-constrained OMP (bsfjax.OMP / ErrorOMP) against scikit-learn."""

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
# OMP
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("S", [1, 12])
@pytest.mark.parametrize("precompute", [True, False])
def test_omp_matches_sklearn_random(S, precompute):
    """Same support and coefficients (1e-6, float64) as orthogonal_mp.

    orthogonal_mp's default path (precompute=False) stops early when the best next atom has
    zero *initial* correlation with f (it tests a stale Xᵀy; here: an atom disjoint from f);
    its Gram path (precompute=True) tests the current correlation, as OMP proper does.  The
    Gram path is the reference; the default path must agree wherever it did not stop early."""
    B = random_frame(4)
    F = random_functions(5, 9, B.shape[0])
    ref = sk_omp(B, F, S=S, precompute=True)
    ref_default = sk_omp(B, F, S=S, precompute=False)
    full = np.sum(ref_default != 0, axis=1) == S
    assert full.sum() >= 6
    np.testing.assert_allclose(ref_default[full], ref[full], atol=1e-12)
    with jax.enable_x64(True):
        alpha, info = encode(B, F, "omp", sparsity=S, precompute=precompute, return_info=True)
    alpha, ref = fold_duplicate(alpha), fold_duplicate(ref)
    np.testing.assert_array_equal(alpha != 0, ref != 0)
    np.testing.assert_allclose(alpha, ref, rtol=0, atol=1e-6)
    assert np.all(info.n_atoms == S) and np.all(info.converged)
    np.testing.assert_allclose(info.residual, np.linalg.norm(F - ref @ B.T, axis=1), rtol=1e-9)


def _tie_free(B, F, S):
    """Functions whose OMP path (scikit-learn's, float64) never has two distinct atoms tied for
    the largest correlation (to 1e-9 relative).  Indicator functions on binary atoms produce
    exact ties (e.g. two equal-size atoms inside the region), which any implementation breaks
    by rounding noise — there the support is not determined."""
    norms = np.linalg.norm(B, axis=0)
    D = B / np.where(norms > 0, norms, 1)
    ok = np.ones(F.shape[0], bool)
    for s in range(S):
        A = sk_omp(B, F, S=s, precompute=True) if s else np.zeros((F.shape[0], B.shape[1]))
        C = np.abs((F - A @ B.T) @ D)
        C[A != 0] = 0
        top = np.sort(C, axis=1)[:, -2:]
        ok &= top[:, 1] - top[:, 0] > 1e-9 * top[:, 1]
    return ok


@pytest.mark.parametrize("weighted", [False, True])
def test_omp_matches_sklearn_faust(faust, weighted):
    """Real frame, indicator functions: same support, coefficients to 1e-6 (float64).

    scikit-learn's default path (precompute=False) stops as soon as the best atom has zero
    *initial* correlation with f (it tests a stale Xᵀy), i.e. when the best next atom is
    disjoint from the region; its Gram path (precompute=True) tests the current correlation
    like OMP proper, so it is the reference here."""
    B, F, S = faust["B"], faust["F"], 10
    w = np.sqrt(faust["mass"]) if weighted else np.ones(B.shape[0])
    Bw, Fw = B * w[:, None], F * w
    ref = sk_omp(Bw, Fw, S=S, precompute=True)
    with jax.enable_x64(True):
        alpha = np.asarray(encode(faust["frame"], F, "omp", sparsity=S,
                                  weights="area" if weighted else None))
    keep = _tie_free(Bw, Fw, S)
    # area weights are irrational: no ties; plain indicators: a few exact ties
    assert keep.all() if weighted else keep.sum() >= 10
    np.testing.assert_array_equal(alpha[keep] != 0, ref[keep] != 0)
    scale = np.abs(ref).max()
    np.testing.assert_allclose(alpha[keep], ref[keep], rtol=0, atol=1e-6 * scale)
    # tied functions still reach an equally good S-term fit
    r_ours = np.linalg.norm(Fw - alpha @ Bw.T, axis=1)
    r_ref = np.linalg.norm(Fw - ref @ Bw.T, axis=1)
    assert np.all(r_ours <= 1.05 * r_ref)


def test_omp_float32_default_dtype(faust):
    F = faust["F"]
    alpha, info = encode(faust["frame"], F, "omp", weights="area", return_info=True)
    assert alpha.dtype == jnp.float32 and info.residual.dtype == jnp.float32
    with jax.enable_x64(True):
        a64 = np.asarray(encode(faust["frame"], F, "omp", weights="area"))
    same = np.all((np.asarray(alpha) != 0) == (a64 != 0), axis=1)
    assert same.sum() >= len(F) - 1  # a near-tie may flip in float32
    np.testing.assert_allclose(np.asarray(alpha)[same], a64[same], atol=1e-4 * np.abs(a64).max())


def test_omp_gram_and_column_paths_agree(faust):
    with jax.enable_x64(True):
        a = encode(faust["frame"], faust["F"], "omp", sparsity=8, precompute=True, weights=None)
        b = encode(faust["frame"], faust["F"], "omp", sparsity=8, precompute=False, weights=None)
    np.testing.assert_allclose(a, b, atol=1e-10)


@pytest.mark.parametrize("method", ["omp", "omp_error"])
def test_omp_chunked_batches_equal_one_chunk(method, monkeypatch):
    """Large batches run in chunks (lax.map, last chunk padded): same result as one chunk."""
    B = random_frame(30, n=50, q=40)
    F = random_functions(31, 8, 50)
    opts = {"sparsity": 6} if method == "omp" else {"eps": 0.2 * np.sum(F * F, 1), "max_atoms": 6}
    with jax.enable_x64(True):
        whole, info_w = encode(B, F, method, return_info=True, **opts)
        monkeypatch.setattr(bsfjax._coding._omp, "_OMP_CHUNK_ELEMS", 3 * 6 * 40)  # chunks of 3
        chunked, info_c = encode(B, F, method, return_info=True, **opts)
    np.testing.assert_allclose(chunked, whole, rtol=0, atol=1e-12)
    for a, b in zip(info_c, info_w):
        np.testing.assert_allclose(a, b, rtol=1e-12)


def test_omp_duplicates_empty_atoms_and_exhaustion():
    """S = q on a frame with an empty and a duplicated atom: never the empty atom, never both
    copies, no NaN; OMP stops once nothing is left to fit, at the least-squares residual."""
    B = random_frame(6, n=40, q=30, density=0.3)
    F = random_functions(7, 5, 40)
    with jax.enable_x64(True):
        alpha, info = encode(B, F, "omp", sparsity=30, return_info=True)
    alpha = np.asarray(alpha)
    assert np.all(np.isfinite(alpha))
    assert np.all(alpha[:, 3] == 0)
    assert not np.any((alpha[:, 7] != 0) & (alpha[:, 11] != 0))
    assert np.all(info.n_atoms <= np.linalg.matrix_rank(B))
    assert np.all(info.converged)
    lsq = np.linalg.norm(F - np.linalg.lstsq(B, F.T, rcond=None)[0].T @ B.T, axis=1)
    np.testing.assert_allclose(info.residual, lsq, rtol=1e-8, atol=1e-10)


def test_zero_function_and_empty_frame():
    """f = 0, an all-empty frame, and f supported where no atom is: α = 0, no NaN."""
    B = random_frame(8, n=30, q=20)
    F = np.zeros((2, 30))
    empty = np.zeros((30, 20))
    f_outside = np.zeros((2, 30))
    B_part = B.copy()
    B_part[:5] = 0.0
    f_outside[:, :5] = [[1.0], [2.0]]
    for method in METHODS:
        for frame, f in ((B, F), (empty, random_functions(9, 2, 30)), (B_part, f_outside)):
            alpha, info = encode(frame, f, method, return_info=True)
            assert np.all(np.asarray(alpha) == 0), method
            assert np.all(np.isfinite(info.residual)) and np.all(info.n_atoms == 0), method
            np.testing.assert_allclose(info.residual, np.linalg.norm(f, axis=-1), rtol=1e-6)



# --------------------------------------------------------------------------------------------
# Error-constrained OMP
# --------------------------------------------------------------------------------------------


def test_omp_error_matches_sklearn_tol():
    """Wide random frame (q > n, bound reachable): per-function ε, same atoms and coefficients
    as orthogonal_mp(tol=ε), and exactly the functions sklearn fits are flagged converged."""
    B = random_frame(10, n=40, q=90, density=0.3)
    F = random_functions(11, 8, 40)
    eps = np.linspace(0.02, 0.3, 8) * np.sum(F * F, axis=1)
    ref = sk_omp(B, F, tol=eps, precompute=True)
    with jax.enable_x64(True):
        alpha, info = encode(B, F, "omp_error", eps=eps, max_atoms=40, return_info=True)
    alpha, ref = fold_duplicate(alpha), fold_duplicate(ref)
    np.testing.assert_array_equal(alpha != 0, ref != 0)
    np.testing.assert_allclose(alpha, ref, rtol=0, atol=1e-6)
    res2 = np.sum((F - ref @ B.T) ** 2, axis=1)
    assert np.all(res2 <= eps) and np.all(info.converged)
    np.testing.assert_array_equal(info.n_atoms, np.sum(ref != 0, axis=1))


def test_omp_error_faust_cap_and_minimality(faust):
    """Real frame, area-weighted, ε = (‖f‖_A / 3)²: where sklearn needs ≤ max_atoms atoms we
    agree exactly; elsewhere we stop at the cap and report converged=False."""
    B, F, cap = faust["B"], faust["F"], 24
    w = np.sqrt(faust["mass"])
    Fw = F * w
    eps = (np.linalg.norm(Fw, axis=1) / 3) ** 2
    ref = sk_omp(B * w[:, None], Fw, tol=eps, precompute=True)
    k_ref = np.sum(ref != 0, axis=1)
    with jax.enable_x64(True):
        alpha, info = encode(faust["frame"], F, "omp_error", eps=eps, max_atoms=cap,
                             weights="area", return_info=True)
    alpha = np.asarray(alpha)
    within = k_ref <= cap
    assert 3 <= within.sum() < len(F)  # both cases occur
    np.testing.assert_array_equal(alpha[within] != 0, ref[within] != 0)
    np.testing.assert_allclose(alpha[within], ref[within], atol=1e-6 * np.abs(ref).max())
    # converged = the bound is met (sklearn may also stop short of it: residual orthogonal to
    # every atom, nothing left to fit)
    met = np.sum((Fw - ref @ (B * w[:, None]).T) ** 2, axis=1) <= eps
    np.testing.assert_array_equal(info.converged, within & met)
    assert np.all(info.n_atoms[~within] == cap)
    # minimality: one atom fewer (plain OMP with S = n_atoms − 1) misses the bound
    with jax.enable_x64(True):
        for i in np.flatnonzero(within & met & (k_ref > 1))[:2]:
            _, inf1 = encode(faust["frame"], F[i], "omp", sparsity=int(k_ref[i]) - 1,
                             weights="area", return_info=True)
            assert float(inf1.residual) ** 2 > eps[i]


def test_omp_error_default_eps_conventions():
    B = random_frame(12, n=40, q=90, density=0.3)
    F = 3.0 * random_functions(13, 6, 40)
    norms = np.linalg.norm(F, axis=1)
    with jax.enable_x64(True):
        a_def, i_def = encode(B, F, "omp_error", max_atoms=40, return_info=True)
        a_rel, _ = encode(B, F, "omp_error", eps=(norms / 10) ** 2, max_atoms=40,
                          return_info=True)
        a_sp, i_sp = encode(B, F, "omp_error", eps="spams", max_atoms=40, return_info=True)
        a_abs = encode(B, F, "omp_error", eps=norms / 10, max_atoms=40)
    np.testing.assert_array_equal(a_def, a_rel)  # default: ε = (‖f‖/10)²
    np.testing.assert_array_equal(a_sp, a_abs)  # "spams": ε = ‖f‖/10 on the squared residual
    assert np.all(np.asarray(i_def.residual) <= norms / 10 + 1e-12)
    assert np.all(np.asarray(i_sp.residual) ** 2 <= norms / 10 + 1e-12)
    assert np.all(i_def.converged) and np.all(i_sp.converged)
