"""Large raw-scan-like targets without landmarks: the whole ``bsfjax transfer`` command, its
accuracy, wall time and peak memory.

The target is built deterministically from a FAUST registration ``tr_reg_T``: Loop-subdivided
twice (``bsfjax.internal.subdivide``: 110K vertices), Gaussian vertex noise of σ = 0.1 % of the
height, 5 holes (every vertex within 3 % of the height of a seeded centre, geodesically along
the edges, removed with its triangles; a disc that would cut a piece off is drawn again), a
stray fragment of 3 triangles 0.5 m away, 20 unreferenced vertices in the file, and the vertex
rows shuffled (a scanner's order). Truth per file row: the SMPL part of the nearest vertex of
the registration (the subdivided, noiseless position). The source is the registration
``tr_reg_S`` (6890 vertices) with its SMPL parts.

For each pair the command ``bsfjax transfer SOURCE TARGET --labels L --out O`` (no landmarks,
every option at its default) runs in a child process of its own: the wall time of the whole
command (start-up, reading, spectra, map, transfer, writing; JAX's compilation included) and its
CPU seconds (user and system: on a loaded machine the wall time is not the command's own), the
child's peak resident set size (``wait4``), the accuracy (share of the target's area labelled
right, barycentric vertex areas of the file's mesh; unreferenced rows have none), and the checks
that the output has one row per file row and ``-1`` on the unreferenced ones. The clean pair
``tr_reg_S → tr_reg_T`` (no landmarks) runs the same way as the reference.

    python benchmarks/bench_scans_large.py --out R.md
    python benchmarks/bench_scans_large.py --out R.md --pairs 0-10 --clean-off
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _harness as h

#: The child process: ``bsfjax transfer`` that reports its own peak resident memory
#: (``VmHWM`` of /proc/self/status, this process's high-water mark since its exec) on its
#: last stderr line.  ``wait4``'s ``ru_maxrss`` would include the parent's memory at the fork
#: (Linux carries it across fork and exec): in a whole-suite run every child read 4.09 GB.
CHILD = ("import sys\nfrom bsfjax.cli import main\ncode = main(sys.argv[1:])\n"
         "hwm = [line for line in open('/proc/self/status') if line.startswith('VmHWM')]\n"
         "print('PEAK_KB', hwm[0].split()[1] if hwm else -1, file=sys.stderr)\nsys.exit(code)")

#: The defaults of the scan-like target, as fractions of the height where so said.
SIGMA, HOLES, HOLE_RADIUS, FRAGMENT_OFFSET, STRAYS, LEVELS = 0.001, 5, 0.03, 0.5, 20, 2


def write_off(path: Path, vertices, faces) -> None:
    import numpy as np

    with open(path, "w") as f:
        f.write(f"OFF\n{len(vertices)} {len(faces)} 0\n")
        np.savetxt(f, vertices, fmt="%.6f")
        np.savetxt(f, np.column_stack([np.full(len(faces), 3), faces]), fmt="%d")


def raw_scan(data: Path, number: int, seed: int, sigma=SIGMA, holes=HOLES, levels=LEVELS):
    """The scan-like target of registration ``number``: ``(vertices, faces, truth)`` in file
    rows (truth: the SMPL part of the nearest registration vertex)."""
    import numpy as np
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components, dijkstra
    from scipy.spatial import cKDTree

    import bsfjax
    from bsfjax.internal import subdivide

    reg = bsfjax.load_mesh(data / "faust" / f"tr_reg_{number:03d}.off")
    labels = h.smpl_labels(data)
    fine = subdivide(reg, "loop", levels)
    v0, f = np.asarray(fine.vertices, np.float64), np.asarray(fine.faces)
    truth = labels[cKDTree(np.asarray(reg.vertices)).query(v0)[1]]
    rng = np.random.default_rng(seed)
    height = float(np.ptp(v0, axis=0).max())
    v = v0 + rng.normal(scale=sigma * height, size=v0.shape)
    # holes: every vertex within HOLE_RADIUS (geodesic, along the edges) of a seeded centre
    # goes, with its triangles: discs of the surface, as a scanner misses them
    e = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1), axis=0)
    w = np.linalg.norm(v0[e[:, 0]] - v0[e[:, 1]], axis=1)
    graph = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(v0),) * 2).tocsr()
    # (a disc that would cut a piece off, fingers at their base, is drawn again: holes, not cuts)
    gone = np.zeros(len(v0), bool)
    while holes:
        disc = np.isfinite(dijkstra(graph, directed=False, indices=rng.integers(len(v0)),
                                    limit=HOLE_RADIUS * height))
        kept = f[~(gone | disc)[f].any(axis=1)]
        used = np.unique(kept)
        n_parts = connected_components(sp.coo_matrix(
            (np.ones(3 * len(kept)), (kept.ravel(), np.roll(kept, 1, axis=1).ravel())),
            shape=(len(v0),) * 2), directed=False)[0] - (len(v0) - used.size)
        if n_parts == 1:
            gone |= disc
            holes -= 1
    f = f[~gone[f].any(axis=1)]
    keep = np.zeros(len(v0), bool)
    keep[f.ravel()] = True
    new = np.cumsum(keep) - 1
    v, truth, f = v[keep], truth[keep], new[f]
    # a stray fragment: 3 triangles (a fan around a vertex's neighbours) moved 0.5 m
    t0 = f[rng.integers(len(f))]
    fan = f[np.isin(f, t0).any(axis=1)][:3]
    ids, inv = np.unique(fan, return_inverse=True)
    frag_v = v[ids] + np.array([FRAGMENT_OFFSET, 0.0, 0.0])
    f = np.concatenate([f, len(v) + inv.reshape(-1, 3)])
    v, truth = np.concatenate([v, frag_v]), np.concatenate([truth, truth[ids]])
    # unreferenced vertices: points near the body, in no triangle (truth -1: no area)
    lo, hi = v0.min(0), v0.max(0)
    v = np.concatenate([v, lo + rng.random((STRAYS, 3)) * (hi - lo)])
    truth = np.concatenate([truth, np.full(STRAYS, -1)])
    # a scanner's order: rows shuffled, triangles too
    order = rng.permutation(len(v))
    rank = np.empty_like(order)
    rank[order] = np.arange(len(v))
    f = rank[f][rng.permutation(len(f))]
    return v[order], f, truth[order]


def file_areas(vertices, faces):
    """Barycentric vertex areas of the file's rows (0 on unreferenced rows)."""
    import numpy as np

    tri = vertices[faces]
    a = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    out = np.zeros(len(vertices))
    np.add.at(out, faces.ravel(), np.repeat(a / 3, 3))
    return out


