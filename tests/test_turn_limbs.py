"""The turn check's alternatives with one pair of limbs mirrored (``MapEstimator``'s
``turn_candidates="limbs"``): their landmark sets, and a partly mirrored map put right."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import bsfjax
from bsfjax import MapEstimator
from bsfjax._maps._estimate import Problem, Run
from bsfjax._maps._turn import check_turn, measures_disagree, turn_landmark_sets
from bsfjax._spectral import unit_area_pair


def _mirror(levels: int) -> np.ndarray:
    """The built-in body's exact mirror symmetry: vertex ``i`` → the vertex at ``i``'s rest
    position reflected in the plane ``x = 0`` (every pose shares the rest pose's vertices)."""
    rest = np.asarray(bsfjax.example_mesh("rest", levels=levels).vertices, np.float64)
    d, s = cKDTree(rest).query(rest * [-1.0, 1.0, 1.0])
    assert d.max() < 1e-6 * np.ptp(rest)  # the body is symmetric
    return s.astype(np.int64)


def test_turn_landmark_sets_closed_form(small_pair):
    """The whole turn first; then each limb landmark mirrored with the landmarks near its
    mirror image (the two hands together), the head (its own mirror image) never alone, and
    no set twice or equal to the whole turn; the same sets on an isometric pose with the
    hands together (the distances are geodesic)."""
    pair, _, _ = small_pair
    S = _mirror(2)
    src = pair.source
    lab = np.asarray(pair.labels)
    names = list(pair.label_names)
    v = np.asarray(src.vertices)
    tip = {}  # each part's vertex farthest from the centroid: the head's, hands', feet's tips
    for n in names[1:]:
        part = np.flatnonzero(lab == names.index(n))
        tip[n] = int(part[np.argmax(np.linalg.norm(v[part] - v.mean(0), axis=1))])
    x = np.array([tip[n] for n in names[1:]])  # head, left/right hand, left/right foot
    y = np.arange(10, 15)  # (the targets are only carried along)
    radius = MapEstimator().turn_radius
    sets = turn_landmark_sets(src, x, S[x], y, radius)
    assert len(sets) == 3
    np.testing.assert_array_equal(sets[0][0], S[x])  # the whole turn
    np.testing.assert_array_equal(sets[1][0], [x[0], S[x[1]], S[x[2]], x[3], x[4]])  # hands
    np.testing.assert_array_equal(sets[2][0], [x[0], x[1], x[2], S[x[3]], S[x[4]]])  # feet
    # without the right foot the left one is mirrored alone
    four = turn_landmark_sets(src, x[:4], S[x[:4]], y[:4], radius)
    assert len(four) == 3 and four[2][0].tolist() == [x[0], x[1], x[2], S[x[3]]]
    # the head and the hands alone: mirroring both hands is the whole turn (bar the head)
    assert len(turn_landmark_sets(src, x[:3], S[x[:3]], y[:3], radius)) == 1
    for lms, t in sets + four:
        np.testing.assert_array_equal(t, y[:len(t)])
    # the arms folded, the hands meeting at the mirror plane: nearly an isometry, so the
    # same sets (the Euclidean test took the hands for their own mirror images and lost them)
    folded = v.astype(np.float64).copy()
    a = 0.5 * np.abs(v[x[1:3], 0]).min()
    far = np.abs(folded[:, 0]) > a
    folded[far, 0] = np.sign(folded[far, 0]) * (2 * a - np.abs(folded[far, 0]))
    assert np.linalg.norm(folded[x[1]] - folded[x[2]]) < radius * np.sqrt(src.area)
    bent = bsfjax.Mesh(folded, np.asarray(src.faces))
    np.testing.assert_allclose(bent.area, src.area, rtol=0.01)  # (bar the fold's triangles)
    for got, want in zip(turn_landmark_sets(bent, x, S[x], y, radius), sets, strict=True):
        np.testing.assert_array_equal(got[0], want[0])
    # in space alone (apart=None, as on clouds) the folded hands are taken for their own
    # mirror images, and the feet, the only limbs left, mirrored are the whole turn: no set
    assert len(turn_landmark_sets(bent, x, S[x], y, radius, apart=None)) == 1
    assert len(turn_landmark_sets(src, x, S[x], y, radius, apart=None)) == 3  # (unfolded)


def test_measures_disagree_with_limb_alternatives():
    """With several alternatives the doubt compares the kept map with its other side: a limb
    alternative or the map checked with the whole turn (``1``), the whole turn with the map
    checked (``0``)."""
    est = MapEstimator()
    # a limb alternative (2) kept, the whole turn (1) better oriented within the slack, of a
    # higher score: the measures disagree; the map checked (0), better oriented still, is
    # not its other side
    assert measures_disagree(est, [0.010, 0.020, 0.005], [0.97, 0.95, 0.94], pick=2)
    assert not measures_disagree(est, [0.010, 0.020, 0.005], [0.97, 0.93, 0.94], pick=2)
    assert not measures_disagree(est, [0.010, 0.004, 0.005], [0.90, 0.95, 0.99], pick=1)
    assert measures_disagree(est, [0.010, 0.004, 0.005], [0.96, 0.95, 0.99], pick=1)
    # two maps of the whole turn (its estimate and the derived one): a limb alternative is
    # compared with the one of least score
    score, orient = [0.010, 0.030, 0.020, 0.005], [0.97, 0.99, 0.93, 0.94]
    assert not measures_disagree(est, score, orient, pick=3, turn=(1, 2))
    assert measures_disagree(est, score, orient, pick=3, turn=(1,))


def _turn_check(est, pair, sm, sn, p2p, symmetry):
    """Phase 4 of ``est`` on the point map ``p2p`` (as if the earlier phases had kept it)."""
    source, _, target, _ = unit_area_pair(sm, sn)
    pb = Problem(source, target, pair.source, pair.target, sm.k, None, None, None, est.k)
    return check_turn(est, pb, Run(None, p2p, None), {}, source, symmetry)


@pytest.mark.parametrize("limb", ["leg", "arm"])
def test_turn_check_puts_a_swapped_pair_of_limbs_back(small_pair, limb):
    """The built-in pair's exact map but with the two legs (arms) swapped, each target leg on
    the source's other leg: a partly mirrored map, which the choice among starts keeps on
    noisy FAUST targets (the two shins swapped on 000→010 with σ = 0.25 % of the height).
    The alternative with that pair of limbs mirrored puts them back (every part but a few
    vertices right); the earlier check (``turn_candidates="mirror"``: the whole turn alone,
    by local distortion) cannot, since the whole turn mirrors the other limbs as well."""
    pair, sm, sn = small_pair
    S = _mirror(2)
    lab = np.asarray(pair.labels)
    names = list(pair.label_names)
    mass = np.asarray(sn.mass)
    swapped = np.isin(lab, [names.index(f"left_{limb}"), names.index(f"right_{limb}")])
    p2p = np.arange(len(lab))
    p2p[swapped] = S[swapped]
    acc = lambda p: np.sum(mass * (lab[p] == lab)) / mass.sum()  # noqa: E731
    assert acc(p2p) < 0.85
    kw = dict(k=20, refine_to=40, zoomout_samples=None)
    run, quality = _turn_check(MapEstimator(**kw), pair, sm, sn, p2p, S)
    assert quality["swapped"] and acc(run.p2p) > 0.97
    # the landmarks it came from: the mirrored ones, or those derived from their map
    assert len(quality["landmarks"][0]) in (MapEstimator().turn_landmarks,
                                            MapEstimator().derived_landmarks)
    old, old_q = _turn_check(MapEstimator(turn_candidates="mirror", **kw), pair, sm, sn, p2p, S)
    assert acc(old.p2p) < 0.9
    with pytest.raises(ValueError, match="turn_candidates must be 'limbs' or 'mirror'"):
        MapEstimator(turn_candidates="all")
