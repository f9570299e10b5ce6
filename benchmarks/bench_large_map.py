"""Benchmark: ``estimate_map`` without landmarks on a large pair, time and peak memory.

The TOSCA cat pair of ``bench_large.py`` (``cat0`` → ``cat6`` on cat0's faces, identity
correspondence) Loop-subdivided ``--levels`` times (0: 27.9K vertices, 1: 111.5K), spectra
of 60 eigenpairs (cached in ``--cache``; computed before the timed call), then
``bsfjax.estimate_map(k=30, refine_to=60)`` with the meshes and no landmarks: 15 starts, the
choice among them, the derived landmarks and the turn check, as ``bsfjax transfer`` runs it.

Three ways in the same run, each in a child process of its own (so each peak resident set
size is its own):

* ``proxy``: the default.  Above ``proxy_above`` vertices (a field of
  ``bsfjax.MapEstimator``) the starts, their choice, the derived landmarks and the turn check
  run on quadric-decimated proxies of about ``proxy_vertices`` vertices, and the kept map is
  carried back (composed with the nearest proxy vertex, ZoomOut on the whole spectra).
* ``selection``: the default before the proxies (``proxy_above=None``).  On a target of more
  than ``selection_vertices`` vertices the candidates' point maps are searched only at the
  corners of ``selection_faces`` random faces and at the distortions' samples; the kept map
  then over every vertex.
* ``every vertex`` (the peer): ``proxy_above=None`` and ``selection_vertices`` raised above
  the target's size, so every candidate is searched over every vertex.

Per way: seconds of the call (one call: it takes tens of seconds to minutes; JAX's compile time
included, as a user's first call) and its CPU seconds (user and system), peak RSS of the
process, the kept start, and the kept map's mean geodesic error against the identity on 500
farthest-point samples of the target (``bsfjax.geodesic_error``, units of √area).

    python benchmarks/bench_large_map.py --out R --levels 0 1
    python benchmarks/bench_large_map.py --out R --levels 2 --ways proxy
"""

from __future__ import annotations

import multiprocessing as mp
import resource
import time
from pathlib import Path

import _harness as h

WAYS = ("proxy", "selection", "every vertex")


def _cpu() -> float:
    """User and system CPU seconds of this process (on a loaded machine the wall time is not
    the call's own)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def one(data: str, levels: int, way: str, cache: str, queue) -> None:
    """One timed ``estimate_map`` in this (child) process; puts its row on ``queue``."""
    import numpy as np

    import bsfjax

    source, target = h.cat_pair(Path(data), levels)
    sm, sn = (bsfjax.spectrum(m, 60, cache_dir=cache) for m in (source, target))
    # estimate_map(k=30, refine_to=60), every other field at its default; the peers run on the
    # whole meshes, and the last searches every candidate over every vertex
    every = {"proxy": {}, "selection": dict(proxy_above=None),
             "every vertex": dict(proxy_above=None, selection_vertices=target.n_vertices + 1)}
    estimator = bsfjax.MapEstimator(k=30, refine_to=60, **every[way])
    t0, c0 = time.perf_counter(), _cpu()
    est = estimator(sm, sn, source_mesh=source, target_mesh=target)
    seconds, cpu = time.perf_counter() - t0, _cpu() - c0
    samples = np.asarray(bsfjax.farthest_point_sampling(target, 500))
    error = bsfjax.geodesic_error(source, est.p2p[samples], samples)
    queue.put({"levels": levels, "vertices": target.n_vertices, "way": way,
               "seconds": round(seconds, 1), "cpu_seconds": round(cpu, 1),
               "peak_rss_gb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6, 2),
               "start": list(est.start), "derived_landmarks_kept": est.landmarks is not None,
               "swapped": bool(est.swapped), "geodesic_error": round(float(error), 4)})


def run(data: Path, levels, cache: Path, ways=WAYS) -> list[dict]:
    rows = []
    ctx = mp.get_context("spawn")  # a fresh process per way: its own peak memory
    for lv in levels:
        for way in ways:
            queue = ctx.Queue()
            proc = ctx.Process(target=one, args=(str(data), lv, way, str(cache), queue))
            proc.start()
            row = queue.get()
            proc.join()
            print(row, flush=True)
            rows.append(row)
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| vertices | way | seconds | CPU seconds | peak RSS GB | kept start | geodesic error |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['vertices']} | {r['way']} | {r['seconds']} | "
                     f"{r.get('cpu_seconds', '')} | {r['peak_rss_gb']} | "
                     f"{tuple(r['start'])} | {r['geodesic_error']} |")
    by = {(r["levels"], r["way"]): r for r in rows}
    for lv in sorted({r["levels"] for r in rows}):
        for fast, slow in (("proxy", "selection"), ("selection", "every vertex")):
            if (lv, fast) not in by or (lv, slow) not in by:
                continue  # (one way only: no ratio)
            a, b = by[(lv, fast)], by[(lv, slow)]
            lines.append(f"\n{a['vertices']} vertices: {fast} is "
                         f"{b['seconds'] / a['seconds']:.2f}× as fast as {slow}, "
                         f"peak {a['peak_rss_gb']} against {b['peak_rss_gb']} GB.")
    lines.append(f"\n{h.cpus_note()}.")
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = h.parser(__doc__)
    h.add_out(ap, type=Path, help="folder for the JSON and Markdown")
    h.add_data(ap)
    ap.add_argument("--levels", type=int, nargs="+", default=[0, 1])
    h.add_cache(ap, h.HOME_CACHE, type=Path, help="spectrum cache folder")
    ap.add_argument("--ways", nargs="+", choices=WAYS, default=list(WAYS),
                    help="the default only (proxy) where the peers would take long: "
                         "level 2, 445.8K vertices")
    args = ap.parse_args(argv)
    h.require_data(*(args.data / "tosca" / "cat" / f"cat{i}.off" for i in (0, 6)))
    rows = run(args.data, args.levels, args.cache, args.ways)
    args.out.mkdir(parents=True, exist_ok=True)
    h.write_json(args.out / "large_map.json", rows)
    h.write_text(args.out / "large_map.md", markdown(rows))
    print(markdown(rows))


if __name__ == "__main__":
    main()
