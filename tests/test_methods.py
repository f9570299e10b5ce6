"""Every transfer method against a closed form or an independent float64 numpy computation."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError
from bsfjax import BSF, LeastSquares, Pair, transfer
from bsfjax import METHODS
from bsfjax.internal import geodesic_ball_radii, product_basis

from .conftest import icosphere


@pytest.fixture(scope="module")
def tiny():
    """42-vertex sphere with its *full* spectrum (k = n), centres and geodesic distances."""
    v, f = icosphere(1)
    mesh = bsfjax.Mesh(v, f)
    spec = bsfjax.spectrum(mesh, mesh.n_vertices)
    ctr = bsfjax.farthest_point_sampling(mesh, 6)
    dist = bsfjax.geodesic_distances(mesh, ctr)
    F = bsfjax.random_indicators(mesh, 4, seed=0, area_fraction=(0.1, 0.3), mass=spec.mass)
    return mesh, spec, ctr, dist, F


@pytest.fixture(scope="module")
def body():
    """The built-in example pair (2018 vertices) with 40 eigenpairs, GT map, centres."""
    ex = bsfjax.example_pair(levels=2)
    s = bsfjax.spectrum(ex.source, 40)
    t = bsfjax.spectrum(ex.target, 40)
    ctr = bsfjax.farthest_point_sampling(ex.source, 0.05)
    F = bsfjax.random_indicators(ex.source, 6, seed=1, mass=s.mass)
    C = np.asarray(bsfjax.fmap_from_p2p(s, t, ex.p2p))
    return ex, s, t, ctr, F, C


def _wlstsq(B, f, a, rcond=None):
    """Area-weighted least squares in float64 numpy: argmin ‖f − Bc‖_A (min norm)."""
    w = np.sqrt(a)
    c = np.linalg.lstsq(B * w[:, None], (f * w).T, rcond=rcond)[0]
    return (B @ c).T, c.T


def _self_pair(spec, ctr=None, dist=None, k=None):
    k = spec.k if k is None else k
    return Pair(spec, spec, np.eye(k), None, np.arange(spec.n_vertices), ctr, dist)


def test_std_full_basis_is_exact_and_identity_transfer(tiny):
    _, spec, _, _, F = tiny
    n = spec.n_vertices
    with jax.enable_x64(True):
        r = transfer("std", _self_pair(spec), F, k=n)
        np.testing.assert_allclose(r.approximation, F, atol=1e-9)
        np.testing.assert_allclose(r.transferred, F, atol=1e-9)


def test_std_and_std2_match_numpy_projection(body):
    ex, s, t, ctr, F, C = body
    k = 8
    phi, psi, a = s.evecs, t.evecs, s.mass
    pair = Pair(s, t, C[:k, :k], C[:2 * k, :2 * k])
    with jax.enable_x64(True):
        for method, kk in (("std", k), ("std2", 2 * k)):
            r = transfer(method, pair, F, k=k)
            coef = (F * a) @ phi[:, :kk]
            np.testing.assert_allclose(r.approximation, coef @ phi[:, :kk].T, atol=1e-10)
            want = coef @ C[:kk, :kk].T @ psi[:, :kk].T
            np.testing.assert_allclose(r.transferred, want, atol=1e-10)
    # std2 with 2k is std with 2k: better than std with k
    e1 = bsfjax.relative_error(F, transfer("std", pair, F, k=k).approximation, a)
    e2 = bsfjax.relative_error(F, transfer("std2", pair, F, k=k).approximation, a)
    assert np.mean(e2) < np.mean(e1)


def test_p2p_identity_is_exact_and_permutation_pulls_back(body):
    ex, s, t, ctr, F, C = body
    pair = Pair(s, t, C[:10, :10], p2p=np.asarray(ex.p2p))
    r = transfer("p2p", pair, F, k=10)
    assert r.approximation is None
    np.testing.assert_array_equal(np.asarray(r.transferred), F)
    perm = np.random.default_rng(0).permutation(s.n_vertices)
    r = transfer("p2p", Pair(s, t, C[:10, :10], p2p=perm), F, k=10)
    np.testing.assert_array_equal(np.asarray(r.transferred), F[:, perm])
    with pytest.raises(BSFError, match="only transfers"):
        transfer("p2p", pair, F, k=10, transfer=False)


def test_prod_matches_float64_extended_map(body):
    """Fit in the products basis (numpy lstsq) and transfer with the explicit extended map
    C_ext[(a,b),(i,j)] = C_ai C_bj + C_bi C_aj (a < b), C_ai C_aj (a = b)."""
    ex, s, t, ctr, F, _ = body
    k, kn = 4, 5
    C = np.random.default_rng(3).normal(size=(kn, k))  # any (rectangular) map
    phi, psi = s.evecs[:, :k], t.evecs[:, :kn]
    iu, ju = np.triu_indices(k)
    P_m = phi[:, iu] * phi[:, ju]
    au, bu = np.triu_indices(kn)
    P_n = psi[:, au] * psi[:, bu]
    C_ext = (C[au][:, iu] * C[bu][:, ju] + np.where((au != bu)[:, None],
                                                     C[bu][:, iu] * C[au][:, ju], 0.0))
    approx, c = _wlstsq(P_m, F, s.mass)
    want = (c @ C_ext.T) @ P_n.T
    with jax.enable_x64(True):
        np.testing.assert_allclose(product_basis(phi), P_m, atol=1e-14)
        r = transfer("prod", Pair(s, t, C), F, k=k, rcond=1e-10)
        np.testing.assert_allclose(r.approximation, approx, atol=1e-8)
        np.testing.assert_allclose(r.transferred, want, atol=1e-8)


def test_geod_balls_radii_and_identity_transfer(tiny):
    mesh, spec, ctr, dist, F = tiny
    params = bsfjax.GeodesicBalls(coder=LeastSquares())
    with jax.enable_x64(True):
        frame = bsfjax.build_frame(spec, ctr, params.taus, params.gamma)
        atoms = np.asarray(frame.atoms)
        areas = (spec.mass @ atoms).reshape(3, -1).mean(axis=1)
        radii = np.sqrt(areas / np.pi)
        np.testing.assert_allclose(geodesic_ball_radii(frame.atoms, spec.mass, 3), radii,
                                   rtol=1e-12)
        balls = (dist[None] <= radii[:, None, None]).reshape(-1, mesh.n_vertices).T.astype(float)
        approx, _ = _wlstsq(balls, F, spec.mass, rcond=np.sqrt(10 * np.finfo(float).eps))
        r = transfer(params, _self_pair(spec, ctr, dist), F, k=spec.k)
        np.testing.assert_allclose(r.approximation, approx, atol=1e-6)
        # full basis + identity map: every ball's projection is exact, so re-binarizing at 1/2
        # gives the same balls back and the transfer equals the approximation
        np.testing.assert_allclose(r.transferred, r.approximation, atol=1e-6)


def test_heat_saturated_kernels_match_numpy(body):
    ex, s, t, ctr, F, C = body
    k = 20
    params = bsfjax.SaturatedHeat(coder=LeastSquares())
    with jax.enable_x64(True):
        frame = bsfjax.build_frame(s.truncate(k), ctr, params.taus, params.gamma)
        g = s.evecs[:, :k] @ np.asarray(frame.coeffs)
        sat = np.minimum(1.0, np.abs(g) / (params.gamma * np.abs(g).max(axis=0)))
        # saturated kernels are exactly 1 on the BSF atoms and < 1 elsewhere
        np.testing.assert_array_equal(sat >= 1.0 - 1e-12, np.asarray(frame.atoms) > 0.5)
        approx, c = _wlstsq(sat, F, s.mass, rcond=np.sqrt(10 * np.finfo(float).eps))
        pair = Pair(s, t, C[:k, :k], centers=ctr)
        r = transfer(params, pair, F, k=k)
        np.testing.assert_allclose(r.approximation, approx, atol=1e-6)
        g_n = t.evecs[:, :k] @ (C[:k, :k] @ np.asarray(frame.coeffs))
        sat_n = np.minimum(1.0, np.abs(g_n) / (params.gamma * np.abs(g_n).max(axis=0)))
        np.testing.assert_allclose(r.transferred, c @ sat_n.T, atol=1e-5)


def test_ours_lstsq_matches_numpy_and_identity_transfer(body):
    ex, s, t, ctr, F, C = body
    k = 20
    with jax.enable_x64(True):
        frame = bsfjax.build_frame(s.truncate(k), ctr)
        B = np.asarray(frame.atoms)
        approx, c = _wlstsq(B, F, s.mass, rcond=np.sqrt(10 * np.finfo(float).eps))
        r = transfer("lstsq", Pair(s, t, C[:k, :k], centers=ctr), F, k=k)
        np.testing.assert_allclose(r.approximation, approx, atol=1e-6)
        tB = np.asarray(bsfjax.transfer_frame(frame, C[:k, :k], t).atoms)
        np.testing.assert_allclose(r.transferred, c @ tB.T, atol=1e-5)
        r_self = transfer("lstsq", _self_pair(s, ctr, k=k), F, k=k)
        np.testing.assert_allclose(r_self.transferred, r_self.approximation, atol=1e-9)


def test_ours_omp_matches_sklearn(body):
    from sklearn.linear_model import orthogonal_mp

    ex, s, t, ctr, F, C = body
    k, S = 20, 5
    with jax.enable_x64(True):
        B = np.asarray(bsfjax.build_frame(s.truncate(k), ctr).atoms)
        w = np.sqrt(s.mass)
        keep = B.sum(axis=0) > 0
        D = (B * w[:, None])[:, keep]
        norms = np.linalg.norm(D, axis=0)
        coef = orthogonal_mp(D / norms, (F * w).T, n_nonzero_coefs=S) / norms[:, None]
        want = (B[:, keep] @ coef).T
        r = transfer("omp", Pair(s, centers=ctr), F, k=k, transfer=False,
                         sparsity=S)
        np.testing.assert_allclose(r.approximation, want, atol=1e-8)


def test_ours_lasso_matches_sklearn(body):
    """½‖f − Bα‖²_A + λ‖α‖₁ with λ = lam·‖Bᵀ A f‖∞ (coding's relative λ) against sklearn."""
    from sklearn.linear_model import Lasso

    ex, s, t, ctr, F, C = body
    k, lam = 10, 0.05
    with jax.enable_x64(True):
        B = np.asarray(bsfjax.build_frame(s.truncate(k), ctr).atoms)
        w = np.sqrt(s.mass)
        X = B * w[:, None]
        r = transfer("lasso", Pair(s, centers=ctr), F[:3], k=k, transfer=False,
                         lam=lam, maxiter=20000)
        for i in range(3):
            y = F[i] * w
            lam_abs = lam * np.abs(X.T @ y).max()
            sk = Lasso(alpha=lam_abs / len(y), fit_intercept=False, tol=1e-12, max_iter=100000)
            want = B @ sk.fit(X, y).coef_
            got = np.asarray(r.approximation[i])
            assert np.sqrt(s.mass @ (got - want) ** 2) < 2e-3 * np.sqrt(s.mass @ F[i] ** 2)


def test_omp_error_bound_is_eps_fraction_of_the_area_norm(body):
    ex, s, t, ctr, F, C = body
    with jax.enable_x64(True):
        frame = bsfjax.build_frame(s.truncate(30), ctr)
        fnorm2 = (F * F) @ s.mass
        for frac in (0.35, 0.5):  # 0.2 is beyond the frame's reach for most of these functions
            r = transfer("omp_error", Pair(s, centers=ctr), F, k=30, transfer=False,
                             eps_fraction=frac)
            alpha, info = bsfjax.encode(frame, F, "omp_error", eps=frac ** 2 * fnorm2,
                                        weights="area", return_info=True)
            np.testing.assert_allclose(r.approximation, bsfjax.decode(frame, alpha), atol=1e-9)
            err = np.asarray(bsfjax.relative_error(F, r.approximation, s.mass))
            conv = np.asarray(info.converged)
            assert conv.any()
            assert np.all(err[conv] <= frac + 1e-9)  # ‖f − f̃‖_A ≤ frac · ‖f‖_A when reached


def test_vmap_over_stacked_pairs_equals_single_runs(body):
    ex, s, t, ctr, F, C = body
    k = 10
    single = [Pair(s, t, C[:k, :k], centers=ctr),
              Pair(t, s, C[:k, :k].T, centers=ctr)]
    stacked = jax.tree.map(lambda *x: np.stack(x), *single)
    FF = np.stack([F, F[::-1]])
    for method in ("std", "prod", "omp"):
        rs = transfer(method, stacked, FF, k=k)
        for i, p in enumerate(single):
            r = transfer(method, p, FF[i], k=k)
            np.testing.assert_allclose(rs.approximation[i], r.approximation, atol=2e-5)
            np.testing.assert_allclose(rs.transferred[i], r.transferred, atol=2e-5)


def test_k_targets_reuse_one_code(body):
    ex, s, t, ctr, F, C = body
    pair = Pair(s, t, C[:20, :10], centers=ctr)
    for method in ("std", "omp"):
        res = transfer(method, pair, F, k=10, k_targets=(5, 12, 20))
        assert isinstance(res.transferred, tuple) and len(res.transferred) == 3
        for kn, tr in zip((5, 12, 20), res.transferred):
            one = transfer(method, Pair(s, t, C[:kn, :10], centers=ctr), F, k=10)
            np.testing.assert_allclose(tr, one.transferred, atol=2e-5)
    with pytest.raises(BSFError, match="k_targets must be non-empty ints in"):
        transfer("std", pair, F, k=10, k_targets=(30,))
    with pytest.raises(BSFError, match="k_targets needs"):
        transfer("std", pair, F, k=10, k_targets=(5,), transfer=False)


def test_every_method_runs_and_errors_are_sane(body):
    ex, s, t, ctr, F, C = body
    dist = bsfjax.geodesic_distances(ex.source, ctr)
    k = 10
    pair = Pair(s, t, C[:k, :k], C[:2 * k, :2 * k], np.asarray(ex.p2p), ctr, dist)
    ref = F[:, ex.p2p]
    for method in METHODS:
        r = transfer(method, pair, F, k=k)
        e = np.asarray(bsfjax.relative_error(ref, r.transferred, t.mass))
        assert np.all(np.isfinite(e)) and np.mean(e) < 1.0, method


def test_validation_errors(body):
    ex, s, t, ctr, F, C = body
    pair = Pair(s, t, C[:10, :10], centers=ctr)
    with pytest.raises(BSFError, match="method must be one of"):
        transfer("fourier", pair, F, k=10)
    with pytest.raises(BSFError, match="centers"):
        transfer("omp", Pair(s, t, C[:10, :10]), F, k=10)
    with pytest.raises(BSFError, match="distances"):
        transfer("geod", pair, F, k=10)
    with pytest.raises(BSFError, match="C2"):
        transfer("std2", pair, F, k=10)
    with pytest.raises(BSFError, match="k_M = 12"):
        transfer("std", pair, F, k=12)
    with pytest.raises(BSFError, match="needs 80 source eigenpairs"):
        transfer("std2", pair, F, k=40)
    with pytest.raises(BSFError, match="p2p"):
        transfer("p2p", pair, F, k=10)
    with pytest.raises(BSFError, match="n_M"):
        transfer("std", pair, F[:, :-1], k=10)
    with pytest.raises(BSFError, match="NaN"):
        transfer("std", pair, np.full_like(F, np.nan), k=10)
    with pytest.raises(BSFError, match="gamma"):
        BSF(gamma=1.5)
    with pytest.raises(BSFError, match="coder"):
        BSF(coder="std")
    with pytest.raises(BSFError, match="has no option"):
        transfer("std", pair, F, k=10, sparsity=3)
