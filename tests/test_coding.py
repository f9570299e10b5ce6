"""Sparse coding (bsfjax.encode / decode) against numpy, scikit-learn and closed-form properties.

Frames here are built independently of ``bsfjax.build_frame``: random binary matrices (with an
empty and a duplicated atom, as real binary frames have), and a small real frame on FAUST
tr_reg_000 made with numpy, ``atoms = |Φ(ĝ ⊙ Φ[x, :])| / max ≥ 0.75``.
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order
from sklearn.linear_model import Lasso, orthogonal_mp, orthogonal_mp_gram

import bsfjax
from bsfjax import BSFError, Frame, decode, encode

from .conftest import data_path

METHODS = ("lstsq", "omp", "omp_error", "lasso")


# --------------------------------------------------------------------------------------------
# Frames and functions
# --------------------------------------------------------------------------------------------


def random_frame(seed, n=120, q=60, density=0.25):
    """Random binary atoms with one empty column and one duplicated column (rank deficient)."""
    rng = np.random.default_rng(seed)
    B = (rng.random((n, q)) < density).astype(np.float64)
    B[:, 3] = 0.0
    B[:, 7] = B[:, 11]
    return B


def fold_duplicate(A):
    """Coefficients with the duplicated atom 11 folded into its copy 7: which of two identical
    atoms OMP picks is a tie (scikit-learn's column swapping and our lowest-index rule differ)."""
    A = np.array(A, dtype=np.float64)
    A[..., 7] += A[..., 11]
    A[..., 11] = 0.0
    return A


def random_functions(seed, m, n, density=0.3):
    """Random step functions plus a little noise: exact ties between atoms' correlations (which
    binary functions on binary atoms produce, and which any OMP breaks by rounding noise) do
    not occur, so the OMP path is determined.  Indicator functions are tested on FAUST."""
    rng = np.random.default_rng(seed)
    return (rng.random((m, n)) < density) + 0.1 * rng.random((m, n))


def as_frame(B, mass=None):
    n, q = B.shape
    return Frame(atoms=B, coeffs=np.zeros((1, q)), taus=np.ones(q), centers=np.zeros(q, int),
                 mass=np.ones(n) if mass is None else mass)


def sk_omp(B, F, S=None, tol=None, precompute=False):
    """orthogonal_mp on the ℓ2-normalised non-empty atoms, mapped back: α_j = β_j / ‖b_j‖.

    ``precompute=True`` is orthogonal_mp's Gram path; it is called here as what it runs,
    ``orthogonal_mp_gram(DᵀD, DᵀF)``, so that the Gram matrix is formed once for all calls."""
    norms = np.linalg.norm(B, axis=0)
    ok = norms > 0
    D = B[:, ok] / norms[ok]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # "ended prematurely"
        if precompute:
            G, Xy = D.T @ D, D.T @ F.T
            if tol is None:
                beta = orthogonal_mp_gram(G, Xy, n_nonzero_coefs=S)
            else:
                beta = np.stack([orthogonal_mp_gram(G, Xy[:, i:i + 1], tol=float(tol[i]),
                                                    norms_squared=[F[i] @ F[i]])
                                 for i in range(F.shape[0])], axis=1)
        elif tol is None:
            beta = orthogonal_mp(D, F.T, n_nonzero_coefs=S)
        else:
            beta = np.stack([orthogonal_mp(D, F[i], tol=float(tol[i]))
                             for i in range(F.shape[0])], axis=1)
    alpha = np.zeros((B.shape[1], F.shape[0]))
    alpha[ok] = beta.reshape(ok.sum(), -1) / norms[ok][:, None]
    return alpha.T


def lasso_objective(B, f, a, lam_abs):
    r = f - B @ a
    return 0.5 * r @ r + lam_abs * np.abs(a).sum()


@pytest.fixture(scope="module")
def faust():
    """A small real frame on FAUST tr_reg_000 (k = 30, 60 centres, 3 scales → q = 180) and 14
    indicator functions: 10 connected regions grown breadth-first from random vertices
    (3–20 % of the vertices) and 4 half-spaces ``y > t`` / ``x > t``."""
    mesh = bsfjax.load_mesh(data_path("faust", "tr_reg_000.off"))
    spec = bsfjax.spectrum(mesh, 30)
    V, n = mesh.vertices, mesh.n_vertices
    rng = np.random.default_rng(0)
    centers = rng.choice(n, 60, replace=False)
    lam = spec.evals * spec.mass.sum()  # scale-invariant τ (unit-area eigenvalues)
    cols = []
    for tau in (1e-3, 5e-3, 1e-2):
        g = spec.evecs @ (np.exp(-tau * (lam - lam[0]))[:, None] * spec.evecs[centers].T)
        cols.append(np.abs(g) / np.abs(g).max(axis=0) >= 0.75)
    B = np.concatenate(cols, axis=1).astype(np.float64)
    f = mesh.faces
    i, j = np.r_[f[:, 0], f[:, 1], f[:, 2]], np.r_[f[:, 1], f[:, 2], f[:, 0]]
    adj = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(n, n)).tocsr()
    regions = []
    for _ in range(10):
        order = breadth_first_order(adj + adj.T, int(rng.integers(n)), directed=False,
                                    return_predecessors=False)
        x = np.zeros(n)
        x[order[: int(rng.uniform(0.03, 0.2) * n)]] = 1.0
        regions.append(x)
    for axis, qt in ((1, 0.3), (1, 0.6), (1, 0.9), (0, 0.5)):
        regions.append((V[:, axis] > np.quantile(V[:, axis], qt)).astype(np.float64))
    return {"B": B, "mass": spec.mass, "F": np.stack(regions),
            "frame": as_frame(B, spec.mass)}


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
        alpha = np.asarray(encode(faust["frame"], F, "lstsq"))
    np.testing.assert_allclose(alpha, ref, rtol=0, atol=1e-8 * np.abs(ref).max())
    # float32: the approximation (not the ill-determined coefficients) to float32 accuracy
    a32 = encode(faust["frame"], F.astype(np.float32), "lstsq")
    assert a32.dtype == jnp.float32
    err = np.linalg.norm((np.asarray(a32, np.float64) - ref) @ B.T, axis=1)
    assert np.all(err <= 1e-4 * np.linalg.norm(F, axis=1))


