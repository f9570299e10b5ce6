"""Benchmark: BSF build and farthest point sampling, bsfjax vs a float64 numpy implementation.

On FAUST tr_reg_000 (6890 vertices), k eigenpairs (default 100), n_BSF = 5 % of the vertices
as centres (344) and the paper's three scales (q = 1032 atoms):

* ``build_frame`` (one jitted call, JAX default dtype) vs numpy float64 doing the same steps
  (coefficients, Φ @ coeffs, |g| / max |g|, threshold);
* ``transfer_frame`` with the identity-map C onto tr_reg_001 vs numpy float64;
* ``farthest_point_sampling(metric="euclidean")`` (jitted ``fori_loop``) vs a numpy loop with a
  running min-distance vector.

Every timing is the median of ``--repeats`` runs after one warm-up call (which compiles), with
``block_until_ready``.  Prints a table with the numpy/bsfjax ratio and writes JSON to ``--out``.

    python benchmarks/bench_frame.py --out bench_frame.json
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import numpy as np

import _harness as h
import bsfjax
from _harness import GAMMA, TAUS, median_time


def main(argv=None):
    ap = h.parser(__doc__)
    h.add_out(ap, type=Path, help="JSON file to write")
    h.add_data(ap)
    ap.add_argument("--k", type=int, default=100)
    ap.add_argument("--fraction", type=float, default=0.05, help="n_BSF as a vertex fraction")
    h.add_repeats(ap, 9)
    args = ap.parse_args(argv)
    h.require_data(*(args.data / "faust" / f"tr_reg_00{i}.off" for i in (0, 1)))

    src = bsfjax.load_mesh(args.data / "faust" / "tr_reg_000.off")
    tgt = bsfjax.load_mesh(args.data / "faust" / "tr_reg_001.off")
    t0 = time.perf_counter()
    spec, spec_t = bsfjax.spectrum(src, args.k), bsfjax.spectrum(tgt, args.k)
    t_spec = time.perf_counter() - t0

    # FPS (euclidean); n: the number of samples the fraction asks for
    first = int(np.random.default_rng(0).integers(src.n_vertices))
    t_fps_jax, centers = median_time(
        lambda: bsfjax.farthest_point_sampling(src, args.fraction, seed=0), args.repeats)
    n = len(centers)
    t_fps_np, centers_np = median_time(lambda: h.numpy_fps(src.vertices, first, n), args.repeats)

    # build
    t_build_jax, frame = median_time(
        lambda: bsfjax.build_frame(spec, centers, TAUS, GAMMA), args.repeats)
    t_build_np, (atoms_np, coeffs_np) = median_time(lambda: h.numpy_build(spec, centers),
                                                    args.repeats)

    # transfer with the identity point map written as a functional map
    C = spec_t.evecs.T @ (spec_t.mass[:, None] * spec.evecs)
    t_tr_jax, moved = median_time(
        lambda: bsfjax.transfer_frame(frame, C, spec_t), args.repeats)
    t_tr_np, moved_np = median_time(lambda: h.numpy_transfer(coeffs_np, C, spec_t.evecs),
                                    args.repeats)

    atoms = np.asarray(frame.atoms) > 0.5
    rows = [
        ("farthest_point_sampling euclidean", t_fps_jax, t_fps_np,
         f"same indices: {bool(np.array_equal(centers, centers_np))}"),
        ("build_frame", t_build_jax, t_build_np,
         f"atom entries differing: {int((atoms != atoms_np).sum())} of {atoms.size}"),
        ("transfer_frame", t_tr_jax, t_tr_np,
         f"atom entries differing: {int(((np.asarray(moved.atoms) > 0.5) != moved_np).sum())} "
         f"of {moved_np.size}"),
    ]
    machine = h.machine_facts()
    result = {
        "mesh": "faust/tr_reg_000.off (transfer target tr_reg_001.off)",
        "n_vertices": src.n_vertices, "k": args.k, "n_centers": int(n),
        "n_atoms": int(frame.n_atoms), "taus": TAUS, "gamma": GAMMA,
        "repeats": args.repeats, "statistic": "median seconds after one warm-up call",
        "spectrum_seconds_both_shapes": t_spec,
        "jax_version": machine["jax"], "backend": machine["backend"],
        "device": machine["device"], "jax_dtype": str(frame.atoms.dtype),
        "numpy_dtype": "float64", "cpu_count": machine["cores"], "machine": machine["arch"],
        "results": [{"op": op, "bsfjax_s": tj, "numpy_s": tn, "numpy_over_bsfjax": tn / tj,
                     "check": chk} for op, tj, tn, chk in rows],
    }
    print(f"FAUST tr_reg_000: n = {src.n_vertices}, k = {args.k}, centres = {n}, "
          f"atoms = {frame.n_atoms}, bsfjax {frame.atoms.dtype} on {jax.default_backend()}, "
          f"median of {args.repeats}")
    print(f"{'op':36s} {'bsfjax ms':>10s} {'numpy f64 ms':>13s} {'ratio':>7s}  check")
    for op, tj, tn, chk in rows:
        print(f"{op:36s} {1e3 * tj:10.2f} {1e3 * tn:13.2f} {tn / tj:7.2f}  {chk}")
    h.write_json(args.out, result)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
