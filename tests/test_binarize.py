"""The binarization rule (bsfjax._frame._binarize): blocked binarization, the rule itself and the
effective τ, against float64 numpy references."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from bsfjax.internal import effective_taus, kernel_mask

from .test_frame import TAUS, assert_atoms_match, build_reference, small  # noqa: F401


@pytest.mark.parametrize("x64", [False, True])
@pytest.mark.parametrize("width", [1, 7, 89])
def test_binarize_in_column_blocks_matches_numpy(small, monkeypatch, x64, width):
    """Column blocks of 1, 7 (the last one shifted to end at q = 90) and 89 atoms give the
    float64 reference's atoms, under jit and vmap."""
    import bsfjax._frame._binarize as frame_mod

    specs, centers = small
    spec = specs[1.0]
    ref_norm, ref_coeffs, ref_g = build_reference(spec, centers, TAUS, (0.75,) * 3)
    monkeypatch.setattr(frame_mod, "BINARIZE_BLOCK_ELEMS", width * spec.n_vertices)
    with jax.enable_x64(x64):
        dtype = jnp.zeros(()).dtype
        E, A = jnp.asarray(spec.evecs, dtype), jnp.asarray(ref_coeffs, dtype)
        g = jnp.asarray(ref_g, dtype)
        atoms = jax.jit(lambda E, A, g: frame_mod.binarize(E, A, g))(E, A, g)
        batched = jax.vmap(frame_mod.binarize, in_axes=(None, 0, None))(E, jnp.stack([A, -A]), g)
    assert atoms.shape == ref_norm.shape and atoms.dtype == dtype
    assert_atoms_match(atoms, ref_norm, ref_g, 1e-9 if x64 else 1e-4)
    np.testing.assert_array_equal(np.asarray(batched[0]), np.asarray(atoms))
    np.testing.assert_array_equal(np.asarray(batched[1]), np.asarray(atoms))  # |−g| = |g|


def test_kernel_mask_rule_and_vanishing_columns():
    """|g| ≥ γ max|g| per column, sign blind; an all-zero kernel gives an empty atom, not NaN."""
    rng = np.random.default_rng(0)
    E = rng.normal(size=(40, 6))
    A = rng.normal(size=(6, 5))
    A[:, 2] = 0.0
    g = np.abs(E @ A)
    gam = np.array([0.3, 0.5, 0.7, 0.9, 0.6])
    with jax.enable_x64(True):
        got = np.asarray(kernel_mask(jnp.asarray(E), jnp.asarray(A), jnp.asarray(gam)))
        neg = np.asarray(kernel_mask(jnp.asarray(E), -jnp.asarray(A), jnp.asarray(gam)))
    ref = g >= gam * g.max(axis=0)
    ref[:, 2] = False
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_array_equal(neg, ref)


def test_effective_taus_conventions():
    taus, mass = jnp.asarray([1.0, 2.0]), jnp.asarray([0.5, 1.5, 2.0])
    np.testing.assert_allclose(effective_taus(taus, mass, "raw"), taus)
    np.testing.assert_allclose(effective_taus(taus, mass, "unit_area"), 4.0 * taus)
