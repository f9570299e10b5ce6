"""Coder objects (bsfjax.LeastSquares, OMP, ErrorOMP, Lasso): the string shorthands, their
validation, the default area weights, and one code for both kinds of frame."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError, ErrorOMP, LeastSquares, Lasso, OMP, AbstractCoder, SparseFrame, build_frame, decode, encode, prune_frame, transfer_frame
from bsfjax.internal import CODERS, as_coder

from .conftest import icosphere
from .coding_common import as_frame, random_frame, random_functions

CASES = [("lstsq", {"rcond": 1e-6}), ("omp", {"sparsity": 7}),
         ("omp_error", {"max_atoms": 12, "eps_fraction": 0.2}),
         ("lasso", {"lam": 0.05, "maxiter": 500})]


@pytest.fixture(scope="module")
def shapes():
    v, f = icosphere(3)
    specs = []
    for seed in (0, 1):
        bump = 1 + 0.15 * np.sin(v @ np.random.default_rng(seed).normal(size=3) * 2.0)
        specs.append(bsfjax.spectrum(bsfjax.Mesh(v * bump[:, None], f), 30))
    src, tgt = specs
    centers = np.arange(0, src.n_vertices, 7)
    dense = build_frame(src, centers, (1e-3, 5e-3, 1e-2), 0.75)
    sparse = build_frame(src, centers, (1e-3, 5e-3, 1e-2), 0.75, sparse=True)
    C = np.asarray(bsfjax.fmap_from_p2p(src, tgt, np.arange(src.n_vertices)))
    return src, tgt, dense, sparse, C


def _same_atoms_dense(sparse, dtype):
    """The dense frame with exactly the sparse frame's atoms (the builds may differ at γ)."""
    return bsfjax.Frame(atoms=sparse.todense(dtype), coeffs=sparse.coeffs, taus=sparse.taus,
                        centers=sparse.centers, mass=sparse.mass, gammas=sparse.gammas)


def test_registry_and_as_coder():
    assert CODERS == {"lstsq": LeastSquares, "omp": OMP, "omp_error": ErrorOMP,
                      "lasso": Lasso}
    assert as_coder("omp", sparsity=20) == OMP(sparsity=20)
    c = Lasso(lam=0.1)
    assert as_coder(c) is c
    assert all(isinstance(as_coder(name), AbstractCoder) for name in CODERS)
    assert OMP().weights == "area" and OMP().sparsity == 10
    assert ErrorOMP().eps_fraction == 0.1 and ErrorOMP().max_atoms == 64
    with pytest.raises(BSFError, match="only taken with a coder name"):
        as_coder(OMP(), sparsity=3)
    with pytest.raises(BSFError, match="method must be one of"):
        as_coder("omg")
    with pytest.raises(BSFError, match="unknown option"):
        as_coder("lstsq", sparsity=3)


@pytest.mark.parametrize("make, match", [
    (lambda: OMP(sparsity=0), "sparsity"),
    (lambda: OMP(sparsity=2.5), "sparsity"),
    (lambda: OMP(precompute="yes"), "precompute"),
    (lambda: OMP(weights="volume"), "weights"),
    (lambda: OMP(weights=-np.ones(4)), "weights"),
    (lambda: ErrorOMP(max_atoms=0), "max_atoms"),
    (lambda: ErrorOMP(eps=-1.0), "eps"),
    (lambda: ErrorOMP(eps="paper"), "eps"),
    (lambda: ErrorOMP(eps_fraction=-0.1), "eps_fraction"),
    (lambda: Lasso(lam=0.0), "lam"),
    (lambda: Lasso(maxiter=0), "maxiter"),
    (lambda: Lasso(tol=float("nan")), "tol"),
    (lambda: Lasso(target_atoms=3, lam=0.1), "not both"),
    (lambda: LeastSquares(rcond=1.5), "rcond"),
])
def test_coder_objects_validate_their_options(make, match):
    with pytest.raises(BSFError, match=match):
        make()


def test_encode_rejects_options_with_a_coder_object():
    B = random_frame(1)
    with pytest.raises(BSFError, match="only taken with a coder name"):
        encode(B, random_functions(2, 1, B.shape[0]), OMP(), sparsity=3)


@pytest.mark.parametrize("name, opts", CASES)
def test_coder_objects_equal_string_shorthands(name, opts):
    B = random_frame(3)
    F = random_functions(4, 5, B.shape[0])
    frame = as_frame(B, mass=np.linspace(0.5, 1.5, B.shape[0]))
    a_str, i_str = encode(frame, F, name, return_info=True, **opts)
    a_obj, i_obj = encode(frame, F, CODERS[name](**opts), return_info=True)
    np.testing.assert_array_equal(np.asarray(a_obj), np.asarray(a_str))
    for x, y in zip(i_obj, i_str):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.mark.parametrize("name, opts", CASES)
def test_default_weights_are_the_frame_areas(name, opts):
    """weights="area" (default) on a Frame is weights=frame.mass; on a plain array, unit."""
    B = random_frame(5)
    F = random_functions(6, 3, B.shape[0])
    mass = np.linspace(0.5, 1.5, B.shape[0])
    with jax.enable_x64(True):
        a = encode(as_frame(B, mass), F, name, **opts)
        b = encode(B, F, name, weights=mass, **opts)
        c = encode(B, F, name, **opts)
        d = encode(B, F, name, weights=None, **opts)
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-10)
    np.testing.assert_array_equal(np.asarray(c), np.asarray(d))


