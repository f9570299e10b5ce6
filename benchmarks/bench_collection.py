"""One source to many targets: one ``bsfjax transfer ... --out-dir`` call against
separate ``bsfjax transfer ... --out`` calls, seconds per target after start-up, compilations.

    python benchmarks/bench_collection.py --out R [--quick] [--batch B] [--one-start]

Sets (meshes from ../shared/data, read by path, nothing copied into the repository):

- ``six``: six FAUST-like targets of six vertex counts (3.4K–6.9K): FAUST
  registrations 001, 002, 010, 011, 012, 021 decimated by 0–50 % with ``fast-simplification``
  (a benchmark-only dependency: ``pip install fast-simplification``), SMPL part labels from the
  source FAUST 000, truth = the label of the nearest registration vertex.
- ``faust``: FAUST 000 → every other FAUST registration and every FAUST_5k remesh (truth
  through ``sampleID.vts``).
- ``tosca``: the TOSCA cat (10K) → every other cat and wolf mesh (27.9K, 10K, 5K, 4.3K
  vertices); a 12-part Voronoi partition of the source, timing only.

For each set: the wall time of one call and of the separate calls (each a fresh process, as a
user runs them, JAX's persistent compilation cache off), the accuracy of both, the two again
with a warm compilation cache (the second of two rounds), and in one process the seconds per target once
compiled (a second pass) with the number of compilations of the first pass.
``--quick``: the ``six`` set only.  ``--batch B``: the one-call runs (``--batch B``) and the
in-process passes (``batch=B``) run B targets per device under ``vmap`` (for accelerators).
``--one-start``: every run with ``--one-start`` (``starts=((k, 7.0),)``): without landmarks
the map from one start, through the batched stages, instead of ``estimate_map``'s choice among
15 starts per target (the default; the sets here have no landmarks).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import _harness as h

DATA = h.DATA


def make_six(folder: Path, labels: np.ndarray):
    import fast_simplification
    from scipy.spatial import cKDTree

    import bsfjax

    out = []
    for name, red in zip(("001", "002", "010", "011", "012", "021"),
                         (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)):
        m = bsfjax.load_mesh(DATA / "faust" / f"tr_reg_{name}.off")
        if red:
            v, f = fast_simplification.simplify(np.asarray(m.vertices, np.float32),
                                                np.asarray(m.faces, np.int32),
                                                target_reduction=red)
            m = bsfjax.Mesh(v.astype(np.float64), f.astype(np.int64))
        path = folder / f"faust{name}_{m.n_vertices}.ply"
        bsfjax.save_mesh(path, m)
        nearest = cKDTree(bsfjax.load_mesh(DATA / "faust" / f"tr_reg_{name}.off").vertices)
        truth = labels[nearest.query(np.asarray(m.vertices))[1]]
        np.savetxt(folder / "truth" / f"{path.stem}.txt", truth, fmt="%d")
        out.append(path)
    return out


def make_faust(folder: Path, labels: np.ndarray):
    from scipy.spatial import cKDTree

    import bsfjax

    out = [p for p in sorted((DATA / "faust").glob("tr_reg_*.off")) if p.stem != "tr_reg_000"]
    for p in out:
        np.savetxt(folder / "truth" / f"{p.stem}.txt", labels, fmt="%d")
    sample = np.loadtxt(DATA / "faust_5k" / "corres" / "sampleID.vts", dtype=int) - 1
    for p in sorted((DATA / "faust_5k").glob("tr_reg_*.off")):
        corr = np.loadtxt(DATA / "faust_5k" / "corres" / f"{p.stem}.vts", dtype=int) - 1
        m = bsfjax.load_mesh(p)
        truth = np.full(m.n_vertices, -2, np.int64)
        truth[corr] = labels[sample]  # vertex corr[k] of the remesh ↔ template vertex sample[k]
        known = np.flatnonzero(truth >= 0)
        fill = cKDTree(m.vertices[known]).query(m.vertices[truth < 0])[1]
        truth[truth < 0] = truth[known[fill]]
        stem = f"{p.stem}_5k"
        link = folder / f"{stem}.off"
        link.write_bytes(p.read_bytes())
        np.savetxt(folder / "truth" / f"{stem}.txt", truth, fmt="%d")
        out.append(link)
    return DATA / "faust" / "tr_reg_000.off", out


def make_tosca(folder: Path):
    import bsfjax

    src = DATA / "tosca_10k" / "cat" / "cat0.off"
    m = bsfjax.load_mesh(src)
    centres = bsfjax.farthest_point_sampling(m, 12, seed=0)
    from scipy.spatial import cKDTree

    lab = cKDTree(m.vertices[np.asarray(centres)]).query(m.vertices)[1]
    np.savetxt(folder / "tosca_labels.txt", lab, fmt="%d")
    targets = []
    for sub in ("tosca", "tosca_10k", "tosca_5k"):
        for p in sorted((DATA / sub).glob("*/*.off")):
            if p == src:
                continue
            link = folder / f"{sub}_{p.stem}.off"
            link.write_bytes(p.read_bytes())
            targets.append(link)
    return src, folder / "tosca_labels.txt", targets


#: every bsfjax call of the comparison starts cold: JAX's persistent compilation cache is off
#: (the ``bsfjax`` command uses one by default); the warm-cache figures set their own folder
COLD = {**os.environ, "JAX_COMPILATION_CACHE_DIR": ""}


def cli(*args, env=None) -> tuple[float, str]:
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "bsfjax.cli", *map(str, args), *FLAGS],
                       capture_output=True,
                       text=True, env=COLD if env is None else env)
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-2000:])
    return time.perf_counter() - t, r.stderr


def accuracy(labels: np.ndarray, truth: np.ndarray, mesh_path: Path) -> float:
    import bsfjax

    mass = np.asarray(bsfjax.spectrum(bsfjax.load_mesh(mesh_path), 2).mass)
    return float(np.sum(mass * (labels == truth)) / mass.sum())


#: extra arguments of every ``bsfjax transfer`` call (``--one-start``)
FLAGS: list[str] = []


def measure(name, source, labels_file, targets, folder: Path, truth: bool, k: int = 30,
            batch: int = 1) -> dict:
    out_one, out_sep = folder / f"{name}_one", folder / f"{name}_sep"
    out_sep.mkdir()
    extra = (["--truth-dir", folder / "truth"] if truth else []) + ["--batch", batch]
    wall_one, _ = cli("transfer", source, *targets, "--labels", labels_file, "--out-dir", out_one,
                      "-k", k, "--no-progress", *extra)
    summary = json.loads((out_one / "summary.json").read_text())["targets"]
    wall_sep = 0.0
    acc_one, acc_sep = [], []
    for p, row in zip(targets, summary):
        t, _ = cli("transfer", source, p, "--labels", labels_file, "--out",
                   out_sep / f"{p.stem}.txt", "-k", k)
        wall_sep += t
        if truth:
            tr = np.loadtxt(folder / "truth" / f"{p.stem}.txt", dtype=int)
            acc_sep.append(accuracy(np.loadtxt(out_sep / f"{p.stem}.txt", dtype=int), tr, p))
            acc_one.append(row["accuracy"])
    # the same two ways with a warm compilation cache (a second run of the same commands)
    warm = {**os.environ, "JAX_COMPILATION_CACHE_DIR": str(folder / f"{name}_jax_cache")}
    for rnd in (1, 2):
        w1, _ = cli("transfer", source, *targets, "--labels", labels_file, "--out-dir",
                    folder / f"{name}_warm{rnd}", "-k", k, "--no-progress", "--batch", batch,
                    env=warm)
        ws = sum(cli("transfer", source, p, "--labels", labels_file, "--out",
                     folder / f"{name}_warm{rnd}_{p.stem}.txt", "-k", k, env=warm)[0]
                 for p in targets)
    steady = in_process(source, labels_file, targets, k, batch)
    steady.update(wall_one_call_warm_cache_s=w1, wall_separate_calls_warm_cache_s=ws)
    if name == "six":
        steady["kill_and_resume"] = kill_and_resume(source, labels_file, targets, folder,
                                                    out_one, k)
    res = {"set": name, "targets": len(targets), "batch": batch,
           "vertices": [r["vertices"] for r in summary],
           "wall_one_call_s": wall_one, "wall_separate_calls_s": wall_sep,
           "speedup": wall_sep / wall_one, **steady}
    if truth:
        res.update(accuracy_one_call=float(np.mean(acc_one)),
                   accuracy_separate=float(np.mean(acc_sep)))
    return res


def kill_and_resume(source, labels_file, targets, folder: Path, reference: Path, k: int) -> dict:
    """Kill a one-call run (SIGKILL) once two targets are written, start it again: the rerun
    must compute only the missing targets, and the files must equal the uninterrupted run's."""
    import signal

    out = folder / "killed"
    argv = [sys.executable, "-m", "bsfjax.cli", "transfer", str(source), *map(str, targets),
            "--labels", str(labels_file), "--out-dir", str(out), "-k", str(k), "--no-progress",
            *FLAGS]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=COLD)
    while proc.poll() is None and len(list(out.glob("[!.]*.txt"))) < 2:  # not temporaries
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done_before = sorted(p.name for p in out.glob("[!.]*.txt"))
    leftovers = [p.name for p in out.iterdir() if p.name.startswith(".")]
    r = subprocess.run(argv, capture_output=True, text=True, env=COLD)
    leftovers_after_rerun = [p.name for p in out.iterdir() if p.name.startswith(".")]
    line = next(ln for ln in r.stderr.splitlines() if "complete (skipped)" in ln)
    same = all((out / f"{p.stem}.txt").read_bytes() == (reference / f"{p.stem}.txt").read_bytes()
               for p in targets)
    return {"killed_after": done_before, "temporaries_left": leftovers,
            "temporaries_after_rerun": leftovers_after_rerun, "rerun": line,
            "rerun_status": r.returncode, "files_equal_uninterrupted": same}


