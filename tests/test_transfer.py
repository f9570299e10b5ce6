"""The transfer engine: the manual route, the vmapped multi-pair run and its device sharding."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import bsfjax
from bsfjax import Mesh
from bsfjax import stack_spectra, transfer_pairs

from .conftest import cpu_devices_env, icosphere


def _pairs(n_pairs=3, k=20, seed=0):
    """Small sphere-like shape pairs with exact correspondence (smooth random bumps)."""
    v, f = icosphere(3)
    rng = np.random.default_rng(seed)
    shapes = []
    for _ in range(2 * n_pairs):
        bump = 1 + 0.15 * np.sin(v @ rng.normal(size=3) * 2.0)
        shapes.append(bsfjax.spectrum(Mesh(v * bump[:, None], f), k))
    return shapes[0::2], shapes[1::2], len(v)


@pytest.fixture(scope="module")
def pairs():
    return _pairs()


def _inputs(src, tgt, n, m=4, seed=1):
    rng = np.random.default_rng(seed)
    P = len(src)
    C = np.stack([bsfjax.fmap_from_p2p(s, t, np.arange(n)) for s, t in zip(src, tgt)])
    centers = np.stack([rng.choice(n, 16, replace=False) for _ in range(P)])
    F = (rng.random((P, m, n)) < 0.3).astype(np.float32)
    return np.asarray(C), centers, F


def _stack(src, tgt, C, centers):
    return [bsfjax.Pair(source=s, target=t, C=c, centers=ctr)
            for s, t, c, ctr in zip(src, tgt, C, centers)]


def test_transfer_is_the_manual_route(pairs):
    """transfer == decode(transfer_frame(frame, C, N), encode(frame, f)) for the same frame."""
    src, tgt, n = pairs
    C, centers, F = _inputs(src, tgt, n)
    frame = bsfjax.build_frame(src[0], centers[0])
    alpha = bsfjax.encode(frame, F[0], "omp", sparsity=5)
    res = bsfjax.transfer("omp", bsfjax.Pair(src[0], tgt[0], C[0], centers=centers[0]), F[0],
                          sparsity=5)
    np.testing.assert_array_equal(np.asarray(res.codes), np.asarray(alpha))
    np.testing.assert_array_equal(np.asarray(res.approximation),
                                  np.asarray(bsfjax.decode(frame, alpha)))
    tframe = bsfjax.transfer_frame(frame, C[0], tgt[0])
    np.testing.assert_array_equal(np.asarray(res.transferred),
                                  np.asarray(bsfjax.decode(tframe, alpha)))


def test_transfer_pairs_matches_per_pair_calls(pairs):
    src, tgt, n = pairs
    C, centers, F = _inputs(src, tgt, n)
    out = transfer_pairs("omp", _stack(src, tgt, C, centers), F, sparsity=6)
    assert out.codes.shape == (3, 4, 48) and out.transferred.shape == (3, 4, n)
    for p in range(3):
        frame = bsfjax.build_frame(src[p], centers[p])
        tframe = bsfjax.transfer_frame(frame, C[p], tgt[p])
        alpha = bsfjax.encode(frame, F[p], "omp", sparsity=6)
        np.testing.assert_allclose(np.asarray(out.codes[p]), np.asarray(alpha), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(np.asarray(out.transferred[p]),
                                   np.asarray(bsfjax.decode(tframe, alpha)), rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(np.asarray(out.approximation[p]),
                                   np.asarray(bsfjax.decode(frame, alpha)), rtol=1e-5, atol=1e-5)


def test_transfer_pairs_validates(pairs):
    src, tgt, n = pairs
    C, centers, F = _inputs(src, tgt, n)
    stacked = _stack(src, tgt, C, centers)
    with pytest.raises(ValueError, match="k_M = 5"):
        transfer_pairs("omp", stacked, F, k=5)
    with pytest.raises(ValueError, match="f must have shape"):
        transfer_pairs("omp", stacked, F[..., :-1])
    with pytest.raises(ValueError, match="NaN"):
        transfer_pairs("omp", stacked, np.where(F > 0, np.nan, 0))
    with pytest.raises(ValueError, match="centers must"):
        transfer_pairs("omp", _stack(src, tgt, C, centers + n), F)
    with pytest.raises(ValueError, match="same fields and shapes"):
        transfer_pairs("omp", stacked[:2] + [bsfjax.Pair(src[0], tgt[0], C[0][:5])], F)
    with pytest.raises(ValueError, match="share"):
        stack_spectra([src[0], src[0].truncate(5)])
    with pytest.raises(ValueError, match="method must be one of"):
        bsfjax.transfer("fourier", stacked[0], F[0])
    with pytest.raises(ValueError, match="options go with a method name"):
        bsfjax.transfer(bsfjax.BSF(), stacked[0], F[0], sparsity=3)


SHARDED = textwrap.dedent("""
    import numpy as np, jax, sys
    sys.path.insert(0, {root!r})
    from tests.test_transfer import _pairs, _inputs, _function_batch, _stack
    from bsfjax import transfer_pairs
    assert jax.device_count() == 4, jax.devices()
    src, tgt, n = _pairs()
    C, centers, F = _inputs(src, tgt, n)
    out = transfer_pairs("omp", _stack(src, tgt, C, centers), F, sparsity=6, weights=None)
    area = transfer_pairs("omp", _stack(src, tgt, C, centers), F, sparsity=6)
    np.savez({path!r}, alpha=np.asarray(out.codes), transferred=np.asarray(out.transferred),
             alpha_area=np.asarray(area.codes),
             devices=len(out.codes.sharding.device_set), **_function_batch(src[0]))
