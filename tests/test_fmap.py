"""Functional map ↔ point map conversions and refinement against numpy/scipy references."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy.spatial import cKDTree

import bsfjax
from bsfjax import BSFError, fmap_from_p2p, fmap_to_p2p, icp_refine, zoomout
from bsfjax.internal import nearest_neighbors

from .conftest import data_path, icosphere


def cached_spectrum(request, mesh, k):
    """Spectrum stored in pytest's cache folder, so test files (and reruns) share it."""
    try:
        cache = request.config.cache.mkdir("bsfjax_spectra")
    except AttributeError:  # cacheprovider disabled
        cache = None
    return bsfjax.spectrum(mesh, k, cache_dir=cache)


@pytest.fixture(scope="module")
def faust(request):
    """FAUST tr_reg_000 → tr_reg_001 (identity ground truth) with 100 eigenpairs each."""
    meshes = [bsfjax.load_mesh(data_path("faust", f"tr_reg_{i}.off")) for i in ("000", "001")]
    return meshes, [cached_spectrum(request, m, 100) for m in meshes]


@pytest.fixture(scope="module")
def small_pair():
    """A sphere and a smooth non-isometric deformation of it (same connectivity: GT = identity)."""
    v, f = icosphere(3)  # 642 vertices
    w = v * np.array([1.0, 0.8, 1.2]) + 0.1 * np.sin(2 * v[:, [1]]) * v
    src, tgt = bsfjax.Mesh(v, f), bsfjax.Mesh(w, f)
    return src, tgt, bsfjax.spectrum(src, 40), bsfjax.spectrum(tgt, 40)


# --------------------------------------------------------------------------- numpy references


def ref_from_p2p(p2p, evecs_m, evecs_n, mass_n):
    pi = np.zeros((evecs_n.shape[0], evecs_m.shape[0]))
    pi[np.arange(len(p2p)), p2p] = 1.0  # the dense pull-back, fine for small meshes
    return evecs_n.T @ np.diag(mass_n) @ pi @ evecs_m


def ref_to_p2p(C, evecs_m, evecs_n, ratio=1.0):
    """Nearest neighbours of Φ_N among Φ_M Cᵀ·ratio, ratio = S_M/S_N: the two shapes compared
    at one area (fmap_to_p2p's docstring)."""
    kn, km = C.shape
    return cKDTree(evecs_m[:, :km] @ C.T * ratio).query(evecs_n[:, :kn])[1]


def area_ratio(sm, sn):
    return float(np.sum(sm.mass) / np.sum(sn.mass))


def ref_zoomout(C, sm, sn, k, step, ratio=None):
    ratio = area_ratio(sm, sn) if ratio is None else ratio
    while C.shape[0] < k:
        p2p = ref_to_p2p(C, sm.evecs, sn.evecs, ratio)
        kk = min(C.shape[0] + step, k)
        C = ref_from_p2p(p2p, sm.evecs[:, :kk], sn.evecs[:, :kk], sn.mass)
    return C


def ref_icp(C, sm, sn, n_iter):
    kn, km = C.shape
    for _ in range(n_iter):
        p2p = ref_to_p2p(C, sm.evecs, sn.evecs)
        u, _, vt = np.linalg.svd(ref_from_p2p(p2p, sm.evecs[:, :km], sn.evecs[:, :kn], sn.mass))
        C = u @ np.eye(kn, km) @ vt
    return C


# --------------------------------------------------------------------------- fmap_from_p2p


def test_from_p2p_matches_dense_pullback(small_pair):
    _, _, sm, sn = small_pair
    sm, sn = sm.truncate(15), sn.truncate(12)
    p2p = np.random.default_rng(0).integers(0, sm.n_vertices, sn.n_vertices)
    ref = ref_from_p2p(p2p, sm.evecs, sn.evecs, sn.mass)
    with jax.enable_x64(True):
        C = np.asarray(fmap_from_p2p(sm, sn, p2p))
    assert C.shape == (12, 15) and C.dtype == np.float64
    np.testing.assert_allclose(C, ref, rtol=1e-12, atol=1e-12)
    C32 = np.asarray(fmap_from_p2p(sm, sn, p2p))
    assert C32.dtype == np.float32
    np.testing.assert_allclose(C32, ref, atol=1e-5)


