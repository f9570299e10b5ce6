"""The mesh-level entry points: estimate_map, transfer_values, transfer_labels."""

from __future__ import annotations

import numpy as np
import pytest

import bsfjax
from bsfjax import estimate_map, transfer_labels, transfer_values
from bsfjax._demo import example_landmarks


@pytest.fixture(scope="module")
def small_pair():
    pair = bsfjax.example_pair(levels=2)
    return pair, bsfjax.spectrum(pair.source, 40), bsfjax.spectrum(pair.target, 40)


def test_estimate_map_and_label_transfer(small_pair):
    pair, sm, sn = small_pair
    lm = example_landmarks(pair)
    est = estimate_map(sm, sn, k=20, landmarks=(lm, lm), refine_to=40)
    assert est.C.shape == (20, 20)
    gt = np.asarray(pair.p2p)
    err = bsfjax.geodesic_error(pair.source, est.p2p, gt)
    assert err < 0.03
    res = transfer_labels(sm, sn, pair.labels, C=est.C, method="omp", mesh=pair.source)
    target_truth = pair.labels[gt]
    assert np.mean(res.labels == target_truth) > 0.85
    assert 0 <= res.unassigned_share < 0.15
    assert res.scores.shape == (6, pair.target.n_vertices)
    # the pull-back through the exact point map is exact
    exact = transfer_labels(sm, sn, pair.labels, p2p=gt, method="p2p")
    np.testing.assert_array_equal(exact.labels, target_truth)
    assert exact.unassigned_share == 0


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


def test_transfer_values_errors(small_pair):
    pair, sm, sn = small_pair
    C = np.eye(20)
    with pytest.raises(ValueError, match="method must be one of"):
        transfer_values(sm, sn, np.zeros(sm.n_vertices), C=C, method="magic")
    with pytest.raises(ValueError, match="values must have shape"):
        transfer_values(sm, sn, np.zeros(5), C=C)
    with pytest.raises(ValueError, match="needs a point map"):
        transfer_values(sm, sn, np.zeros(sm.n_vertices), method="p2p")
    with pytest.raises(ValueError, match="labels must have one entry"):
        transfer_labels(sm, sn, np.zeros(3, int), C=C)
    with pytest.raises(ValueError, match="landmarks must be two lists of equal length"):
        estimate_map(sm, sn, k=10, landmarks=([1, 2], [3]))
    with pytest.raises(ValueError, match="landmarks must be vertex indices"):
        estimate_map(sm, sn, k=10, landmarks=([1, 10**6], [3, 4]))


def test_estimate_map_without_landmarks_uses_the_orientation_term(small_pair):
    """No landmarks: with the meshes the orientation term tells left from right (the example
    body's arms and legs are separate parts), and it changes the estimate."""
    pair, sm, sn = small_pair
    gt = np.asarray(pair.p2p)
    mass = np.asarray(sn.mass)
    plain = estimate_map(sm, sn, k=20, refine_to=40)
    oriented = estimate_map(sm, sn, k=20, refine_to=40, source_mesh=pair.source,
                            target_mesh=pair.target)
    assert not np.allclose(plain.C_initial, oriented.C_initial)
    acc = np.sum(mass * (pair.labels[oriented.p2p] == pair.labels[gt])) / mass.sum()
    assert acc > 0.95
    with_lm = estimate_map(sm, sn, k=20, refine_to=40, landmarks=([0], [0]),
                           source_mesh=pair.source, target_mesh=pair.target)
    ref = estimate_map(sm, sn, k=20, refine_to=40, landmarks=([0], [0]))
    np.testing.assert_array_equal(with_lm.C, ref.C)  # with landmarks the meshes are unused


def test_transfer_labels_refined_default_reports_its_regime(small_pair):
    pair, sm, sn = small_pair
    gt = np.asarray(pair.p2p)
    res = transfer_labels(sm, sn, pair.labels, p2p=gt)  # default method: "refined"
    assert res.regime in bsfjax._highlevel.REGIMES and res.unassigned_share == 0.0
    assert 0.9 < res.confidence <= 1.0 + 1e-6
    mass = np.asarray(sn.mass)
    assert res.agreement == pytest.approx(np.sum(mass * (res.labels == pair.labels)) / mass.sum())
    assert res.agreement > 0.95
    assert transfer_labels(sm, sn, pair.labels, p2p=gt, method="p2p").regime is None
