"""The bsfjax command line: help, version, and clean one-line errors."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import bsfjax
import bsfjax.internal
from bsfjax.cli import main
from bsfjax.internal import TURN_DOUBT


def run(*args):
    return subprocess.run([sys.executable, "-m", "bsfjax.cli", *args], capture_output=True, text=True,
                          timeout=120)


def test_help_and_version():
    r = run("--help")
    assert r.returncode == 0 and "usage: bsfjax" in r.stdout
    r = run("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"bsfjax {bsfjax.__version__}"


def test_spectrum_command(tmp_path, sphere_mesh, capsys):
    mesh_path = tmp_path / "s.ply"
    bsfjax.save_mesh(mesh_path, sphere_mesh)
    out = tmp_path / "spec.npz"
    assert main(["spectrum", str(mesh_path), "-k", "8", "--out", str(out)]) == 0
    with np.load(out) as z:
        np.testing.assert_allclose(z["evals"], bsfjax.spectrum(sphere_mesh, 8).evals)


def test_spectrum_command_method_is_passed_through(tmp_path, sphere_mesh, monkeypatch):
    import bsfjax._spectral as spectrum_module

    mesh_path = tmp_path / "s.ply"
    bsfjax.save_mesh(mesh_path, sphere_mesh)
    seen = []
    real = spectrum_module.spectrum

    def spy(mesh, k, **kw):
        seen.append(kw.get("method", "auto"))
        return real(mesh, k, **kw)

    monkeypatch.setattr(spectrum_module, "spectrum", spy)
    for method in ("dense", "lanczos"):
        out = tmp_path / f"spec-{method}.npz"
        assert main(["spectrum", str(mesh_path), "-k", "8", "--out", str(out),
                     "--method", method]) == 0
        with np.load(out) as z:
            np.testing.assert_allclose(z["evals"], real(sphere_mesh, 8, method=method).evals,
                                       rtol=1e-6, atol=1e-9)
    assert main(["spectrum", str(mesh_path), "-k", "8", "--out", str(tmp_path / "a.npz")]) == 0
    assert seen == ["dense", "lanczos", "auto"]
    r = run("spectrum", str(mesh_path), "-k", "8", "--out", str(tmp_path / "x.npz"),
            "--method", "nope")
    assert r.returncode == 2 and "invalid choice" in r.stderr


def test_bad_input_is_one_line_without_traceback(tmp_path):
    out = tmp_path / "never.npz"
    r = run("spectrum", str(tmp_path / "missing.off"), "--out", str(out))
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0 and "no such file" in r.stderr
    assert not out.exists()


@pytest.fixture(scope="module")
def cli_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    pair = bsfjax.example_pair(levels=2)
    bsfjax.save_mesh(d / "src.ply", pair.source)
    bsfjax.save_mesh(d / "tgt.off", pair.target)
    np.savetxt(d / "labels.txt", pair.labels, fmt="%d")
    np.save(d / "identity.npy", np.asarray(pair.p2p))
    np.savetxt(d / "short.txt", pair.labels[:-3], fmt="%d")
    return d, pair


def test_transfer_command_labels_with_point_map(cli_files):
    d, pair = cli_files
    out, ply = d / "out.npy", d / "coloured.ply"
    rc = main(["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--labels", str(d / "labels.txt"),
               "--out", str(out), "--map", "p2p", str(d / "identity.npy"), "-k", "20",
               "--mesh-out", str(ply)])
    assert rc == 0
    got = np.load(out)
    assert got.shape == (pair.target.n_vertices,)
    assert np.mean(got == pair.labels) > 0.85
    import meshio

    m = meshio.read(ply)
    assert m.points.shape[0] == pair.target.n_vertices
    assert {"red", "green", "blue", "label"} <= set(m.point_data)
    np.testing.assert_array_equal(m.point_data["label"], got)


def test_transfer_command_smpl_json_labels_in_and_out(cli_files, tmp_path, capsys):
    """Labels as SMPL's {part: [vertices]} .json: read, pulled back through the given map, and
    written as .json with the source's part names; a .json truth is scored by those names."""
    d, pair = cli_files
    names = [f"part {n}" for n in pair.label_names]
    parts = {names[i]: np.flatnonzero(pair.labels == i).tolist() for i in range(len(names))}
    (tmp_path / "parts.json").write_text(json.dumps(parts))
    p2p = np.asarray(pair.p2p)
    truth = {n: np.flatnonzero(pair.labels[p2p] == i).tolist() for i, n in enumerate(names)}
    (tmp_path / "truth.json").write_text(json.dumps(truth))
    out = tmp_path / "target_parts.json"
    rc = main(["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--labels",
               str(tmp_path / "parts.json"), "--map", "p2p", str(d / "identity.npy"), "-k", "20",
               "--truth", str(tmp_path / "truth.json"), "--out", str(out)])
    assert rc == 0
    got = json.loads(out.read_text())
    assert got == truth  # the exact map's pull-back, part by part, under the source's names
    assert main(["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--function",
                 str(d / "labels.txt"), "--map", "p2p", str(d / "identity.npy"), "-k", "20",
                 "--out", str(tmp_path / "f.json")]) == 2  # a function is not written as .json
    # a source with a part the target's truth lacks (an empty one, sorted first): the truth is
    # compared part by part by name, not by its own numbering
    (tmp_path / "more.json").write_text(json.dumps({"a empty part": [], **parts}))
    capsys.readouterr()
    assert main(["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--labels",
                 str(tmp_path / "more.json"), "--map", "p2p", str(d / "identity.npy"), "-k",
                 "20", "--truth", str(tmp_path / "truth.json"), "--out",
                 str(tmp_path / "more_out.json")]) == 0
    assert "accuracy against" in (err := capsys.readouterr().err) and "100.0% of the target" in err
    (tmp_path / "odd.json").write_text(json.dumps({"other": list(range(len(p2p)))}))
    assert main(["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--labels",
                 str(tmp_path / "parts.json"), "--map", "p2p", str(d / "identity.npy"), "-k",
                 "20", "--truth", str(tmp_path / "odd.json"), "--out", str(out)]) == 2
    assert "parts ['other'] are not parts of the labels file" in capsys.readouterr().err


