"""Benchmark: Laplacian assembly and the k = 100 eigensolve, bsfjax vs libigl / robust-laplacian
+ scipy, on a ~7K-vertex mesh (FAUST tr_reg_000) and a ~40K-vertex one (TOSCA cat 10K, Loop-
subdivided once), all in the same run.

* assembly: ``bsfjax.laplacian`` (cotangent W + mixed Voronoi A) vs ``igl.cotmatrix`` +
  ``igl.massmatrix(VORONOI)`` (same definitions), and ``robust_laplacian.mesh_laplacian``;
* eigensolve: ``bsfjax.spectrum_from_operators(W, A, 100)`` vs a bare
  ``scipy.sparse.linalg.eigsh(W, 100, M=A, sigma=-0.01)`` on the same matrices (pyFM's call).

Median of ``--repeats`` runs.  Writes JSON and a Markdown table to ``--out`` (a folder).

    python benchmarks/bench_spectrum.py --out bench-results

``--large 1 2`` instead times the eigensolve alone on the full TOSCA cat (27 894 V) Loop-
subdivided once (111 500 V) and twice (445 848 V), single runs, in one process:
``bsfjax.spectrum(mesh, k)`` (assembly included; the default ``method="auto"``, block Lanczos
with CHOLMOD when ``cholespy`` is installed) and ``method="fast"`` against a bare
``scipy.sparse.linalg.eigsh(W, k, M=A, sigma=-0.01, which="LM")`` on the same ``W, A``, with
the accuracy of each result: eigenvalues relative to eigsh's, ``max |ΦᵀAΦ − I|``, the largest
relative residual ``‖Wφ − λAφ‖_{A⁻¹} / λ_k``, and the largest principal-angle sine between the
spans of the first ``j`` eigenvectors (``j`` = 25, 50, 100: the eigenspaces)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_spectrum.py --out R --large 1 2
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg

import _harness as h
import bsfjax
from bsfjax.internal import subdivide

DATA = h.DATA


def accuracy(evals, evecs, W, a, ref_evals=None, ref_evecs=None):
    """Accuracy of one eigensolver result (see the module docstring)."""
    k = len(evals)
    out = {"a_orthonormality": float(abs(evecs.T @ (a[:, None] * evecs) - np.eye(k)).max())}
    R = (W @ evecs - (a[:, None] * evecs) * evals) / np.sqrt(a)[:, None]
    out["max_relative_residual"] = float(np.linalg.norm(R, axis=0).max() / evals[-1])
    if ref_evals is not None:
        floor = ref_evals[1] if k > 1 else 1.0  # λ₁ = 0: compare it on the scale of λ₂
        out["max_relative_eigenvalue_error"] = float(
            (abs(evals - ref_evals) / np.maximum(abs(ref_evals), floor)).max())
        for j in (25, 50, 100):
            if j <= k:
                M = evecs[:, :j].T @ (a[:, None] * ref_evecs[:, :j])
                smin = np.linalg.svd(M, compute_uv=False).min()
                out[f"subspace_sine_first_{j}"] = float(np.sqrt(max(0.0, 1 - min(smin, 1) ** 2)))
    return out


def large(levels, k, out):
    """The eigensolve on the subdivided TOSCA cat: bsfjax against bare scipy eigsh."""
    import threadpoolctl

    from bsfjax.internal import has_cholmod

    m0 = bsfjax.load_mesh(DATA / "tosca" / "cat" / "cat0.off")
    rows = []
    for lev in levels:
        m = subdivide(m0, "loop", lev) if lev else m0
        W, A = bsfjax.laplacian(m)
        a = A.diagonal()
        t = time.perf_counter()
        ref_l, ref_v = scipy.sparse.linalg.eigsh(W.tocsc(), k, M=A.tocsc(), sigma=-0.01,
                                                 which="LM")
        t_scipy = time.perf_counter() - t
        order = np.argsort(ref_l)
        ref_l, ref_v = ref_l[order], ref_v[:, order]
        t = time.perf_counter()
        ours = bsfjax.spectrum(m, k)
        t_ours = time.perf_counter() - t
        t = time.perf_counter()
        fast = bsfjax.spectrum(m, k, method="fast")
        t_fast = time.perf_counter() - t
        row = dict(mesh=f"tosca cat0, Loop x{lev}", n=m.n_vertices, k=k,
                   cholmod=has_cholmod(), blas=threadpoolctl.threadpool_info(),
                   eigsh_s=t_scipy, spectrum_s=t_ours, fast_s=t_fast,
                   ratio=t_scipy / t_ours, ratio_fast=t_scipy / t_fast,
                   scipy_eigsh=accuracy(ref_l, ref_v, W, a),
                   spectrum=accuracy(ours.evals, ours.evecs, W, a, ref_l, ref_v),
                   fast=accuracy(fast.evals, fast.evecs, W, a, ref_l, ref_v))
        rows.append(row)
        print(json.dumps({k_: v for k_, v in row.items() if k_ != "blas"}, indent=1), flush=True)
    md = [f"k={k} eigensolve, same W and A, one process (ratio = eigsh / bsfjax)", "",
          "| mesh | n | bare eigsh | bsfjax.spectrum | ratio | fast | ratio | max rel. eigenvalue "
          "error | max residual | A-orthonormality |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r['mesh']} | {r['n']} | {r['eigsh_s']:.1f} s | {r['spectrum_s']:.1f} s | "
                  f"{r['ratio']:.2f}x | {r['fast_s']:.1f} s | {r['ratio_fast']:.2f}x | "
                  f"{r['spectrum']['max_relative_eigenvalue_error']:.1e} | "
                  f"{r['spectrum']['max_relative_residual']:.1e} (eigsh "
                  f"{r['scipy_eigsh']['max_relative_residual']:.1e}) | "
                  f"{r['spectrum']['a_orthonormality']:.1e} |")
    out = Path(out)
    h.write_json(out / "spectrum_large.json", rows)
    h.write_text(out / "spectrum_large.md", "\n".join(md) + "\n")
    print("\n".join(md))


def main(argv=None):
    ap = h.parser(__doc__)
    h.add_out(ap, default="bench-results")
    h.add_repeats(ap, 5)
    ap.add_argument("-k", type=int, default=100)
    ap.add_argument("--large", type=int, nargs="*", default=None,
                    help="Loop subdivision levels of the TOSCA cat to time instead")
    args = ap.parse_args(argv)
    if args.large is not None:
        h.require_data(DATA / "tosca" / "cat" / "cat0.off", option=None)
        return large(args.large or [1, 2], args.k, args.out)
    h.require_data(DATA / "faust" / "tr_reg_000.off", DATA / "tosca_10k" / "cat" / "cat0.off",
                   option=None)
    import igl
    import robust_laplacian

    meshes = {
        "faust tr_reg_000": bsfjax.load_mesh(DATA / "faust" / "tr_reg_000.off"),
        "cat 10K, Loop x1": subdivide(bsfjax.load_mesh(DATA / "tosca_10k" / "cat" / "cat0.off")),
    }
    rows = []
    for name, m in meshes.items():
        V, F = np.asarray(m.vertices), np.asarray(m.faces)
        t_ours = h.timed(lambda: bsfjax.laplacian(m), args.repeats).median
        t_igl = h.timed(lambda: (igl.cotmatrix(V, F),
                                 igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI)),
                        args.repeats).median
        t_rob = h.timed(lambda: robust_laplacian.mesh_laplacian(V, F), args.repeats).median
        W, A = bsfjax.laplacian(m)
        reps = max(1, args.repeats // 2)
        t_eig = h.timed(lambda: bsfjax.spectrum_from_operators(W, A, args.k), reps).median
        Wc, Ac = W.tocsc(), A.tocsc()
        t_scipy = h.timed(lambda: scipy.sparse.linalg.eigsh(Wc, args.k, M=Ac, sigma=-0.01,
                                                            which="LM"), reps).median
        rows.append(dict(mesh=name, n=m.n_vertices, assembly_bsfjax_s=t_ours, assembly_igl_s=t_igl,
                         assembly_robust_s=t_rob, eig_bsfjax_s=t_eig, eig_scipy_s=t_scipy,
                         assembly_ratio_igl=t_igl / t_ours, eig_ratio_scipy=t_scipy / t_eig))
        print(rows[-1], flush=True)
    machine = h.short_machine()
    md = [f"Laplacian assembly and k={args.k} eigensolve ({machine}; median of {args.repeats}; "
          "ratio > 1 means bsfjax is faster)", "",
          "| mesh | n | assembly bsfjax | libigl | robust-laplacian | igl/bsfjax | eigsh bsfjax | bare scipy | scipy/bsfjax |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        md.append(f"| {r['mesh']} | {r['n']} | {1e3*r['assembly_bsfjax_s']:.1f} ms | {1e3*r['assembly_igl_s']:.1f} ms"
                  f" | {1e3*r['assembly_robust_s']:.1f} ms | {r['assembly_ratio_igl']:.2f}x | {r['eig_bsfjax_s']:.2f} s"
                  f" | {r['eig_scipy_s']:.2f} s | {r['eig_ratio_scipy']:.2f}x |")
    out = Path(args.out)
    h.write_json(out / "spectrum.json", {"machine": machine, "rows": rows})
    h.write_text(out / "spectrum.md", "\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
