"""Landmark-guided ZoomOut (``_maps/_guide.py``): its features, its search, its continuation,
and what it is for: a partial target whose cut leg no longer slides into the missing foot."""

import jax
import numpy as np
import pytest

import bsfjax as bj
from bsfjax._maps._fmap import _from_p2p, _size_schedule, _zoomout_jit
from bsfjax._maps._guide import (CLOUD_ADDED_LANDMARKS, CLOUD_ZOOMOUT_STEP, estimates_again,
                                 follows_landmarks, for_point_clouds,
                                 guided_search)
from bsfjax.internal import estimate_size, guided_zoomout, landmark_geodesics, vertex_areas
from bsfjax._maps._turn import LIMB_APART

from .conftest import data_path

#: the docs' 5 landmark vertices of the FAUST registrations (head, hands, feet)
LANDMARKS = (412, 3216, 5907, 6296, 2445)


def test_features_are_dijkstra_distances_at_a_fitted_scale(sphere_mesh):
    """The features are the Dijkstra distances over √area of their shape (a scaled copy, in
    other units: the source's), the target's times the scale σ: the smaller of the landmark
    distances' least-squares fit and the distance quantiles' ratio (here both 1/factor when
    the areas say the target is factor² smaller), clipped to [1/1.2, 1.2]."""
    mass = np.asarray(vertex_areas(sphere_mesh))
    lm = [0, 50, 200, 400]
    ref = bj.geodesic_distances(sphere_mesh, lm).T / np.sqrt(mass.sum())
    scaled = bj.Mesh(np.asarray(sphere_mesh.vertices) * 1000.0, sphere_mesh.faces)
    g_m, g_n = landmark_geodesics(sphere_mesh, scaled, (lm, lm), (mass, mass * 1e6))
    np.testing.assert_allclose(g_m, ref, rtol=1e-12)
    np.testing.assert_allclose(g_n, ref, rtol=1e-9)
    for factor, sigma in ((1.1, 1 / 1.1), (2.0, 1 / 1.2)):
        _, g_n = landmark_geodesics(sphere_mesh, sphere_mesh, (lm, lm),
                                    (mass, mass / factor**2))
        np.testing.assert_allclose(g_n, ref * factor * sigma, rtol=1e-9)


def test_the_smaller_scale_estimate_is_kept(sphere_mesh):
    """σ is the smaller of the landmark fit and the median over landmarks of the ratio of the
    distances' area-weighted 0.3-quantiles (an ellipsoid target: the two differ)."""
    mass = np.asarray(vertex_areas(sphere_mesh))
    v = np.asarray(sphere_mesh.vertices) * np.array([1.0, 1.0, 1.4])
    target = bj.Mesh(v, sphere_mesh.faces)
    mass_n = np.asarray(vertex_areas(target))
    lm = [0, 50, 200, 400]
    g_m = bj.geodesic_distances(sphere_mesh, lm).T / np.sqrt(mass.sum())
    d_n = bj.geodesic_distances(target, lm).T / np.sqrt(mass_n.sum())

    def quantile(x, w, q=0.3):  # the smallest value with a share q of the weight at or below
        order = np.argsort(x)
        return x[order][np.flatnonzero(np.cumsum(w[order]) >= q * w.sum())[0]]

    fit = np.sum(g_m[lm] * d_n[lm]) / np.sum(d_n[lm] ** 2)
    ratio = np.median([quantile(g_m[:, i], mass) / quantile(d_n[:, i], mass_n)
                       for i in range(len(lm))])
    assert abs(fit - ratio) > 0.01  # (the case tells them apart)
    _, g_n = landmark_geodesics(sphere_mesh, target, (lm, lm), (mass, mass_n))
    np.testing.assert_allclose(g_n, d_n * min(fit, ratio), rtol=1e-9)


