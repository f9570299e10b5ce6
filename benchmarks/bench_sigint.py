"""Ctrl-C at random moments of a FAUST transfer: no segfault, no traceback, no
partial or temporary file.

Runs ``python -m bsfjax.cli transfer`` on two FAUST registrations (labels from the SMPL part
segmentation, the identity point map, ``--out`` and ``--mesh-out``) ``N`` times, each into a
fresh output folder, and sends SIGINT at a moment drawn uniformly from ``[0, T]``, ``T`` the
duration of an uninterrupted run (measured first).  Each run must end with status 130
(interrupted) or 0 (finished first), never by a signal (a negative status: SIGSEGV is -11);
its stderr must not contain ``Traceback``; its folder must hold nothing (130) or both complete
outputs (0, or 130 when the signal came after the commit); no temporary file may be left.

    PYTHONPATH=. python benchmarks/bench_sigint.py --runs 100 [--seed 0]

Needs ../shared/data (FAUST registrations and the SMPL segmentation).  Prints a table.
"""

from __future__ import annotations

import collections
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _harness as h

#: The code under test: this checkout, or BSFJAX_ROOT (e.g. a `git archive` snapshot, so that
#: editing the checkout during a long run does not change the code being interrupted).
ROOT = Path(os.environ.get("BSFJAX_ROOT", h.ROOT))
DATA = h.DATA if h.DATA.exists() else Path("/work/shared/data")


def _inputs(work: Path) -> list[str]:
    import numpy as np

    np.savetxt(work / "labels.txt", h.smpl_labels(DATA), fmt="%d")
    np.savetxt(work / "p2p.txt", np.arange(6890), fmt="%d")
    return [str(DATA / "faust" / "tr_reg_000.off"), str(DATA / "faust" / "tr_reg_001.off"),
            "--labels", str(work / "labels.txt"), "--map", "p2p", str(work / "p2p.txt"),
            "-k", "30"]


def _run(args: list[str], out: Path, delay: float | None) -> tuple[int, str, float]:
    out.mkdir()
    cmd = [sys.executable, "-m", "bsfjax.cli", "transfer", *args, "--out", str(out / "out.txt"),
           "--mesh-out", str(out / "out.ply")]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    if delay is not None:
        time.sleep(delay)
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    _, err = p.communicate()
    return p.returncode, err.decode(errors="replace"), time.perf_counter() - t0


def _check_folder(out: Path, rc: int) -> str:
    """'' if the folder is as it must be, else what is wrong."""
    names = sorted(p.name for p in out.iterdir())
    if any(n.startswith(".") for n in names):
        return f"temporary files left: {names}"
    if not names:
        return "" if rc == 130 else "no output after status 0"
    if names != ["out.ply", "out.txt"]:
        return f"partial outputs: {names}"
    lines = (out / "out.txt").read_text().splitlines()
    if len(lines) != 6890:
        return f"out.txt has {len(lines)} lines"
    return ""


def main() -> None:
    ap = h.parser(__doc__)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    h.require_data(*(DATA / "faust" / f"tr_reg_00{i}.off" for i in (0, 1)),
                   DATA / h.SMPL_SEGMENTATION, option=None)
    # a benchmark started in the background (nohup … &) inherits SIGINT ignored, and so would
    # every child (an ignored signal stays ignored across exec): give them the default
    signal.signal(signal.SIGINT, signal.default_int_handler)
    rng = random.Random(a.seed)
    with tempfile.TemporaryDirectory(prefix="bench_sigint_") as tmp:
        work = Path(tmp)
        args = _inputs(work)
        rc, err, full = _run(args, work / "calibration", None)
        assert rc == 0, err
        print(f"uninterrupted run: {full:.1f} s; {a.runs} runs with SIGINT at U(0, {full:.1f}) s",
              flush=True)
        codes = collections.Counter()
        tracebacks, signals, bad_folders, extra_lines = [], [], [], []
        for i in range(a.runs):
            delay = rng.uniform(0.0, full)
            rc, err, _ = _run(args, work / f"run{i:03d}", delay)
            codes[rc] += 1
            if "Traceback" in err:
                tracebacks.append((i, delay, err.strip().splitlines()[-3:]))
            if rc < 0:
                signals.append((i, delay, rc))
            wrong = _check_folder(work / f"run{i:03d}", rc)
            if wrong:
                bad_folders.append((i, delay, wrong))
            if rc == 130 and err.strip().splitlines()[-1:] != ["bsfjax: interrupted"]:
                extra_lines.append((i, delay, err.strip().splitlines()[-1:]))
            print(f"run {i:3d}: SIGINT at {delay:5.2f} s -> status {rc}"
                  + (f"  !! {wrong}" if wrong else ""), flush=True)
            if rc not in (0, 130) or wrong or "Traceback" in err:
                print("    stderr: " + " | ".join(err.strip().splitlines()[-4:]), flush=True)
        print("\n| runs | exit status (count) | tracebacks | killed by a signal | bad folders "
              "| last stderr line not 'bsfjax: interrupted' |")
        print("|---|---|---|---|---|---|")
        hist = ", ".join(f"{k}: {v}" for k, v in sorted(codes.items()))
        print(f"| {a.runs} | {hist} | {len(tracebacks)} | {len(signals)} | {len(bad_folders)} "
              f"| {len(extra_lines)} |")
        for what, rows in (("tracebacks", tracebacks), ("signals", signals),
                           ("bad folders", bad_folders), ("other last lines", extra_lines)):
            if rows:
                print(what, rows[:10])


if __name__ == "__main__":
    main()
