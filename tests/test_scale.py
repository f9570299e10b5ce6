"""Scale invariance of the whole pipeline: a mesh in units of 1e-15 … 1e15 and
functions of magnitude 1e-15 … 1e15 give the relative errors of unit scale, in float32 and
float64.  Magnitudes are rescaled on the host in float64 before any cast (unit-area spectra,
unit-scale functions); the relative error is scale invariant, so it must not move.

Small shapes (a bumpy 162-vertex sphere and a smooth deformation of it, vertex i ↔ vertex i)
so that each test takes a few seconds.
"""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import jax
import numpy as np
import pytest

import bsfjax

from .conftest import icosphere

#: (mesh scale, function scale): the four extreme corners and the two mixed ones
SCALES = ((1e-15, 1e-15), (1e-15, 1e15), (1e15, 1e-15), (1e15, 1e15), (1e-15, 1.0),
          (1.0, 1e15))
K = 20


@pytest.fixture(scope="module")
def pair():
    v, f = icosphere(2)
    rng = np.random.default_rng(0)
    v = v * (1 + 0.15 * rng.random((len(v), 1)))  # no symmetric ties
    w = v * np.array([1.2, 0.9, 1.0]) + 0.1 * np.sin(3 * v[:, [1, 2, 0]])
    ex = SimpleNamespace(source=bsfjax.Mesh(v, f), target=bsfjax.Mesh(w, f),
                         p2p=np.arange(len(v)))
    F = bsfjax.random_indicators(ex.source, 4, seed=3)
    return ex, F


def _errors(ex, F, mesh_scale: float, fn_scale: float, method: str) -> np.ndarray:
    src = bsfjax.Mesh(ex.source.vertices * mesh_scale, ex.source.faces)
    tgt = bsfjax.Mesh(ex.target.vertices * mesh_scale, ex.target.faces)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sm, sn = bsfjax.spectrum(src, K), bsfjax.spectrum(tgt, K)
        C = bsfjax.fmap_from_p2p(sm, sn, ex.p2p)
        out = bsfjax.transfer_values(sm, sn, F * fn_scale, C=C, p2p=ex.p2p, mesh=src,
                                     method=method)
        err = bsfjax.relative_error(F[:, ex.p2p] * fn_scale, out, sn.mass)
    err = np.asarray(err, np.float64)
    assert np.all(np.isfinite(err))
    return err


@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
@pytest.mark.parametrize("method", ["omp", "std", "p2p"])
def test_pipeline_is_scale_invariant(pair, x64, method):
    ex, F = pair
    with jax.enable_x64(x64):
        ref = _errors(ex, F, 1.0, 1.0, method)
        assert np.all(ref < 1.0)  # a real transfer, not all zeros (error 1)
        rtol = 1e-9 if x64 else 2e-4
        for ms, fs in SCALES:
            got = _errors(ex, F, ms, fs, method)
            np.testing.assert_allclose(got, ref, rtol=rtol, atol=rtol,
                                       err_msg=f"mesh x{ms:g}, functions x{fs:g}")


@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
def test_extreme_mesh_scale_in_float32(pair, x64):
    """1e±20: areas 1e±40 are beyond float32, yet the transfer is the unit-scale one."""
    ex, F = pair
    with jax.enable_x64(x64):
        ref = _errors(ex, F, 1.0, 1.0, "omp")
        for s in (1e-20, 1e20):
            np.testing.assert_allclose(_errors(ex, F, s, 1.0, "omp"), ref,
                                       rtol=1e-9 if x64 else 2e-4, atol=1e-6)


@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
def test_codes_and_metrics_scale(pair, x64):
    """encode / decode / relative_error: f·s codes to α·s and back, for s = 1e±30."""
    ex, F = pair
    with jax.enable_x64(x64):
        spec = bsfjax.spectrum(ex.source, K)
        frame = bsfjax.build_frame(spec, bsfjax.farthest_point_sampling(ex.source, 8))
        a1 = np.asarray(bsfjax.encode(frame, F), np.float64)
        r1 = np.asarray(bsfjax.decode(frame, a1), np.float64)
        for s in (1e-30, 1e30):
            a = np.asarray(bsfjax.encode(frame, F * s), np.float64)
            np.testing.assert_allclose(a / s, a1, rtol=1e-4, atol=1e-6)
            np.testing.assert_allclose(np.asarray(bsfjax.decode(frame, a), np.float64) / s, r1,
                                       rtol=1e-4, atol=1e-6)
            e = bsfjax.relative_error(F * s, np.asarray(r1) * s, spec.mass)
            np.testing.assert_allclose(e, bsfjax.relative_error(F, r1, spec.mass), rtol=1e-4)
        # float64 values beyond float32, in float32 arithmetic: still the unit-scale ratio
        e = bsfjax.relative_error(F * 1e300, np.roll(F, 1, 1) * 1e300, spec.mass * 1e-300)
        np.testing.assert_allclose(e, bsfjax.relative_error(F, np.roll(F, 1, 1), spec.mass),
                                   rtol=1e-5)


@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
@pytest.mark.parametrize("landmarks", [True, False], ids=["landmarks", "orientation-term"])
def test_shapes_in_different_units(pair, x64, landmarks):
    """A target in millimetres and a source in metres: the maps and labels of both in metres
    (keeping the pair's relative scale would get 2 % of the SMPL parts of such a FAUST pair
    right).  ``C`` follows the target's units: ×s for a target ×s in length."""
    ex, _ = pair
    labels = (ex.source.vertices[:, 0] > 0).astype(int) + 2 * (ex.source.vertices[:, 2] > 0)
    lm = ([0, 40, 80, 120], [0, 40, 80, 120]) if landmarks else None
    with jax.enable_x64(x64), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sm = bsfjax.spectrum(ex.source, K)
        out = {}
        for s in (1.0, 1e3, 1e-3):
            tgt = bsfjax.Mesh(ex.target.vertices * s, ex.target.faces)
            sn = bsfjax.spectrum(tgt, K)
            est = bsfjax.estimate_map(sm, sn, k=10, refine_to=K, landmarks=lm,
                                      source_mesh=ex.source, target_mesh=tgt, zoomout_samples=None)
            lab = bsfjax.transfer_labels(sm, sn, labels, C=est.C, p2p=est.p2p).labels
            back = bsfjax.fmap_to_p2p(bsfjax.fmap_from_p2p(sm, sn, ex.p2p), sm, sn)
            out[s] = (np.asarray(est.C) / s, np.asarray(est.p2p), lab, np.asarray(back))
    C1, p1, lab1, back1 = out[1.0]
    if landmarks:  # a real map (without landmarks this near-sphere has no good one: only the
        # invariance is checked there, which the orientation term's operators also need)
        assert np.mean(p1 == ex.p2p) > 0.9 and np.mean(lab1 == labels[ex.p2p]) > 0.95
    for s in (1e3, 1e-3):
        C, p, lab, back = out[s]
        tol = 1e-8 if x64 else 2e-3
        np.testing.assert_allclose(C, C1, atol=tol, err_msg=f"target x{s:g}")
        # float32: a few near-ties of the nearest-neighbour searches may go the other way
        assert np.mean(p == p1) >= (1.0 if x64 else 0.98), f"target x{s:g}"
        assert np.mean(lab == lab1) >= (1.0 if x64 else 0.98), f"target x{s:g}"
        np.testing.assert_array_equal(back, back1)
