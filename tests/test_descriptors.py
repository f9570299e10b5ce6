"""HKS / WKS and their landmark versions against float64 numpy formulas."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError, hks, wks
from bsfjax.internal import hks_times, wks_energies

from .conftest import icosphere


@pytest.fixture(scope="module")
def shapes():
    """An ellipsoid-like closed mesh, the same mesh scaled ×3, and their spectra (k = 30)."""
    v, f = icosphere(3)
    v = v * np.array([1.0, 0.7, 1.3]) + 0.05 * np.sin(3 * v[:, [0]])
    small, big = bsfjax.Mesh(v, f), bsfjax.Mesh(3.0 * v, f)
    return small, big, bsfjax.spectrum(small, 30), bsfjax.spectrum(big, 30)


def np_hks(evals, evecs, times, landmarks=None, scaled=True):
    """Σ_l e^{−tλ_l} φ_l(x)² (or φ_l(y) φ_l(x)), written the long way."""
    w = np.exp(-np.outer(times, evals))  # (T, k)
    if scaled:
        w = w / w.sum(1, keepdims=True)
    if landmarks is None:
        return (evecs**2) @ w.T
    cols = [evecs @ (w[t] * evecs[y]) for y in landmarks for t in range(len(times))]
    return np.stack(cols, axis=1)


def np_wks(evals, evecs, n_e, variance=7.0, landmarks=None):
    """pyFM / Aubry WKS with automatic energies, constant eigenpair dropped."""
    keep = evals > 1e-8 * evals.max()
    ev, ph = evals[keep], evecs[:, keep]
    e_min, e_max = np.log(ev.min()), np.log(ev.max())
    sigma = variance * (e_max - e_min) / n_e
    es = np.linspace(e_min + 2 * sigma, e_max - 2 * sigma, n_e)
    w = np.exp(-((es[:, None] - np.log(ev)[None]) ** 2) / (2 * sigma**2))
    w = w / w.sum(1, keepdims=True)
    if landmarks is None:
        return (ph**2) @ w.T
    return np.stack([ph @ (w[e] * ph[y]) for y in landmarks for e in range(n_e)], axis=1)


def test_hks_matches_formula(shapes):
    _, _, s, _ = shapes
    times = np.geomspace(1e-3, 1.0, 7)
    with jax.enable_x64(True):
        got = np.asarray(hks(s, times=times, area_normalize=False))
        raw = np.asarray(hks(s, times=times, area_normalize=False, scaled=False))
    np.testing.assert_allclose(got, np_hks(s.evals, s.evecs, times), rtol=1e-12)
    np.testing.assert_allclose(raw, np_hks(s.evals, s.evecs, times, scaled=False), rtol=1e-12)
    assert got.shape == (s.n_vertices, 7)


def test_hks_automatic_times(shapes):
    _, _, s, _ = shapes
    lam = s.evals * s.area  # unit-area eigenvalues
    expect = np.geomspace(4 * math.log(10) / lam[-1], 4 * math.log(10) / lam[1], 20)
    with jax.enable_x64(True):
        np.testing.assert_allclose(np.asarray(hks_times(s, 20)), expect, rtol=1e-12)
        got = np.asarray(hks(s, 20))
    ref = np_hks(lam, s.evecs * np.sqrt(s.area), expect)
    np.testing.assert_allclose(got, ref, rtol=1e-10)


def test_wks_matches_formula_and_pyfm_convention(shapes):
    _, _, s, _ = shapes
    with jax.enable_x64(True):
        got = np.asarray(wks(s, 25, area_normalize=False))
        energies, sigma = wks_energies(s, 25, area_normalize=False)
    np.testing.assert_allclose(got, np_wks(s.evals, s.evecs, 25), rtol=1e-10)
    assert got.shape == (s.n_vertices, 25)
    assert energies.shape == (25,) and float(sigma) > 0
    # Area normalization only multiplies every automatic-energy column by the area.
    with jax.enable_x64(True):
        np.testing.assert_allclose(np.asarray(wks(s, 25)), s.area * got, rtol=1e-10)


def test_wks_explicit_energies_and_variance(shapes):
    _, _, s, _ = shapes
    es, sigma = np.linspace(1.0, 4.0, 5), 0.3
    lam = s.evals * s.area
    keep = s.evals > 1e-8 * s.evals.max()
    w = np.exp(-((es[:, None] - np.log(lam[keep])[None]) ** 2) / (2 * sigma**2))
    ref = (s.area * s.evecs[:, keep] ** 2) @ (w / w.sum(1, keepdims=True)).T
    with jax.enable_x64(True):
        got = np.asarray(wks(s, energies=es, sigma=sigma))
    np.testing.assert_allclose(got, ref, rtol=1e-10)
    with jax.enable_x64(True):  # a wider filter smooths: neighbouring columns get closer
        narrow = np.asarray(wks(s, 30, variance=2.0))
        wide = np.asarray(wks(s, 30, variance=12.0))
    gap = lambda d: np.abs(np.diff(d, axis=1)).mean() / np.abs(d).mean()  # noqa: E731
    assert gap(wide) < gap(narrow)


@pytest.mark.parametrize("kind", ["hks", "wks"])
def test_landmark_descriptors(shapes, kind):
    _, _, s, _ = shapes
    lms = np.array([0, 17, 300])
    with jax.enable_x64(True):
        if kind == "hks":
            times = np.array([0.01, 0.05, 0.2])
            got = np.asarray(hks(s, times=times, landmarks=lms, area_normalize=False))
            ref = np_hks(s.evals, s.evecs, times, landmarks=lms)
            diag = np.asarray(hks(s, times=times, area_normalize=False))
        else:
            got = np.asarray(wks(s, 3, landmarks=lms, area_normalize=False))
            ref = np_wks(s.evals, s.evecs, 3, landmarks=lms)
            diag = np.asarray(wks(s, 3, area_normalize=False))
    assert got.shape == (s.n_vertices, 9)  # landmark-major: column l * 3 + t
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-14)
    # The kernel centred at y, evaluated at y, is the ordinary signature at y.
    for li, y in enumerate(lms):
        np.testing.assert_allclose(got[y, 3 * li:3 * li + 3], diag[y], rtol=1e-10)
    # Symmetry of the kernel: k(y1, y2) = k(y2, y1).
    np.testing.assert_allclose(got[lms[1], 0:3], got[lms[0], 3:6], rtol=1e-10)


def test_area_normalization_makes_descriptors_scale_invariant(shapes):
    small, big, s_small, s_big = shapes
    times = np.array([0.01, 0.1])
    with jax.enable_x64(True):
        a = np.asarray(hks(s_small, times=times))
        b = np.asarray(hks(s_big, times=times))
        a_raw = np.asarray(hks(s_small, times=times, area_normalize=False))
        b_raw = np.asarray(hks(s_big, times=times, area_normalize=False))
        wa, wb = np.asarray(wks(s_small, 10)), np.asarray(wks(s_big, 10))
    np.testing.assert_allclose(a, b, rtol=1e-6)
    np.testing.assert_allclose(wa, wb, rtol=1e-6)
    assert np.abs(a_raw - b_raw).max() > 0.1 * np.abs(a_raw).max()  # raw times are not


def test_batched_equals_single_and_float32(shapes):
    _, _, s1, s2 = shapes
    stack = jax.tree.map(lambda *x: np.stack(x), s1, s2)
    with jax.enable_x64(True):
        both = np.asarray(wks(stack, 12, landmarks=[3, 9]))
        one = [np.asarray(wks(s, 12, landmarks=[3, 9])) for s in (s1, s2)]
        per = np.asarray(hks(stack, 8, landmarks=np.array([[1], [2]])))
        per_ref = [np.asarray(hks(s, 8, landmarks=[i])) for s, i in ((s1, 1), (s2, 2))]
    np.testing.assert_allclose(both, np.stack(one), rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(per, np.stack(per_ref), rtol=1e-10, atol=1e-13)
    f32 = np.asarray(wks(stack, 12, landmarks=[3, 9]))
    assert f32.dtype == np.float32
    np.testing.assert_allclose(f32, both, rtol=2e-4, atol=1e-5 * np.abs(both).max())


def test_truncated_k(shapes):
    _, _, s, _ = shapes
    with jax.enable_x64(True):
        np.testing.assert_allclose(np.asarray(hks(s, 5, k=12)),
                                   np.asarray(hks(s.truncate(12), 5)), rtol=1e-12)


def test_bad_input_raises(shapes):
    _, _, s, _ = shapes
    n = s.n_vertices
    with pytest.raises(ValueError, match=r"landmarks must be vertex indices in \[0, 642\)"):
        wks(s, 10, landmarks=[n])
    with pytest.raises(ValueError, match="landmarks"):
        hks(s, 10, landmarks=[-1])
    with pytest.raises(BSFError, match="integer"):
        hks(s, 10, landmarks=[1.5])
    with pytest.raises(BSFError, match="k must be"):
        wks(s, 10, k=31)
    with pytest.raises(BSFError, match="times must be positive"):
        hks(s, times=[0.1, -1.0])
    with pytest.raises(BSFError, match="sigma must be given"):
        wks(s, energies=[1.0, 2.0])
    with pytest.raises(BSFError, match="n_times"):
        hks(s, 0)
    with pytest.raises(BSFError, match="variance"):
        wks(s, 10, variance=-1.0)
    with pytest.raises(BSFError, match="Spectrum"):
        hks(s.evecs, 10)
