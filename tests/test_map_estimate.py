"""MapEstimator and estimate_map (with landmarks, from several starts, the turn check) and
mirror_symmetry."""

from __future__ import annotations

import numpy as np
import pytest

import bsfjax
from bsfjax import MapEstimator, estimate_map
from bsfjax.internal import example_landmarks
from bsfjax._maps._turn import landmarks_from_map, measures_disagree, selection_rows

from .conftest import data_path, icosphere


def test_estimate_map_zoomout_step(small_pair):
    """``zoomout_step`` is ZoomOut's ``step`` from the initial estimate: the point map equals
    :func:`bsfjax.zoomout` with that step then :func:`bsfjax.fmap_to_p2p`, an independent route
    (the unit-area rescaling is one common power of 4: exact); a bad step is named."""
    pair, sm, sn = small_pair
    lm = example_landmarks(pair)
    maps = {}
    for step in (1, 3):
        est = estimate_map(sm, sn, k=20, landmarks=(lm, lm), refine_to=40, zoomout_step=step)
        C = bsfjax.zoomout(est.C_initial, sm, sn, 40, step=step)
        np.testing.assert_array_equal(est.p2p, bsfjax.fmap_to_p2p(C, sm, sn))
        maps[step] = est.p2p
    assert not np.array_equal(maps[1], maps[3])  # the step changes the path
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="zoomout_step must be an integer >= 1"):
            estimate_map(sm, sn, k=20, landmarks=(lm, lm), refine_to=40, zoomout_step=bad)


def test_estimate_map_without_landmarks_uses_the_orientation_term(small_pair):
    """No landmarks: with the meshes the orientation term tells left from right (the example
    body's arms and legs are separate parts), and it changes the estimate."""
    pair, sm, sn = small_pair
    gt = np.asarray(pair.p2p)
    mass = np.asarray(sn.mass)
    plain = estimate_map(sm, sn, k=20, refine_to=40)
    oriented = estimate_map(sm, sn, k=20, refine_to=40, source_mesh=pair.source,
                            target_mesh=pair.target, starts=((20, 7.0),))
    assert not np.allclose(plain.C_initial, oriented.C_initial)
    assert plain.distortion is None and oriented.distortion is None  # one start: no choice
    for est in (oriented, estimate_map(sm, sn, k=20, refine_to=40, source_mesh=pair.source,
                                       target_mesh=pair.target)):  # one start, and the default
        acc = np.sum(mass * (pair.labels[est.p2p] == pair.labels[gt])) / mass.sum()
        assert acc > 0.95
    ref = estimate_map(sm, sn, k=20, refine_to=40, landmarks=([0], [0]))
    unguided = MapEstimator(k=20, refine_to=40, landmark_guidance=0.0)(
        sm, sn, ([0], [0]), source_mesh=pair.source, target_mesh=pair.target)
    np.testing.assert_array_equal(unguided.C, ref.C)  # with landmarks: no orientation term
    guided = estimate_map(sm, sn, k=20, refine_to=40, landmarks=([0], [0]),
                          source_mesh=pair.source, target_mesh=pair.target)
    assert not np.allclose(guided.C, ref.C)  # but the meshes guide ZoomOut (test_guide.py)


def test_choice_coverage_weighs_the_coverage_errors_in_phase_2(small_pair):
    """``choice_coverage``: phase 2 keeps the start that :func:`bsfjax.choose_map` picks with
    the single-start maps' coverage errors (:func:`bsfjax.map_coverage` with the spectra's
    masses) beside their distortions and orientations (an independent route); on these starts
    that is another start than the distortion's alone, and the option is in the resume key."""
    pair, sm, sn = small_pair
    meshes = dict(source_mesh=pair.source, target_mesh=pair.target)
    starts = ((10, 14.0), (16, 7.0), (24, 3.5), (20, 3.5))
    maps = np.stack([estimate_map(sm, sn, k=20, refine_to=40, starts=(s,), **meshes).p2p
                     for s in starts])
    dist = bsfjax.map_distortion(pair.source, pair.target, maps, fit_scale=True)
    orient = bsfjax.orientation_agreement(pair.source, pair.target, maps)
    cover = bsfjax.map_coverage(pair.source, pair.target, maps, source_mass=sm.mass,
                                target_mass=sn.mass)
    with_cover = bsfjax.choose_map(dist, orient, coverage=cover)
    assert with_cover != bsfjax.choose_map(dist, orient)
    est = {c: MapEstimator(k=20, refine_to=40, starts=starts, derived_landmarks=0,
                           turn_check=False, choice_coverage=c)(sm, sn, **meshes)
           for c in (False, True)}
    assert est[True].start == starts[with_cover]
    assert est[False].start == starts[bsfjax.choose_map(dist, orient)]
    np.testing.assert_array_equal(est[True].p2p, maps[with_cover])
    with pytest.raises(ValueError, match="other spectra, meshes, starts or options"):
        MapEstimator(k=20, refine_to=40, starts=starts, choice_coverage=True)(
            sm, sn, **meshes, resume=est[False])


