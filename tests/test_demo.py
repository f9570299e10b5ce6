"""The main job (``bsfjax demo``) and the high-level transfer entry points."""

from __future__ import annotations

import json

import numpy as np
import pytest

import bsfjax
from bsfjax._demo import example_landmarks, format_table, run_demo
from bsfjax import estimate_map, transfer_labels, transfer_values


@pytest.fixture(scope="module")
def small_pair():
    pair = bsfjax.example_pair(levels=2)
    return pair, bsfjax.spectrum(pair.source, 40), bsfjax.spectrum(pair.target, 40)


def test_demo_writes_results_and_figures(tmp_path):
    res = run_demo(tmp_path, levels=2, k=20, k_refine=30, n_functions=8, progress=False)
    data = json.loads((tmp_path / "results.json").read_text())
    assert data["example"]["n_vertices"] == 2018
    rows = {(r["map"], r["method"]): r for r in data["errors"]}
    assert set(rows) == {(m, s) for m in ("ground truth", "estimated") for s in ("std", "omp")}
    for r in rows.values():
        assert 0 < r["approximation_error"] < 1 and 0 < r["transfer_error"] < 1
        assert r["segmentation_accuracy"] > 0.8  # six large parts on a near-isometric pair
    # the refined estimated map is close to the identity ground truth
    assert data["map_geodesic_error"]["refined"] < data["map_geodesic_error"]["estimated"]
    assert data["map_geodesic_error"]["refined"] < 0.05
    table = format_table(res)
    assert "E_app" in table and "omp" in table
    from PIL import Image  # matplotlib depends on pillow

    pngs = sorted(tmp_path.glob("*.png"))
    assert {p.name for p in pngs} == set(data["figures"]) and len(pngs) >= 8
    for p in pngs:
        img = np.asarray(Image.open(p).convert("RGB"), dtype=float)
        assert img.shape[0] >= 200 and img.shape[1] >= 300
        assert img.std() > 10  # not blank
        assert len(np.unique(img.reshape(-1, 3) // 16, axis=0)) > 8  # shaded: many colours


def test_landmarks_are_part_extremities(small_pair):
    pair, _, _ = small_pair
    lm = example_landmarks(pair)
    assert lm.shape == (6,)
    np.testing.assert_array_equal(pair.labels[lm], np.arange(6))  # one per part


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