""")


def _function_batch(spec):
    """OMP codes of 7 functions (not a multiple of 4: padded) in a sparse and a dense frame, a
    least-squares approximation, and whether encode took the multi-device path."""
    import bsfjax._coding._encode as coding

    centers = np.arange(0, spec.n_vertices, 9)
    F = (np.random.default_rng(5).random((7, spec.n_vertices)) < 0.3).astype(np.float32)
    out = {}
    for kind in ("sparse", "dense"):
        frame = bsfjax.build_frame(spec, centers, sparse=kind == "sparse")
        a, info = bsfjax.encode(frame, F, "omp", weights="area", return_info=True)
        out[f"{kind}_omp"] = np.asarray(a)
        out[f"{kind}_omp_res"] = np.asarray(info.residual)
    out["dense_approx"] = np.asarray(bsfjax.decode(frame, bsfjax.encode(frame, F, "lstsq")))
    seen = []
    orig = coding.map_over_devices
    coding.map_over_devices = lambda *a: seen.append(1) or orig(*a)
    try:
        bsfjax.encode(frame, F, "omp", weights="area")
    finally:
        coding.map_over_devices = orig
    out["encode_sharded"] = np.asarray(len(seen))
    return out


def test_four_cpu_devices_give_identical_results(pairs, tmp_path):
    """Sharding the pair axis (3 pairs: padded to 4) and the function axis of encode (7
    functions: padded to 8) over 4 forced host devices changes nothing: Euclidean codes bit for
    bit, area-weighted codes the same atoms with values equal to float32 rounding."""
    src, tgt, n = pairs
    C, centers, F = _inputs(src, tgt, n)
    single = transfer_pairs("omp", _stack(src, tgt, C, centers), F, sparsity=6, weights=None)
    area = transfer_pairs("omp", _stack(src, tgt, C, centers), F, sparsity=6)
    path = tmp_path / "sharded.npz"
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = cpu_devices_env(4)
    r = subprocess.run([sys.executable, "-c", SHARDED.format(root=root, path=str(path))], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    ref = _function_batch(src[0])
    assert int(ref["encode_sharded"]) == 0  # one device here: the plain path
    with np.load(path) as z:
        assert int(z["devices"]) == 4 and int(z["encode_sharded"]) == 1
        np.testing.assert_array_equal(z["alpha"], np.asarray(single.codes))
        # area-weighted codes (the default): the same atoms, values to float32 rounding (XLA
        # fuses the √w row scaling differently for 1 and 3 pairs per device)
        a1, a4 = np.asarray(area.codes), z["alpha_area"]
        np.testing.assert_array_equal(a4 != 0, a1 != 0)
        np.testing.assert_allclose(a4, a1, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(z["transferred"], np.asarray(single.transferred), rtol=1e-6, atol=1e-6)
        for key, value in ref.items():
            if key == "encode_sharded":
                continue
            if key.endswith("_omp"):  # the codes themselves: bit for bit
                np.testing.assert_array_equal(z[key], value, err_msg=key)
            else:  # residuals / approximations: XLA may round a batched product differently
                np.testing.assert_allclose(z[key], value, rtol=1e-6, atol=1e-6, err_msg=key)


def test_frames_beyond_the_dense_budget_run_eagerly_on_list_frames(pairs, monkeypatch):
    """Above the dense budget the engine builds SparseFrames (eagerly): same numbers."""
    import bsfjax._frame._build as frame_mod
    import bsfjax._transfer._engine as transfer_mod

    src, tgt, n = pairs
    C, centers, F = _inputs(src, tgt, n)
    p = bsfjax.Pair(src[0], tgt[0], C[0], centers=centers[0])
    dense = bsfjax.transfer("omp", p, F[0], sparsity=6)
    kinds = []
    orig = frame_mod.transfer_frame

    def spy(frame, *a, **kw):
        kinds.append(type(frame).__name__)
        return orig(frame, *a, **kw)

    monkeypatch.setattr(frame_mod, "DENSE_BUDGET_BYTES", 1024)
    monkeypatch.setattr(transfer_mod, "DENSE_BUDGET_BYTES", 1024)
    monkeypatch.setattr("bsfjax._transfer._bsf.transfer_frame", spy)
    listed = bsfjax.transfer("omp", p, F[0], sparsity=6)
    assert kinds == ["SparseFrame"]
    np.testing.assert_array_equal(np.asarray(listed.codes) != 0, np.asarray(dense.codes) != 0)
    np.testing.assert_allclose(np.asarray(listed.transferred), np.asarray(dense.transferred),
                               rtol=1e-5, atol=1e-5)
    pruned = bsfjax.transfer("omp", p, F[0], sparsity=6, prune=True)
    monkeypatch.undo()
    masked = bsfjax.transfer("omp", p, F[0], sparsity=6, prune=True)
    np.testing.assert_allclose(np.asarray(pruned.codes), np.asarray(masked.codes), rtol=1e-5,
                               atol=1e-6)
    np.testing.assert_allclose(np.asarray(pruned.transferred), np.asarray(masked.transferred),
                               rtol=1e-5, atol=1e-5)