def test_estimate_map_without_landmarks_keeps_the_best_start(small_pair):
    """Several starts: the result is the start that :func:`bsfjax.choose_map` picks from the
    single-start maps' distortion (up to a scale: ``fit_scale``) and orientation (an
    independent route), with those values; ``fit_scale=False`` picks by the plain distortion;
    the default starts are ``landmark_free_starts`` up to ``refine_to``; bad starts are named."""
    pair, sm, sn = small_pair
    meshes = dict(source_mesh=pair.source, target_mesh=pair.target)
    starts = ((10, 3.5), (20, 7.0), (30, 14.0), (12, 7.0))
    single = [estimate_map(sm, sn, k=20, refine_to=40, starts=(s,), **meshes) for s in starts]
    maps = np.stack([e.p2p for e in single])
    dist = bsfjax.map_distortion(pair.source, pair.target, maps, fit_scale=True)
    orient = bsfjax.orientation_agreement(pair.source, pair.target, maps)
    best = bsfjax.choose_map(dist, orient)
    plain = bsfjax.map_distortion(pair.source, pair.target, maps)
    est0 = bsfjax.MapEstimator(k=20, refine_to=40, starts=starts, derived_landmarks=0,
                               turn_check=False, fit_scale=False)(sm, sn, **meshes)
    assert est0.start == starts[bsfjax.choose_map(plain, orient)]
    assert est0.distortion == pytest.approx(plain[bsfjax.choose_map(plain, orient)])
    est = estimate_map(sm, sn, k=20, refine_to=40, starts=starts, derived_landmarks=0,
                       turn_check=False, **meshes)
    np.testing.assert_array_equal(est.p2p, single[best].p2p)
    np.testing.assert_array_equal(est.C, single[best].C)
    assert est.start == starts[best] and est.C_initial.shape == (starts[best][0],) * 2
    assert est.distortion == pytest.approx(dist[best]) and est.orientation == orient[best]
    assert est.landmarks is None and est.swapped is None
    assert len({m.tobytes() for m in maps}) > 1  # the starts reach different maps
    # k0 above refine_to is skipped: at refine_to = 25 the choice is among the first, second
    # and fourth start
    low = estimate_map(sm, sn, k=20, refine_to=25, starts=starts, derived_landmarks=0,
                       turn_check=False, **meshes)
    kept = [starts[i] for i in (0, 1, 3)]
    maps = np.stack([estimate_map(sm, sn, k=20, refine_to=25, starts=(s,), **meshes).p2p
                     for s in kept])
    assert low.start == kept[bsfjax.choose_map(
        bsfjax.map_distortion(pair.source, pair.target, maps, fit_scale=True),
        bsfjax.orientation_agreement(pair.source, pair.target, maps))]
    with pytest.raises(ValueError, match="several starts are told apart by the meshes"):
        estimate_map(sm, sn, k=20, refine_to=40, starts=starts)
    for bad, msg in ((5, "starts must be a sequence"), (((20,),), "starts must be"),
                     (((0, 7.0),), "k0 must be an integer"),
                     (((20, -1.0),), "variance must be a positive"),
                     (((50, 7.0),), "no start has k0 <= refine_to = 40")):
        with pytest.raises(ValueError, match=msg):
            estimate_map(sm, sn, k=20, refine_to=40, starts=bad, **meshes)


def test_estimate_map_without_landmarks_reads_landmarks_off_its_map(small_pair):
    """The second estimate: landmarks read off the kept start's map (farthest source points,
    each with the target vertex whose image is nearest), then estimate_map with them as given
    landmarks (an independent route); kept only where choose_map prefers it."""
    pair, sm, sn = small_pair
    meshes = dict(source_mesh=pair.source, target_mesh=pair.target)
    starts = ((10, 3.5), (20, 7.0))
    first = estimate_map(sm, sn, k=20, refine_to=40, starts=starts, derived_landmarks=0,
                         turn_check=False, **meshes)
    src = np.asarray(bsfjax.farthest_point_sampling(pair.source, 12))
    v = np.asarray(pair.source.vertices)
    near = np.argmin(np.linalg.norm(v[first.p2p][None] - v[src][:, None], axis=2), axis=1)
    # (phase 3 runs phase 1 unguided: the landmark guidance is for given landmarks)
    given = MapEstimator(k=20, refine_to=40, landmark_guidance=0.0)(sm, sn, (src, near),
                                                                   **meshes)
    maps = np.stack([first.p2p, given.p2p])
    keep = bsfjax.choose_map(bsfjax.map_distortion(pair.source, pair.target, maps),
                             bsfjax.orientation_agreement(pair.source, pair.target, maps))
    est = estimate_map(sm, sn, k=20, refine_to=40, starts=starts, derived_landmarks=12,
                       turn_check=False, **meshes)
    assert est.start == first.start
    np.testing.assert_array_equal(est.p2p, [first, given][keep].p2p)
    if keep == 1:
        np.testing.assert_array_equal(est.landmarks[0], src)
        np.testing.assert_array_equal(est.landmarks[1], near)
        np.testing.assert_array_equal(est.C_initial, given.C_initial)
    else:
        assert est.landmarks is None
    # on the example pair (one body in two poses) a right map reads off right landmarks
    gt = np.asarray(pair.p2p)
    assert np.mean(gt[near] == src) >= 0.5
    # the samples given instead of their number: the same map
    samples = (bsfjax.subsample(pair.source, 300), bsfjax.subsample(pair.target, 300))
    for kw in (dict(zoomout_samples=300), dict(zoomout_samples=samples)):
        np.testing.assert_array_equal(
            estimate_map(sm, sn, k=20, refine_to=40, starts=starts, **kw, **meshes).p2p,
            estimate_map(sm, sn, k=20, refine_to=40, starts=starts, zoomout_samples=300,
                         **meshes).p2p)
    with pytest.raises(ValueError, match="zoomout_samples must be an int, None, or"):
        other = bsfjax.subsample(bsfjax.example_pair(levels=1).target, 100)  # 506 vertices
        estimate_map(sm, sn, k=20, refine_to=40, zoomout_samples=(samples[0], other), **meshes)
    with pytest.raises(ValueError, match="derived_landmarks must be an integer >= 0"):
        estimate_map(sm, sn, k=20, refine_to=40, derived_landmarks=-1, **meshes)