def test_identity_self_map_is_identity_matrix(small_pair):
    _, _, sm, _ = small_pair
    with jax.enable_x64(True):
        C = np.asarray(fmap_from_p2p(sm, sm, np.arange(sm.n_vertices)))
    np.testing.assert_allclose(C, np.eye(sm.k), atol=1e-10)  # Φᵀ A Φ = I
    assert np.array_equal(np.asarray(fmap_to_p2p(C, sm, sm)), np.arange(sm.n_vertices))


def test_faust_ground_truth_roundtrip_recovers_identity(faust):
    """fmap_from_p2p then fmap_to_p2p at k = 100 on FAUST 000 → 001 (identity ground truth)."""
    meshes, (sm, sn) = faust
    gt = np.arange(sn.n_vertices)
    C = fmap_from_p2p(sm, sn, gt)
    assert C.shape == (100, 100)
    p2p = np.asarray(fmap_to_p2p(C, sm, sn))
    exact = np.mean(p2p == gt)
    # Most vertices map exactly to themselves; the rest land next to the right place.
    assert exact > 0.6, exact
    dist = np.linalg.norm(meshes[0].vertices[p2p] - meshes[0].vertices[gt], axis=1)
    assert np.mean(dist < 0.02) > 0.95  # within 2 cm on a 1.7 m body
    # A smaller basis is a blurrier map: the roundtrip gets worse when k drops.
    C30 = np.asarray(C)[:30, :30]
    p2p_30 = np.asarray(fmap_to_p2p(C30, sm, sn))
    assert np.mean(p2p_30 == gt) < exact - 0.1
    # float64: exactly scipy's answer on this crowded embedding (near-ties at 1e-6 relative),
    # the shapes compared at one area (Φ_N against Φ_M Cᵀ·S_M/S_N; here S_M/S_N = 0.991)
    with jax.enable_x64(True):
        p2p_64 = np.asarray(fmap_to_p2p(C30, sm, sn))
    ratio = np.sum(sm.mass) / np.sum(sn.mass)
    assert abs(ratio - 1) > 0.005  # the areas differ: without the ratio the answer differs
    np.testing.assert_array_equal(p2p_64, ref_to_p2p(C30 * ratio, sm.evecs, sn.evecs))
    assert not np.array_equal(p2p_64, ref_to_p2p(C30, sm.evecs, sn.evecs))


# --------------------------------------------------------------------------- nearest neighbours


@pytest.mark.parametrize("chunk_size", [None, 7, 100, 5000])
def test_nearest_neighbors_equal_ckdtree(chunk_size):
    rng = np.random.default_rng(1)
    ref = rng.standard_normal((900, 12))
    qry = ref[rng.integers(0, 900, 701)] + 0.3 * rng.standard_normal((701, 12))
    d, expect = cKDTree(ref).query(qry, k=2)
    with jax.enable_x64(True):
        got = np.asarray(nearest_neighbors(ref, qry, chunk_size=chunk_size))
    np.testing.assert_array_equal(got, expect[:, 0])
    # float32: identical except where the two best float64 distances (nearly) tie.
    got32 = np.asarray(nearest_neighbors(ref, qry, chunk_size=chunk_size))
    clear = (d[:, 1] - d[:, 0]) > 1e-4 * d[:, 0]
    assert clear.mean() > 0.99
    np.testing.assert_array_equal(got32[clear], expect[clear, 0])