@pytest.mark.parametrize("x64", [False, True])
def test_search_is_the_brute_force_nearest_neighbour(x64):
    """One guided step against a float64 brute-force search of the stacked embeddings, the
    weight scaled by the mean row norm over the real rows (w_n > 0) times √area."""
    rng = np.random.default_rng(0)
    n_m, n_n, k, L = 300, 250, 12, 4
    phi_m, phi_n = rng.normal(size=(n_m, k)), rng.normal(size=(n_n, k))
    C = rng.normal(size=(k, k))
    g_m, g_n = rng.random((n_m, L)), rng.random((n_n, L))
    w_n = rng.random(n_n)
    w_n[:20] = 0.0  # padding rows
    s = 0.7 * np.linalg.norm(phi_n[20:], axis=1).mean() * np.sqrt(w_n.sum())
    ref = np.concatenate([phi_m @ C.T, s * g_m], 1)
    qry = np.concatenate([phi_n, s * g_n], 1)
    want = np.argmin(((qry[:, None] - ref[None]) ** 2).sum(-1), axis=1)
    with jax.enable_x64(x64):
        got = np.asarray(guided_search(*(jax.numpy.asarray(x) for x in
                                         (C, phi_m, phi_n, w_n, g_m, g_n)), 0.7, chunk=64))
    assert np.mean(got == want) >= (1.0 if x64 else 0.99)


def test_weight_zero_is_zoomout(small_pair):
    """With weight 0 the continuation is plain ZoomOut (the tested route), map for map."""
    ex, sm, sn = small_pair
    rng = np.random.default_rng(1)
    p0 = np.where(rng.random(sn.n_vertices) < 0.2, rng.integers(0, sm.n_vertices, sn.n_vertices),
                  np.arange(sn.n_vertices))
    phi_m, phi_n, mass = (np.asarray(x) for x in (sm.evecs, sn.evecs, sn.mass))
    C0 = _from_p2p(p0, phi_m[:, :20], phi_n[:, :20], mass)
    sizes = _size_schedule(20, 40, 4, 5)
    g = np.zeros((sm.n_vertices, 3)), np.ones((sn.n_vertices, 3))
    guided = guided_zoomout(C0, phi_m, phi_n, mass, *g, sizes=sizes, chunk=512, weight=0.0)
    plain = _zoomout_jit(C0, phi_m, phi_n, mass, sizes_n=sizes, sizes_m=sizes, chunk=512,
                         adjoint=False)
    np.testing.assert_allclose(np.asarray(guided), np.asarray(plain), atol=1e-5)


def test_estimate_size():
    assert estimate_size(30, 100, True) == 100  # guided to the spectra's size
    assert estimate_size(30, 100, False) == 60  # the landmark-free choice at 2k
    assert estimate_size(30, 50, False) == 50


def test_negative_guidance_is_refused():
    with pytest.raises(bj.BSFError, match="landmark_guidance"):
        bj.MapEstimator(landmark_guidance=-1.0)


@pytest.fixture(scope="module")
def partial_pair():
    """FAUST 000 and 010 without its left forearm and hand and its right foot (the scan
    suite's partial target), prepared as ``bsfjax transfer`` does, with 100 eigenpairs."""
    seg = bj.load_labels(data_path("segmentations", "smpl_vert_segmentation.json"))
    truth, names = np.asarray(seg.labels), list(seg.names)
    cut = ("leftForeArm", "leftHand", "leftHandIndex1", "rightFoot", "rightToeBase")
    full = bj.load_mesh(data_path("faust", "tr_reg_010.off"))
    remove = np.isin(truth, [names.index(p) for p in cut])
    f = np.asarray(full.faces)
    faces = f[~remove[f].any(axis=1)]
    kept = np.unique(faces)
    new = np.full(full.n_vertices, -1)
    new[kept] = np.arange(kept.size)
    target = bj.prepare_scan(bj.Mesh(np.asarray(full.vertices)[kept], new[faces])).mesh
    source = bj.load_mesh(data_path("faust", "tr_reg_000.off"))
    lm = [i for i in LANDMARKS if not remove[i]]
    return (source, target, bj.spectrum(source, 100), bj.spectrum(target, 100),
            (lm, [int(new[i]) for i in lm]), truth, kept)


