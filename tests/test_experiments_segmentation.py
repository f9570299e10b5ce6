"""``reproduce segmentation`` (``bsfjax/experiments/segmentation.py``): labels, metrics, run."""

import numpy as np
import pytest

import bsfjax as bj
from bsfjax.experiments import reproduce
from bsfjax.experiments._datasets import load_dataset
from bsfjax.experiments.segmentation import (K_SPECTRA, label_metrics,
                                             report, segmentation_experiment,
                                             segmentation_pair, shape_labels,
                                             template_vertices)

from .conftest import DATA, data_path


def test_label_metrics_closed_form():
    ex = bj.example_pair(levels=1)
    m = ex.target
    mass = np.asarray(bj.spectrum(m, 3).mass)
    truth = ex.labels
    perfect = label_metrics(truth, truth, mass, m)
    assert perfect["accuracy"] == pytest.approx(100) and perfect["iou_worst"] == pytest.approx(1)
    assert perfect["unassigned"] == 0 and perfect["border_accuracy"] == pytest.approx(100)
    pred = truth.copy()
    part = truth == truth.max()
    pred[part] = -1  # one part unassigned
    r = label_metrics(pred, truth, mass, m)
    share = mass[part].sum() / mass.sum()
    assert r["accuracy"] == pytest.approx(100 * (1 - share))
    assert r["unassigned"] == pytest.approx(100 * share)
    assert r["iou_worst"] == 0.0
    n_parts = len(np.unique(truth))
    assert r["iou_mean"] == pytest.approx((n_parts - 1) / n_parts)


def _example_folder(tmp_path):
    ex = bj.example_pair(levels=2)
    folder = tmp_path / "data"
    folder.mkdir()
    bj.save_mesh(folder / "tr_reg_000.off", ex.source)
    bj.save_mesh(folder / "tr_reg_001.off", ex.target)
    seg = tmp_path / "parts.txt"
    np.savetxt(seg, ex.labels, fmt="%d")
    return folder, seg


def test_run_on_the_example_pair(tmp_path):
    folder, seg = _example_folder(tmp_path)
    ds = load_dataset(folder)
    rows = segmentation_experiment(ds, segmentation=seg, pairs=1, k=20,
                                   methods=("p2p", "refined", "std"), progress=False,
                                   cache_dir=tmp_path / "cache")
    assert len(rows) == 3 * 3
    by = {(r["map"], r["method"]): r for r in rows}
    assert by[("truth", "p2p")]["accuracy"] == pytest.approx(100)
    assert by[("crude", "refined")]["accuracy"] >= by[("crude", "p2p")]["accuracy"] - 1
    assert all(r["unassigned"] == 0 for r in rows if r["method"] != "std")
    assert {r["regime"] for r in rows if r["method"] == "refined"} <= set(bj.REGIMES)
    rep = report(rows, (20,))
    assert "| default | refined |" in rep.markdown
    png = rep.figure(tmp_path / "seg.png")
    assert png.stat().st_size > 1000


def test_one_pair_is_a_row_of_the_experiment(tmp_path):
    """``segmentation_pair`` (what the benchmark's decimated targets run) gives the rows the
    experiment gives for the same pair, and names a method or map it does not know."""
    folder, seg = _example_folder(tmp_path)
    ds = load_dataset(folder)
    i, j = ds.pairs(1, 0)[0]
    kw = dict(methods=("p2p", "refined"), maps=("default", "truth"))
    rows = segmentation_experiment(ds, segmentation=seg, pair_list=[(i, j)], k=20,
                                   progress=False, keep_labels=0, **kw)
    template, _ = bj.load_labels(seg)
    src, tgt = ds.shapes[i], ds.shapes[j]
    sm, sn = (bj.spectrum(e.mesh, min(K_SPECTRA, e.n_vertices - 1)) for e in (src, tgt))
    alone = segmentation_pair(sm, sn, (src.mesh, tgt.mesh), shape_labels(ds, i, template),
                              shape_labels(ds, j, template), ds.ground_truth(i, j), k=20,
                              names=(src.name, tgt.name), **kw)
    drop = lambda r: {k: v for k, v in r.items() if k != "seconds"}  # noqa: E731
    assert [drop(r) for r in alone] == [drop(r) for r in rows]
    assert [(r["map"], r["method"]) for r in alone] == [
        ("default", "p2p"), ("default", "refined"), ("truth", "p2p"), ("truth", "refined")]
    assert alone[2]["accuracy"] == pytest.approx(100)
    with pytest.raises(bj.BSFError, match="methods must be among"):
        segmentation_pair(sm, sn, (src.mesh, tgt.mesh), template, template, ds.ground_truth(i, j),
                          methods=("p2p", "bogus"))
    with pytest.raises(bj.BSFError, match="maps must be among"):
        segmentation_pair(sm, sn, (src.mesh, tgt.mesh), template, template, ds.ground_truth(i, j),
                          maps=("exact",))


