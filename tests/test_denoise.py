"""Denoising before the spectrum: `bsfjax.denoise`, `bsfjax.noise_level`, and their use by
default in `bsfjax transfer` (one target and ``--out-dir``) and `transfer_collection`."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

import bsfjax
from bsfjax.cli import main
from bsfjax.internal import vertex_areas

from .conftest import data_path, icosphere

LANDMARKS = "412,3216,5907,6296,2445:412,3216,5907,6296,2445"


def _volume(mesh) -> float:
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    return float(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6)


def _noisy(mesh, sigma: float, seed: int = 0):
    v = np.asarray(mesh.vertices)
    rng = np.random.default_rng(seed)
    return bsfjax.Mesh(v + rng.normal(size=v.shape) * sigma, mesh.faces, name="noisy")


@pytest.fixture(scope="module")
def sphere():
    v, f = icosphere(4)
    return bsfjax.Mesh(v, f)


def test_taubin_sphere_closer_and_volume(sphere):
    noisy = _noisy(sphere, 0.01)
    smooth = bsfjax.denoise(noisy, 10)
    err = lambda m: np.abs(np.linalg.norm(m.vertices, axis=1) - 1).mean()  # noqa: E731
    assert err(smooth) < 0.5 * err(noisy)
    assert abs(_volume(smooth) / (4 / 3 * np.pi) - 1) < 0.03
    # same connectivity, same vertex order
    assert np.array_equal(smooth.faces, noisy.faces)
    assert smooth.n_vertices == noisy.n_vertices


def test_auto_strength_clean_and_noisy(sphere):
    assert bsfjax.denoise_iterations(sphere) == 0
    assert bsfjax.denoise(sphere) is sphere
    h = np.mean(np.linalg.norm(sphere.vertices[sphere.faces[:, 0]]
                               - sphere.vertices[sphere.faces[:, 1]], axis=1))
    noisy = _noisy(sphere, 0.3 * h)
    assert bsfjax.noise_level(noisy) > 0.2
    assert bsfjax.denoise_iterations(noisy) > 0
    assert bsfjax.noise_level(bsfjax.denoise(noisy)) < bsfjax.noise_level(noisy) / 2


def test_example_pair_clean():
    pair = bsfjax.example_pair()
    for mesh in (pair.source, pair.target):
        assert bsfjax.noise_level(mesh) < 0.05
        assert bsfjax.denoise_iterations(mesh) == 0
        assert bsfjax.denoise(mesh) is mesh  # the spectrum is the same


def test_strength_checked(sphere):
    with pytest.raises(bsfjax.BSFError):
        bsfjax.denoise(sphere, "strong")
    with pytest.raises(bsfjax.BSFError):
        bsfjax.denoise(sphere, -1)
    assert bsfjax.denoise(sphere, 0) is sphere
    cloud = bsfjax.PointCloud(sphere.vertices)
    assert bsfjax.noise_level(cloud) < 0.1 and bsfjax.denoise(cloud) is cloud  # ("auto": kept)


def test_keeps_file_rows(tmp_path, sphere):
    noisy = _noisy(sphere, 0.01)
    v, f = np.asarray(noisy.vertices), np.asarray(noisy.faces)
    path = tmp_path / "m.off"  # an unreferenced vertex: the reader drops row 0
    path.write_text(f"OFF\n{len(v) + 1} {len(f)} 0\n9 9 9\n"
                    + "".join(f"{a} {b} {c}\n" for a, b, c in v)
                    + "".join(f"3 {a + 1} {b + 1} {c + 1}\n" for a, b, c in f))
    with pytest.warns(UserWarning):
        m = bsfjax.load_mesh(path)
    d = bsfjax.denoise(m)
    assert d is not m and np.array_equal(d.vertex_ids, m.vertex_ids)
    assert d.n_file_rows == m.n_file_rows == len(v) + 1


def test_faust_registration_clean():
    m = bsfjax.load_mesh(data_path("faust", "tr_reg_000.off"))
    assert bsfjax.noise_level(m) < 0.1
    assert bsfjax.denoise_iterations(m) == 0


def _faust_case(tmp_path):
    src = data_path("faust", "tr_reg_000.off")
    tgt = data_path("faust", "tr_reg_010.off")
    truth = bsfjax.load_labels(data_path("segmentations", "smpl_vert_segmentation.json"))
    truth = np.asarray(truth.labels)
    labels = tmp_path / "smpl.txt"
    np.savetxt(labels, truth, fmt="%d")
    clean = bsfjax.load_mesh(tgt)
    v = np.asarray(clean.vertices)
    noisy = _noisy(clean, 0.0025 * np.ptp(v[:, 1]), seed=10)
    noisy_path = tmp_path / "noisy.off"
    bsfjax.save_mesh(noisy_path, noisy)
    return src, tgt, noisy_path, labels, truth, vertex_areas(clean)


def _cli(*argv) -> str:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main([str(a) for a in argv]) == 0
    return err.getvalue()


def test_faust_noisy_with_landmarks(tmp_path):
    src, tgt, noisy, labels, truth, mass = _faust_case(tmp_path)
    acc = {}
    for name, target, extra in (("clean", tgt, ()), ("noisy", noisy, ()),
                                ("raw", noisy, ("--no-denoise",))):
        out = tmp_path / f"{name}.txt"
        said = _cli("transfer", src, target, "--labels", labels, "--out", out, "--landmarks",
                    LANDMARKS, *extra)
        lab = np.loadtxt(out, dtype=np.int64)
        assert lab.shape == (6890,)
        acc[name] = float(np.sum(mass * (lab == truth)) / mass.sum())
        if name == "noisy":
            line = [s for s in said.splitlines() if s.startswith("denoise:")][0]
            assert "source noise level" in line and " 0 Taubin" in line.split(";")[0]
            assert " 0 Taubin" not in line.split(";")[1]
        if name == "raw":
            assert "denoise:" not in said
    assert acc["clean"] > 0.93
    assert acc["noisy"] > acc["clean"] - 0.015, acc


def test_collection_reports_strength(tmp_path):
    src, tgt, noisy, labels, truth, _ = _faust_case(tmp_path)
    lm = [[int(i) for i in LANDMARKS.split(":")[0].split(",")]] * 2
    lm_file = tmp_path / "lm.json"
    lm_file.write_text(json.dumps({"noisy.off": lm, tgt.name: lm}))
    out = tmp_path / "out"
    said = _cli("transfer", src, tgt, noisy, "--labels", labels, "--out-dir", out,
                "--landmarks-file", lm_file, "--no-progress")
    assert "denoise: source noise level" in said
    rows = {r["target"]: r for r in json.loads((out / "summary.json").read_text())["targets"]}
    assert rows[str(noisy)]["denoise_iterations"] > 0
    assert rows[str(tgt)]["denoise_iterations"] == 0
    lab = np.loadtxt(out / "noisy.txt", dtype=np.int64)
    assert lab.shape == (6890,) and np.mean(lab == truth) > 0.9


def test_prepare_scan_split_then_denoise(sphere):
    """`prepare_scan`: the main body of a noisy mesh with debris, smoothed as `denoise` smooths
    that body alone, and values on it back on every vertex as read."""
    h = np.mean(np.linalg.norm(sphere.vertices[sphere.faces[:, 0]]
                               - sphere.vertices[sphere.faces[:, 1]], axis=1))
    body = _noisy(sphere, 0.3 * h)
    far = np.array([[5.0, 0, 0], [5.1, 0, 0], [5.0, 0.1, 0]])  # debris, out of reach
    n = body.n_vertices
    whole = bsfjax.Mesh(np.vstack([body.vertices, far]),
                        np.vstack([body.faces, [[n, n + 1, n + 2]]]), name="scan")
    prep = bsfjax.prepare_scan(whole)
    assert prep.parts.n_other_components == 1 and prep.mesh.n_vertices == n
    expected_it = bsfjax.denoise_iterations(body)
    assert prep.denoise_iterations == expected_it > 0
    assert prep.noise_level == pytest.approx(bsfjax.noise_level(body))
    np.testing.assert_allclose(prep.mesh.vertices, bsfjax.denoise(body, expected_it).vertices)
    assert "noise level" in prep.summary("target") and f"{expected_it} Taubin" in prep.summary()
    back = prep.to_whole(np.arange(n))
    assert back.shape == (n + 3,) and np.array_equal(back[:n], np.arange(n))
    assert np.all(back[n:] == -1)  # too far from the body: unassigned
    off = bsfjax.prepare_scan(whole, False)
    assert off.denoise_iterations == 0 and off.noise_level is None
    np.testing.assert_array_equal(off.mesh.vertices, body.vertices)
    assert bsfjax.prepare_scan(whole, 3).denoise_iterations == 3
    with pytest.raises(bsfjax.BSFError, match="denoise strength"):
        bsfjax.prepare_scan(whole, -1)