def test_guidance_keeps_a_cut_leg_in_place(partial_pair):
    """With 4 landmarks the unguided estimate slides the shortened leg into the missing foot
    (92.5 % of the target's area on its SMPL part); the guided one does not (95.2 %)."""
    source, target, sm, sn, lm, truth, kept = partial_pair
    mass = np.asarray(vertex_areas(target))[:kept.size]

    def accuracy(guidance):
        est = bj.MapEstimator(landmark_guidance=guidance)(sm, sn, lm, source_mesh=source,
                                                          target_mesh=target)
        right = truth[np.asarray(est.p2p)[:kept.size]] == truth[kept]
        return float(mass[right].sum() / mass.sum())

    plain, guided = accuracy(0.0), accuracy(1.5)
    assert guided > 0.945 and guided > plain + 0.02, (plain, guided)


def test_clouds_run_unguided_with_a_larger_zoomout_step_the_coverage_and_the_derived_map(
        sphere_mesh):
    est = bj.MapEstimator()
    cloud = bj.PointCloud(np.asarray(sphere_mesh.vertices))
    assert for_point_clouds(est, sphere_mesh, sphere_mesh) is est
    on_cloud = for_point_clouds(est, sphere_mesh, cloud)
    assert on_cloud.landmark_guidance == 0.0
    assert on_cloud.zoomout_step == CLOUD_ZOOMOUT_STEP > est.zoomout_step
    assert on_cloud.turn_step == est.zoomout_step  # (the turn check: as on meshes)
    assert on_cloud.choice_coverage and not est.choice_coverage
    assert on_cloud.keep_derived and not est.keep_derived
    assert on_cloud.added_landmarks == CLOUD_ADDED_LANDMARKS > est.added_landmarks == 0
    assert on_cloud.turn_limbs_apart is None and est.turn_limbs_apart == LIMB_APART
    assert for_point_clouds(est, cloud, sphere_mesh).k == est.k
    # a step the user made larger stays theirs
    assert for_point_clouds(bj.MapEstimator(zoomout_step=10), cloud).zoomout_step == 10


def test_a_second_estimate_only_where_it_can_differ(sphere_mesh):
    """``estimates_again`` (the rule ``bsfjax transfer`` and `transfer_collection` share):
    between triangle meshes, with ``derived_guidance`` off and the guidance on, an estimate
    with landmarks (phases 3 and 4 then follow phase 1) or a landmark-free one from several
    starts.  A landmark-free single start never reaches the phases that the derived pairs
    guide, so ``--one-start`` would pay for the same map twice."""
    est, m, cloud = bj.MapEstimator(), sphere_mesh, bj.PointCloud(np.asarray(sphere_mesh.vertices))
    lm = ([0, 1], [0, 1])
    assert estimates_again(est, None, m, m, 60)
    assert estimates_again(est, lm, m, m, 60)
    assert estimates_again(est.__class__(starts=((30, 7.0),)), lm, m, m, 60)
    for other in (est.__class__(derived_guidance=True), est.__class__(landmark_guidance=0.0),
                  est.__class__(derived_landmarks=0, turn_check=False)):
        assert not estimates_again(other, lm, m, m, 60)
    assert not estimates_again(est, lm, m, cloud, 60)
    # the second estimate's estimator then runs phases 3 and 4 after the landmarks' map
    again = est.__class__(derived_guidance=True)
    assert follows_landmarks(again, lm, m, m)
    assert not follows_landmarks(est, lm, m, m) and not follows_landmarks(again, None, m, m)
    assert not follows_landmarks(again, lm, m, cloud)
    assert not estimates_again(est.__class__(derived_guidance=True), None, m, m, 60)
    assert not estimates_again(est.__class__(starts=((30, 7.0),)), None, m, m, 60)
    assert not estimates_again(est.__class__(landmark_guidance=0.0), None, m, m, 60)
    assert not estimates_again(est.__class__(derived_landmarks=0, turn_check=False), None, m,
                               m, 60)
    assert not estimates_again(est, None, m, cloud, 60)
    assert not estimates_again(est, None, cloud, m, 60)
    # the starts that ZoomOut to refine_to keeps: all but one above it
    assert not estimates_again(est.__class__(starts=((10, 7.0), (50, 7.0))), None, m, m, 20)
    assert estimates_again(est.__class__(starts=((10, 7.0), (50, 7.0))), None, m, m, 60)