def test_reproduce_needs_the_segmentation(tmp_path):
    folder, _ = _example_folder(tmp_path)
    with pytest.raises(bj.BSFError, match="--segmentation"):
        reproduce("segmentation", folder, tmp_path / "out", pairs=1, progress=False)
    with pytest.raises(bj.BSFError, match="takes no segmentation"):
        reproduce("table3", folder, tmp_path / "out", pairs=1, progress=False,
                  segmentation="x.json")


@pytest.mark.skipif(not (DATA / "faust_5k").exists(), reason="../shared/data/faust_5k absent")
def test_remeshed_labels_follow_the_template():
    """FAUST_5k: a vertex named by the ``.vts`` list has its template vertex's label."""
    ds = load_dataset(data_path("faust_5k"))
    seg = data_path("segmentations", "smpl_vert_segmentation.json")
    template, _ = bj.load_labels(seg)
    lab = shape_labels(ds, 0, template)
    e = ds.shapes[0]
    sid = np.loadtxt(data_path("faust_5k", "corres", "sampleID.vts"), dtype=int) - 1
    first = np.unique(e.vts, return_index=True)[1]
    np.testing.assert_array_equal(lab[e.vts[first]], template[sid[first]])
    assert lab.shape == (e.n_vertices,) and lab.min() >= 0


@pytest.mark.skipif(not (DATA / "faust_5k").exists(), reason="../shared/data/faust_5k absent")
def test_template_vertices_of_a_remeshed_shape_lie_on_it():
    """FAUST_5k 000 is a remesh of the registration ``tr_reg_000``: after a similarity fit,
    each 5K vertex lies near its template vertex on that registration, the vertices no
    ``.vts`` entry names (filled from their nearest named vertex) too; on a shape of the
    template's size the map is the identity."""
    ds = load_dataset(data_path("faust_5k"))
    e = ds.shapes[0]
    t = template_vertices(ds, 0, 6890)
    sid = np.loadtxt(data_path("faust_5k", "corres", "sampleID.vts"), dtype=int) - 1
    first = np.unique(e.vts, return_index=True)[1]
    np.testing.assert_array_equal(t[e.vts[first]], sid[first])
    X, Y = e.mesh.vertices, bj.load_mesh(data_path("faust", "tr_reg_000.off")).vertices[t]
    mx, my = X.mean(0), Y.mean(0)
    U, S, Vt = np.linalg.svd((X - mx).T @ (Y - my))
    fitted = S.sum() / ((X - mx) ** 2).sum() * (X - mx) @ (U @ Vt) + my
    dist = np.linalg.norm(fitted - Y, axis=1)  # metres; the body is 1.77 m tall
    unnamed = np.setdiff1d(np.arange(e.n_vertices), e.vts)
    assert unnamed.size > 1000 and dist.mean() < 0.015 and dist[unnamed].mean() < 0.02
    reg = load_dataset(data_path("faust"))
    np.testing.assert_array_equal(template_vertices(reg, 0, 6890), np.arange(6890))


def test_fewer_landmarks_are_the_first_of_the_default_ones(tmp_path, monkeypatch):
    """``1 landmark`` / ``2 landmarks`` estimate with the first one / two of the default map's
    landmark pairs (FPS on the source, ground-truth images) and nothing else changed: with all
    of them the call is the default map's."""
    import bsfjax.experiments.segmentation as seg_mod
    folder, seg = _example_folder(tmp_path)
    ds = load_dataset(folder)
    i, j = ds.pairs(1, 0)[0]
    calls = []
    real = seg_mod.estimate_map

    def spy(*args, **kw):
        calls.append(kw.get("landmarks"))
        return real(*args, **kw)

    monkeypatch.setattr(seg_mod, "estimate_map", spy)
    rows = segmentation_experiment(ds, segmentation=seg, pair_list=[(i, j)], k=20,
                                   methods=("p2p",), progress=False, keep_labels=0,
                                   maps=("default", "1 landmark", "2 landmarks"))
    full, one, two = calls
    assert len(full[0]) == len(full[1]) == seg_mod.N_LANDMARKS
    for got, n in ((one, 1), (two, 2)):
        np.testing.assert_array_equal(got[0], full[0][:n])
        np.testing.assert_array_equal(got[1], full[1][:n])
    assert [r["map"] for r in rows] == ["default", "1 landmark", "2 landmarks"]