def test_transfer_command_labels_per_triangle(cli_files, tmp_path, capsys):
    """A .seg file (one label per triangle, as PSB / COSEG) goes in and comes out per
    triangle, as the library's transfer_face_labels gives it, with face colours in the PLY; a
    .txt of that length is read the same way; the wrong lengths and suffixes are named."""
    d, pair = cli_files
    labels = bsfjax.face_labels_from_vertices(pair.source, pair.labels)
    truth = bsfjax.face_labels_from_vertices(pair.target, pair.labels[np.asarray(pair.p2p)])
    np.savetxt(tmp_path / "parts.seg", labels, fmt="%d")
    np.savetxt(tmp_path / "parts.txt", labels, fmt="%d")
    np.savetxt(tmp_path / "truth.seg", truth, fmt="%d")
    base = ["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--map", "p2p",
            str(d / "identity.npy"), "-k", "20"]
    out, ply = tmp_path / "out.seg", tmp_path / "out.ply"
    assert main([*base, "--labels", str(tmp_path / "parts.seg"), "--truth",
                 str(tmp_path / "truth.seg"), "--out", str(out), "--mesh-out", str(ply)]) == 0
    err = capsys.readouterr().err
    assert "labels of triangles with p2p" in err and "of its triangles" in err
    got = np.loadtxt(out, dtype=int)
    sm, sn = bsfjax.spectrum(pair.source, 3), bsfjax.spectrum(pair.target, 3)
    want = bsfjax.transfer_face_labels(sm, sn, labels, source_mesh=pair.source,
                                       target_mesh=pair.target, method="p2p",
                                       p2p=np.asarray(pair.p2p)).labels
    np.testing.assert_array_equal(got, want)
    assert np.mean(got == truth) > 0.99
    import meshio

    np.testing.assert_array_equal(meshio.read(ply).cell_data["label"][0], got)
    assert main([*base, "--labels", str(tmp_path / "parts.txt"), "--out",
                 str(tmp_path / "out.npy")]) == 0  # as many labels as triangles: per triangle
    np.testing.assert_array_equal(np.load(tmp_path / "out.npy"), got)
    for labels_file, out_file, match in (
            ("parts.seg", "out.json", "the labels are per triangle"),
            (str(d / "labels.txt"), "out.seg", "the labels are per vertex"),
            (str(d / "short.txt"), "out.txt", r"source mesh has \d+ vertices and \d+ triangles")):
        capsys.readouterr()
        assert main([*base, "--labels", str(tmp_path / labels_file), "--out",
                     str(tmp_path / out_file)]) == 2
        assert re.search(match, capsys.readouterr().err)
    (tmp_path / "short.seg").write_text("0\n1\n")
    assert main([*base, "--labels", str(tmp_path / "short.seg"), "--out", str(out)]) == 2
    assert "a .seg file has one label per triangle" in capsys.readouterr().err
    assert main([*base, "--labels", str(tmp_path / "parts.seg"), "--truth",
                 str(d / "labels.txt"), "--out", str(out)]) == 2
    assert "expected one label per target triangle" in capsys.readouterr().err


