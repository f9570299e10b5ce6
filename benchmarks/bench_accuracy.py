"""Accuracy benchmark: approximation (Eq. 14) and ground-truth transfer (Eq. 15) errors.

For FAUST pairs from ../shared/data/faust, k ∈ {10, 30, 50, 70, 90} and random connected
indicator functions covering 5–25 % of the area, the mean area-weighted relative error
(square-root form ‖f − f̃‖_A / ‖f‖_A) of the plain spectral projection (``std``) and of every
BSF coding method, on the source (approximation) and after transfer with the ground-truth map.
The table is a finding, not a target: where BSF does not beat the projection, it says so.

    python benchmarks/bench_accuracy.py --out /tmp/acc [--pairs 2 --functions 100 --seed 0]

Writes ``accuracy.json`` (settings, per-(method, k) mean / std / median, wall time) and
``accuracy.md`` into ``--out``.
"""

from __future__ import annotations

import time
from pathlib import Path

import _harness as h
from bsfjax.experiments import CODERS
from bsfjax.experiments import load_dataset, pivot_markdown, summarize, transfer_experiment


def main(argv=None) -> int:
    ap = h.parser(__doc__)
    h.add_data(ap, "faust", type=str, help="FAUST folder")
    h.add_out(ap)
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--functions", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--ks", default="10,30,50,70,90")
    args = ap.parse_args(argv)
    h.require_data(args.data)
    ks = h.int_list(args.ks)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    dataset = load_dataset(args.data)
    rows = transfer_experiment(dataset, pairs=args.pairs, functions=args.functions, ks=ks,
                               methods=("std",) + CODERS, seed=args.seed, approximation=True,
                               cache_dir=out / ".spectra")
    wall = time.perf_counter() - t0
    pairs = sorted({(r["source"], r["target"]) for r in rows})
    approx = summarize(rows, ("method", "k"), "approx_error")
    transfer = summarize(rows, ("method", "k"), "error")
    result = {"data": args.data, "pairs": pairs, "functions_per_pair": args.functions,
              "seed": args.seed, "ks": ks, "error": "sqrt(sum A (f - g)^2) / sqrt(sum A f^2)",
              "approximation": approx, "transfer": transfer, "wall_s": wall}
    h.write_json(out / "accuracy.json", result, indent=1)
    std = {s["k"]: s["mean"] for s in approx if s["method"] == "std"}
    beats = [f"- k = {s['k']}: {s['method']} {s['mean']:.3f} vs std {std[s['k']]:.3f} "
             f"({'beats' if s['mean'] < std[s['k']] else 'does NOT beat'} the projection)"
             for s in approx if s["method"] != "std"]
    md = (f"# Accuracy\n\nFAUST pairs {pairs}, {args.functions} random connected "
          f"indicators (5–25 % of the area) per pair, seed {args.seed}; mean of "
          "‖f − f̃‖_A / ‖f‖_A.\n\n## Approximation (Eq. 14)\n\n"
          + pivot_markdown(rows, "method", "k", value="approx_error")
          + "\n\n## Transfer with the ground-truth map (Eq. 15)\n\n"
          + pivot_markdown(rows, "method", "k") + "\n\n## BSF vs projection (approximation)\n\n"
          + "\n".join(beats) + f"\n\nWall time {wall:.0f} s.\n")
    h.write_text(out / "accuracy.md", md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
