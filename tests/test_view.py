"""The polyscope viewer (bsfjax.view, bsfjax.plot.view / render, bsfjax view, transfer --render)
under polyscope's mock backend (no GPU, no display), and one real EGL render where EGL works.

polyscope is one scene per process: this file's process runs the mock backend; the EGL test
runs in a subprocess."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import bsfjax
from bsfjax.cli import main

from .conftest import icosphere

ps = pytest.importorskip("polyscope")
from bsfjax import plot  # noqa: E402
from bsfjax._plot import label_colour  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GREY = label_colour(np.array([-1]))[0]
RED = np.array([0.86, 0.08, 0.08])


def _colours(name, cloud=False):
    s = ps.get_point_cloud(name) if cloud else ps.get_surface_mesh(name)
    buf = s.get_quantity_buffer("parts", "colors")
    return np.array([buf.get_value(i).as_tuple() for i in range(buf.size())])


def _majority(lab, faces):  # independent: a face's label is the one two or three corners share
    a, b, c = lab[faces].T
    return np.where(b == c, b, a)


@pytest.fixture(scope="module")
def scene():
    v, f = icosphere(2)
    src = bsfjax.Mesh(v, f)
    tgt = bsfjax.Mesh(v * [1.0, 1.3, 0.9], f)
    labels = (np.arctan2(v[:, 1], v[:, 0]) > 0).astype(int) + 2 * (v[:, 2] > 0.3)  # 4 parts
    result = labels.copy()
    result[v[:, 0] > 0.7] = 0  # wrong where x > 0.7 (part 0 there is wrong or right)
    result[v[:, 2] < -0.8] = -1  # unassigned cap
    return src, tgt, labels, result


def test_view_registers_the_shapes_with_part_colours_under_the_mock_backend(scene):
    src, tgt, labels, result = scene
    got = plot.view(src, tgt, labels=labels, results=result, truth=labels, backend="mock")
    assert got.structures == ("source", "target", "target errors")
    assert all(ps.has_surface_mesh(n) for n in got.structures)
    f = src.faces
    want = label_colour(_majority(labels, f))
    assert np.allclose(_colours("source"), want, atol=1e-6)
    face_res = _majority(result, f)
    tc = _colours("target")
    assert np.allclose(tc[face_res == -1], GREY, atol=1e-6)  # unassigned: grey
    assert np.allclose(tc[face_res >= 0], label_colour(face_res[face_res >= 0]), atol=1e-6)
    # the errors panel: red exactly where a face's majority is a wrong label
    state = _majority(np.where(result < 0, 2, (result != labels).astype(int)), f)
    ec = _colours("target errors")
    assert state.min() == 0 and (state == 1).any() and (state == 2).any()
    assert np.allclose(ec[state == 1], RED, atol=1e-6)
    assert np.allclose(ec[state == 2], GREY, atol=1e-6)
    assert not np.isclose(ec[state == 0], RED, atol=0.1).all(axis=1).any()
    # categorical: every face has one of the palette's colours, none blended
    assert len({tuple(np.round(c, 5)) for c in tc}) <= len(np.unique(result))
    # the side panel's scores against numpy (barycentric vertex areas)
    area = np.zeros(tgt.n_vertices)
    np.add.at(area, tgt.faces.ravel(), np.repeat(tgt.face_areas() / 3, 3))
    acc = area[result == labels].sum() / area.sum()
    sc = got.scores["target"]
    assert sc["accuracy"] == pytest.approx(acc, rel=1e-12)
    for part in range(4):
        inter = area[(result == part) & (labels == part)].sum()
        union = area[(result == part) | (labels == part)].sum()
        assert sc["iou"][part] == pytest.approx(inter / union, rel=1e-12)
    assert sc["unassigned"] == pytest.approx(area[result < 0].sum() / area.sum(), rel=1e-12)


def test_point_clouds_are_points_coloured_by_their_own_labels(scene):
    src, _, labels, _ = scene
    cloud = bsfjax.PointCloud(src.vertices * 1.1)
    got = plot.view(src, [cloud, src], labels=labels, results=[labels[::-1], labels],
                    names=["a", "b", "c"], layout="one", backend="mock")
    assert got.kinds == ("surface", "points", "surface")
    assert ps.has_point_cloud("b") and not ps.has_surface_mesh("b")
    assert np.allclose(_colours("b", cloud=True), label_colour(labels[::-1]), atol=1e-6)
    assert ps.get_surface_mesh("a").is_enabled() and not ps.get_surface_mesh("c").is_enabled()


def test_render_writes_one_png_per_view_and_bsfjax_view_is_lazy(scene, tmp_path):
    src, tgt, labels, result = scene
    got = plot.render(src, (tgt.vertices, tgt.faces), tmp_path, labels=labels, results=result,
                      views=("front", "side", 30), size=(320, 200), backend="mock")
    assert [p.name for p in got.paths] == ["view_front.png", "view_side.png", "view_30.png"]
    assert all(p.is_file() for p in got.paths)
    got = bsfjax.view(src, None, labels=labels, backend="mock", show=False)
    assert got.structures == ("source",)
    for bad, match in (({"views": ("top",)}, "unknown view"), ({"size": (5, 5)}, "16 to 8192"),
                       ({"layout": "grid"}, "layout must be")):
        with pytest.raises(bsfjax.BSFError, match=match):
            plot.render(src, None, tmp_path, backend="mock", **bad)
    with pytest.raises(bsfjax.BSFError, match="one label per vertex"):
        plot.view(src, tgt, labels=labels[:-1], backend="mock")
    code = "import sys, bsfjax; bsfjax.as_mesh; print('polyscope' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, check=True)
    assert out.stdout.strip() == "False"


def test_no_display_and_no_polyscope_are_one_line_each(monkeypatch):
    from bsfjax._plot import _polyscope

    monkeypatch.setitem(_polyscope._STATE, "backend", None)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    with pytest.raises(bsfjax.BSFError, match="no display .*--screenshot"):
        _polyscope.polyscope("auto", window=True)
    monkeypatch.setitem(sys.modules, "polyscope", None)
    with pytest.raises(bsfjax.BSFError, match=r"pip install 'bsfjax\[view\]'"):
        _polyscope.polyscope("mock")


def test_cli_view_screenshot_and_transfer_render(scene, tmp_path, capsys):
    src, tgt, labels, result = scene
    bsfjax.save_mesh(tmp_path / "src.ply", src)
    bsfjax.save_mesh(tmp_path / "tgt.ply", tgt)
    names = ["arm", "head", "leg", "torso"]
    bsfjax.save_labels(tmp_path / "parts.json", labels, names)
    bsfjax.save_labels(tmp_path / "result.json", result, names)  # "unassigned" part: -1
    np.savetxt(tmp_path / "truth.txt", labels, fmt="%d")
    rc = main(["view", str(tmp_path / "src.ply"), str(tmp_path / "tgt.ply"), "--labels",
               str(tmp_path / "parts.json"), "--result", str(tmp_path / "result.json"),
               "--truth", str(tmp_path / "truth.txt"), "--screenshot", str(tmp_path / "png"),
               "--views", "front,back", "--size", "300x200", "--backend", "mock"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert sorted(p.name for p in (tmp_path / "png").iterdir()) == ["view_back.png",
                                                                     "view_front.png"]
    tc = _colours("tgt")  # the last scene rendered stays registered until the next one
    assert np.allclose(tc[_majority(result, tgt.faces) == -1], GREY, atol=1e-6)
    acc = plot.render(src, tgt, tmp_path / "x", results=result, truth=labels,
                      backend="mock").scores["target"]["accuracy"]
    assert f"tgt: {acc:.1%} of the area right" in out
    # bsfjax transfer --render: the source and its result, one PNG per view
    np.savetxt(tmp_path / "p2p.txt", np.arange(src.n_vertices), fmt="%d")
    rc = main(["transfer", str(tmp_path / "src.ply"), str(tmp_path / "tgt.ply"), "--labels",
               str(tmp_path / "parts.json"), "--map", "p2p", str(tmp_path / "p2p.txt"),
               "--method", "p2p", "--out", str(tmp_path / "out.json"), "--truth",
               str(tmp_path / "parts.json"), "--render", str(tmp_path / "r")])
    assert rc == 0
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == ["tgt_back.png",
                                                                   "tgt_front.png"]
    assert json.loads((tmp_path / "out.json").read_text())["arm"]
    assert np.allclose(_colours("tgt errors")[:, 0], _colours("tgt errors")[:, 0])
    err = _colours("tgt errors")
    assert not np.isclose(err, RED, atol=1e-6).all(axis=1).any()  # the identity map: all right


def test_egl_screenshot_of_a_shaded_mesh(tmp_path):
    """A real headless render (EGL): skipped with the reason where EGL cannot start."""
    code = f"""
import numpy as np, bsfjax
from bsfjax import plot
from tests.conftest import icosphere
v, f = icosphere(3)
lab = (v[:, 0] > 0).astype(int)
plot.render(bsfjax.Mesh(v, f), None, {str(tmp_path)!r}, labels=lab, size=(200, 160),
            backend="egl")
"""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)
    if run.returncode != 0:
        if "could not start its egl backend" in run.stderr or "EGL" in run.stderr:
            why = [ln for ln in run.stderr.splitlines() if "Error: " in ln and "EGL" in ln]
            pytest.skip(f"EGL is not available here: {(why or ['EGL failed'])[-1].strip()}")
        raise AssertionError(run.stderr)
    import matplotlib.image as mpimg

    img = mpimg.imread(tmp_path / "view_front.png")[..., :3]
    assert img.shape[:2] == (160, 200)
    ink = np.abs(img - img[0, 0]).sum(-1) > 0.1  # not the background
    assert 0.05 < ink.mean() < 0.9
    # the two parts, shaded: tab10's blue (label 0) and orange (label 1) pixels, each a share
    r, b = img[ink][:, 0], img[ink][:, 2]
    assert (b > r + 0.15).mean() > 0.1 and (r > b + 0.15).mean() > 0.1