def test_error_omp_default_bound_is_the_transfer_engine_bound():
    """ErrorOMP() bounds ‖f − Bα‖²_W by (eps_fraction ‖f‖_W)², the bound the transfer engine
    used to pass explicitly."""
    B = random_frame(7, n=40, q=90, density=0.3)
    F = random_functions(8, 6, 40)
    w = np.linspace(0.5, 2.0, 40)
    with jax.enable_x64(True):
        a_def = encode(B, F, ErrorOMP(eps_fraction=0.2, max_atoms=40, weights=w))
        a_exp = encode(B, F, ErrorOMP(eps=0.04 * np.sum(w * F * F, axis=1), max_atoms=40,
                                      weights=w))
    np.testing.assert_array_equal(np.asarray(a_def), np.asarray(a_exp))


@pytest.mark.parametrize("x64", [False, True])
@pytest.mark.parametrize("name, opts", CASES)
def test_dense_and_sparse_frames_give_the_same_codes(shapes, x64, name, opts):
    _, _, _, sparse, _ = shapes
    n = sparse.n_vertices
    F = (np.random.default_rng(9).random((4, n)) < 0.4)
    with jax.enable_x64(x64):
        dtype = jnp.zeros(()).dtype
        s = jax.tree.map(lambda x: jnp.asarray(np.asarray(x), None if x.dtype.kind == "i"
                                               else dtype), sparse)
        d = _same_atoms_dense(s, dtype)
        a_d, i_d = encode(d, F.astype(dtype), name, return_info=True, **opts)
        a_s, i_s = encode(s, F.astype(dtype), name, return_info=True, **opts)
        rec_d, rec_s = np.asarray(decode(d, a_d)), np.asarray(decode(s, a_s))
    assert a_s.dtype == a_d.dtype == dtype
    tol = 1e-8 if x64 else 2e-3
    if name == "lasso":  # FISTA stops at tol: iterates differ a little
        tol = max(tol, 1e-3)
    np.testing.assert_allclose(rec_s, rec_d, rtol=tol, atol=tol)
    np.testing.assert_allclose(np.asarray(i_s.residual), np.asarray(i_d.residual),
                               rtol=tol, atol=tol)
    if name in ("omp", "omp_error"):
        np.testing.assert_array_equal(np.asarray(i_s.n_atoms), np.asarray(i_d.n_atoms))


def test_prune_and_p2p_pull_back_on_sparse_frames(shapes):
    src, tgt, _, _, C = shapes
    # two equal scales: every atom of the second is a duplicate of the first
    sparse = build_frame(src, np.arange(0, src.n_vertices, 7), (1e-3, 1e-3, 1e-2), 0.75,
                         sparse=True)
    dense = _same_atoms_dense(sparse, jnp.float32)
    p2p = np.random.default_rng(10).integers(0, src.n_vertices, tgt.n_vertices)
    alpha = np.random.default_rng(11).normal(size=(2, sparse.n_atoms)).astype(np.float32)
    ps, a_s = prune_frame(sparse, alpha)
    pd, a_d = prune_frame(dense, alpha)
    assert isinstance(ps, SparseFrame) and ps.n_atoms == pd.n_atoms < sparse.n_atoms
    np.testing.assert_array_equal(np.asarray(ps.todense(jnp.float32)), np.asarray(pd.atoms))
    np.testing.assert_array_equal(np.asarray(ps.columns), np.asarray(pd.columns))
    np.testing.assert_array_equal(np.asarray(a_s), np.asarray(a_d))
    for name in ("coeffs", "taus", "centers", "gammas"):
        np.testing.assert_array_equal(np.asarray(getattr(ps, name)), np.asarray(getattr(pd, name)))
    np.testing.assert_allclose(np.asarray(decode(ps, a_s)), np.asarray(decode(sparse, alpha)),
                               rtol=1e-5, atol=1e-5)
    ts = transfer_frame(sparse, C, tgt, p2p=p2p)
    td = transfer_frame(dense, C, tgt, p2p=p2p)
    assert isinstance(ts, SparseFrame)
    np.testing.assert_array_equal(np.asarray(ts.todense(jnp.float32)), np.asarray(td.atoms))
    np.testing.assert_array_equal(np.asarray(td.atoms), np.asarray(dense.atoms)[p2p])
    np.testing.assert_allclose(np.asarray(ts.coeffs), np.asarray(td.coeffs), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(ts.mass), np.asarray(tgt.mass), rtol=1e-6)
    # build_frame(prune=True) builds sparse too, with the dense build's columns
    built = build_frame(src, np.arange(0, src.n_vertices, 7), (1e-3, 1e-3, 1e-2), 0.75,
                        prune=True, sparse=True)
    built_d = build_frame(src, np.arange(0, src.n_vertices, 7), (1e-3, 1e-3, 1e-2), 0.75,
                          prune=True)
    assert isinstance(built, SparseFrame)
    np.testing.assert_array_equal(np.asarray(built.columns), np.asarray(built_d.columns))


def test_sparse_frames_are_validated_like_dense_ones(shapes):
    _, _, _, sparse, _ = shapes
    dense = _same_atoms_dense(sparse, jnp.float32)
    n = sparse.n_vertices
    huge = np.full((1, n), 1e30, np.float32)
    nan = np.zeros((1, sparse.n_atoms), np.float32)
    nan[0, 3] = np.nan
    for fr in (dense, sparse):
        # huge values are rescaled on the host, the same for both kinds of frame
        a = np.asarray(encode(fr, huge, "omp"))
        assert np.all(np.isfinite(a))
        np.testing.assert_allclose(a * 1e-30, np.asarray(encode(fr, huge * 1e-30, "omp")),
                                   rtol=1e-5, atol=1e-6)
        with pytest.raises(BSFError, match="alpha contains 1 NaN"):
            decode(fr, nan)
        with pytest.raises(BSFError, match="f contains"):
            encode(fr, np.full((1, n), np.inf), "lstsq")