def run_command(source, target, labels, out, extra=()) -> dict:
    """``bsfjax transfer`` in a child process: wall seconds, peak RSS (GB), stderr."""
    cmd = [sys.executable, "-c", CHILD, "transfer", str(source), str(target),
           "--labels", str(labels), "--out", str(out), *extra]
    with tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, cwd=Path(out).parent,
                                env={**os.environ,
                                     "PYTHONPATH": os.environ.get("PYTHONPATH", str(h.ROOT))})
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - t0
        err.seek(0)
        text = err.read()
    if os.waitstatus_to_exitcode(status):
        raise RuntimeError(f"bsfjax transfer failed: {text}")
    lines = text.splitlines()
    peak_kb = usage.ru_maxrss  # (where /proc has no VmHWM: the rusage, an upper bound)
    if lines and lines[-1].startswith("PEAK_KB") and int(lines[-1].split()[1]) > 0:
        peak_kb, text = int(lines[-1].split()[1]), "\n".join(lines[:-1])
    return dict(seconds=round(seconds, 1), peak_rss_gb=round(peak_kb / 1e6, 2),
                cpu_seconds=round(usage.ru_utime + usage.ru_stime, 1), stderr=text)


def run(data: Path, folder: Path, pairs, seed: int, clean: bool, extra=()) -> list[dict]:
    import numpy as np

    labels = folder / "smpl.txt"
    np.savetxt(labels, h.smpl_labels(data), fmt="%d")
    rows = []
    for s, t in pairs:
        source = data / "faust" / f"tr_reg_{s:03d}.off"
        v, f, truth = raw_scan(data, t, seed + t)
        target = folder / f"scan_{t:03d}.off"
        write_off(target, v, f)
        out = folder / f"out_{s}_{t}.txt"
        res = run_command(source, target, labels, out, extra)
        got = np.loadtxt(out, dtype=np.int64)
        area = file_areas(v, f)
        row = dict(pair=f"{s:03d}→{t:03d}", target="raw scan", vertices=len(v), faces=len(f),
                   rows_ok=bool(got.shape == truth.shape),
                   strays_unassigned=bool(np.all(got[truth == -1] == -1)),
                   accuracy=round(100 * float(np.sum(area * (got == truth)) / area.sum()), 2),
                   seconds=res["seconds"], cpu_seconds=res["cpu_seconds"],
                   peak_rss_gb=res["peak_rss_gb"],
                   log=[ln for ln in res["stderr"].splitlines() if "warning" not in ln][-8:])
        print(row, flush=True)
        rows.append(row)
        if clean:
            reg = data / "faust" / f"tr_reg_{t:03d}.off"
            res = run_command(source, reg, labels, out, extra)
            got = np.loadtxt(out, dtype=np.int64)
            m = __import__("bsfjax").load_mesh(reg)
            area = file_areas(np.asarray(m.vertices, np.float64), np.asarray(m.faces))
            row = dict(pair=f"{s:03d}→{t:03d}", target="clean", vertices=6890,
                       accuracy=round(100 * float(np.sum(area * (got == h.smpl_labels(data)))
                                                  / area.sum()), 2),
                       seconds=res["seconds"], cpu_seconds=res["cpu_seconds"],
                       peak_rss_gb=res["peak_rss_gb"])
            print(row, flush=True)
            rows.append(row)
    return rows


