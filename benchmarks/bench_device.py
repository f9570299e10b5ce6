"""The pipeline after the eigensolve on an accelerator against the CPU of the same machine.

Measures, in one process, each JAX stage with the default device (a GPU when JAX has one) and
with the host CPU (``jax.default_device(cpu)``), on the built-in example pair:

- ``build_frame`` (paper's τ and γ, 5 % centres) and its transfer through a functional map;
- ``encode`` with OMP (S = 10) of F random indicators, F in ``--functions``;
- the whole BSF transfer of F indicators (``bsfjax.transfer("omp", ...)``) and the default
  ``refined`` labels (``transfer_labels``);
- the same on a subdivided example (``--large-levels``, 129K vertices at 5), where the frame is a
  ``SparseFrame``.

The eigensolve stays on the CPU (SciPy / CHOLMOD) and is timed once.  Each figure is the median
of ``--repeats`` warm calls (after one call that compiles); the first call is reported apart.

    python benchmarks/bench_device.py --out R            # about 3 minutes on an H200 machine
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import jax

import bsfjax
from _harness import add_out, add_repeats, describe_machine, parser, timed, write_json, write_text


def _timed(fn, repeats):
    t = timed(fn, repeats)
    return t.first, t.median


def _stages(pair, sm, sn, C, functions, repeats, label):
    """(stage, first call, median warm call) per stage on the current default device."""
    centers = bsfjax.farthest_point_sampling(pair.source, 0.05)
    rows = []
    frame = None

    def build():
        nonlocal frame
        frame = bsfjax.build_frame(sm, centers)
        return _leaves(frame)

    rows.append(("build_frame", *_timed(build, repeats)))
    rows.append(("transfer_frame", *_timed(lambda: _leaves(bsfjax.transfer_frame(frame, C, sn)),
                                             repeats)))
    for n_f in functions:
        F = bsfjax.random_indicators(pair.source, n_f, seed=0)
        rows.append((f"encode OMP, {n_f} functions",
                     *_timed(lambda: bsfjax.encode(frame, F, "omp"), repeats)))
        p = bsfjax.Pair(sm, sn, C, centers=centers)
        rows.append((f"transfer omp, {n_f} functions",
                     *_timed(lambda: bsfjax.transfer("omp", p, F).transferred, repeats)))
    p2p = bsfjax.fmap_to_p2p(C, sm, sn)
    rows.append(("transfer_labels refined",
                 *_timed(lambda: bsfjax.transfer_labels(sm, sn, pair.labels, C=C, p2p=p2p,
                                                        method="refined").labels, repeats)))
    return [(label, *r) for r in rows]


def _leaves(tree):
    return jax.tree_util.tree_leaves(tree)


def _case(levels, k, functions, repeats, devices):
    t = time.perf_counter()
    pair = bsfjax.example_pair(levels=levels)
    sm, sn = bsfjax.spectrum(pair.source, k), bsfjax.spectrum(pair.target, k)
    eig = time.perf_counter() - t
    C = bsfjax.fmap_from_p2p(sm, sn, pair.p2p)
    rows = []
    for name, dev in devices:
        with jax.default_device(dev):
            rows += _stages(pair, sm, sn, C, functions, repeats, name)
    return pair.source.n_vertices, eig, rows


def main(argv=None):
    ap = parser(__doc__)
    add_out(ap, help="folder for device.md and device.json")
    ap.add_argument("-k", type=int, default=30)
    ap.add_argument("--functions", type=int, nargs="+", default=[50, 1000])
    add_repeats(ap, 5)
    ap.add_argument("--large-levels", type=int, default=5,
                    help="subdivision levels of the large case (0: skip it)")
    args = ap.parse_args(argv)
    default = jax.devices()[0]
    devices = [(f"{default.platform} ({default.device_kind})", default)]
    if default.platform != "cpu":
        devices.append((f"cpu ({os.cpu_count()} cores)", jax.devices("cpu")[0]))
    cases = [("example pair", 3, args.functions)]
    if args.large_levels:
        cases.append(("subdivided example", args.large_levels, args.functions[:1]))
    report, lines = [], []
    machine = describe_machine()
    lines += [f"# The pipeline after the eigensolve: {devices[0][0]} against the CPU", "",
              f"Machine: {machine}.", ""]
    for title, levels, functions in cases:
        n, eig, rows = _case(levels, args.k, functions, args.repeats, devices)
        lines += [f"## {title}: {n} vertices, k = {args.k} (eigensolve on the CPU: {eig:.1f} s)",
                  "", "| stage | " + " | ".join(d for d, _ in devices) + " | ratio |",
                  "|---|" + "---|" * (len(devices) + 1)]
        by = {}
        for dev, stage, first, warm in rows:
            by.setdefault(stage, {})[dev] = (first, warm)
            report.append({"case": title, "vertices": n, "device": dev, "stage": stage,
                           "first_s": first, "warm_s": warm})
        for stage, per in by.items():
            cells = [f"{per[d][1] * 1e3:.1f} ms (first {per[d][0]:.2f} s)" for d, _ in devices]
            ratio = (f"{per[devices[1][0]][1] / per[devices[0][0]][1]:.1f}×"
                     if len(devices) > 1 else "–")
            lines.append(f"| {stage} | " + " | ".join(cells) + f" | {ratio} |")
        lines.append("")
        print("\n".join(lines), flush=True)
    out = Path(args.out)
    write_text(out / "device.md", "\n".join(lines) + "\n")
    write_json(out / "device.json", report)


if __name__ == "__main__":
    main()
