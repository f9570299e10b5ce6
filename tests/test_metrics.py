"""relative_error: the square-root form of the paper's Eqs. 14/15, against float64 numpy."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from bsfjax import BSFError, relative_error


def _numpy_error(f, g, a):
    return np.sqrt(np.sum(a * (f - g) ** 2, axis=-1)) / np.sqrt(np.sum(a * f ** 2, axis=-1))


def test_matches_float64_formula_batched():
    rng = np.random.default_rng(0)
    f, g = rng.normal(size=(3, 4, 50)), rng.normal(size=(3, 4, 50))
    a = rng.uniform(0.1, 2.0, size=50)
    with jax.enable_x64(True):
        e = relative_error(f, g, a)
        assert e.dtype == jnp.float64 and e.shape == (3, 4)
        np.testing.assert_allclose(np.asarray(e), _numpy_error(f, g, a), rtol=1e-12)
    e32 = relative_error(f, g, a)  # float32 by default
    assert e32.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(e32), _numpy_error(f, g, a), rtol=1e-5)


def test_square_root_form_and_invariances():
    rng = np.random.default_rng(1)
    f = rng.normal(size=(5, 30))
    a = rng.uniform(0.5, 1.5, 30)
    np.testing.assert_allclose(relative_error(f, np.zeros_like(f), a), 1.0, rtol=1e-6)
    np.testing.assert_allclose(relative_error(f, 2 * f, a), 1.0, rtol=1e-6)
    np.testing.assert_allclose(relative_error(f, 1.5 * f, a), 0.5, rtol=1e-6)  # not 0.25
    np.testing.assert_allclose(relative_error(f, f, a), 0.0, atol=1e-7)
    g = f + 0.1 * rng.normal(size=f.shape)
    np.testing.assert_allclose(relative_error(3 * f, 3 * g, 7 * a), relative_error(f, g, a),
                               rtol=1e-5)


def test_area_weighting_matters():
    f = np.array([[1.0, 1.0, 0.0]])
    g = np.array([[0.0, 1.0, 0.0]])
    # error on vertex 0 only: sqrt(a0 / (a0 + a1))
    np.testing.assert_allclose(relative_error(f, g, np.array([3.0, 1.0, 5.0])), [np.sqrt(0.75)],
                               rtol=1e-6)


def test_zero_reference_rule_no_nan():
    a = np.array([1.0, 4.0, 1.0])
    z = np.zeros((2, 3))
    g = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    e = np.asarray(relative_error(z, g, a))
    assert np.all(np.isfinite(e))
    np.testing.assert_allclose(e, [0.0, np.sqrt(5.0)], rtol=1e-6)  # absolute error ‖g‖_A


@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
def test_tiny_reference_beside_a_large_estimate(x64):
    """f = 1e-30 against f̃ = 1 is an error of 1e30 (its squares underflow in float32, which
    would give 0.5); f = 1e-205 is zero in float32 (the absolute-error rule) and
    gives the exact 6.3e204 in float64; under jit the same."""
    a = np.array([1.0, 3.0])
    f = np.array([[1e-30, 0.0], [1.58e-205, 0.0], [1e-36, 0.0]])
    g = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    want = np.sqrt(np.sum(a * (f - g) ** 2, -1)) / (np.abs(f[:, 0]) * np.sqrt(a[0]))
    with jax.enable_x64(x64):
        e = np.asarray(relative_error(f, g, a), np.float64)
        jitted = np.asarray(jax.jit(relative_error)(f, g, a), np.float64)
    np.testing.assert_allclose(e[[0, 2]], want[[0, 2]], rtol=1e-5)
    np.testing.assert_allclose(e[1], want[1] if x64 else 1.0, rtol=1e-5)  # ‖f̃ − f‖_A
    np.testing.assert_allclose(jitted[[0, 2]], want[[0, 2]], rtol=1e-5)
    assert np.all(np.isfinite(e)) and np.all(np.isfinite(jitted))


def test_broadcast_mass_per_pair_and_jit_vmap():
    rng = np.random.default_rng(2)
    f, g = rng.normal(size=(2, 3, 10)), rng.normal(size=(2, 3, 10))
    a = rng.uniform(0.5, 1.5, (2, 1, 10))
    want = _numpy_error(f, g, a)
    np.testing.assert_allclose(relative_error(f, g, a), want, rtol=1e-5)
    jitted = jax.jit(lambda x, y, m: relative_error(x, y, m))
    np.testing.assert_allclose(jitted(f, g, a), want, rtol=1e-5)
    vm = jax.vmap(relative_error)(jnp.asarray(f), jnp.asarray(g), jnp.asarray(a[:, 0]))
    np.testing.assert_allclose(vm, want, rtol=1e-5)


@pytest.mark.parametrize("args, match", [
    ((np.ones((2, 4)), np.ones((2, 5)), np.ones(4)), "last axis"),
    ((np.ones(4), np.ones(4), np.ones(3)), "last axis"),
    ((np.array([1.0, np.nan]), np.ones(2), np.ones(2)), "reference contains NaN"),
    ((np.ones(2), np.array([np.inf, 1.0]), np.ones(2)), "estimate contains NaN"),
    ((np.ones(2), np.ones(2), np.array([1.0, -1.0])), "mass must be >= 0"),
    ((np.ones(2), np.ones(2), np.zeros(2)), "at least one positive"),
    ((1.0, 1.0, 1.0), "scalar"),
    ((np.ones((2, 3)), np.ones((4, 3)), np.ones(3)), "do not broadcast"),
])
def test_bad_input(args, match):
    with pytest.raises(BSFError, match=match):
        relative_error(*args)
