"""Benchmark: the BSF pipeline after the eigensolve on a large mesh, time and peak memory.

The full-resolution TOSCA cat (``tosca/cat/cat0.off``, 27894 V) Loop-subdivided ``--levels``
times (1: 111 K vertices, 2: 445 K), transferred to ``cat6`` subdivided the same way.  ``cat6``
has cat0's vertices in correspondence but a partly different triangulation (see the data
README), so it is subdivided on **cat0's face array**: vertex ``i`` ↔ vertex ``i`` then holds
for every vertex of the refined pair (identity correspondence), at the price of cat0's edges
on cat6's pose.  Stages, all with a :class:`bsfjax.SparseFrame` (the dense frame would be
``n × q × 4`` bytes: 7.4 GB at 111 K):

With ``--decimate N`` both refined meshes are then decimated to about ``N`` vertices by
``fast_simplification`` (benchmark-only dependency): the source's quadric edge collapses are
replayed on both meshes (``replay_simplification``), so the pair keeps one face array and the
identity correspondence (``--levels 3 --decimate 1000000``: the 1M-vertex run).

1. spectra, k = 100 (``bsfjax.spectrum`` in a child process, cached in ``--cache``; the
   measured process only loads them, so its peak memory excludes the eigensolver);
2. farthest point sampling of ``--fraction`` (default 5 %) of the vertices (euclidean);
3. ``build_frame(..., sparse=True)``, the paper's three scales, γ = 0.75;
4. ``encode`` of ``--functions`` random connected regions (indicators of 5–25 % of the area,
   as in ``bench_coding.py``) with ``omp`` (sparsity 10), all in one batch;
5. decoding the codes on the source (the approximation) and its relative error;
6. ``transfer_frame`` with the identity functional map ``C = fmap_from_p2p(identity)``;
7. decoding the codes on the target (the transferred functions) and their relative error.

The source frame stays alive through the transfer and the final decode, as in a user's script
(``frame``, ``alpha``, ``transfer_frame(frame, C, target)``, ``decode``).

Times are single runs (these stages take seconds to minutes) and include JAX's compile time,
as a first call by a user would.  Memory: peak resident set size of the process
(``resource.getrusage``) and, per stage, the peak sampled every 20 ms by a background thread
(``psutil``).  Writes JSON to ``--out``.

    python benchmarks/bench_large.py --out bench-results/large.json --levels 1
    python benchmarks/bench_large.py --out large-fast.json --levels 1 --method fast
    python benchmarks/bench_large.py --out large1m.json --levels 3 --decimate 1000000 \
        --fraction 0.022
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

import jax
import numpy as np

import bsfjax
from bsfjax.internal import write_text_atomic
from bsfjax.internal import subdivide

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_coding import random_regions  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
GIB = 2**30


def cat_pair(data: Path, levels: int, decimate: int | None = None):
    """cat0 and cat6 (on cat0's faces) Loop-subdivided ``levels`` times, then (``decimate``)
    both decimated to about that many vertices by the same edge collapses; identity map."""
    m0 = bsfjax.load_mesh(data / "tosca" / "cat" / "cat0.off")
    m6 = bsfjax.load_mesh(data / "tosca" / "cat" / "cat6.off")
    m6 = bsfjax.Mesh(m6.vertices, m0.faces, name="cat6 on cat0 faces")
    s0, s6 = subdivide(m0, "loop", levels), subdivide(m6, "loop", levels)
    if not decimate:
        return s0, s6
    import fast_simplification as fs

    faces = np.asarray(s0.faces, np.int32)
    target = 2 * int(decimate) + (faces.shape[0] - 2 * s0.n_vertices)  # Euler: F − 2V fixed
    _, _, collapses = fs.simplify(np.asarray(s0.vertices, np.float32), faces,
                                  target_count=target, return_collapses=True)
    out = []
    for m in (s0, s6):
        v, f, _ = fs.replay_simplification(np.asarray(m.vertices, np.float32), faces, collapses)
        out.append(bsfjax.Mesh(np.asarray(v, np.float64), np.asarray(f, np.int64),
                               name=f"{m.name} decimated"))
    return tuple(out)


def cached_spectra(data: Path, levels: int, k: int, cache: Path, method: str = "auto",
                   decimate: int | None = None):
    """Spectra of the pair, computed (if not cached) in a child process."""
    code = ("import sys; sys.path.insert(0, {bench!r}); from bench_large import cat_pair, "
            "Path; import bsfjax; "
            "[bsfjax.spectrum(m, {k}, cache_dir={cache!r}, method={method!r}) for m in "
            "cat_pair(Path({data!r}), {levels}, {decimate!r})]").format(
                bench=str(Path(__file__).resolve().parent), k=k, cache=str(cache),
                data=str(data), levels=levels, method=method, decimate=decimate)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True)
    return time.perf_counter() - t0


class PeakRSS:
    """Peak resident set size of this process over a ``with`` block (sampled every 20 ms)."""

    def __init__(self):
        import psutil

        self._proc = psutil.Process()
        self.peak = 0

    def _run(self):
        while not self._stop.is_set():
            self.peak = max(self.peak, self._proc.memory_info().rss)
            self._stop.wait(0.02)

    def __enter__(self):
        self._stop = threading.Event()
        self.peak = self._proc.memory_info().rss
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, self._proc.memory_info().rss)


def stage(name, fn, rows):
    with PeakRSS() as mem:
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn())
        dt = time.perf_counter() - t0
    rows.append({"stage": name, "seconds": dt, "peak_rss_gib": mem.peak / GIB})
    print(f"{name:34s} {dt:9.2f} s   peak RSS {mem.peak / GIB:6.2f} GiB", flush=True)
    return out


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / GIB
    return (f"{cpu}, {os.cpu_count()} cores, {mem:.0f} GiB RAM, {platform.system()}; "
            f"jax {jax.__version__} {jax.default_backend()} ({jax.device_count()} device(s))")


def run(data: Path, levels: int, k: int, n_functions: int, cache: Path, sparsity: int = 10,
        method: str = "auto", fraction: float = 0.05, decimate: int | None = None):
    t_spec = cached_spectra(data, levels, k, cache, method, decimate)
    rows = []
    src_mesh, tgt_mesh = stage("load + Loop subdivision (both)",
                               lambda: cat_pair(data, levels, decimate), rows)
    src = stage("load cached spectrum (source)",
                lambda: bsfjax.spectrum(src_mesh, k, cache_dir=cache, method=method), rows)
    tgt = stage("load cached spectrum (target)",
                lambda: bsfjax.spectrum(tgt_mesh, k, cache_dir=cache, method=method), rows)
    n = src_mesh.n_vertices
    centers = stage(f"farthest_point_sampling {fraction:.1%}",
                    lambda: bsfjax.farthest_point_sampling(src_mesh, fraction), rows)
    frame = stage("build_frame (sparse)", lambda: bsfjax.build_frame(src, centers, sparse=True),
                  rows)
    F = random_regions(src_mesh, np.asarray(src.mass), n_functions, seed=0).astype(np.float32)
    alpha = stage(f"encode {n_functions} functions omp S={sparsity}",
                  lambda: bsfjax.encode(frame, F, "omp", sparsity=sparsity, weights=None), rows)
    approx = stage("decode on source (approximation)", lambda: bsfjax.decode(frame, alpha), rows)
    err_a = np.asarray(bsfjax.relative_error(F, approx, src.mass))
    del approx
    C = stage("fmap_from_p2p (identity)", lambda: bsfjax.fmap_from_p2p(src, tgt, np.arange(n)),
              rows)
    tframe = stage("transfer_frame (sparse)", lambda: bsfjax.transfer_frame(frame, C, tgt), rows)
    moved = stage("decode on target", lambda: bsfjax.decode(tframe, alpha), rows)
    err_t = np.asarray(bsfjax.relative_error(F, moved, tgt.mass))
    q = frame.n_atoms
    pipeline = sum(r["seconds"] for r in rows if r["stage"].startswith(
        ("farthest", "build_frame", "encode", "fmap_from", "transfer_frame", "decode")))
    lists_bytes = sum(0 if a is None else a.nbytes for a in (frame.atom_lists,
                                                             frame.atom_segments))
    result = {
        "mesh": f"tosca/cat/cat0.off -> cat6.off, Loop x{levels}"
                + (f", decimated to {decimate} (fast_simplification, replayed)"
                   if decimate else ""),
        "n_vertices": n, "n_faces": int(src_mesh.faces.shape[0]), "k": k,
        "spectrum_method": method, "fraction": fraction, "n_atoms": q,
        "n_functions": n_functions,
        "sparsity": sparsity, "nnz": frame.nnz, "atom_list_width": int(frame.atom_lists.shape[1]),
        "density": frame.nnz / (n * q),
        "dense_frame_gib_float32": n * q * 4 / GIB,
        "sparse_frame_gib": lists_bytes / GIB,
        "lists_dtype": str(frame.atom_lists.dtype),
        "target_nnz": tframe.nnz,
        "spectrum_child_seconds": t_spec,
        "pipeline_seconds_after_eigensolve": pipeline,
        "peak_rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / GIB,
        "relative_error_approximation_median": float(np.median(err_a)),
        "relative_error_transfer_median": float(np.median(err_t)),
        "stages": rows, "machine": machine(),
        "note": "single runs, compile time included; spectra computed once in a child process",
    }
    print(json.dumps({k_: v for k_, v in result.items() if k_ != "stages"}, indent=1))
    return result


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="JSON file to write")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--levels", type=int, default=1, help="Loop subdivisions of the cat")
    ap.add_argument("--k", type=int, default=100)
    ap.add_argument("--functions", type=int, default=100)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/bsfjax-spectra"))
    ap.add_argument("--method", default="auto", help="bsfjax.spectrum's method ('fast': the "
                    "approximate eigensolver, to see its effect on the transfer error)")
    ap.add_argument("--fraction", type=float, default=0.05,
                    help="share of the vertices sampled as atom centres (default 0.05)")
    ap.add_argument("--decimate", type=int, default=None, help="decimate both refined meshes "
                    "to about this many vertices (same collapses; needs fast_simplification)")
    args = ap.parse_args(argv)
    result = run(args.data, args.levels, args.k, args.functions, args.cache,
                 method=args.method, fraction=args.fraction, decimate=args.decimate)
    write_text_atomic(args.out, json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