def test_estimate_map_turn_check_keeps_what_choose_map_prefers(small_pair):
    """The turn check keeps the map without it, or an alternative that ``choose_map`` prefers
    to it by local distortion (at ``turn_radius`` on ``turn_samples`` samples) and orientation;
    with landmarks or one start it does not run; a non-bool is named."""
    fields = MapEstimator()
    pair, sm, sn = small_pair
    meshes = dict(source_mesh=pair.source, target_mesh=pair.target)
    starts = ((10, 3.5), (20, 7.0))
    kw = dict(k=20, refine_to=40, starts=starts, derived_landmarks=12, **meshes)
    without = estimate_map(sm, sn, turn_check=False, **kw)
    est = estimate_map(sm, sn, **kw)
    assert isinstance(est.swapped, bool) and est.start == without.start
    if not est.swapped:
        np.testing.assert_array_equal(est.p2p, without.p2p)
        assert est.distortion == without.distortion
    else:  # an alternative of lower local times global distortion, or better oriented
        both = np.stack([without.p2p, est.p2p])
        local = bsfjax.map_distortion(pair.source, pair.target, both,
                                      n_samples=fields.turn_samples, radius=fields.turn_radius)
        score = local * bsfjax.map_distortion(pair.source, pair.target, both)
        orient = bsfjax.orientation_agreement(pair.source, pair.target, both)
        assert score[1] <= score[0] or orient[1] > orient[0]
    assert isinstance(est.turn_doubtful, bool) and without.turn_doubtful is None
    one = estimate_map(sm, sn, k=20, refine_to=40, starts=((20, 7.0),), **meshes)
    assert one.swapped is None and one.turn_doubtful is None


def test_measures_disagree_closed_form():
    """The turn check is in doubt when, within the orientation slack, the map of least local
    distortion is not the map of best orientation; past the slack orientation alone decides."""
    est = MapEstimator()
    slack = est.orientation_slack
    assert not measures_disagree(est, [0.10, 0.20], [0.95, 0.90])  # both prefer map 0
    assert not measures_disagree(est, [0.20, 0.10], [0.90, 0.95])  # both prefer map 1
    assert measures_disagree(est, [0.161, 0.157], [0.905, 0.823])  # FAUST 020 -> FAUST_5k 001
    assert measures_disagree(est, [0.10, 0.20], [0.90, 0.95])
    assert not measures_disagree(est, [0.10, 0.20], [0.90, 0.90 + slack + 0.01])
    assert not measures_disagree(est, [0.10, 0.10], [0.90, 0.90])  # ties: both keep map 0
    # a wider slack: the same values are in doubt
    assert measures_disagree(MapEstimator(orientation_slack=0.2), [0.10, 0.20],
                             [0.90, 0.90 + slack + 0.01])


def test_turn_check_keeps_the_map_of_a_target_too_coarse_for_it(small_pair):
    """No two target samples closer than the radius (here: a radius below every edge): no
    local distortion to compare, so the map without the check is kept, not an error."""
    pair, sm, sn = small_pair
    fields = dict(k=20, refine_to=40, starts=((10, 3.5), (20, 7.0)))
    meshes = dict(source_mesh=pair.source, target_mesh=pair.target)
    without = MapEstimator(turn_check=False, **fields)(sm, sn, **meshes)
    est = MapEstimator(turn_radius=1e-9, **fields)(sm, sn, **meshes)
    assert est.swapped is False and est.turn_doubtful is None
    np.testing.assert_array_equal(est.p2p, without.p2p)
    with pytest.raises(ValueError, match="turn_check must be True or False"):
        estimate_map(sm, sn, turn_check="yes", **fields, **meshes)
    with pytest.raises(ValueError, match="turn_radius must be a positive"):
        MapEstimator(turn_radius=0.0)


