"""The block shift-invert Lanczos eigensolver (``bsfjax._spectral._eigensolver``) and the ``method``
option of ``spectrum`` / ``spectrum_from_operators``: closed forms, dense LAPACK and ARPACK
references, both linear-solver backends, breakdown, non-convergence and the cache key."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp

import bsfjax
from bsfjax import BSFError
from bsfjax._spectral._block_basis import ORTH_LEVEL, _cholqr, _orthonormalize, _rotate_in_place
from bsfjax._spectral._eigensolver import MissedEigenvalue, block_lanczos
from bsfjax._spectral._factorize import factorize, has_cholmod
from bsfjax.internal import interval_operators

from .conftest import icosphere

BACKENDS = ["superlu"] + (["cholmod"] if has_cholmod() else [])


def _sigma(W, a):
    return -1e-6 * float(W.diagonal().mean() / a.mean())


def _projector_gap(P1, P2, a):
    """Largest principal-angle sine between span P1 and span P2 (both A-orthonormal)."""
    M = P1.T @ (a[:, None] * P2)
    return float(np.sqrt(max(0.0, 1.0 - np.linalg.svd(M, compute_uv=False).min() ** 2)))


@pytest.fixture(scope="module")
def sphere3():
    v, f = icosphere(3)  # 642 vertices, eigenvalues l(l+1) with multiplicity 2l+1
    return bsfjax.Mesh(v, f)


@pytest.mark.parametrize("backend", BACKENDS)
def test_interval_closed_form(backend):
    # the lumped-mass P1 interval is the Neumann finite-difference Laplacian: its eigenvalues
    # are exactly (4/h²) sin²(π l / (2(n−1))), its eigenvectors cos(π l i / (n−1))
    n, k = 1500, 24
    W, a = interval_operators(n)
    lam, phi, info = block_lanczos(W, a, k, _sigma(W, a), backend=backend)
    h = 1.0 / (n - 1)
    l = np.arange(k)
    exact = 4 / h**2 * np.sin(np.pi * l / (2 * (n - 1))) ** 2
    np.testing.assert_allclose(lam[1:], exact[1:], rtol=1e-10)
    assert abs(lam[0]) < 1e-8 * exact[-1]
    assert abs(phi.T @ (a[:, None] * phi) - np.eye(k)).max() < 1e-10
    cosines = np.cos(np.pi * np.outer(np.arange(n), l) / (n - 1))
    cosines /= np.sqrt(np.einsum("ij,i,ij->j", cosines, a, cosines))
    overlap = np.abs(np.einsum("ij,i,ij->j", phi, a, cosines))
    assert overlap.min() > 1 - 1e-10  # simple eigenvalues: each vector is the cosine
    assert info["backend"] == backend and info["residual"] <= 1e-8


def test_small_bases_restart_correctly():
    # k = 10 with block 4: a 34-vector basis restarted many times (a stale Rayleigh–Ritz
    # result reused at a restart once stalled exactly this case); also k = 3 and k = 40
    n = 2000
    W, a = interval_operators(n)
    h = 1.0 / (n - 1)
    for k, block in ((10, 4), (3, None), (40, None)):
        lam, _, info = block_lanczos(W, a, k, _sigma(W, a), block=block, backend="superlu")
        exact = 4 / h**2 * np.sin(np.pi * np.arange(k) / (2 * (n - 1))) ** 2
        np.testing.assert_allclose(lam[1:], exact[1:], rtol=1e-10)
        assert info["restarts"] <= 4


def test_nonnegative_sigma_goes_to_arpack():
    W, a = interval_operators(1000)
    with_shift = bsfjax.spectrum_from_operators(W, a, 8, sigma=0.5)
    arpack = bsfjax.spectrum_from_operators(W, a, 8, method="lanczos")
    np.testing.assert_allclose(with_shift.evals, arpack.evals, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
def test_sphere_matches_dense_lapack(sphere3, backend):
    W, A = bsfjax.laplacian(sphere3)
    a = A.diagonal()
    k = 40  # cuts no eigenspace: l = 0..5 have 1+3+5+7+9+11 = 36 vectors, l = 6 has 13
    ref_l, ref_v = scipy.linalg.eigh(W.toarray(), np.diag(a), subset_by_index=[0, 48])
    lam, phi, _ = block_lanczos(W, a, k, _sigma(W, a), backend=backend)
    np.testing.assert_allclose(lam[1:], ref_l[1:k], rtol=1e-9)
    assert abs(phi.T @ (a[:, None] * phi) - np.eye(k)).max() < 1e-10
    # multiplicity 2l+1: compare eigenspaces, not vectors
    assert _projector_gap(phi[:, :36], ref_v[:, :36], a) < 1e-6
    resid = W @ phi - (a[:, None] * phi) * lam
    assert np.linalg.norm(resid / np.sqrt(a)[:, None], axis=0).max() < 1e-8 * lam[-1]


def test_spectrum_methods_agree_on_faust(faust_mesh):
    # the 6890-vertex FAUST scan: block Lanczos against ARPACK, same operators, k = 30
    block = bsfjax.spectrum(faust_mesh, 30, method="block")
    arpack = bsfjax.spectrum(faust_mesh, 30, method="lanczos")
    np.testing.assert_allclose(block.evals[1:], arpack.evals[1:], rtol=1e-9)
    gaps = np.diff(arpack.evals)
    simple = np.flatnonzero((gaps[:-1] > 1e-3 * arpack.evals[-1])
                            & (gaps[1:] > 1e-3 * arpack.evals[-1])) + 1
    dots = np.einsum("ij,i,ij->j", block.evecs, block.mass, arpack.evecs)
    assert np.abs(dots[simple]).min() > 1 - 1e-6  # same vectors (the sign rule fixes signs)
    np.testing.assert_array_equal(bsfjax.spectrum(faust_mesh, 30, method="block").evecs,
                                  block.evecs)  # deterministic


def test_fast_method_error_is_as_documented(faust_mesh):
    exact = bsfjax.spectrum(faust_mesh, 30, method="lanczos")
    fast = bsfjax.spectrum(faust_mesh, 30, method="fast")
    rel = np.abs(fast.evals[1:] - exact.evals[1:]) / exact.evals[1:]
    assert rel.max() < 1e-5
    gram = fast.evecs.T @ (fast.mass[:, None] * fast.evecs)
    assert abs(gram - np.eye(30)).max() < 1e-10
    # the span of the first 20 stays close to the exact one (measured ~1e-7 on the cat)
    assert _projector_gap(fast.evecs[:, :20], exact.evecs[:, :20], exact.mass) < 1e-3


def test_breakdown_few_distinct_eigenvalues():
    # W = diag with 3 distinct values: the Krylov space is exhausted after one block, and the
    # solver must continue with fresh directions instead of dividing by zero
    n, k = 400, 6
    vals = np.repeat([0.0, 1.0, 5.0], [2, 5, n - 7])
    W, a = sp.diags(vals).tocsr(), np.ones(n)
    lam, phi, _ = block_lanczos(W, a, k, -0.01, block=4)
    np.testing.assert_allclose(lam, [0, 0, 1, 1, 1, 1], atol=1e-10)
    assert abs(phi.T @ phi - np.eye(k)).max() < 1e-10
    assert abs(phi[7:]).max() < 1e-8  # nothing from the eigenvalue 5


def test_probe_catches_a_missed_multiplicity():
    v, f = icosphere(2)  # 162 vertices; λ(l=2) has multiplicity 5 > block 4
    W, A = bsfjax.laplacian(bsfjax.Mesh(v, f))
    a = A.diagonal()
    with pytest.raises(MissedEigenvalue, match="missed 1 eigenvalue"):
        block_lanczos(W, a, 10, _sigma(W, a), tol=1e-3, backend="superlu")


@pytest.mark.parametrize("older", ["tiny", "large"])
def test_orthonormalize_keeps_the_krylov_relation(older):
    # Z = Q C + Qn R with Qn orthonormal and ⟂ Q, whether the older columns' share is below
    # ORTH_LEVEL (update skipped: the share stays in Qn, within the level) or above it
    rng = np.random.default_rng(3)
    n, m, b, lo = 500, 40, 4, 32
    Q = np.asfortranarray(np.linalg.qr(rng.standard_normal((n, m)))[0])
    coef = rng.standard_normal((m, b))
    coef[:lo] *= 1e-15 if older == "tiny" else 1.0
    P = rng.standard_normal((n, b))
    for _ in range(2):
        P -= Q @ (Q.T @ P)  # the new directions, ⟂ Q
    Z = np.asfortranarray(Q @ coef + P)
    Z0 = Z.copy()
    C, Qn, R = _orthonormalize(Z, Q, lo, rng)
    assert abs(Qn.T @ Qn - np.eye(b)).max() < 1e-13
    assert abs(Q.T @ Qn).max() < (ORTH_LEVEL if older == "tiny" else 1e-14)
    np.testing.assert_allclose(Q @ C + Qn @ R, Z0, atol=1e-12)
    np.testing.assert_allclose(C, coef, atol=1e-12)


def test_cholqr_and_in_place_rotation():
    rng = np.random.default_rng(4)
    Z = np.asfortranarray(rng.standard_normal((300, 6)) * np.array([1, 10, 1e3, 1, 1, 1e-2]))
    Z0 = Z.copy()
    for G in (None, Z.T @ Z):
        Qn, R = _cholqr(Z, G)
        assert abs(Qn.T @ Qn - np.eye(6)).max() < 1e-14
        np.testing.assert_allclose(Qn @ R, Z0, rtol=0, atol=1e-12 * abs(Z0).max())
        assert np.array_equal(Z, Z0)  # the input stays intact (the caller's fallback needs it)
    assert np.isnan(np.diag(_cholqr(np.ones((50, 3)))[1])).all()  # rank deficient
    Q = np.asfortranarray(rng.standard_normal((1000, 12)))
    S = rng.standard_normal((10, 7))
    want = Q[:, :10] @ S
    _rotate_in_place(Q, 10, S, rows=64)  # slabs that do not divide the rows
    np.testing.assert_allclose(Q[:, :7], want, rtol=1e-13, atol=1e-13)


def test_probe_gets_the_rayleigh_block_from_the_krylov_relation(monkeypatch):
    # the probe's Yᵀ K Y comes from the Krylov relation (Λ − (Yᵀ (K − σ) Q_new) G Θ⁻¹), not
    # from K applied to all of Y: it must equal the direct product to rounding
    import bsfjax._spectral._eigensolver as E
    seen = {}
    probe = E._missed_eigenvalues

    def spy(T, W, d, Y, YKY, lam, b, rng, **kw):
        seen.update(W=W, d=d, Y=np.array(Y), YKY=YKY, lam=lam)
        return probe(T, W, d, Y, YKY, lam, b, rng, **kw)
    monkeypatch.setattr(E, "_missed_eigenvalues", spy)
    W, a = interval_operators(1200)
    # a loose tolerance (the "fast" method's), so that Yᵀ K Y is visibly not Λ
    lam, phi, _ = block_lanczos(W, a, 20, _sigma(W, a), tol=1e-3)
    d, Y = seen["d"], seen["Y"]
    direct = Y.T @ ((W @ (Y / d[:, None])) / d[:, None])
    off = abs(direct - np.diag(seen["lam"])).max()
    assert off > 1e-11 * lam[-1]
    assert abs(seen["YKY"] - direct).max() < 0.05 * off  # (measured: 2e-9 against 2e-7)
    np.testing.assert_allclose(Y / d[:, None], phi, rtol=0, atol=1e-14)


def test_failed_confirmation_restarts_from_the_ritz_vectors(monkeypatch):
    # the confirmation writes the Ritz vectors over the basis; if the true residuals fail,
    # that is a thick restart keeping k vectors, and the solver goes on to the same pairs
    import bsfjax._spectral._eigensolver as E
    W, a = interval_operators(1500)
    lam0, phi0, info0 = block_lanczos(W, a, 16, _sigma(W, a))
    calls = []
    real = E._residual_norms

    def fail_once(*args):
        res = real(*args)
        calls.append(res)
        return res + (1.0 if len(calls) == 1 else 0.0)
    monkeypatch.setattr(E, "_residual_norms", fail_once)
    lam, phi, info = block_lanczos(W, a, 16, _sigma(W, a))
    assert len(calls) >= 2 and info["restarts"] == info0["restarts"] + 1
    assert info["solves"] > info0["solves"]
    np.testing.assert_allclose(lam[1:], lam0[1:], rtol=1e-10)
    assert abs(phi.T @ (a[:, None] * phi) - np.eye(16)).max() < 1e-10
    assert abs(np.abs(np.einsum("ij,i,ij->j", phi, a, phi0)) - 1).max() < 1e-8


def test_mapped_basis_and_released_tail():
    # the basis lives in its own anonymous map; after the eigenvectors (its first k columns)
    # are taken, the memory past them is given back: those pages read zeros, the columns
    # kept are intact, also when they end inside a page
    import mmap

    from bsfjax._spectral._block_basis import _mapped_empty, _release_after
    n, m, k = 1000, 12, 5
    Q, buf = _mapped_empty(n, m)
    assert Q.shape == (n, m) and Q.flags.f_contiguous and Q.flags.writeable
    Q[:] = np.arange(1.0, m + 1.0)
    _release_after(buf, Q[:, :k].nbytes)
    np.testing.assert_array_equal(Q[:, :k], np.broadcast_to(np.arange(1.0, k + 1.0), (n, k)))
    if hasattr(buf, "madvise") and hasattr(mmap, "MADV_DONTNEED"):
        start = -(-Q[:, :k].nbytes // mmap.PAGESIZE) * mmap.PAGESIZE // 8
        flat = Q.reshape(-1, order="F")
        assert np.all(flat[start:] == 0.0) and np.all(flat[:n * k] > 0)


def test_errors_are_clear():
    W, a = interval_operators(800)
    with pytest.raises(BSFError, match="did not converge"):
        block_lanczos(W, a, 30, _sigma(W, a), tol=1e-30, max_restarts=1)
    with pytest.raises(BSFError, match="k \\+ 2\\*block"):
        block_lanczos(W, a, 790, _sigma(W, a), block=8)
    with pytest.raises(BSFError, match="method must be one of"):
        bsfjax.spectrum_from_operators(W, a, 5, method="arnoldi")
    with pytest.raises(BSFError, match="backend"):
        factorize(W, "umfpack")
    if not has_cholmod():
        with pytest.raises(BSFError, match="cholespy"):
            factorize(W + sp.eye(800), "cholmod")


def test_method_option_and_cache_key(tmp_path, sphere3):
    with pytest.raises(BSFError, match="method must be one of"):
        bsfjax.spectrum(sphere3, 5, method=3)
    spec_mod = __import__("bsfjax._spectral._spectrum", fromlist=["x"])
    assert spec_mod._resolve_method("auto", 500, 10) == "dense"
    assert spec_mod._resolve_method("auto", 5000, 10) == "lanczos"  # ARPACK is faster there
    assert spec_mod._resolve_method("auto", 50_000, 10) == ("block" if has_cholmod() else "lanczos")
    # from 45 eigenpairs the block solver is the faster at any size (k = 100 at 5.5K:
    # 0.26 s against 0.36 s; k = 45 at 5.0K: 0.12 s against 0.18 s)
    assert spec_mod._resolve_method("auto", 5000, 45) == ("block" if has_cholmod() else "lanczos")
    assert spec_mod._resolve_method("auto", 5000, 44) == "lanczos"
    assert spec_mod._resolve_method("fast", 5000, 10) == "fast"
    keys = {spec_mod._cache_key(sphere3, 10, "mixed", False, m)
            for m in ("block", "lanczos", "dense", "fast")}
    assert len(keys) == 4
    first = bsfjax.spectrum(sphere3, 10, cache_dir=tmp_path, method="lanczos")
    # the sphere's 5-fold λ(l=2) exceeds the block of 4: the block solver misses or stalls,
    # and spectrum says so and falls back to ARPACK instead of returning a wrong basis
    with pytest.warns(UserWarning, match="falling back to method='lanczos'"):
        fast = bsfjax.spectrum(sphere3, 10, cache_dir=tmp_path, method="fast")
    assert len(list(tmp_path.glob("*.npz"))) == 2  # one file per solver
    again = bsfjax.spectrum(sphere3, 10, cache_dir=tmp_path, method="lanczos")
    np.testing.assert_array_equal(again.evecs, first.evecs)
    np.testing.assert_allclose(fast.evals, first.evals, rtol=1e-5, atol=1e-8)


def test_auto_falls_back_silently(sphere3, monkeypatch):
    """Where ``"auto"`` picks the block solver and it fails (here made to fail, as it does on a
    multiplicity above its block), ``"auto"`` goes on with ARPACK without a warning: the user
    chose no solver.  The spectrum is ARPACK's; a solver the user named warns."""
    spec_mod = __import__("bsfjax._spectral._spectrum", fromlist=["x"])

    def fails(*args, **kwargs):
        raise MissedEigenvalue("missed 1 eigenvalue")
    monkeypatch.setattr(spec_mod, "block_lanczos", fails)
    monkeypatch.setattr(spec_mod, "has_cholmod", lambda: True)
    assert spec_mod._resolve_method("auto", sphere3.n_vertices, 100) == "block"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        auto = bsfjax.spectrum(sphere3, 100)
    ref = bsfjax.spectrum(sphere3, 100, method="lanczos")
    np.testing.assert_array_equal(auto.evals, ref.evals)
    with pytest.warns(UserWarning, match="missed 1 eigenvalue; falling back"):
        bsfjax.spectrum(sphere3, 100, method="block")
