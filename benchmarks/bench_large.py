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

import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np

import _harness as h
import bsfjax
from _harness import GIB, PeakRSS


def cached_spectra(data: Path, levels: int, k: int, cache: Path, method: str = "auto",
                   decimate: int | None = None):
    """Spectra of the pair, computed (if not cached) in a child process."""
    code = ("import sys; sys.path.insert(0, {bench!r}); from pathlib import Path; "
            "from _harness import cat_pair; import bsfjax; "
            "[bsfjax.spectrum(m, {k}, cache_dir={cache!r}, method={method!r}) for m in "
            "cat_pair(Path({data!r}), {levels}, {decimate!r})]").format(
                bench=str(h.BENCHMARKS), k=k, cache=str(cache),
                data=str(data), levels=levels, method=method, decimate=decimate)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True)
    return time.perf_counter() - t0


def stage(name, fn, rows):
    with PeakRSS() as mem:
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn())
        dt = time.perf_counter() - t0
    rows.append({"stage": name, "seconds": dt, "peak_rss_gib": mem.peak / GIB})
    print(f"{name:34s} {dt:9.2f} s   peak RSS {mem.peak / GIB:6.2f} GiB", flush=True)
    return out


def run(data: Path, levels: int, k: int, n_functions: int, cache: Path, sparsity: int = 10,
        method: str = "auto", fraction: float = 0.05, decimate: int | None = None):
    t_spec = cached_spectra(data, levels, k, cache, method, decimate)
    rows = []
    src_mesh, tgt_mesh = stage("load + Loop subdivision (both)",
                               lambda: h.cat_pair(data, levels, decimate), rows)
    src = stage("load cached spectrum (source)",
                lambda: bsfjax.spectrum(src_mesh, k, cache_dir=cache, method=method), rows)
    tgt = stage("load cached spectrum (target)",
                lambda: bsfjax.spectrum(tgt_mesh, k, cache_dir=cache, method=method), rows)
    n = src_mesh.n_vertices
    centers = stage(f"farthest_point_sampling {fraction:.1%}",
                    lambda: bsfjax.farthest_point_sampling(src_mesh, fraction), rows)
    frame = stage("build_frame (sparse)", lambda: bsfjax.build_frame(src, centers, sparse=True),
                  rows)
    F = h.random_regions(src_mesh, np.asarray(src.mass), n_functions, seed=0).astype(np.float32)
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
        "stages": rows, "machine": h.describe_machine(),
        "note": "single runs, compile time included; spectra computed once in a child process",
    }
    print(json.dumps({k_: v for k_, v in result.items() if k_ != "stages"}, indent=1))
    return result


def main(argv=None):
    ap = h.parser(__doc__)
    h.add_out(ap, type=Path, help="JSON file to write")
    h.add_data(ap)
    ap.add_argument("--levels", type=int, default=1, help="Loop subdivisions of the cat")
    ap.add_argument("--k", type=int, default=100)
    ap.add_argument("--functions", type=int, default=100)
    h.add_cache(ap, h.TMP_CACHE, type=Path, help="spectrum cache folder")
    ap.add_argument("--method", default="auto", help="bsfjax.spectrum's method ('fast': the "
                    "approximate eigensolver, to see its effect on the transfer error)")
    ap.add_argument("--fraction", type=float, default=0.05,
                    help="share of the vertices sampled as atom centres (default 0.05)")
    ap.add_argument("--decimate", type=int, default=None, help="decimate both refined meshes "
                    "to about this many vertices (same collapses; needs fast_simplification)")
    args = ap.parse_args(argv)
    h.require_data(*(args.data / "tosca" / "cat" / f"cat{i}.off" for i in (0, 6)))
    result = run(args.data, args.levels, args.k, args.functions, args.cache,
                 method=args.method, fraction=args.fraction, decimate=args.decimate)
    h.write_json(args.out, result)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