def test_gram_float64_binary_fast_path_is_exact():
    """0/1 atoms: G is computed by a float32 GEMM (exact integers) — equal to float64 numpy."""
    B = random_frame(32, n=300, q=70)
    W = B * np.linspace(0.5, 1.5, 300)[:, None]  # not 0/1: the float64 GEMM
    with jax.enable_x64(True):
        for X in (B, W):
            G = jax.jit(bsfjax._coding._gram)(jnp.asarray(X))
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
        a = encode(faust["frame"], faust["F"], "omp", sparsity=8, precompute=True)
        b = encode(faust["frame"], faust["F"], "omp", sparsity=8, precompute=False)
    np.testing.assert_allclose(a, b, atol=1e-10)


@pytest.mark.parametrize("method", ["omp", "omp_error"])
def test_omp_chunked_batches_equal_one_chunk(method, monkeypatch):
    """Large batches run in chunks (lax.map, last chunk padded): same result as one chunk."""
    B = random_frame(30, n=50, q=40)
    F = random_functions(31, 8, 50)
    opts = {"sparsity": 6} if method == "omp" else {"eps": 0.2 * np.sum(F * F, 1), "max_atoms": 6}
    with jax.enable_x64(True):
        whole, info_w = encode(B, F, method, return_info=True, **opts)
        monkeypatch.setattr(bsfjax._coding, "_OMP_CHUNK_ELEMS", 3 * 6 * 40)  # chunks of 3
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
        alpha = np.asarray(encode(faust["frame"], F, "lasso", lam=lam))
    a32 = np.asarray(encode(faust["frame"], F.astype(np.float32), "lasso", lam=lam), np.float64)
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


# --------------------------------------------------------------------------------------------
# Weights, batching, jit / vmap, decode
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
def test_area_weights_equal_row_scaling(faust, method):
    """weights='area' codes in ‖·‖_A: the same as scaling B's and f's rows by √mass."""
    F = faust["F"][:4]
    w = np.sqrt(faust["mass"])
    with jax.enable_x64(True):
        a, info = encode(faust["frame"], F, method, weights="area", return_info=True)
        b = encode(faust["B"] * w[:, None], F * w, method)
        c = encode(faust["B"], F, method, weights=faust["mass"])
    np.testing.assert_allclose(a, b, atol=1e-9 * np.abs(b).max())
    np.testing.assert_allclose(a, c, atol=1e-12 * np.abs(b).max())
    r = np.sqrt(np.sum(faust["mass"] * (F - np.asarray(a) @ faust["B"].T) ** 2, axis=1))
    np.testing.assert_allclose(info.residual, r, rtol=1e-8)


@pytest.mark.parametrize("method", METHODS)
def test_vmap_jit_and_batch_equal_single_calls(method):
    B = random_frame(18)
    F = random_functions(19, 5, B.shape[0])
    opts = {"omp_error": {"eps": 0.3 * np.sum(F * F, axis=1)[0], "max_atoms": 20}}.get(
        method, {})
    with jax.enable_x64(True):
        loop = np.stack([np.asarray(encode(B, f, method, **opts)) for f in F])
        batch = encode(B, F, method, **opts)
        vm = jax.vmap(lambda f: encode(B, f, method, **opts))(jnp.asarray(F))
        jt = jax.jit(lambda f: encode(B, f, method, **opts))(jnp.asarray(F))
        nested = encode(B, F.reshape(5, 1, -1), method, **opts)
    for other in (batch, vm, jt, nested.reshape(5, -1)):
        np.testing.assert_allclose(other, loop, rtol=0, atol=1e-10 * np.abs(loop).max())