def test_transfer_command_function_with_estimated_map(cli_files):
    d, pair = cli_files
    f = (pair.labels == 1).astype(float)  # the head
    np.savetxt(d / "head.txt", f)
    out = d / "head_out.txt"
    rc = main(["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--function", str(d / "head.txt"),
               "--out", str(out), "-k", "20", "--landmarks", "{0}:{0}".format(
                   ",".join(str(i) for i in bsfjax.internal.example_landmarks(pair)))])
    assert rc == 0
    got = np.loadtxt(out)
    err = bsfjax.relative_error(f, got, bsfjax.spectrum(pair.target, 5).mass)
    assert float(err) < 0.5


@pytest.mark.parametrize("extra,match", [
    (["--labels", "{d}/missing.txt"], "no such file"),
    (["--labels", "{d}/short.txt"], "source mesh has 2018 vertices"),
    (["--labels", "{d}/labels.txt", "--method", "magic"], "--method must be one of"),
    (["--labels", "{d}/labels.txt", "--landmarks", "1,2,3:4,5"], "same, non-zero length"),
    (["--labels", "{d}/labels.txt", "--map", "p2p"], "--map must be"),
    (["--labels", "{d}/labels.txt", "--map", "fmap", "{d}/labels.txt"], "square"),
])
def test_transfer_command_bad_input(cli_files, extra, match, capsys):
    # in-process (a fresh interpreter per case cost ~8 s each); the subprocess path, exit status
    # and one-line stderr included, is checked once below
    d, _ = cli_files
    out = d / "never.txt"
    args = ["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--out", str(out)]
    args += [a.format(d=d) for a in extra]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    err_lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(err_lines) == 1 and match in err_lines[0]
    assert not out.exists()


def test_transfer_command_bad_input_in_a_subprocess(cli_files):
    d, _ = cli_files
    out = d / "never.txt"
    r = run("transfer", str(d / "nope.ply"), str(d / "tgt.off"), "--labels", str(d / "labels.txt"),
            "--out", str(out))
    assert r.returncode == 2 and "nope.ply: no such file" in r.stderr and not out.exists()
    assert "Traceback" not in r.stderr and r.stderr.strip().count("\n") == 0


def test_compilation_cache_keeps_every_program(cli_files, tmp_path):
    """The command keeps every compiled program in the persistent cache, not only those that
    took JAX's default second to compile (then none of this small run's would be kept), and
    a second run reads them back to the same output."""
    import os

    d, _ = cli_files
    cache = tmp_path / "jax-cache"
    env = {k: v for k, v in os.environ.items() if k != "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"}
    env["JAX_COMPILATION_CACHE_DIR"] = str(cache)
    args = [sys.executable, "-m", "bsfjax.cli", "transfer", str(d / "src.ply"), str(d / "tgt.off"),
            "--labels", str(d / "labels.txt"), "--map", "p2p", str(d / "identity.npy"), "-k", "10"]
    outs = []
    for i in (1, 2):
        outs.append(tmp_path / f"out{i}.txt")
        r = subprocess.run(args + ["--out", str(outs[-1])], capture_output=True, text=True,
                           env=env)
        assert r.returncode == 0, r.stderr
        if i == 1:
            kept = len(list(cache.iterdir()))
            assert kept >= 10, kept  # ~18 programs; with JAX's default threshold: 0
    assert len(list(cache.iterdir())) == kept  # the second run compiled nothing new
    assert outs[0].read_text() == outs[1].read_text()


