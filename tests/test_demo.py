"""The main job (``bsfjax demo``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import bsfjax
from bsfjax.internal import example_landmarks, format_table, run_demo


@pytest.fixture(scope="module")
def small_pair():
    pair = bsfjax.example_pair(levels=2)
    return pair, bsfjax.spectrum(pair.source, 40), bsfjax.spectrum(pair.target, 40)


def test_demo_writes_results_and_figures(tmp_path):
    res = run_demo(tmp_path, levels=2, k=20, k_refine=30, n_functions=8, progress=False)
    data = json.loads((tmp_path / "results.json").read_text())
    assert data["example"]["n_vertices"] == 2018
    rows = {(r["map"], r["method"]): r for r in data["errors"]}
    assert set(rows) == {(m, s) for m in ("ground truth", "estimated")
                         for s in ("p2p", "refined", "std", "omp")}
    for (m, s), r in rows.items():
        if s == "refined":  # a pull-back too: no approximation
            assert r["approximation_error"] is None
        elif s == "p2p":  # the pull-back has no approximation; exact with the exact point map
            assert r["approximation_error"] is None
            assert (r["transfer_error"] == 0) == (m == "ground truth")
        else:
            assert 0 < r["approximation_error"] < 1
        assert 0 <= r["transfer_error"] < 1
        assert r["segmentation_accuracy"] > 0.8  # six large parts on a near-isometric pair
    assert rows[("ground truth", "p2p")]["segmentation_accuracy"] == 1.0
    # the default method: at least the pull-back through the estimated map, nothing unassigned
    est = rows[("estimated", "refined")]
    assert est["segmentation_accuracy"] >= rows[("estimated", "p2p")]["segmentation_accuracy"]
    assert est["unassigned_share"] == 0.0
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
