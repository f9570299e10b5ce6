"""bsfjax.encode / decode: weights, batching, jit / vmap, validation."""

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
    np.testing.assert_allclose(encode(frame, F, "omp", sparsity=5, weights=None),
                               encode(np.asarray(frame.atoms), F, "omp", sparsity=5), atol=1e-6)
    # its default weights are its vertex areas
    np.testing.assert_allclose(encode(frame, F, "omp", sparsity=5),
                               encode(np.asarray(frame.atoms), F, "omp", sparsity=5,
                                      weights=np.asarray(frame.mass)), atol=1e-6)



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
    # a plain atom array has no areas: weights="area" (the default) means unit weights
    np.testing.assert_array_equal(encode(B, f, weights="area"), encode(B, f, weights=None))
    with pytest.raises(BSFError, match="frame atoms must have shape"):
        encode(np.stack([B, B]), f)
    with pytest.raises(BSFError, match="frame"):
        encode("not a frame", f)
    with pytest.raises(BSFError, match="alpha must have shape"):
        decode(B, np.zeros((2, 7)))
    # traced inputs skip value checks but keep shape checks
    with pytest.raises(BSFError, match="f has length"):
        jax.jit(lambda x: encode(B, x))(jnp.zeros((2, 5)))