def table(rows) -> str:
    lines = ["| pair | target | vertices | accuracy | seconds | CPU seconds | peak RSS GB | "
             "one row per file row |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ok = "" if "rows_ok" not in r else ("yes" if r["rows_ok"] and r["strays_unassigned"]
                                            else "NO")
        lines.append(f"| {r['pair']} | {r['target']} | {r['vertices']} | {r['accuracy']:.1f} % | "
                     f"{r['seconds']} | {r['cpu_seconds']} | {r['peak_rss_gb']} | {ok} |")
    return "\n".join(lines) + "\n"


def main():
    ap = h.parser(__doc__)
    h.add_out(ap, help="output Markdown file (a .json of the rows beside it)")
    h.add_data(ap)
    ap.add_argument("--pairs", default="0-10,1-11",
                    help="source-target registration numbers, comma-separated (default 0-10,1-11)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the noise, holes and order "
                    "(plus the target's number)")
    ap.add_argument("--clean-off", action="store_true", help="skip the clean reference pairs")
    ap.add_argument("--keep", type=Path, help="write the scan-like targets to this folder")
    args, extra = ap.parse_known_args()
    h.require_data(h.Path(args.data) / "faust", h.Path(args.data) / h.SMPL_SEGMENTATION)
    pairs = h.pair_list(args.pairs)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        rows = run(Path(args.data), folder, pairs, args.seed, not args.clean_off, extra)
    text = table(rows) + f"\n{h.cpus_note(load=True)}.\n"
    print(text)
    h.write_text(args.out, text)
    h.write_json(h.Path(args.out).with_suffix(".json"), {"rows": rows})


if __name__ == "__main__":
    main()
