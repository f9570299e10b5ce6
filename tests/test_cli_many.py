"""``bsfjax transfer SOURCE TARGET... --out-dir``: many targets, resume, errors, processes."""

from __future__ import annotations

import json
import socket
import subprocess
import sys

import numpy as np
import pytest

import bsfjax
from bsfjax import REGIMES
from bsfjax.cli import main

from .conftest import cpu_devices_env


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("many")
    small, large = bsfjax.example_pair(levels=1), bsfjax.example_pair(levels=2)
    bsfjax.save_mesh(d / "src.ply", small.source)
    np.savetxt(d / "labels.txt", small.labels, fmt="%d")
    (d / "tg").mkdir()
    bsfjax.save_mesh(d / "tg" / "t506.ply", small.target)
    bsfjax.save_mesh(d / "tg" / "t2018.off", large.target)
    (d / "truth").mkdir()
    np.savetxt(d / "truth" / "t506.txt", small.labels[small.p2p], fmt="%d")
    (d / "bad").mkdir()
    (d / "bad" / "broken.off").write_text("OFF\n3 1 0\n0 0 0\n")  # truncated
    return d


def _argv(d, out, *targets, extra=()):
    # --one-start: maps without landmarks through the batched stages these tests are about
    # (the default's choice among starts is estimate_map's own: tests/test_collection.py)
    return ["transfer", str(d / "src.ply"), *[str(t) for t in targets], "--labels",
            str(d / "labels.txt"), "--out-dir", str(out), "-k", "10", "--no-progress",
            "--one-start", *extra]


@pytest.fixture(scope="module")
def one_process(files):
    """One run over the good targets (a folder and a file): the reference of the tests below."""
    out = files / "one"
    assert main(_argv(files, out, files / "tg", files / "src.ply")) == 0
    return out


def test_writes_every_target_and_a_summary(files, one_process):
    summary = json.loads((one_process / "summary.json").read_text())["targets"]
    assert [r["target"].rsplit("/", 1)[-1] for r in summary] == ["t2018.off", "t506.ply",
                                                                  "src.ply"]
    for r, n in zip(summary, (2018, 506, 506)):
        assert r["status"] == "ok" and r["vertices"] == n
        assert 0 <= r["unassigned_share"] <= 0.01 and r["regime"] in REGIMES
        assert np.isfinite(r["map_energy"]) and r["seconds"] > 0
        labels = np.loadtxt(one_process / f"{r['target'].rsplit('/', 1)[-1].split('.')[0]}.txt")
        assert labels.shape == (n,)


def test_truth_a_bad_target_and_resume(files, one_process, capsys):
    out = files / "run"
    argv = _argv(files, out, files / "tg" / "t506.ply", files / "bad" / "broken.off",
                 extra=["--truth-dir", str(files / "truth"), "--mesh-out-dir", str(out / "ply")])
    assert main(argv) == 1  # the bad target is reported, the other one finishes
    err = capsys.readouterr().err
    assert "broken.off: error:" in err
    rows = {r["target"].rsplit("/", 1)[-1]: r
            for r in json.loads((out / "summary.json").read_text())["targets"]}
    assert rows["broken.off"]["status"] == "error" and "broken.off" in rows["broken.off"]["error"]
    assert rows["t506.ply"]["accuracy"] > 0.9
    assert (out / "ply" / "t506.ply").is_file() and not (out / "broken.txt").exists()
    # the same labels as the run without the bad target
    np.testing.assert_array_equal(np.loadtxt(out / "t506.txt"),
                                  np.loadtxt(one_process / "t506.txt"))
    # rerun: the complete target is skipped (its file untouched), only the bad one is retried
    before = (out / "t506.txt").stat().st_mtime_ns
    assert main(argv) == 1
    assert "1 complete (skipped), 1 to run" in capsys.readouterr().err
    assert (out / "t506.txt").stat().st_mtime_ns == before
    rows = {r["target"].rsplit("/", 1)[-1]: r
            for r in json.loads((out / "summary.json").read_text())["targets"]}
    assert rows["t506.ply"]["status"] == "ok" and "accuracy" in rows["t506.ply"]  # kept
    # a missing output (a run killed before it) is computed again; --overwrite redoes all;
    # what the killed run left of its atomic writes is removed, nothing else
    (out / "ply" / "t506.ply").unlink()
    stale = [out / ".t506.txt.k4xdw8yy.tmp.txt", out / "ply" / ".t506.ply.a_b1c2d3.tmp.ply"]
    kept = [out / ".t506.txt.notours.tmp.txt", out / "notes.tmp.txt"]
    for f in stale + kept:
        f.write_text("partial")
    assert main(argv[:3] + argv[4:]) == 0  # without the bad target
    assert "0 complete (skipped), 1 to run" in capsys.readouterr().err
    assert (out / "ply" / "t506.ply").is_file()
    assert not any(f.exists() for f in stale) and all(f.read_text() == "partial" for f in kept)
    assert main(argv[:3] + argv[4:] + ["--overwrite"]) == 0
    assert "0 complete (skipped), 1 to run" in capsys.readouterr().err
    assert (out / "t506.txt").stat().st_mtime_ns > before


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_processes_write_what_one_process_writes(files, one_process):
    """jax.distributed on localhost (gloo), two processes of two CPU devices each: target j
    goes to global device j mod 4, so process 0 runs two targets (one on each of its devices)
    and process 1 one; the files are those of the one-process run, bit for bit."""
    out = files / "two"
    port = _free_port()
    env = cpu_devices_env(2)
    procs = [subprocess.Popen([sys.executable, "-m", "bsfjax.cli",
                               *_argv(files, out, files / "tg", files / "src.ply"),
                               "--coordinator", f"127.0.0.1:{port}", "--num-processes", "2",
                               "--process-id", str(i)], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for i in range(2)]
    errs = [p.communicate(timeout=600)[1] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], errs
    assert "on 2 processes" in errs[0]
    assert "wrote 2 targets" in errs[0] and "wrote 1 targets" in errs[1], errs
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in one_process.iterdir())
    for name in ("t506.txt", "t2018.txt", "src.txt"):
        assert (out / name).read_bytes() == (one_process / name).read_bytes()
    drop = lambda rows: [{k: v for k, v in r.items() if k != "seconds"} for r in rows]  # noqa: E731
    assert drop(json.loads((out / "summary.json").read_text())["targets"]) == \
        drop(json.loads((one_process / "summary.json").read_text())["targets"])


