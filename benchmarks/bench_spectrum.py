"""Benchmark: Laplacian assembly and the k = 100 eigensolve, bsfjax vs libigl / robust-laplacian
+ scipy, on a ~7K-vertex mesh (FAUST tr_reg_000) and a ~40K-vertex one (TOSCA cat 10K, Loop-
subdivided once), all in the same run.

* assembly: ``bsfjax.laplacian`` (cotangent W + mixed Voronoi A) vs ``igl.cotmatrix`` +
  ``igl.massmatrix(VORONOI)`` (same definitions), and ``robust_laplacian.mesh_laplacian``;
* eigensolve: ``bsfjax.spectrum_from_operators(W, A, 100)`` vs a bare
  ``scipy.sparse.linalg.eigsh(W, 100, M=A, sigma=-0.01)`` on the same matrices (pyFM's call).

Median of ``--repeats`` runs.  Writes JSON and a Markdown table to ``--out`` (a folder).

    python benchmarks/bench_spectrum.py --out bench-results
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg

import bsfjax
from bsfjax._files import write_text_atomic
from bsfjax._subdivision import subdivide

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def median_time(fn, repeats):
    fn()
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="bench-results")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("-k", type=int, default=100)
    args = ap.parse_args(argv)
    import igl
    import robust_laplacian

    meshes = {
        "faust tr_reg_000": bsfjax.load_mesh(DATA / "faust" / "tr_reg_000.off"),
        "cat 10K, Loop x1": subdivide(bsfjax.load_mesh(DATA / "tosca_10k" / "cat" / "cat0.off")),
    }
    rows = []
    for name, m in meshes.items():
        V, F = np.asarray(m.vertices), np.asarray(m.faces)
        t_ours = median_time(lambda: bsfjax.laplacian(m), args.repeats)
        t_igl = median_time(lambda: (igl.cotmatrix(V, F),
                                     igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI)), args.repeats)
        t_rob = median_time(lambda: robust_laplacian.mesh_laplacian(V, F), args.repeats)
        W, A = bsfjax.laplacian(m)
        reps = max(1, args.repeats // 2)
        t_eig = median_time(lambda: bsfjax.spectrum_from_operators(W, A, args.k), reps)
        Wc, Ac = W.tocsc(), A.tocsc()
        t_scipy = median_time(lambda: scipy.sparse.linalg.eigsh(Wc, args.k, M=Ac, sigma=-0.01,
                                                                which="LM"), reps)
        rows.append(dict(mesh=name, n=m.n_vertices, assembly_bsfjax_s=t_ours, assembly_igl_s=t_igl,
                         assembly_robust_s=t_rob, eig_bsfjax_s=t_eig, eig_scipy_s=t_scipy,
                         assembly_ratio_igl=t_igl / t_ours, eig_ratio_scipy=t_scipy / t_eig))
        print(rows[-1], flush=True)
    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, {platform.system()}"
    md = [f"Laplacian assembly and k={args.k} eigensolve ({machine}; median of {args.repeats}; "
          "ratio > 1 means bsfjax is faster)", "",
          "| mesh | n | assembly bsfjax | libigl | robust-laplacian | igl/bsfjax | eigsh bsfjax | bare scipy | scipy/bsfjax |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r['mesh']} | {r['n']} | {1e3*r['assembly_bsfjax_s']:.1f} ms | {1e3*r['assembly_igl_s']:.1f} ms"
                  f" | {1e3*r['assembly_robust_s']:.1f} ms | {r['assembly_ratio_igl']:.2f}x | {r['eig_bsfjax_s']:.2f} s"
                  f" | {r['eig_scipy_s']:.2f} s | {r['eig_ratio_scipy']:.2f}x |")
    out = Path(args.out)
    write_text_atomic(out / "spectrum.json", json.dumps({"machine": machine, "rows": rows}, indent=2))
    write_text_atomic(out / "spectrum.md", "\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