def test_landmarks_and_derived_guidance_go_on_from_the_landmarks_map(small_pair,
                                                                     monkeypatch):
    """With landmarks, ``derived_guidance`` runs phases 3 and 4 from phase 1's map (the one
    the landmarks give without it), measured, and returns the map they keep; without it the
    landmarks' map is returned as it is."""
    import dataclasses

    ex, sm, sn = small_pair
    lm = ([0, 100, 200, 300], [0, 100, 200, 300])  # (levels keep the coarse vertices first)
    kw = dict(source_mesh=ex.source, target_mesh=ex.target)
    seen = []
    real = bj.MapEstimator._later_phases

    def spy(self, pb, run, quality, *rest, **kw):
        seen.append((run.p2p.copy(), dict(quality), kw))
        seen.append(real(self, pb, run, quality, *rest, **kw))
        return seen[-1]

    monkeypatch.setattr(bj.MapEstimator, "_later_phases", spy)
    est = bj.MapEstimator(k=10, refine_to=20, zoomout_samples=300)
    plain = est(sm, sn, lm, **kw)
    assert not seen and plain.distortion is None and plain.swapped is None
    got = dataclasses.replace(est, derived_guidance=True)(sm, sn, lm, **kw)
    (start, measured, options), (kept, quality) = seen
    assert options == {"given": True}  # (phase 3 then prefers its guided estimate)
    np.testing.assert_array_equal(start, plain.p2p)
    distortion = bj.map_distortion(ex.source, ex.target, plain.p2p, fit_scale=True)
    np.testing.assert_allclose(measured["distortion"], distortion, rtol=1e-6)
    np.testing.assert_allclose(measured["orientation"],
                               bj.orientation_agreement(ex.source, ex.target, plain.p2p))
    np.testing.assert_array_equal(got.p2p, kept.p2p)
    assert got.distortion == quality["distortion"] and got.swapped is not None


def test_guided_to_is_checked(small_pair):
    _, sm, sn = small_pair
    with pytest.raises(bj.BSFError, match="guided_to must be an integer"):
        bj.MapEstimator(k=10, guided_to=10_000)(sm, sn, ([0, 1], [0, 1]))


def test_derived_landmarks_guide_a_partial_target_without_landmarks(partial_pair):
    """Without landmarks, ``derived_guidance`` also runs the estimates with landmark pairs
    read off a map guided by them; the choice keeps the guided one on the cut target, whose
    arm and leg stay in place (as ``bsfjax transfer --partial``: ZoomOut to 60, guided to
    100; phase 3 alone, without the turn check: 89.1 % unguided, 93.5 % guided)."""
    source, target, sm, sn, _, truth, kept = partial_pair
    mass = np.asarray(vertex_areas(target))[:kept.size]

    def accuracy(est):
        right = truth[np.asarray(est.p2p)[:kept.size]] == truth[kept]
        return float(mass[right].sum() / mass.sum())

    kw = dict(source_mesh=source, target_mesh=target)
    first = bj.MapEstimator(refine_to=60, turn_check=False)(sm, sn, **kw)
    # (the guided estimate goes on from the first one's kept start, as bsfjax transfer does)
    again = bj.MapEstimator(refine_to=60, derived_guidance=True, turn_check=False)(
        sm, sn, resume=first, **kw)
    plain, guided = accuracy(first), accuracy(again)
    assert guided > 0.93 and guided > plain + 0.02, (plain, guided)


def test_derived_guidance_is_checked():
    with pytest.raises(bj.BSFError, match="derived_guidance must be True or False"):
        bj.MapEstimator(derived_guidance=1)