def test_a_python_caller_gets_its_cache_threshold_back(tmp_path, monkeypatch):
    """In-process, the command keeps every program (threshold 0) while it runs, and the
    caller's own threshold is back afterwards, also after an error."""
    import contextlib

    import jax

    import bsfjax._util

    monkeypatch.delenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", raising=False)
    seen = []
    real = bsfjax._util.output_transaction

    @contextlib.contextmanager
    def recording():
        seen.append(jax.config.jax_persistent_cache_min_compile_time_secs)
        with real():
            yield

    monkeypatch.setattr(bsfjax._util, "output_transaction", recording)
    before = jax.config.jax_persistent_cache_min_compile_time_secs
    try:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 2.5)
        assert main(["example", "--out", str(tmp_path / "ex"), "--levels", "1"]) == 0
        assert jax.config.jax_persistent_cache_min_compile_time_secs == 2.5
        assert main(["transfer", str(tmp_path / "none.off"), str(tmp_path / "none.off"),
                     "--labels", str(tmp_path / "none.txt"), "--out",
                     str(tmp_path / "o.txt")]) == 2
        assert jax.config.jax_persistent_cache_min_compile_time_secs == 2.5
    finally:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", before)
    assert seen[0] == 0.0


def test_example_command_writes_a_pair_that_transfer_reads(tmp_path, capsys):
    d = tmp_path / "ex"
    assert main(["example", "--out", str(d), "--levels", "2"]) == 0
    pair = bsfjax.example_pair(levels=2)
    src = bsfjax.load_mesh(d / "source.ply")
    np.testing.assert_allclose(src.vertices, pair.source.vertices, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(np.loadtxt(d / "labels.txt", dtype=int), pair.labels)
    np.testing.assert_array_equal(np.loadtxt(d / "target_labels.txt", dtype=int),
                                  pair.labels[pair.p2p])
    lm = (d / "landmarks.txt").read_text().strip()
    assert "bsfjax transfer" in capsys.readouterr().out
    out = tmp_path / "out.txt"
    rc = main(["transfer", str(d / "source.ply"), str(d / "target.ply"), "--labels",
               str(d / "labels.txt"), "--landmarks", lm, "--truth", str(d / "target_labels.txt"),
               "-k", "20", "--out", str(out)])
    assert rc == 0
    err = capsys.readouterr().err
    reported = float(err.split("accuracy against")[1].split(":")[1].split("%")[0]) / 100
    got = np.loadtxt(out, dtype=int)
    mass = bsfjax.spectrum(pair.target, 2).mass
    assert reported == pytest.approx(np.sum(mass * (got == pair.labels)) / np.sum(mass), abs=1e-3)
    assert reported > 0.8
    # without landmarks: the map is chosen among starts, and the command says which it kept
    with pytest.warns(UserWarning, match="no --landmarks"):
        rc = main(["transfer", str(d / "source.ply"), str(d / "target.ply"), "--labels",
                   str(d / "labels.txt"), "--truth", str(d / "target_labels.txt"), "-k", "20",
                   "--out", str(out)])
    assert rc == 0
    err = capsys.readouterr().err
    assert "no landmarks: kept start k0 = " in err and "geodesic distortion" in err
    assert float(err.split("accuracy against")[1].split(":")[1].split("%")[0]) > 90


def test_transfer_warns_when_the_turn_check_is_in_doubt(tmp_path, monkeypatch, capsys):
    """Without landmarks, a map whose turn check is in doubt (``MapEstimate.turn_doubtful``)
    is said to be possibly turned, with the advice; a map not in doubt is not."""
    import bsfjax._cli._transfer as cli_transfer
    d = tmp_path / "ex"
    assert main(["example", "--out", str(d), "--levels", "2"]) == 0
    args = ["transfer", str(d / "source.ply"), str(d / "target.ply"), "--labels",
            str(d / "labels.txt"), "-k", "20", "--out", str(tmp_path / "out.txt")]
    real = cli_transfer.map_estimator
    for doubt in (True, False):
        monkeypatch.setattr(cli_transfer, "map_estimator",
                            lambda *a, doubt=doubt: doubting(real(*a), doubt))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert main(args) == 0
        said = [str(w.message) for w in caught if "turned front to back (left and right "
                "swapped)" in str(w.message)]
        assert said == ([TURN_DOUBT] if doubt else [])
        assert "no landmarks: kept start" in capsys.readouterr().err


def test_a_target_missing_parts_is_matched_again_as_partial(tmp_path, monkeypatch, capsys):
    """Without landmarks, a transfer that finds source parts with no counterpart estimates its
    map again with ``derived_guidance`` (as ``--partial``) and says so; with ``--partial``
    there is one estimate."""
    import argparse

    import bsfjax._cli._transfer as cli_transfer
    d = tmp_path / "ex"
    assert main(["example", "--out", str(d), "--levels", "2"]) == 0
    args = ["transfer", str(d / "source.ply"), str(d / "target.ply"), "--labels",
            str(d / "labels.txt"), "-k", "20", "--out", str(tmp_path / "out.txt")]
    real_line = cli_transfer.missing_line
    monkeypatch.setattr(cli_transfer, "missing_line",
                        lambda *a, **kw: (real_line(*a, **kw)[0], 1))  # (one part missing)
    for extra, again in (([], True), (["--partial"], False)):
        assert main(args + extra) == 0
        err = capsys.readouterr().err
        assert (cli_transfer.PARTIAL_AGAIN in err) == again
        assert err.count("no landmarks: kept start") == (2 if again else 1)
    flags = argparse.Namespace(one_start=False, partial=True)
    assert cli_transfer.map_estimator(flags, 20).derived_guidance


def doubting(estimator, doubt: bool):
    """The estimator, its maps' turn check in doubt (or not)."""
    import dataclasses

    class Doubting(type(estimator)):
        def __call__(self, *args, **kwargs):
            return super().__call__(*args, **kwargs)._replace(turn_doubtful=doubt)

    return Doubting(**{f.name: getattr(estimator, f.name)
                       for f in dataclasses.fields(estimator)})


def test_truth_needs_labels_and_the_target_length(cli_files, capsys):
    d, _ = cli_files
    out = d / "never_truth.txt"
    base = ["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--out", str(out)]
    assert main([*base, "--function", str(d / "labels.txt"), "--truth", str(d / "labels.txt")]) == 2
    assert "--truth compares labels" in capsys.readouterr().err and not out.exists()
    assert main([*base, "--labels", str(d / "labels.txt"), "--truth", str(d / "short.txt")]) == 2
    assert "expected one label per target vertex" in capsys.readouterr().err
    assert not out.exists()


def test_transfer_between_real_meshes_with_landmarks(tmp_path, capsys):
    """FAUST tr_reg_000 -> tr_reg_001 (identity ground truth): an 8-part Voronoi segmentation,
    an estimated map from WKS + 5 landmarks, a label file and a coloured PLY."""
    from tests.conftest import data_path

    a, b = data_path("faust", "tr_reg_000.off"), data_path("faust", "tr_reg_001.off")
    m = bsfjax.load_mesh(a)
    v = np.asarray(m.vertices)
    c = np.asarray(bsfjax.farthest_point_sampling(m, 8, seed=0))
    labels = np.argmin(((v[:, None, :] - v[c][None]) ** 2).sum(-1), axis=1)
    np.savetxt(tmp_path / "labels.txt", labels, fmt="%d")
    lm = ",".join(str(int(i)) for i in bsfjax.farthest_point_sampling(m, 5, seed=0))
    out, ply = tmp_path / "out.npy", tmp_path / "coloured.ply"
    rc = main(["transfer", str(a), str(b), "--labels", str(tmp_path / "labels.txt"),
               "--landmarks", f"{lm}:{lm}", "--truth", str(tmp_path / "labels.txt"), "-k", "20",
               "--out", str(out), "--mesh-out", str(ply)])
    assert rc == 0
    got = np.load(out)
    assert got.shape == (m.n_vertices,) and np.mean(got == labels) > 0.8
    import meshio

    np.testing.assert_array_equal(meshio.read(ply).point_data["label"], got)
