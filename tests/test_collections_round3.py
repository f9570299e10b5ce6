"""Collections, round 3: outputs never overwrite inputs, one bad target does not stop a
collection, stale results are not reused, memory is checked before it is spent, and a
multi-process start-up fails in one line (docs/robustness.md, section 7)."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys

import numpy as np
import pytest

import bsfjax
from bsfjax.cli import main


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("round3")
    small = bsfjax.example_pair(levels=1)
    bsfjax.save_mesh(d / "src.ply", small.source)
    np.savetxt(d / "labels.txt", small.labels, fmt="%d")
    (d / "tg").mkdir()
    bsfjax.save_mesh(d / "tg" / "t506.ply", small.target)
    names = [f"p{n}" for n in small.label_names]
    (d / "parts.json").write_text(json.dumps(
        {n: np.flatnonzero(small.labels == i).tolist() for i, n in enumerate(names)}))
    return d


def _argv(d, out, *targets, labels=None, extra=()):
    return ["transfer", str(d / "src.ply"), *[str(t) for t in targets], "--labels",
            str(labels or d / "labels.txt"), "--out-dir", str(out), "-k", "10", "--no-progress",
            "--one-start", *extra]


def _one_error_line(capsys, *needles):
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert err.startswith("bsfjax transfer: error:"), err
    for n in needles:
        assert n in err, err
    return err


def _snapshot(folder):
    return {p: p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# ------------------------------------------------------------- 1. inputs taken for outputs


def test_mesh_out_dir_equal_to_the_targets_folder_is_refused(files, tmp_path, capsys):
    before = _snapshot(files / "tg")
    argv = _argv(files, tmp_path / "o", files / "tg", extra=["--mesh-out-dir", str(files / "tg")])
    assert main(argv) == 2
    _one_error_line(capsys, "--mesh-out-dir mesh of target t506.ply", "the input target")
    assert _snapshot(files / "tg") == before and not (tmp_path / "o").exists()


def test_truth_dir_equal_to_out_dir_is_refused(files, tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    small = bsfjax.example_pair(levels=1)
    np.savetxt(out / "t506.txt", small.labels[small.p2p], fmt="%d")  # a truth, in --out-dir
    before = _snapshot(out)
    for extra in ([], ["--overwrite"]):
        argv = _argv(files, out, files / "tg", extra=["--truth-dir", str(out), *extra])
        assert main(argv) == 2
        _one_error_line(capsys, "--out-dir output of target t506.ply",
                        "--truth-dir truth of target t506.ply")
        assert _snapshot(out) == before


def test_labels_file_in_the_output_folder_is_refused(files, tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    shutil.copy(files / "labels.txt", out / "t506.txt")
    argv = _argv(files, out, files / "tg", labels=out / "t506.txt")
    assert main(argv) == 2
    _one_error_line(capsys, "--out-dir output of target t506.ply", "the input --labels")
    assert (out / "t506.txt").read_bytes() == (files / "labels.txt").read_bytes()


def test_target_named_summary_is_refused(files, tmp_path, capsys):
    shutil.copy(files / "tg" / "t506.ply", tmp_path / "summary.ply")
    argv = _argv(files, tmp_path / "o", tmp_path / "summary.ply", labels=files / "parts.json")
    assert main(argv) == 2
    _one_error_line(capsys, "--out-dir summary", "--out-dir output of target summary.ply")


def test_path_clashes_resolve_links_and_dots(tmp_path):
    from bsfjax import BSFError
    from bsfjax.internal import check_path_clashes

    (tmp_path / "a").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "a")
    with pytest.raises(BSFError, match="is the same file as the input x"):
        check_path_clashes([("out", tmp_path / "link" / "f.txt")],
                           [("x", tmp_path / "a" / ".." / "a" / "f.txt")])
    with pytest.raises(BSFError, match="o1 'o1' and o2 './o1' are the same file"):
        check_path_clashes([("o1", "o1"), ("o2", "./o1")])
    check_path_clashes([("o", tmp_path / "a" / "g.txt")], [("x", tmp_path / "a" / "f.txt")])


# ------------------------------------------------------------- 2. one bad target


def test_bad_targets_fail_alone(files, tmp_path, capsys):
    """A truth of the wrong length, an output path that is a folder: each its target's
    failure in summary.json; the good target is written; exit status 1."""
    tg = tmp_path / "tg"
    tg.mkdir()
    for name in ("a", "b", "c"):
        shutil.copy(files / "tg" / "t506.ply", tg / f"{name}.ply")
    truth = tmp_path / "truth"
    truth.mkdir()
    np.savetxt(truth / "a.txt", np.zeros(7), fmt="%d")  # wrong length
    out = tmp_path / "o"
    (out / "b.txt").mkdir(parents=True)  # cannot be written
    assert main(_argv(files, out, tg, extra=["--truth-dir", str(truth)])) == 1
    err = capsys.readouterr().err
    rows = {r["target"].rsplit("/", 1)[-1]: r
            for r in json.loads((out / "summary.json").read_text())["targets"]}
    assert rows["a.ply"]["status"] == "error" and "expected 506 labels" in rows["a.ply"]["error"]
    assert rows["b.ply"]["status"] == "error" and "b.txt" in rows["b.ply"]["error"]
    assert rows["c.ply"]["status"] == "ok" and np.loadtxt(out / "c.txt").shape == (506,)
    assert "a.ply: error:" in err and "b.ply: error:" in err and "wrote 1 targets" in err
    assert not (out / "a.txt").exists()


def test_reserved_part_name_fails_its_target_only(files, tmp_path, capsys):
    """A source part named 'unassigned' (the name save_labels writes unassigned vertices
    under): the targets with unassigned vertices fail alone, in summary.json."""
    parts = json.loads((files / "parts.json").read_text())
    first = sorted(parts)[0]
    parts["unassigned"] = parts.pop(first)
    (tmp_path / "parts.json").write_text(json.dumps(parts))
    out = tmp_path / "o"
    argv = _argv(files, out, files / "tg", files / "src.ply", labels=tmp_path / "parts.json",
                 extra=["--method", "lstsq", "--threshold", "0.95"])
    status = main(argv)
    rows = json.loads((out / "summary.json").read_text())["targets"]
    bad = [r for r in rows if r["status"] == "error"]
    assert bad and all("unassigned" in r["error"] for r in bad)
    assert status == 1 and len(rows) == 2


# ------------------------------------------------------------- 3. stale results


def test_rerun_with_other_inputs_or_options_recomputes(files, tmp_path, capsys):
    out = tmp_path / "o"
    argv = _argv(files, out, files / "tg")
    assert main(argv) == 0
    manifest = json.loads((out / "manifest" / "t506.json").read_text())
    assert manifest["key"]["k"] == 10 and len(manifest["key"]["target"]) == 64
    capsys.readouterr()
    assert main(argv) == 0
    assert "1 complete (skipped), 0 to run" in capsys.readouterr().err
    # other -k, --method, labels: the old file is not reported as complete
    small = bsfjax.example_pair(levels=1)
    other = tmp_path / "other.txt"
    np.savetxt(other, (small.labels + 1) % 3, fmt="%d")
    for changed in (_argv(files, out, files / "tg", extra=["-k", "8"]),
                    _argv(files, out, files / "tg", extra=["--method", "p2p"]),
                    _argv(files, out, files / "tg", labels=other)):
        assert main(changed) == 0
        assert "0 complete (skipped), 1 to run" in capsys.readouterr().err
    key = json.loads((out / "manifest" / "t506.json").read_text())["key"]
    assert key["values"] != manifest["key"]["values"]


def test_resume_keeps_the_finished_targets_figures(files, tmp_path, capsys):
    """A run killed after its first target (no summary.json written): the rerun skips it and
    its summary row keeps the figures."""
    out = tmp_path / "o"
    shutil.copy(files / "tg" / "t506.ply", tmp_path / "b.ply")
    assert main(_argv(files, out, files / "tg" / "t506.ply")) == 0
    row = json.loads((out / "summary.json").read_text())["targets"][0]
    (out / "summary.json").unlink()  # killed before the summary
    capsys.readouterr()
    assert main(_argv(files, out, files / "tg" / "t506.ply", tmp_path / "b.ply")) == 0
    assert "1 complete (skipped), 1 to run" in capsys.readouterr().err
    rows = json.loads((out / "summary.json").read_text())["targets"]
    assert rows[0] == row and rows[1]["status"] == "ok"


# ------------------------------------------------------------- 4. memory


def test_dense_system_is_checked_before_it_is_allocated(files, tmp_path, capsys):
    from bsfjax import BSFError, Spectrum
    from bsfjax.internal import check_fmap_memory

    assert check_fmap_memory(30, available=10 ** 9) == 3 * 900 ** 2 * 4
    with pytest.raises(BSFError, match=r"k = 60: .* needs 156 MB, more than the 100 MB"):
        check_fmap_memory(60, available=10 ** 8)
    n, k = 510, 505
    rng = np.random.default_rng(0)
    s = Spectrum(evals=np.arange(k, dtype=float), evecs=rng.standard_normal((n, k)),
                 mass=np.ones(n))
    d = rng.standard_normal((n, 3))
    with pytest.raises(BSFError, match=r"k = 505: the functional-map estimate's dense .* needs"):
        bsfjax.estimate_fmap(s, s, d, d, k=505)
    with pytest.raises(BSFError, match=r"k = 505"):
        bsfjax.MapEstimator(k=505, refine_to=505)(s, s, ([0, 1], [0, 1]))
    # the command line: one line, before the spectra
    big = bsfjax.example_pair(levels=2)
    bsfjax.save_mesh(tmp_path / "a.ply", big.source)
    bsfjax.save_mesh(tmp_path / "b.ply", big.target)
    np.savetxt(tmp_path / "l.txt", big.labels, fmt="%d")
    one = ["transfer", str(tmp_path / "a.ply"), str(tmp_path / "b.ply"), "--labels",
           str(tmp_path / "l.txt"), "-k", "505"]
    assert main(one + ["--out", str(tmp_path / "o.txt")]) == 2
    assert "k = 505" in capsys.readouterr().err and not (tmp_path / "o.txt").exists()
    assert main(one + ["--out-dir", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "k = 505", "GB")


def test_batch_is_capped_at_the_targets(files):
    from bsfjax.internal import capped_batch

    import jax

    d = len(jax.local_devices())
    assert capped_batch(1000, 10, 2 * d) == 2
    assert capped_batch(1000, 10) == 1000 and capped_batch(3, 10, 100 * d) == 3
    # a collection of one target at --batch 1000 holds one copy, not 1000
    res = dict(bsfjax.transfer_collection(files / "src.ply", np.loadtxt(files / "labels.txt",
                                                                       dtype=int),
                                          [files / "tg" / "t506.ply"], k=10, batch=1000,
                                          starts=((10, 7.0),)))
    assert res[0].labels.shape == (506,)


# ------------------------------------------------------------- 5. processes


@pytest.mark.parametrize("coordinator", ["garbage", "host:abc", "host:0", ":1234", "::1:80",
                                         "host:70000"])
def test_malformed_coordinator_is_one_line(files, tmp_path, capsys, coordinator):
    argv = _argv(files, tmp_path / "o", files / "tg",
                 extra=["--coordinator", coordinator, "--num-processes", "2", "--process-id",
                        "1"])
    assert main(argv) == 2
    _one_error_line(capsys, "--coordinator must be HOST:PORT", repr(coordinator))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cli(args, env=None, timeout=60):
    env = dict(os.environ, **(env or {}))
    return subprocess.run([sys.executable, "-m", "bsfjax.cli", *args], env=env,
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("process_id", [1, 0])
def test_unreachable_coordinator_or_missing_peer_is_one_line(files, tmp_path, process_id):
    """Process 1 of 2 with no coordinator on the port; process 0 of 2 whose peer never
    comes: ``--timeout 2``, then one line and exit status 2 (not XLA's abort)."""
    argv = _argv(files, tmp_path / "o", files / "tg",
                 extra=["--coordinator", f"127.0.0.1:{_free_port()}", "--num-processes", "2",
                        "--process-id", str(process_id), "--timeout", "2"])
    r = _cli(argv, env={"JAX_PLATFORMS": "cpu"})
    err = r.stderr.strip()
    assert r.returncode == 2, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines[-1].startswith("bsfjax transfer: error: jax.distributed did not start within "
                                "--timeout 2 s"), err
    assert "Check failure" not in err and "Traceback" not in err, err


def test_unavailable_platform_is_one_line(files, tmp_path):
    r = _cli(["transfer", str(files / "src.ply"), str(files / "tg" / "t506.ply"), "--labels",
              str(files / "labels.txt"), "--out", str(tmp_path / "o.txt"), "-k", "10"],
             env={"JAX_PLATFORMS": "cuda"})
    if r.returncode == 0:  # pragma: no cover - a machine with CUDA
        pytest.skip("CUDA is available here")
    err = r.stderr.strip()
    assert r.returncode == 2 and "Traceback" not in err, err
    assert err.splitlines()[-1].startswith("bsfjax transfer: error: JAX cannot start its "
                                           "backend (JAX_PLATFORMS='cuda')"), err