@pytest.mark.parametrize("extra, match", [
    (["--out", "x.txt"], "give --out FILE .* or --out-dir DIR"),
    (["--landmarks", "1:1"], "--landmarks cannot be used with --out-dir DIR"),
    (["--map", "p2p", "m.txt"], "with --out-dir the map is estimated"),
    (["--coordinator", "127.0.0.1:1"], "go together"),
    (["--truth-dir", "nowhere"], "--truth-dir nowhere: no such folder"),
    (["--timeout", "0"], "--timeout must be an integer >= 1"),
])
def test_bad_options_are_one_line(files, tmp_path, capsys, extra, match):
    argv = _argv(files, tmp_path / "o", files / "tg", extra=extra)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    import re

    assert re.search(match, err), err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_bad_targets_and_landmark_files(files, tmp_path, capsys):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for sub in ("a", "b"):
        (tmp_path / sub / "same.off").write_text("x")
    (tmp_path / "empty").mkdir()
    lm = tmp_path / "lm.json"
    lm.write_text(json.dumps({"t506.ply": [[1, 2], [3]]}))
    cases = [
        ([tmp_path / "a", tmp_path / "b"], [], "same name 'same'"),
        ([tmp_path / "empty"], [], "no mesh files"),
        ([str(tmp_path / "*.none")], [], "matches no file"),
        ([files / "tg"], ["--landmarks-file", str(lm)], "entry 't506.ply' must be"),
        ([files / "tg"], ["--landmarks-file", str(tmp_path / "a" / "same.off")],
         "cannot read JSON"),
    ]
    for targets, extra, match in cases:
        argv = _argv(files, tmp_path / "o", *targets, extra=extra)
        assert main(argv) == 2, targets
        err = capsys.readouterr().err
        assert match in err, err


def test_landmarks_file_maps_names_and_stems_to_targets(tmp_path):
    from pathlib import Path

    from bsfjax._cli._many import _read_landmarks_file
    from bsfjax.internal import CLIError

    lm = tmp_path / "lm.json"
    lm.write_text(json.dumps({"b.off": [[1, 2], [3, 4]], "c": [[5], [6]], "other.ply": [[0], [0]]}))
    got = _read_landmarks_file(str(lm), [Path("x/a.ply"), Path("y/b.off"), Path("c.obj")], CLIError)
    assert got == {1: ([1, 2], [3, 4]), 2: ([5], [6])}


def test_cluster_detection_and_flags(monkeypatch):
    """No flags: jax.distributed.initialize() (its own SLURM / Open MPI detection) only inside
    such a job; the flags are passed as given and must come together."""
    import argparse

    import jax

    from bsfjax._cli._distributed import _initialize_distributed
    from bsfjax.internal import CLIError

    calls = []
    monkeypatch.setattr(jax.distributed, "initialize", lambda **kw: calls.append(kw))
    monkeypatch.setattr(jax.config, "update", lambda *a: None)
    args = argparse.Namespace(coordinator=None, num_processes=None, process_id=None)
    for var in ("SLURM_NTASKS", "OMPI_COMM_WORLD_SIZE"):
        monkeypatch.delenv(var, raising=False)
    _initialize_distributed(args, CLIError)
    monkeypatch.setenv("SLURM_NTASKS", "1")  # a one-task job: nothing to share
    _initialize_distributed(args, CLIError)
    assert calls == []
    monkeypatch.setenv("SLURM_NTASKS", "4")
    _initialize_distributed(args, CLIError)
    monkeypatch.delenv("SLURM_NTASKS")
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")
    _initialize_distributed(args, CLIError)
    assert calls == [{"initialization_timeout": 90}] * 2  # --timeout's default
    args = argparse.Namespace(coordinator="h:1", num_processes=3, process_id=2, timeout=7)
    _initialize_distributed(args, CLIError)
    assert calls[-1] == dict(coordinator_address="h:1", num_processes=3, process_id=2,
                             initialization_timeout=7)
    with pytest.raises(CLIError, match="--process-id must be in"):
        _initialize_distributed(argparse.Namespace(coordinator="h:1", num_processes=2,
                                                   process_id=2), CLIError)