@pytest.mark.parametrize("n_valid", [701, 650, 64, 1])
def test_padded_queries_are_skipped(n_valid):
    """``_nearest(..., n_valid)`` (a target padded to its size bucket): the real queries get
    cKDTree's answers, every chunk past them is skipped (answer 0), jitted with ``n_valid``
    traced (one program for every count)."""
    from bsfjax._maps._fmap import _nearest

    rng = np.random.default_rng(3)
    ref = rng.standard_normal((900, 12))
    qry = ref[rng.integers(1, 900, 701)] + 0.01 * rng.standard_normal((701, 12))
    expect = cKDTree(ref).query(qry)[1]
    with jax.enable_x64(True):
        got = np.asarray(jax.jit(_nearest, static_argnums=2)(ref, qry, 64, n_valid))
    np.testing.assert_array_equal(got[:n_valid], expect[:n_valid])
    first_skipped = -(-n_valid // 64) * 64  # the chunk holding the last real query runs whole
    np.testing.assert_array_equal(got[first_skipped:], 0)
    np.testing.assert_array_equal(got[n_valid:first_skipped], expect[n_valid:first_skipped])

def test_nearest_neighbors_far_from_origin():
    """Far from the origin, ‖x‖² − 2x·y + ‖y‖² in float32 alone cannot rank neighbours."""
    rng = np.random.default_rng(2)
    ref = 1e3 + rng.standard_normal((500, 3))
    qry = ref[:300] + 0.05 * rng.standard_normal((300, 3))
    d, expect = cKDTree(ref).query(qry, k=2)
    clear = (d[:, 1] - d[:, 0]) > 1e-3
    got = np.asarray(nearest_neighbors(ref, qry))
    np.testing.assert_array_equal(got[clear], expect[clear, 0])
    # The naive float32 expanded form does get some of them wrong: the test can tell.
    r32, q32 = ref.astype(np.float32), qry.astype(np.float32)
    naive = np.argmin((r32**2).sum(1)[None] - 2 * q32 @ r32.T, axis=1)
    assert np.mean(naive[clear] != expect[clear, 0]) > 0.05


@pytest.mark.parametrize("adjoint", [False, True])
def test_fmap_to_p2p_matches_ckdtree(small_pair, adjoint):
    _, _, sm, sn = small_pair
    C = np.random.default_rng(3).standard_normal((20, 25)) * 0.1 + np.eye(20, 25)
    if adjoint:  # invariant to the areas
        expect = cKDTree(sm.evecs[:, :25]).query(sn.evecs[:, :20] @ C)[1]
    else:
        assert abs(area_ratio(sm, sn) - 1) > 0.005  # areas 1 % apart: the ratio matters
        expect = ref_to_p2p(C, sm.evecs, sn.evecs, area_ratio(sm, sn))
        assert not np.array_equal(expect, ref_to_p2p(C, sm.evecs, sn.evecs))
    rows = np.random.default_rng(5).choice(sn.n_vertices, 150, replace=False)
    with jax.enable_x64(True):
        got = np.asarray(fmap_to_p2p(C, sm, sn, adjoint=adjoint, chunk_size=64))
        # some target vertices only: each its match in the whole map
        part = np.asarray(fmap_to_p2p(C, sm, sn, adjoint=adjoint, chunk_size=64, rows=rows))
    np.testing.assert_array_equal(got, expect)
    assert got.dtype == np.int32 and got.shape == (sn.n_vertices,)
    np.testing.assert_array_equal(part, expect[rows])
    for bad, msg in (([sn.n_vertices], "rows must be target vertex indices in"),
                     ([[0, 1]], "rows must be a 1-D array"),
                     (np.zeros(0, int), "rows is empty")):
        with pytest.raises(BSFError, match=msg):
            fmap_to_p2p(C, sm, sn, rows=bad)


# --------------------------------------------------------------------------- refinement


def test_zoomout_matches_numpy_reference(small_pair):
    _, _, sm, sn = small_pair
    gt = np.arange(sn.n_vertices)
    with jax.enable_x64(True):
        C0 = np.asarray(fmap_from_p2p(sm.truncate(6), sn.truncate(6), gt))
        C0 = C0 + 0.05 * np.random.default_rng(4).standard_normal(C0.shape)
        C = np.asarray(zoomout(C0, sm, sn, 30, step=4))  # 6 → 10 → … → 26 → 30 (clipped)
    assert C.shape == (30, 30)
    np.testing.assert_allclose(C, ref_zoomout(C0, sm, sn, 30, 4), atol=1e-10)


def test_zoomout_rectangular_schedule(small_pair):
    _, _, sm, sn = small_pair
    gt = np.arange(sn.n_vertices)
    C0 = fmap_from_p2p(sm.truncate(8), sn.truncate(5), gt)
    C = zoomout(C0, sm, sn, (23, 20), step=5)  # (k_source, k_target), as pyFM's K
    assert C.shape == (20, 23)


def test_zoomout_improves_faust_map(faust):
    meshes, (sm, sn) = faust
    gt = np.arange(sn.n_vertices)
    C0 = fmap_from_p2p(sm.truncate(20), sn.truncate(20), gt)
    C = zoomout(C0, sm, sn, 60, step=5)
    v = meshes[0].vertices
    err0 = np.linalg.norm(v[np.asarray(fmap_to_p2p(C0, sm, sn))] - v, axis=1).mean()
    err = np.linalg.norm(v[np.asarray(fmap_to_p2p(C, sm, sn))] - v, axis=1).mean()
    assert err < 0.7 * err0, (err0, err)  # measured 0.0232 → 0.0126


def test_sampled_zoomout_matches_numpy_quadrature(small_pair):
    """ZoomOut on subsamples: nearest source sample of each target sample, and the functional
    map integrated over the target's Voronoi cells (numpy float64 reference)."""
    src, tgt, sm, sn = small_pair
    sub_m, sub_n = bsfjax.subsample(src, 150), bsfjax.subsample(tgt, 200, seed=3)
    w = np.bincount(sub_n.cells, weights=np.asarray(sn.mass), minlength=200)
    assert w.sum() == pytest.approx(float(np.sum(sn.mass)))
    with jax.enable_x64(True):
        C0 = np.asarray(fmap_from_p2p(sm.truncate(6), sn.truncate(6), np.arange(sn.n_vertices)))
        C0 = C0 + 0.05 * np.random.default_rng(4).standard_normal(C0.shape)
        C = np.asarray(zoomout(C0, sm, sn, 30, step=4, samples=(sub_m, sub_n)))
        exact = np.asarray(zoomout(C0, sm, sn, 30, step=4))
        every = tuple(bsfjax.subsample(m, 10_000) for m in (src, tgt))
        C_every = np.asarray(zoomout(C0, sm, sn, 30, step=4, samples=every))
    restrict = lambda s, sub, mass: bsfjax.Spectrum(s.evals, s.evecs[sub.indices], mass)  # noqa
    want = ref_zoomout(C0, restrict(sm, sub_m, np.ones(150)), restrict(sn, sub_n, w), 30, 4,
                       ratio=area_ratio(sm, sn))
    np.testing.assert_allclose(C, want, atol=1e-10)
    np.testing.assert_allclose(C_every, exact, atol=1e-12)  # every vertex its own sample
    assert not np.allclose(C, exact, atol=1e-3)  # the samples did change the computation


def test_sampled_zoomout_improves_faust_map(faust):
    meshes, (sm, sn) = faust
    gt = np.arange(sn.n_vertices)
    C0 = fmap_from_p2p(sm.truncate(20), sn.truncate(20), gt)
    samples = tuple(bsfjax.subsample(m, 1000) for m in meshes)
    C = zoomout(C0, sm, sn, 60, step=5, samples=samples)
    v = meshes[0].vertices
    err0 = np.linalg.norm(v[np.asarray(fmap_to_p2p(C0, sm, sn))] - v, axis=1).mean()
    err = np.linalg.norm(v[np.asarray(fmap_to_p2p(C, sm, sn))] - v, axis=1).mean()
    assert err < 0.7 * err0, (err0, err)  # as the full ZoomOut (0.0232 → 0.0126)


def test_zoomout_bad_samples_raise(small_pair):
    src, tgt, sm, sn = small_pair
    C0 = fmap_from_p2p(sm.truncate(6), sn.truncate(6), np.arange(sn.n_vertices))
    sub = bsfjax.subsample(src, 50)
    with pytest.raises(BSFError, match="samples must be"):
        zoomout(C0, sm, sn, 20, samples=sub)
    with pytest.raises(BSFError, match="target samples"):
        zoomout(C0, sm, sn, 20, samples=(sub, bsfjax.Subsample(sub.indices, sub.cells[:10])))
    with pytest.raises(BSFError, match="source samples"):
        zoomout(C0, sm, sn, 20, samples=(bsfjax.Subsample(sub.indices + 1000, sub.cells), sub))


def unit(s):
    """The spectrum of the shape rescaled to area 1 exactly (the references' common area)."""
    a = float(np.sum(s.mass))
    return bsfjax.Spectrum(np.asarray(s.evals) * a, np.asarray(s.evecs) * np.sqrt(a),
                           np.asarray(s.mass) / a)


@pytest.mark.parametrize("bijective", [False, True])
def test_icp_orthogonal_and_matches_reference(small_pair, bijective):
    _, _, sm0, sn0 = small_pair
    gt = np.arange(sn0.n_vertices)
    r = np.sqrt(area_ratio(sm0, sn0))  # C between the unit-area shapes = C·√(S_M/S_N)
    with jax.enable_x64(True):
        C0 = np.asarray(fmap_from_p2p(sm0.truncate(15), sn0.truncate(15), gt))
        C0 = C0 + 0.05 * np.random.default_rng(5).standard_normal(C0.shape)
        C = np.asarray(icp_refine(C0, sm0, sn0, n_iter=3, bijective=bijective)) * r
    # the references run on the unit-area shapes, where the result is orthogonal
    sm, sn, C0 = unit(sm0), unit(sn0), C0 * r
    np.testing.assert_allclose(C.T @ C, np.eye(15), atol=1e-10)
    if not bijective:
        np.testing.assert_allclose(C, ref_icp(C0, sm, sn, 3), atol=1e-10)
    else:  # reference: average with the transposed functional map of the inverse point map
        ref = C0
        for _ in range(3):
            fwd = ref_from_p2p(ref_to_p2p(ref, sm.evecs, sn.evecs), sm.evecs[:, :15],
                               sn.evecs[:, :15], sn.mass)
            bwd = ref_from_p2p(ref_to_p2p(ref.T, sn.evecs, sm.evecs), sn.evecs[:, :15],
                               sm.evecs[:, :15], sm.mass)
            u, _, vt = np.linalg.svd(0.5 * (fwd + bwd.T))
            ref = u @ vt
        np.testing.assert_allclose(C, ref, atol=1e-10)
    # ICP keeps the map near the ground truth it started from.
    p2p = np.asarray(fmap_to_p2p(C / r, sm0, sn0))
    src = small_pair[0].vertices
    assert np.linalg.norm(src[p2p] - src, axis=1).mean() < 0.15


# --------------------------------------------------------------------------- bad input


def test_shape_mismatches_raise(small_pair):
    _, _, sm, sn = small_pair
    n = sn.n_vertices
    with pytest.raises(ValueError, match="C has shape"):
        fmap_to_p2p(np.eye(50), sm, sn)
    with pytest.raises(ValueError, match="matrix"):
        fmap_to_p2p(np.ones(5), sm, sn)
    with pytest.raises(ValueError, match=r"p2p must have shape \(642,\)"):
        fmap_from_p2p(sm, sn, np.arange(n - 1))
    with pytest.raises(ValueError, match=r"in \[0, 642\)"):
        fmap_from_p2p(sm, sn, np.full(n, n))
    with pytest.raises(ValueError, match="integer"):
        fmap_from_p2p(sm, sn, np.zeros(n))
    with pytest.raises(BSFError, match="exceeds"):
        zoomout(np.eye(10), sm, sn, 41)
    with pytest.raises(BSFError, match="at least the size"):
        zoomout(np.eye(10), sm, sn, 5)
    with pytest.raises(BSFError, match="step"):
        zoomout(np.eye(10), sm, sn, 20, step=0)
    with pytest.raises(BSFError, match="n_iter"):
        icp_refine(np.eye(10), sm, sn, n_iter=-1)
    with pytest.raises(BSFError, match="chunk_size"):
        fmap_to_p2p(np.eye(10), sm, sn, chunk_size=0)
    with pytest.raises(BSFError, match="Spectrum"):
        fmap_to_p2p(np.eye(10), sm.evecs, sn)
    with pytest.raises(BSFError, match="same d"):
        nearest_neighbors(np.ones((5, 3)), np.ones((5, 2)))