def in_process(source, labels_file, targets, k, batch: int = 1) -> dict:
    """First pass (compilations counted) and second pass (compiled) in one process."""
    code = f"""
import json, time, numpy as np, warnings
warnings.filterwarnings("ignore")
from jax import monitoring
import bsfjax
n = [0]
monitoring.register_event_duration_secs_listener(
    lambda ev, d, **kw: n.__setitem__(0, n[0] + (ev == "/jax/core/compile/backend_compile_duration")))
lab = np.loadtxt({str(labels_file)!r}, dtype=int)
targets = {[str(t) for t in targets]!r}
out = {{}}
for p in (1, 2):
    c0, t = n[0], time.perf_counter()
    res = dict(bsfjax.transfer_collection({str(source)!r}, lab, targets, k={k}, batch={batch},
                                          starts={((k, 7.0),) if FLAGS else None!r}))
    out[p] = dict(seconds=time.perf_counter() - t, compiles=n[0] - c0,
                  per_target=[res[i].seconds for i in range(len(targets))],
                  vertices=[res[i].n_vertices for i in range(len(targets))])
print(json.dumps(out))
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=COLD)
    if r.returncode != 0:
        raise RuntimeError(r.stderr[-2000:])
    out = json.loads(r.stdout.strip().splitlines()[-1])
    first, second = out["1"], out["2"]
    per = np.asarray(second["per_target"])
    verts = np.asarray(second["vertices"])
    near5k = (verts >= 4000) & (verts <= 6000)
    return {"first_pass_s": first["seconds"], "compilations_first_pass": first["compiles"],
            "compilations_second_pass": second["compiles"],
            "second_pass_s": second["seconds"],
            "seconds_per_target_compiled": float(per.mean()),
            "seconds_per_5k_target_compiled": float(per[near5k].mean()) if near5k.any() else None}


def main() -> None:
    ap = h.parser(__doc__)
    h.add_out(ap)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--batch", type=int, default=1, help="targets per device under vmap")
    ap.add_argument("--one-start", action="store_true",
                    help="without landmarks, one start per map (the batched stages)")
    args = ap.parse_args()
    h.require_data(DATA / h.SMPL_SEGMENTATION, DATA / "faust", option=None)
    if args.one_start:
        FLAGS.append("--one-start")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    labels = h.smpl_labels(DATA)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "truth").mkdir()
        np.savetxt(folder / "smpl.txt", labels, fmt="%d")
        sets = [("six", DATA / "faust" / "tr_reg_000.off", folder / "smpl.txt",
                 make_six(folder, labels), True)]
        if not args.quick:
            src, faust = make_faust(folder, labels)
            sets.append(("faust", src, folder / "smpl.txt", faust, True))
            src, lab, tosca = make_tosca(folder)
            sets.append(("tosca", src, lab, tosca, False))
        for name, src, lab, targets, truth in sets:
            r = measure(name, src, lab, targets, folder, truth, batch=args.batch)
            rows.append(r)
            print(json.dumps(r), flush=True)
    h.write_json(out / "collection.json", rows, indent=1)
    lines = ["| set | targets | vertices | one call | separate calls | speed-up | s/target "
             "compiled | s/5K target | compilations | accuracy one / separate | warm "
             "compilation cache: one / separate |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        acc = (f"{100 * r['accuracy_one_call']:.2f} / {100 * r['accuracy_separate']:.2f} %"
               if "accuracy_one_call" in r else "—")
        s5k = r["seconds_per_5k_target_compiled"]
        lines.append(f"| {r['set']} | {r['targets']} | {min(r['vertices'])}–{max(r['vertices'])} "
                     f"| {r['wall_one_call_s']:.1f} s | {r['wall_separate_calls_s']:.1f} s | "
                     f"**{r['speedup']:.2f}×** | {r['seconds_per_target_compiled']:.2f} s | "
                     f"{'—' if s5k is None else f'{s5k:.2f} s'} | "
                     f"{r['compilations_first_pass']} (then {r['compilations_second_pass']}) | "
                     f"{acc} | {r['wall_one_call_warm_cache_s']:.1f} s / "
                     f"{r['wall_separate_calls_warm_cache_s']:.1f} s |")
    h.write_text(out / "collection.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
