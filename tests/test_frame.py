"""Binary Sparse Frame build (Algorithm 1) and transfer (Eq. 11-12) against float64 numpy."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError, Frame, build_frame, farthest_point_sampling, transfer_frame

from .conftest import data_path, icosphere

TAUS = (1e-3, 5e-3, 1e-2)


# --------------------------------------------------------------------------- references


def normalized_reference(evecs, coeffs):
    """|g| / max|g| per column of g = evecs @ coeffs, in float64 (0 for a vanishing column)."""
    g = np.abs(np.asarray(evecs, np.float64) @ np.asarray(coeffs, np.float64))
    m = g.max(axis=0)
    return g / np.where(m > 0, m, 1.0)


def build_reference(spec, centers, taus, gammas, unit_area=True):
    """Paper Algorithm 1, one (scale, centre) at a time, float64.  Scale-major columns."""
    scale = spec.mass.sum() if unit_area else 1.0
    coeffs, gcol = [], []
    for t, gam in zip(taus, gammas):
        ghat = np.exp(-t * scale * (spec.evals - spec.evals[0]))
        for c in centers:
            coeffs.append(ghat * spec.evecs[c])
            gcol.append(gam)
    coeffs = np.stack(coeffs, axis=1)
    return normalized_reference(spec.evecs, coeffs), coeffs, np.array(gcol)


def assert_atoms_match(atoms, normalized, gammas, tol):
    """Exact equality wherever the float64 value is not within ``tol`` of its threshold."""
    atoms = np.asarray(atoms)
    assert set(np.unique(atoms).tolist()) <= {0.0, 1.0}
    clear = np.abs(normalized - gammas) > tol
    assert clear.mean() > 0.999  # the comparison covers (almost) everything
    np.testing.assert_array_equal(atoms[clear], (normalized >= gammas)[clear].astype(atoms.dtype))


def iou(a, b):
    a, b = np.asarray(a) > 0.5, np.asarray(b) > 0.5
    return (a & b).sum(0) / np.maximum((a | b).sum(0), 1)


# --------------------------------------------------------------------------- fixtures


def bumpy_sphere_arrays():
    v, f = icosphere(3)
    rng = np.random.default_rng(7)
    return v * (1 + 0.05 * rng.standard_normal((len(v), 1))), f  # no symmetric eigenspaces


@pytest.fixture(scope="module")
def small():
    """Spectra of a small irregular sphere at scales 1, 10, 0.01, and 30 FPS centres."""
    v, f = bumpy_sphere_arrays()
    specs = {s: bsfjax.spectrum(bsfjax.Mesh(v * s, f), 30) for s in (1.0, 10.0, 0.01)}
    return specs, farthest_point_sampling(v, 30, seed=0)


@pytest.fixture(scope="module")
def faust():
    """FAUST tr_reg_000 → tr_reg_001 (same connectivity: vertex i ↔ vertex i), k = 50."""
    m = bsfjax.load_mesh(data_path("faust", "tr_reg_000.off"))
    n = bsfjax.load_mesh(data_path("faust", "tr_reg_001.off"))
    sm, sn = bsfjax.spectrum(m, 50), bsfjax.spectrum(n, 50)
    centers = farthest_point_sampling(m, 0.05, seed=0)  # n_BSF = 5 %
    return sm, sn, centers, build_frame(sm, centers)


# --------------------------------------------------------------------------- build


@pytest.mark.parametrize("x64", [False, True])
@pytest.mark.parametrize("gamma", [0.75, (0.5, 0.75, 0.9)])
def test_build_matches_numpy(small, x64, gamma):
    specs, centers = small
    spec = specs[1.0]
    gammas = np.broadcast_to(gamma, (3,))
    ref_norm, ref_coeffs, ref_g = build_reference(spec, centers, TAUS, gammas)
    with jax.enable_x64(x64):
        fr = build_frame(spec, centers, taus=TAUS, gamma=gamma)
        dtype = jnp.zeros(()).dtype
    assert fr.atoms.dtype == dtype == fr.coeffs.dtype
    assert fr.atoms.dtype == (np.float64 if x64 else np.float32)
    q = 3 * len(centers)
    assert fr.atoms.shape == (spec.n_vertices, q) and fr.coeffs.shape == (30, q)
    assert_atoms_match(fr.atoms, ref_norm, ref_g, 1e-9 if x64 else 1e-4)
    np.testing.assert_allclose(fr.coeffs, ref_coeffs, rtol=1e-12 if x64 else 1e-5,
                               atol=(1e-14 if x64 else 1e-6) * np.abs(ref_coeffs).max())
    # scale-major metadata, as documented
    np.testing.assert_array_equal(fr.centers, np.tile(centers, 3))
    np.testing.assert_allclose(fr.taus, np.repeat(TAUS, len(centers)), rtol=1e-7)
    np.testing.assert_allclose(fr.gammas, ref_g, rtol=1e-7)
    np.testing.assert_allclose(fr.mass, spec.mass, rtol=1e-7)
    assert fr.tau_convention == "unit_area"
    # atoms are small blobs that grow with τ and contain their centre
    if gamma == 0.75:
        sizes = np.asarray(fr.atoms).sum(0).reshape(3, -1).mean(1)
        assert 1 <= sizes[0] < sizes[1] < sizes[2] < 0.2 * spec.n_vertices
    assert np.asarray(fr.atoms)[np.asarray(fr.centers), np.arange(q)].all()


def test_build_raw_convention_matches_numpy(small):
    specs, centers = small
    spec = specs[1.0]
    taus = (0.05, 0.2)
    ref_norm, _, ref_g = build_reference(spec, centers, taus, (0.75, 0.75), unit_area=False)
    fr = build_frame(spec, centers, taus=taus, tau_convention="raw")
    assert fr.tau_convention == "raw"
    assert_atoms_match(fr.atoms, ref_norm, ref_g, 1e-4)
    np.testing.assert_allclose(fr.effective_taus, fr.taus)


def test_unit_area_is_raw_with_tau_times_area(small):
    specs, centers = small
    spec = specs[1.0]
    area = spec.mass.sum()
    with jax.enable_x64(True):
        unit = build_frame(spec, centers)
        raw = build_frame(spec, centers, taus=tuple(t * area for t in TAUS), tau_convention="raw")
        np.testing.assert_allclose(unit.effective_taus, raw.taus, rtol=1e-12)
    np.testing.assert_allclose(unit.coeffs, raw.coeffs, rtol=1e-10, atol=1e-14)
    ref_norm, _, ref_g = build_reference(spec, centers, TAUS, (0.75,) * 3)
    assert_atoms_match(raw.atoms, ref_norm, ref_g, 1e-9)


@pytest.mark.parametrize("x64", [False, True])
def test_unit_area_is_scale_invariant_raw_is_not(small, x64):
    specs, centers = small
    with jax.enable_x64(x64):
        base = np.asarray(build_frame(specs[1.0], centers).atoms)
        base_raw = np.asarray(build_frame(specs[1.0], centers, tau_convention="raw").atoms)
        for s in (10.0, 0.01):
            np.testing.assert_array_equal(build_frame(specs[s], centers).atoms, base)
        small_raw = np.asarray(build_frame(specs[0.01], centers, tau_convention="raw").atoms)
        big_raw = np.asarray(build_frame(specs[10.0], centers, tau_convention="raw").atoms)
    # shrinking by 100 multiplies λ by 10⁴: the raw kernels diffuse over the whole shape
    assert small_raw.mean() > 0.9 > 0.1 > base_raw.mean()
    assert (big_raw != base_raw).any()


def test_build_1d_interval():
    n = 301
    spec = bsfjax.interval_spectrum(n, 40, length=2.0)
    x = np.linspace(0.0, 2.0, n)
    centers = farthest_point_sampling(x[:, None], 12, seed=0)
    fr = build_frame(spec, centers, taus=(1e-3, 1e-2), gamma=0.5)
    ref_norm, _, ref_g = build_reference(spec, centers, (1e-3, 1e-2), (0.5, 0.5))
    assert_atoms_match(fr.atoms, ref_norm, ref_g, 1e-4)
    atoms = np.asarray(fr.atoms) > 0.5
    for j, c in enumerate(np.asarray(fr.centers)):
        on = np.flatnonzero(atoms[:, j])
        assert on[0] <= c <= on[-1] and len(on) == on[-1] - on[0] + 1  # an interval around c


def test_build_scalar_inputs(small):
    specs, centers = small
    fr = build_frame(specs[1.0], int(centers[3]), taus=5e-3)
    full = build_frame(specs[1.0], centers, taus=5e-3)
    assert fr.atoms.shape == (642, 1)
    np.testing.assert_array_equal(fr.atoms[:, 0], full.atoms[:, 3])


def test_build_is_traceable(small):
    """Validation works on tracers: jit and vmap over stacked spectra of equal size."""
    specs, centers = small
    eager = [build_frame(specs[s], centers).atoms for s in (1.0, 10.0)]
    jitted = jax.jit(lambda sp: build_frame(sp, centers).atoms)(specs[1.0])
    np.testing.assert_array_equal(jitted, eager[0])
    stacked = jax.tree.map(lambda *a: jnp.stack(a), specs[1.0], specs[10.0])
    batched = jax.vmap(lambda sp: build_frame(sp, centers).atoms)(stacked)
    np.testing.assert_array_equal(batched, np.stack(eager))


@pytest.mark.parametrize("kwargs,match", [
    (dict(taus=(1e-3, 0.0)), "taus must be positive"),
    (dict(taus=-1e-3), "taus must be positive"),
    (dict(taus=(np.nan,)), "taus must be positive"),
    (dict(taus=(np.inf,)), "taus must be positive"),
    (dict(taus=()), "taus must be"),
    (dict(gamma=0.0), r"gamma must be in the open interval \(0, 1\)"),
    (dict(gamma=1.0), r"gamma must be in the open interval \(0, 1\)"),
    (dict(gamma=(0.5, 1.2, 0.5)), r"gamma must be in the open interval \(0, 1\)"),
    (dict(gamma=(0.5, 0.6)), r"gamma must be one float or one per tau \(3\), got 2"),
    (dict(centers=[]), "centers is empty"),
    (dict(centers=[0, 642]), r"centers must index the 642 vertices .* \[0, 642\]"),
    (dict(centers=[-1, 3]), r"centers must index the 642 vertices"),
    (dict(centers=[0.0, 2.5]), "centers must be integer vertex indices, got dtype float64"),
    (dict(centers=[[1, 2]]), "centers must be a 1-D array"),
    (dict(tau_convention="area"), "tau_convention must be one of"),
])
def test_build_rejects_bad_input(small, kwargs, match):
    specs, centers = small
    kw = dict(centers=centers) | kwargs
    with pytest.raises(BSFError, match=match):
        build_frame(specs[1.0], **kw)


def test_build_rejects_non_spectrum(small):
    specs, centers = small
    with pytest.raises(BSFError, match="spectrum must be a bsfjax.Spectrum"):
        build_frame(specs[1.0].evecs, centers)
    with pytest.raises(BSFError, match="tau_convention must be one of"):
        Frame(*(jnp.zeros(1),) * 5, tau_convention="nope")


# --------------------------------------------------------------------------- transfer


def test_transfer_identity_reproduces(small, faust):
    sphere = small[0][1.0]
    for spec, frame in ((faust[0], faust[3]), (sphere, build_frame(sphere, small[1]))):
        out = transfer_frame(frame, np.eye(spec.k), spec)
        np.testing.assert_array_equal(out.atoms, frame.atoms)
        np.testing.assert_array_equal(out.coeffs, frame.coeffs)
        for name in ("taus", "centers", "gammas", "mass"):
            np.testing.assert_array_equal(getattr(out, name), getattr(frame, name))
        assert out.tau_convention == frame.tau_convention


def test_transfer_uses_first_kM_rows(small):
    specs, centers = small
    spec = specs[1.0]
    frame = build_frame(spec, centers)
    out = transfer_frame(frame, np.eye(20), spec.truncate(20))
    direct = build_frame(spec.truncate(20), centers)
    np.testing.assert_array_equal(out.coeffs, direct.coeffs)
    np.testing.assert_array_equal(out.atoms, direct.atoms)


@pytest.mark.parametrize("x64", [False, True])
def test_transfer_matches_numpy_rectangular(small, x64):
    specs, centers = small
    spec = specs[1.0]
    rng = np.random.default_rng(0)
    C = np.eye(24, 30) + 0.1 * rng.standard_normal((24, 30))  # k_N = 24 ≠ k_M = 30
    with jax.enable_x64(x64):
        frame = build_frame(spec, centers)
        out = transfer_frame(frame, C, specs[10.0])  # target has k = 30 ≥ 24: uses 24
    coeffs = C @ np.asarray(frame.coeffs, np.float64)
    assert out.coeffs.shape == (24, frame.n_atoms) and out.atoms.shape == (642, frame.n_atoms)
    np.testing.assert_allclose(out.coeffs, coeffs, rtol=1e-5, atol=1e-6 * np.abs(coeffs).max())
    ref = normalized_reference(specs[10.0].evecs[:, :24], coeffs)
    assert_atoms_match(out.atoms, ref, np.asarray(frame.gammas)[None, :], 1e-9 if x64 else 1e-4)
    np.testing.assert_allclose(out.mass, specs[10.0].mass, rtol=1e-6)


def test_transfer_vanishing_column_is_zero_not_nan(small):
    specs, centers = small
    frame = build_frame(specs[1.0], centers)
    out = transfer_frame(frame, np.zeros((30, 30)), specs[1.0])
    assert not np.isnan(np.asarray(out.atoms)).any() and not np.asarray(out.atoms).any()
    # one dead column among live ones: only that column is emptied
    dead = eqx_replace_coeffs(frame, frame.coeffs.at[:, 5].set(0.0))
    out = transfer_frame(dead, np.eye(30), specs[1.0])
    assert not np.asarray(out.atoms[:, 5]).any()
    np.testing.assert_array_equal(np.delete(np.asarray(out.atoms), 5, 1),
                                  np.delete(np.asarray(frame.atoms), 5, 1))


def eqx_replace_coeffs(frame, coeffs):
    import equinox as eqx

    return eqx.tree_at(lambda f: f.coeffs, frame, coeffs)


def test_transfer_faust_ground_truth(faust):
    """FAUST 000 → 001 with the identity point map written as C = Φ_Nᵀ A_N Φ_M: the
    transferred atoms must overlap the source atoms (their true images) vertex by vertex."""
    sm, sn, centers, frame = faust
    C = sn.evecs.T @ (sn.mass[:, None] * sm.evecs)  # (50, 50)
    out = transfer_frame(frame, C, sn)
    assert out.atoms.shape == frame.atoms.shape == (6890, 3 * len(centers))
    scores = iou(out.atoms, frame.atoms)
    per_scale = scores.reshape(3, -1).mean(1)
    # measured: mean 0.946, per scale (0.915, 0.953, 0.970), 5th percentile 0.82
    assert scores.mean() > 0.9
    assert (per_scale > 0.87).all()
    assert np.percentile(scores, 5) > 0.7
    # a wrong correspondence (atoms paired with other atoms) scores near zero
    shuffled = iou(out.atoms, np.roll(np.asarray(frame.atoms), 17, axis=1))
    assert shuffled.mean() < 0.1
    # k_N ≠ k_M: 40 target eigenfunctions from 50 source ones still transfer well
    out40 = transfer_frame(frame, C[:40], sn)
    assert out40.coeffs.shape == (40, frame.n_atoms)
    assert iou(out40.atoms, frame.atoms).mean() > 0.85


def test_transfer_rejects_bad_input(small):
    specs, centers = small
    frame = build_frame(specs[1.0].truncate(20), centers)
    spec = specs[1.0]
    with pytest.raises(BSFError, match="C has k_M = 25 columns but frame has only 20"):
        transfer_frame(frame, np.eye(20, 25), spec)
    with pytest.raises(BSFError, match="C has k_N = 31 rows but target_spectrum has only 30"):
        transfer_frame(frame, np.ones((31, 20)), spec)
    with pytest.raises(BSFError, match=r"C must be a 2-D \(k_N, k_M\) matrix, got shape \(20,\)"):
        transfer_frame(frame, np.ones(20), spec)
    with pytest.raises(BSFError, match="C contains NaN"):
        transfer_frame(frame, np.full((20, 20), np.nan), spec)
    with pytest.raises(BSFError, match="target_spectrum must be a bsfjax.Spectrum"):
        transfer_frame(frame, np.eye(20), spec.evecs)
    with pytest.raises(BSFError, match="frame must be a bsfjax.Frame"):
        transfer_frame(frame.atoms, np.eye(20), spec)
    bare = Frame(frame.atoms, frame.coeffs, frame.taus, frame.centers, frame.mass)
    with pytest.raises(BSFError, match="frame has no gammas"):
        transfer_frame(bare, np.eye(20), spec)