def test_turn_check_unturns_a_faust_pair():
    """FAUST 001 → 010 (two people) without landmarks: the choice among starts lands on a map
    turned front to back (about a third of the SMPL parts right: the torso bands); the turn
    check swaps it for the right one.  The source's mirror symmetry it uses maps each SMPL
    part to its mirror part."""
    seg = data_path("segmentations", "smpl_vert_segmentation.json")
    src = bsfjax.load_mesh(data_path("faust", "tr_reg_001.off"))
    tgt = bsfjax.load_mesh(data_path("faust", "tr_reg_010.off"))
    labels, names = bsfjax.load_labels(seg)
    sm, sn = bsfjax.spectrum(src, 60), bsfjax.spectrum(tgt, 60)
    mirror = {n: n.replace("left", "RIGHT").replace("right", "left").replace("RIGHT", "right")
              for n in names}
    mirror_id = np.array([names.index(mirror[n]) for n in names])
    sym = bsfjax.mirror_symmetry(sm, src, k=30)
    mass = np.asarray(sm.mass)
    assert np.sum(mass * (labels[sym] == mirror_id[labels])) / mass.sum() > 0.95
    assert bsfjax.orientation_agreement(src, src, sym) < 0.2
    kw = dict(k=30, refine_to=60, source_mesh=src, target_mesh=tgt)
    mass_n = np.asarray(sn.mass)
    acc = lambda p: np.sum(mass_n * (labels[p] == labels)) / mass_n.sum()  # noqa: E731
    est = estimate_map(sm, sn, **kw)
    assert est.swapped and acc(est.p2p) > 0.9
    assert est.turn_doubtful is False  # both measures prefer the alternative here
    # (both from est's kept start: phases 1 and 2 are the same, and resume skips them)
    plain = MapEstimator(k=30, refine_to=60, turn_check=False)
    assert acc(plain(sm, sn, source_mesh=src, target_mesh=tgt, resume=est).p2p) < 0.4
    # the symmetry given (as transfer_collection does) or computed: one map
    np.testing.assert_array_equal(
        MapEstimator(k=30, refine_to=60)(sm, sn, source_mesh=src, target_mesh=tgt,
                                         source_symmetry=sym, resume=est).p2p, est.p2p)


def test_mirror_symmetry_tries_every_start_when_one_keeps_the_orientation():
    """FAUST tr_reg_002: the single start's self-map falls part of the way to the identity
    (it keeps the orientation on about a third of the area, and maps most SMPL parts onto
    themselves).  Then every start is tried, and the one kept maps each part to its mirror
    part."""
    seg = data_path("segmentations", "smpl_vert_segmentation.json")
    mesh = bsfjax.load_mesh(data_path("faust", "tr_reg_002.off"))
    labels, names = bsfjax.load_labels(seg)
    mirror = np.array([names.index(n.replace("left", "RIGHT").replace("right", "left")
                                   .replace("RIGHT", "right")) for n in names])
    spec = bsfjax.spectrum(mesh, 60)
    mass = np.asarray(spec.mass)
    mirrored = lambda sym: np.sum(mass * (labels[sym] == mirror[labels])) / mass.sum()  # noqa: E731
    sym = bsfjax.mirror_symmetry(spec, mesh, k=30)
    assert mirrored(sym) > 0.95 and bsfjax.orientation_agreement(mesh, mesh, sym) < 0.1
    # (rows, and the estimator's method against the function: the bent ellipsoid's test)
    one = MapEstimator(orientation_slack=1.0).mirror_symmetry(spec, mesh)  # the single start
    assert mirrored(one) < 0.5 and bsfjax.orientation_agreement(mesh, mesh, one) > 0.2


def test_mirror_symmetry_of_a_shape_with_one_mirror_plane():
    """An ellipsoid bent so that x → −x is its only symmetry (the icosphere's vertices and
    faces are symmetric under it): the self-map is that mirror, vertex for vertex, and so
    reverses orientation and keeps distances (the orientation-preserving estimate would be the
    identity); bad inputs are named."""
    from scipy.spatial import cKDTree
    v, f = icosphere(4)
    v = v * [1.0, 1.6, 2.3]
    v = np.c_[v[:, 0], v[:, 1] + 0.25 * v[:, 2] ** 2, v[:, 2] + 0.3 * v[:, 1] ** 2]
    mesh = bsfjax.Mesh(v, f)
    mirror = cKDTree(v).query(v * [-1, 1, 1])[1]
    np.testing.assert_allclose(v[mirror], v * [-1, 1, 1], atol=1e-12)
    spec = bsfjax.spectrum(mesh, 40)
    sym = bsfjax.mirror_symmetry(spec, mesh, k=20, samples=None)
    assert sym.shape == (mesh.n_vertices,) and np.mean(sym == mirror) > 0.99
    assert bsfjax.orientation_agreement(mesh, mesh, sym) < 0.05
    assert np.mean(sym == np.arange(mesh.n_vertices)) < 0.05  # only the plane's own points
    rows = np.array([7, 0, 7, 100])  # some vertices only: their images in the whole map
    np.testing.assert_array_equal(
        bsfjax.mirror_symmetry(spec, mesh, k=20, samples=None, rows=rows), sym[rows])
    # the estimator's method with its defaults is the function's (its defaults stated once)
    np.testing.assert_array_equal(MapEstimator().mirror_symmetry(spec, mesh),
                                  bsfjax.mirror_symmetry(spec, mesh))
    with pytest.raises(ValueError, match="refine_to must be an integer"):
        bsfjax.mirror_symmetry(spec, mesh, k=20, refine_to=50)
    with pytest.raises(ValueError, match="vertices but the source spectrum has"):
        bsfjax.mirror_symmetry(spec, bsfjax.Mesh(*icosphere(2)), k=20)
    with pytest.raises(ValueError, match="source_symmetry must have one source vertex"):
        pair = bsfjax.example_pair(levels=1)
        s1 = bsfjax.spectrum(pair.source, 20)
        estimate_map(s1, bsfjax.spectrum(pair.target, 20), k=10, refine_to=20,
                     source_mesh=pair.source, target_mesh=pair.target,
                     source_symmetry=np.arange(5))