@pytest.mark.parametrize("method", ["lstsq", "omp"])
def test_vmap_over_frames(method):
    """A stack of frames (e.g. one per shape) with one function each, under one vmap."""
    Bs = np.stack([random_frame(s) for s in (26, 27, 28)])
    F = random_functions(29, 3, Bs.shape[1])
    frames = jax.tree.map(lambda *x: jnp.stack(x), *[as_frame(B) for B in Bs])
    with jax.enable_x64(True):
        vm = jax.vmap(lambda fr, f: encode(fr, f, method, weights="area"))(frames, F)
        loop = np.stack([np.asarray(encode(B, f, method)) for B, f in zip(Bs, F)])
    np.testing.assert_allclose(vm, loop, rtol=0, atol=1e-10 * np.abs(loop).max())


def test_batch_shapes_info_and_decode():
    B = random_frame(20)
    F = random_functions(21, 6, B.shape[0]).reshape(2, 3, -1)
    alpha, info = encode(as_frame(B), F, "omp", sparsity=4, return_info=True)
    assert alpha.shape == (2, 3, B.shape[1])
    assert info.n_atoms.shape == info.residual.shape == info.converged.shape == (2, 3)
    assert np.all(info.n_atoms == 4)
    rec = decode(as_frame(B), alpha)
    assert rec.shape == F.shape
    np.testing.assert_allclose(rec, np.asarray(alpha) @ B.T, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(info.residual, np.linalg.norm(F - np.asarray(rec), axis=-1),
                               rtol=1e-4, atol=1e-4)
    assert encode(B, np.zeros((0, B.shape[0])), "omp").shape == (0, B.shape[1])


def test_encode_accepts_build_frame(faust):
    """A frame from bsfjax.build_frame works like its atom array."""
    if not hasattr(bsfjax, "build_frame"):
        pytest.skip("bsfjax.build_frame not available")
    mesh = bsfjax.load_mesh(data_path("faust", "tr_reg_000.off"))
    frame = bsfjax.build_frame(bsfjax.spectrum(mesh, 20), np.arange(0, mesh.n_vertices, 400))
    F = faust["F"][:3]
    np.testing.assert_allclose(encode(frame, F, "omp", sparsity=5),
                               encode(np.asarray(frame.atoms), F, "omp", sparsity=5), atol=1e-6)


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, match", [
    ({"method": "omg"}, "method"),
    ({"method": "omp", "sparsity": 0}, "sparsity"),
    ({"method": "omp", "sparsity": 61}, "sparsity"),
    ({"method": "omp", "sparsity": 2.5}, "sparsity"),
    ({"method": "omp", "sparsity": True}, "sparsity"),
    ({"method": "omp", "sparsty": 3}, "sparsty"),
    ({"method": "omp", "lam": 0.1}, "lam"),
    ({"method": "omp", "precompute": "yes"}, "precompute"),
    ({"method": "omp_error", "max_atoms": 0}, "max_atoms"),
    ({"method": "omp_error", "eps": -1.0}, "eps"),
    ({"method": "omp_error", "eps": np.ones(3)}, "eps"),
    ({"method": "omp_error", "eps": "paper"}, "eps"),
    ({"method": "lasso", "lam": 0.0}, "lam"),
    ({"method": "lasso", "lam": -0.1}, "lam"),
    ({"method": "lasso", "lam": float("nan")}, "lam"),
    ({"method": "lasso", "maxiter": 0}, "maxiter"),
    ({"method": "lasso", "tol": 0.0}, "tol"),
    ({"method": "lasso", "init": np.zeros((2, 5))}, "init"),
    ({"method": "lstsq", "rcond": 1.5}, "rcond"),
    ({"method": "lstsq", "sparsity": 3}, "sparsity"),
    ({"method": "omp", "weights": "volume"}, "weights"),
    ({"method": "omp", "weights": np.ones(7)}, "weights"),
    ({"method": "omp", "weights": -np.ones(120)}, "weights"),
    ({"method": "omp", "return_info": 1}, "return_info"),
])
def test_bad_options_raise(kwargs, match):
    B = random_frame(22)
    F = random_functions(23, 2, B.shape[0])
    with pytest.raises(BSFError, match=match):
        encode(B, F, **kwargs)


def test_bad_inputs_raise():
    B = random_frame(24)
    f = random_functions(25, 2, B.shape[0])
    with pytest.raises(BSFError, match=r"f has length 119.*n = 120"):
        encode(B, f[:, :-1])
    bad = f.copy()
    bad[1, 4] = np.nan
    with pytest.raises(BSFError, match="f contains 1 NaN"):
        encode(B, bad)
    bad[1, 4] = np.inf
    with pytest.raises(BSFError, match="f contains"):
        encode(B, bad, "lstsq")
    with pytest.raises(BSFError, match="weights='area' needs a bsfjax.Frame"):
        encode(B, f, weights="area")
    with pytest.raises(BSFError, match="frame atoms must have shape"):
        encode(np.stack([B, B]), f)
    with pytest.raises(BSFError, match="frame"):
        encode("not a frame", f)
    with pytest.raises(BSFError, match="alpha must have shape"):
        decode(B, np.zeros((2, 7)))
    # traced inputs skip value checks but keep shape checks
    with pytest.raises(BSFError, match="f has length"):
        jax.jit(lambda x: encode(B, x))(jnp.zeros((2, 5)))