def test_json_labels_come_back_as_json_per_target(files, one_process, tmp_path, capsys):
    """SMPL-style .json labels: each target's labels as .json under the source's part names
    (the same labels as the .txt run), a .json truth scored, and a rerun skips them."""
    small = bsfjax.example_pair(levels=1)
    names = [f"p{n}" for n in small.label_names]
    lab = np.loadtxt(files / "labels.txt").astype(int)
    (tmp_path / "parts.json").write_text(json.dumps(
        {n: np.flatnonzero(lab == i).tolist() for i, n in enumerate(names)}))
    (tmp_path / "truth").mkdir()
    truth = small.labels[small.p2p]
    (tmp_path / "truth" / "t506.json").write_text(json.dumps(
        {n: np.flatnonzero(truth == i).tolist() for i, n in enumerate(names)}))
    out = tmp_path / "out"
    argv = _argv(files, out, files / "tg" / "t506.ply",
                 extra=["--truth-dir", str(tmp_path / "truth")])
    argv[argv.index(str(files / "labels.txt"))] = str(tmp_path / "parts.json")
    assert main(argv) == 0
    got = json.loads((out / "t506.json").read_text())
    want = np.loadtxt(one_process / "t506.txt").astype(int)
    assert got == {n: np.flatnonzero(want == i).tolist() for i, n in enumerate(names)}
    assert not (out / "t506.txt").exists()
    row = json.loads((out / "summary.json").read_text())["targets"][0]
    assert row["accuracy"] == pytest.approx(
        np.sum(np.asarray(bsfjax.spectrum(small.target, 2).mass) * (want == truth)) /
        small.target.area, rel=1e-6)
    capsys.readouterr()
    assert main(argv) == 0
    assert "1 complete (skipped), 0 to run" in capsys.readouterr().err


def test_labels_per_triangle_come_back_per_triangle(files, tmp_path, capsys):
    """A .seg source: each target's triangles labelled (DIR/<stem>.seg), scored against a
    .seg truth, as the one-target command labels them; a rerun skips them."""
    small = bsfjax.example_pair(levels=1)
    np.savetxt(tmp_path / "parts.seg",
               bsfjax.face_labels_from_vertices(small.source, small.labels), fmt="%d")
    (tmp_path / "truth").mkdir()
    truth = bsfjax.face_labels_from_vertices(small.target, small.labels[np.asarray(small.p2p)])
    np.savetxt(tmp_path / "truth" / "t506.seg", truth, fmt="%d")
    out = tmp_path / "out"
    argv = _argv(files, out, files / "tg" / "t506.ply",
                 extra=["--truth-dir", str(tmp_path / "truth"), "--mesh-out-dir",
                        str(tmp_path / "ply")])
    argv[argv.index(str(files / "labels.txt"))] = str(tmp_path / "parts.seg")
    assert main(argv) == 0
    got = np.loadtxt(out / "t506.seg", dtype=int)
    assert got.shape == (small.target.n_faces,) and not (out / "t506.txt").exists()
    row = json.loads((out / "summary.json").read_text())["targets"][0]
    area = small.target.face_areas()
    assert row["accuracy"] == pytest.approx(np.sum(area * (got == truth)) / area.sum())
    assert row["accuracy"] > 0.8 and row["regime"] in REGIMES
    import meshio

    np.testing.assert_array_equal(meshio.read(tmp_path / "ply" / "t506.ply")
                                  .cell_data["label"][0], got)
    capsys.readouterr()
    assert main(argv) == 0
    assert "1 complete (skipped), 0 to run" in capsys.readouterr().err


def test_summary_says_when_the_turn_check_is_in_doubt(files, tmp_path, monkeypatch, capsys):
    """Without landmarks or ``--one-start``, each target's map is estimate_map's choice among
    starts: its turn check's doubt goes into summary.json, and a doubt is said per target."""
    import bsfjax._cli._io as cli_io
    from bsfjax.internal import TURN_DOUBT

    from .test_cli import doubting
    real = cli_io.map_estimator
    monkeypatch.setattr(cli_io, "map_estimator", lambda *a: doubting(real(*a), True))
    out = tmp_path / "doubt"
    argv = [a for a in _argv(files, out, files / "tg" / "t506.ply") if a != "--one-start"]
    assert main(argv) == 0
    row = json.loads((out / "summary.json").read_text())["targets"][0]
    assert row["status"] == "ok" and row["turn_doubtful"] is True
    assert f"t506.ply: warning: {TURN_DOUBT}" in capsys.readouterr().err
    # with --one-start there is no turn check, and no entry
    assert main(_argv(files, tmp_path / "one", files / "tg" / "t506.ply")) == 0
    row = json.loads((tmp_path / "one" / "summary.json").read_text())["targets"][0]
    assert "turn_doubtful" not in row
