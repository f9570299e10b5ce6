"""The mesh-level entry points after the map: transfer_values, transfer_labels (with a map from
estimate_map)."""

from __future__ import annotations

import numpy as np
import pytest

import bsfjax
from bsfjax import estimate_map, transfer_labels, transfer_values
from bsfjax.internal import example_landmarks


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


def test_transfer_labels_refined_default_reports_its_regime(small_pair):
    pair, sm, sn = small_pair
    gt = np.asarray(pair.p2p)
    res = transfer_labels(sm, sn, pair.labels, p2p=gt)  # default method: "refined"
    assert res.regime in bsfjax._pipeline._mesh_level.REGIMES and res.unassigned_share == 0.0
    assert 0.9 < res.confidence <= 1.0 + 1e-6
    mass = np.asarray(sn.mass)
    assert res.agreement == pytest.approx(np.sum(mass * (res.labels == pair.labels)) / mass.sum())
    assert res.agreement > 0.95
    assert transfer_labels(sm, sn, pair.labels, p2p=gt, method="p2p").regime is None