def test_estimate_map_on_a_large_target_compares_its_candidates_on_part_of_it(small_pair):
    """Above ``selection_vertices`` the starts' maps are searched only at the corners of
    ``selection_faces`` random faces and at the distortion samples: with every face that is the
    whole map again (the same result as the full comparison); with a quarter of the faces the
    same start is kept and its map is then searched over every vertex, and the landmarks read
    off a candidate are target vertices that were searched."""
    pair, sm, sn = small_pair
    fields = dict(k=20, refine_to=40, starts=((10, 3.5), (20, 7.0), (30, 14.0)))
    meshes = dict(source_mesh=pair.source, target_mesh=pair.target)
    quick = dict(derived_landmarks=0, turn_check=False)
    full = MapEstimator(**fields)(sm, sn, **meshes)
    full_quick = MapEstimator(**quick, **fields)(sm, sn, **meshes)
    assert selection_rows(MapEstimator(), pair.target) == (None, None)  # a small target
    every = dict(selection_vertices=100, selection_faces=10 ** 9)  # every face, every vertex
    same = MapEstimator(**every, **fields)(sm, sn, **meshes)
    np.testing.assert_array_equal(same.p2p, full.p2p)
    assert same.start == full.start and same.orientation == pytest.approx(full.orientation)
    some = dict(selection_vertices=100, selection_faces=pair.target.n_faces // 4)
    rows, faces = selection_rows(MapEstimator(**some), pair.target)
    assert faces.size == pair.target.n_faces // 4 and rows.size < pair.target.n_vertices
    part = MapEstimator(**some, **quick, **fields)(sm, sn, **meshes)
    assert part.start == full_quick.start
    np.testing.assert_array_equal(part.p2p, full_quick.p2p)  # then searched everywhere
    est = MapEstimator(**some, **fields)(sm, sn, **meshes)
    gt, mass = np.asarray(pair.p2p), np.asarray(sn.mass)
    assert np.sum(mass * (pair.labels[est.p2p] == pair.labels[gt])) / mass.sum() > 0.95
    assert est.landmarks is not None  # (the derived estimate is kept on this pair)
    assert np.isin(est.landmarks[1], rows).all()


def test_landmarks_read_off_a_map_skip_the_vertices_not_searched(small_pair):
    """``-1`` entries (target vertices not searched) are never read as landmarks: each source
    landmark takes the searched target vertex whose image is nearest to it."""
    pair, _, _ = small_pair
    gt = np.asarray(pair.p2p).astype(np.int64)
    part = gt.copy()
    hidden = np.arange(0, gt.size, 3)
    part[hidden] = -1
    src, tgt = landmarks_from_map(pair.source, part, 8)
    assert not np.isin(tgt, hidden).any() and (tgt >= 0).all()
    v = np.asarray(pair.source.vertices)
    known = np.flatnonzero(part >= 0)
    d = np.linalg.norm(v[part[known]][None] - v[src][:, None], axis=2)
    np.testing.assert_allclose(np.linalg.norm(v[part[tgt]] - v[src], axis=1), d.min(axis=1))


def test_estimate_map_is_the_estimator_with_its_defaults(small_pair):
    """``estimate_map``'s defaults are the [`MapEstimator`] fields, and it returns what the
    estimator does; a field changed changes the map where it must (the single start's WKS
    variance, ZoomOut's step, the orientation term's weight), and bad fields are named when
    the estimator is made."""
    import inspect
    pair, sm, sn = small_pair
    lm = example_landmarks(pair)
    meshes = dict(source_mesh=pair.source, target_mesh=pair.target)
    default = MapEstimator()
    for fn, names in ((estimate_map, ("k", "refine_to", "n_energies", "zoomout_samples",
                                      "zoomout_step", "starts", "derived_landmarks",
                                      "turn_check")),
                      (bsfjax.mirror_symmetry, ("k", "refine_to", "n_energies", "zoomout_step"))):
        params = inspect.signature(fn).parameters
        for name in names:
            assert params[name].default == getattr(default, name), name
    assert inspect.signature(bsfjax.mirror_symmetry).parameters["samples"].default == \
        default.zoomout_samples
    fields = MapEstimator(k=20, refine_to=40)
    est = estimate_map(sm, sn, k=20, landmarks=(lm, lm), refine_to=40, **meshes)
    same = fields(sm, sn, (lm, lm), **meshes)
    for a, b in zip(est, same):
        if a is not None and not isinstance(a, tuple):
            np.testing.assert_array_equal(a, b)
    starts = ((10, 3.5), (20, 7.0))
    est = estimate_map(sm, sn, k=20, refine_to=40, starts=starts, **meshes)
    same = MapEstimator(k=20, refine_to=40, starts=starts)(sm, sn, **meshes)
    np.testing.assert_array_equal(est.p2p, same.p2p)
    assert (est.start, est.distortion, est.swapped) == (same.start, same.distortion, same.swapped)
    # the single start's variance: the estimate from the start (k, 3.5)
    wider = MapEstimator(k=20, refine_to=40, wks_variance=3.5)(sm, sn, (lm, lm), **meshes)
    assert not np.array_equal(wider.C_initial, est.C_initial)
    np.testing.assert_array_equal(
        wider.C, estimate_map(sm, sn, k=20, refine_to=40, landmarks=(lm, lm),
                              starts=((20, 3.5),), **meshes).C)
    step = MapEstimator(k=20, refine_to=40, zoomout_step=1)(sm, sn, (lm, lm))
    np.testing.assert_array_equal(
        step.p2p, estimate_map(sm, sn, k=20, landmarks=(lm, lm), refine_to=40,
                               zoomout_step=1).p2p)
    one = dict(k=20, refine_to=40, starts=((20, 7.0),))
    plain = MapEstimator(orient_weight=0.25, **one)(sm, sn, **meshes)
    oriented = MapEstimator(**one)(sm, sn, **meshes)
    assert not np.allclose(plain.C_initial, oriented.C_initial)
    for bad, msg in ((dict(zoomout_step=0), "zoomout_step must be an integer >= 1"),
                     (dict(orientation_slack=2.0), "orientation_slack must be in"),
                     (dict(turn_landmarks=0), "turn_landmarks must be an integer"),
                     (dict(wks_variance=-1.0), "wks_variance must be a positive"),
                     (dict(orient_weight=0.0), "orient_weight must be a positive")):
        with pytest.raises(ValueError, match=msg):
            MapEstimator(**bad)


def test_resume_goes_on_from_the_kept_start():
    """``resume``: an estimator that differs only in ``derived_guidance`` goes on from the
    first estimate's kept start (phases 1 and 2 not run again) to the map it reaches on its
    own, bit for bit; an estimate with other options, or from one start, is refused."""
    import dataclasses

    small = bsfjax.example_pair(levels=1)
    sm, sn = bsfjax.spectrum(small.source, 100), bsfjax.spectrum(small.target, 100)
    kw = dict(source_mesh=small.source, target_mesh=small.target)
    first = MapEstimator(k=10, refine_to=20, zoomout_samples=300)(sm, sn, **kw)
    guided = MapEstimator(k=10, refine_to=20, zoomout_samples=300, derived_guidance=True)
    fresh = guided(sm, sn, **kw)
    assert not np.array_equal(fresh.p2p, first.p2p)  # (the guidance changes this map)
    calls = []
    real = MapEstimator._estimate
    try:
        MapEstimator._estimate = lambda self, *a, **k: calls.append(1) or real(self, *a, **k)
        resumed = guided(sm, sn, resume=first, **kw)
        n_resumed = len(calls)
        calls.clear()
        guided(sm, sn, **kw)
    finally:
        MapEstimator._estimate = real
    # (the starts with k0 <= refine_to = 20: phase 1's estimates, not run again)
    assert n_resumed == len(calls) - sum(k0 <= 20 for k0, _ in guided.landmark_free_starts)
    np.testing.assert_array_equal(resumed.p2p, fresh.p2p)
    np.testing.assert_array_equal(resumed.C, fresh.C)
    # (the distortions: the Dijkstra runs are shared in another order, to the last bit)
    assert resumed.start == fresh.start
    assert resumed.distortion == pytest.approx(fresh.distortion, rel=1e-12)
    with pytest.raises(bsfjax.BSFError, match="other spectra, meshes, starts or options"):
        dataclasses.replace(guided, n_energies=50)(sm, sn, resume=first, **kw)
    # the same spectra with another target mesh (phase 2 compared the maps on the meshes)
    moved = bsfjax.Mesh(np.asarray(small.target.vertices) * 1.01, small.target.faces)
    with pytest.raises(bsfjax.BSFError, match="other spectra, meshes, starts or options"):
        guided(sm, sn, resume=first, source_mesh=small.source, target_mesh=moved)
    # the meshes rebuilt from the same arrays: the same key
    again = {r: bsfjax.Mesh(np.array(m.vertices), np.array(m.faces))
             for r, m in (("source_mesh", small.source), ("target_mesh", small.target))}
    np.testing.assert_array_equal(guided(sm, sn, resume=first, **again).p2p, fresh.p2p)
    one = MapEstimator(k=10, refine_to=20, starts=((10, 7.0),))(sm, sn, **kw)
    assert one.choice is None
    with pytest.raises(bsfjax.BSFError, match="resume must be a MapEstimate made from several"):
        guided(sm, sn, resume=one, **kw)


def test_turn_step_grows_the_turn_checks_maps_at_its_step_and_the_kept_one_at_zoomout_step(
        monkeypatch):
    """``turn_step``: phases 1–3 grow their maps at ``zoomout_step``, phase 4 its maps (the
    kept one, the turned ones, the source's mirror symmetry) at ``turn_step``, and the map it
    keeps is grown again at ``zoomout_step``.  With ``zoomout_step`` 6 and ``turn_step`` 2 the
    estimate keeps the start of the step-6 estimator without phase 4 and, where the check
    keeps the map, returns that estimate bit for bit (an independent route), its distortion
    that of the returned map; ZoomOut ran at both steps, where ``turn_step`` ``None`` runs
    at 6 alone; it resumes from a step-6 estimate, not from a step-2 one; a bad step is
    named."""
    import dataclasses

    from bsfjax._maps import _estimator, _turn

    small = bsfjax.example_pair(levels=1)
    sm, sn = bsfjax.spectrum(small.source, 100), bsfjax.spectrum(small.target, 100)
    kw = dict(source_mesh=small.source, target_mesh=small.target)
    six = MapEstimator(k=10, refine_to=30, zoomout_samples=300, zoomout_step=6,
                       derived_landmarks=0, turn_check=False)
    unchecked = six(sm, sn, **kw)
    steps = []
    for module in (_estimator, _turn):
        def spy(*a, _zoomout=module.zoomout, **k):
            steps.append(k["step"])
            return _zoomout(*a, **k)
        monkeypatch.setattr(module, "zoomout", spy)
    checked = dataclasses.replace(six, turn_check=True, turn_step=2)(sm, sn, **kw)
    assert set(steps) == {2, 6}
    assert checked.start == unchecked.start and checked.swapped is False
    np.testing.assert_array_equal(checked.p2p, unchecked.p2p)
    assert checked.distortion == pytest.approx(float(bsfjax.map_distortion(
        small.source, small.target, checked.p2p[None], fit_scale=True)[0]), rel=1e-6)
    steps.clear()
    dataclasses.replace(six, turn_check=True)(sm, sn, **kw)
    assert set(steps) == {6}
    then = dataclasses.replace(six, derived_landmarks=20, turn_check=True, turn_step=2)
    resumed = then(sm, sn, resume=unchecked, **kw)
    np.testing.assert_array_equal(resumed.p2p, then(sm, sn, **kw).p2p)
    assert resumed.start == unchecked.start
    with pytest.raises(bsfjax.BSFError, match="other spectra, meshes, starts or options"):
        then(sm, sn, resume=dataclasses.replace(six, zoomout_step=2)(sm, sn, **kw), **kw)
    with pytest.raises(ValueError, match="turn_step must be an integer >= 1"):
        MapEstimator(turn_step=0)


def test_choose_derived_closed_form():
    """Phase 3's choice: by ``choose_map`` (distortion within the orientation slack), or with
    ``trust`` the first derived estimate within the slack of the best orientation, or the
    preferred one (``prefer``) within ``GUIDED_SLACK`` of the least distortion."""
    from bsfjax._maps._estimate import choose_derived

    est = MapEstimator()
    slack = est.orientation_slack
    found = [("pairs a", "run a"), ("pairs b", "run b")]
    q = dict(distortion=0.03, orientation=0.90)
    # the kept run is the least distorted: kept without trust, the first derived one with it
    dist, orient = [0.03, 0.05, 0.04], [0.90, 0.88, 0.91]
    assert choose_derived(est, "run", q, found, dist, orient, False) == ("run", q, False)
    run, quality, trusted = choose_derived(est, "run", q, found, dist, orient, True)
    assert (run, trusted, quality["landmarks"]) == ("run a", True, "pairs a")
    assert quality["distortion"] == 0.05 and quality["orientation"] == 0.88
    # past the slack a derived estimate is not kept; the next one within it is
    orient = [0.90, 0.90 - slack - 0.05, 0.89]
    assert choose_derived(est, "run", q, found, dist, orient, True)[0] == "run b"
    orient = [0.90, 0.90 - slack - 0.05, 0.90 - slack - 0.01]
    assert choose_derived(est, "run", q, found, dist, orient, True) == ("run", q, False)
    # where choose_map already prefers a derived estimate, trust changes nothing
    dist, orient = [0.05, 0.03, 0.04], [0.90, 0.91, 0.90]
    assert choose_derived(est, "run", q, found, dist, orient, True)[1:] == \
        choose_derived(est, "run", q, found, dist, orient, False)[1:]
    assert choose_derived(est, "run", q, found, dist, orient, True)[0] == "run a"
    # ``prefer`` (with given landmarks, the guided estimate): kept within GUIDED_SLACK of the
    # least distortion and the orientation slack, else the choice as without it
    from bsfjax._maps._estimate import GUIDED_SLACK

    orient = [0.90, 0.90, 0.90]
    for d2, want in ((0.03 * (1 + GUIDED_SLACK) * 0.999, "run b"),
                     (0.03 * (1 + GUIDED_SLACK) * 1.001, "run")):
        dist = [0.03, 0.05, d2]
        assert choose_derived(est, "run", q, found, dist, orient, False, prefer=2)[0] == want
    dist = [0.03, 0.05, 0.03]
    assert choose_derived(est, "run", q, found, dist, [0.90, 0.90, 0.90 - slack - 0.01],
                          False, prefer=2)[0] == "run"
    # (over a derived estimate of less distortion too, and reported as kept)
    run, quality, _ = choose_derived(est, "run", q, found, [0.04, 0.03, 0.031], orient, False,
                                     prefer=2)
    assert (run, quality["landmarks"], quality["distortion"]) == ("run b", "pairs b", 0.031)
    with pytest.raises(ValueError, match="keep_derived must be True or False"):
        MapEstimator(keep_derived=1)


def test_keep_derived_keeps_the_derived_estimate_unless_the_turn_check_doubts_it(
        small_pair, monkeypatch):
    """``keep_derived``: phase 3 keeps the estimate made with the landmark pairs read off the
    kept start's map (`estimate_map` with them as given, unguided: an independent route)
    whenever its orientation agreement is within the slack, whatever the distortions; where
    that changed the pick and the turn check is then doubtful, phases 3 and 4 run again by the
    distortion: the result of ``keep_derived=False``."""
    from bsfjax._maps import _turn

    pair, sm, sn = small_pair
    meshes = dict(source_mesh=pair.source, target_mesh=pair.target)
    kw = dict(k=20, refine_to=40, starts=((10, 14.0), (16, 7.0)), derived_landmarks=12)
    first = MapEstimator(**kw, turn_check=False)(sm, sn, **meshes)
    assert first.landmarks is None  # (the distortion keeps the start's map here)
    start = MapEstimator(**dict(kw, derived_landmarks=0), turn_check=False)(sm, sn, **meshes)
    src, near = landmarks_from_map(pair.source, start.p2p, 12)
    given = MapEstimator(k=20, refine_to=40, landmark_guidance=0.0)(sm, sn, (src, near),
                                                                   **meshes)
    orient = bsfjax.orientation_agreement(pair.source, pair.target,
                                          np.stack([start.p2p, given.p2p]))
    assert orient[1] >= orient.max() - MapEstimator().orientation_slack
    kept = MapEstimator(**kw, turn_check=False, keep_derived=True)(sm, sn, **meshes)
    np.testing.assert_array_equal(kept.p2p, given.p2p)
    assert not np.array_equal(kept.p2p, first.p2p)
    np.testing.assert_array_equal(kept.landmarks[0], src)
    assert kept.distortion == pytest.approx(float(bsfjax.map_distortion(
        pair.source, pair.target, given.p2p[None], fit_scale=True)[0]), rel=1e-6)
    # the turn check doubtful (its choice made to keep the map it is given, in doubt): the
    # distortion's pick, as without the option; not doubtful: the derived estimate stays
    for doubt in (True, False):
        monkeypatch.setattr(_turn, "turn_choice",  # (phase 4: _turn.check_turn)
                            lambda est, pb, runs, joint, turn: (0, doubt, np.ones(len(runs))))
        est = {c: MapEstimator(**kw, keep_derived=c)(sm, sn, **meshes) for c in (False, True)}
        assert est[True].turn_doubtful is doubt and est[True].swapped is False
        np.testing.assert_array_equal(est[True].p2p, (est[False] if doubt else kept).p2p)
        assert (est[True].landmarks is None) is doubt


def test_added_landmarks_estimate_again_with_pairs_read_off_the_first_map(small_pair):
    """``added_landmarks``: with given landmarks and the meshes, the estimate made again with
    the given pairs and that many read off the first map (`landmarks_from_map` on the
    estimator's own first map: an independent route), reported in ``landmarks``; without the
    meshes, or 0, the first map."""
    pair, sm, sn = small_pair
    meshes = dict(source_mesh=pair.source, target_mesh=pair.target)
    lm = example_landmarks(pair)
    first = MapEstimator(k=20, refine_to=40)(sm, sn, (lm, lm), **meshes)
    src, near = landmarks_from_map(pair.source, first.p2p, 8)
    both = (np.concatenate([lm, src]), np.concatenate([lm, near]))
    again = MapEstimator(k=20, refine_to=40)(sm, sn, both, **meshes)
    est = MapEstimator(k=20, refine_to=40, added_landmarks=8)(sm, sn, (lm, lm), **meshes)
    np.testing.assert_array_equal(est.p2p, again.p2p)
    np.testing.assert_array_equal(est.C_initial, again.C_initial)
    np.testing.assert_array_equal(est.landmarks[0], src)
    np.testing.assert_array_equal(est.landmarks[1], near)
    assert first.landmarks is None and not np.array_equal(first.C_initial, again.C_initial)
    bare = MapEstimator(k=20, refine_to=40, added_landmarks=8)(sm, sn, (lm, lm))
    plain = MapEstimator(k=20, refine_to=40)(sm, sn, (lm, lm))
    np.testing.assert_array_equal(bare.p2p, plain.p2p)
    assert bare.landmarks is None
    with pytest.raises(ValueError, match="added_landmarks must be an integer >= 0"):
        MapEstimator(added_landmarks=-1)
