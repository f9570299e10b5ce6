"""Benchmark suite: every stage of bsfjax beside its float64 peer, at several mesh sizes, one run.

Sizes (``--sizes``, comma separated):

========  ==========================================================================  =========
``7k``    FAUST ``tr_reg_000`` → ``tr_reg_001`` (identity ground truth)                 6 890 V
``50k``   TOSCA cat 10K ``cat0`` → ``cat1`` Loop-subdivided once (shared faces)        40 008 V
``200k``  the same cats Loop-subdivided twice                                          160 008 V
========  ==========================================================================  =========

Stages and peers (same inputs, same run; peers float64):

* Laplacian — ``bsfjax.laplacian`` vs libigl ``cotmatrix`` + ``massmatrix(VORONOI)``;
* spectrum (k = 100) — ``bsfjax.spectrum_from_operators`` vs bare scipy ``eigsh(W, k, M=A,
  sigma=-0.01)`` (pyFM's call) on the same matrices;
* sampling — ``farthest_point_sampling`` (5 %, euclidean) vs a numpy loop (``bench_frame.py``);
* frame build / frame transfer (identity map) — vs numpy (``bench_frame.py``; above
  ``--dense-peer-gib`` of float64 atoms the peer works in column blocks into a scipy CSC matrix,
  and bsfjax builds a :class:`bsfjax.SparseFrame`, automatically);
* coding of 100 random connected regions (``bench_coding.py``): ``lstsq`` vs
  ``numpy.linalg.lstsq``, ``omp`` (S = 10) vs scikit-learn ``orthogonal_mp`` (default and
  ``precompute=True``), ``omp_error`` (ε = (0.3‖f‖)², 256 atoms) vs ``orthogonal_mp_gram(tol)``
  per function on one shared Gram matrix, ``lasso`` vs scikit-learn ``Lasso`` per function.  Slow per-function peers run on
  the first ``--peer-functions`` functions at the larger sizes and their per-function time is
  scaled to 100 (one-off set-up such as a shared Gram matrix counted once; marked "×N
  extrapolated");
* fmap estimation (k = 30, WKS descriptors from bsfjax given to both) — ``estimate_fmap`` vs
  pyFM ``FunctionalMapping.fit``;
* point-map conversion (k = 30) — ``fmap_to_p2p`` vs pyFM ``FM_to_p2p``;
* whole pipeline after the eigensolve for 100 functions: sampling + frame + ``omp`` + frame
  transfer + decoding on the target, vs numpy + scikit-learn doing the same steps (at 7k the
  two sides are called alternately, ``--repeats`` rounds, and each row has its own medians).

A peer that cannot run at a size (the dense float64 frame or Gram matrix does not fit) is listed
with its reason.  Times: median of ``--repeats`` calls after one warm-up call (compilation) at
7k, fewer at larger sizes (``repeats`` in the JSON).  Writes ``results.json`` and ``results.md``
(medians, peer/bsfjax ratios > 1 meaning bsfjax is faster, the machine) into ``--out``.

    python benchmarks/run_all.py --out bench-results --sizes 7k,50k,200k
"""

from __future__ import annotations

import os

# OpenBLAS (numpy/scipy's BLAS) keeps its worker threads spinning for ~0.1 s after every call;
# on a 2-core machine they then compete with XLA's threads for the cores: FAUST's pipeline
# measured right after a numpy GEMM took 93 ms instead of 57.  A short spin (2⁴ cycles; set
# before numpy loads OpenBLAS) removes that cross-talk between the two sides of one run
# without slowing the peers (pipeline peer 311 ms with it, 291–332 ms without).
os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "4")

import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import jax  # noqa: E402
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg  # noqa: E402

import _harness as h  # noqa: E402
import bsfjax  # noqa: E402
from _harness import (  # noqa: E402
    GAMMA, TAUS, PeakRSS, numpy_build, numpy_fps, numpy_transfer, pyfm_mesh, random_regions,
    rel_residual, sk_lasso, sk_omp,
)
from bsfjax.internal import DENSE_BUDGET_BYTES, subdivide  # noqa: E402

K, K_FIT, FRACTION, SPARSITY, N_FUNCTIONS = 100, 30, 0.05, 10, 100
EPS_FRACTION, MAX_ATOMS, LAM = 0.3, 256, 0.01


def load_size(name: str, data: Path):
    """``(label, source mesh, target mesh)``; identity correspondence in every case."""
    if name == "7k":
        return ("FAUST tr_reg_000→001",
                *(bsfjax.load_mesh(data / "faust" / f"tr_reg_00{i}.off") for i in (0, 1)))
    levels = {"50k": 1, "200k": 2}.get(name)
    if levels is None:
        raise SystemExit(f"unknown size {name!r}: choose from 7k, 50k, 200k")
    meshes = [subdivide(bsfjax.load_mesh(data / "tosca_10k" / "cat" / f"cat{i}.off"), "loop", levels)
              for i in (0, 1)]
    return (f"TOSCA cat 10K cat0→cat1, Loop×{levels}", *meshes)


def timed(fn, repeats: int):
    """(median seconds of ``repeats`` calls after one warm-up call — the warm-up's own when
    ``repeats`` is 0 —, result, warm-up seconds)."""
    t = h.timed(fn, repeats)
    return t.median, t.out, t.first


def interleaved(ours, peer, repeats: int):
    """(median seconds of ``ours``, of ``peer``, peer's result): one warm-up call each, then
    ``repeats`` rounds of one call of each, so that slow phases of a shared machine fall on both
    sides rather than on whichever ran then."""
    jax.block_until_ready(ours())
    out = peer()
    ta, tb = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(ours())
        ta.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        out = peer()
        tb.append(time.perf_counter() - t0)
    return float(np.median(ta)), float(np.median(tb)), out


#: Seconds of a peer's one-off set-up (not per function) in its last call, e.g. the Gram matrix
#: of ``sk_omp_error_gram``: an extrapolation to more functions scales only the rest.
PEER_SETUP = {"s": 0.0}


def sk_omp_error_gram(B, F, eps):
    """``omp_error`` peer: scikit-learn ``orthogonal_mp_gram`` per function (ε differs per
    function) on one shared Gram matrix of the normalised atoms (formed once, timed)."""
    from sklearn.linear_model import orthogonal_mp_gram

    t0 = time.perf_counter()
    norms = np.linalg.norm(B, axis=0)
    ok = norms > 0
    D = B[:, ok] / norms[ok]
    G = D.T @ D
    PEER_SETUP["s"] = time.perf_counter() - t0
    Xy = D.T @ F.T
    beta = np.stack([orthogonal_mp_gram(G, Xy[:, i], tol=float(eps[i]),
                                        norms_squared=np.array([F[i] @ F[i]]))
                     for i in range(F.shape[0])], axis=1)
    alpha = np.zeros((B.shape[1], F.shape[0]))
    alpha[ok] = beta / norms[ok, None]
    return alpha.T


def blocked_build(evecs, coeffs, gamma_cols, block=1024):
    """float64 numpy frame in column blocks (``|g| ≥ γ max|g|``), as a scipy CSC matrix."""
    cols = []
    for s in range(0, coeffs.shape[1], block):
        g = np.abs(evecs @ coeffs[:, s:s + block])
        m = g.max(axis=0)
        cols.append(sp.csc_matrix((g >= gamma_cols[s:s + block] * m) & (m > 0)))
    return sp.hstack(cols, format="csc")


class Suite:
    def __init__(self, args):
        self.args = args
        self.rows: list[dict] = []

    def add(self, size, n, stage, ours, peer_name, peer, note="", repeats=None):
        """``ours``/``peer``: seconds or None (not run); ``peer`` may be (seconds, factor)."""
        factor, setup = 1, 0.0
        if isinstance(peer, tuple):
            peer, factor, setup = peer
        # extrapolated peers: the one-off set-up once, the per-function part × factor
        peer_total = None if peer is None else setup + (peer - setup) * factor
        row = {"size": size, "n": n, "stage": stage, "bsfjax_s": ours, "peer": peer_name,
               "peer_s": peer_total, "ratio": None if (peer_total is None or not ours)
               else peer_total / ours, "note": note + (f" (peer ×{factor} extrapolated)"
                                                       if factor != 1 else ""),
               "repeats": repeats}
        self.rows.append(row)
        r = "" if row["ratio"] is None else f"x{row['ratio']:.2f}"
        print(f"[{size}] {stage:32s} bsfjax {fmt(ours):>9s}  {peer_name:38s} {fmt(peer_total):>9s} "
              f"{r:>8s} {row['note']}", flush=True)


def fmt(t):
    if t is None:
        return "—"
    return f"{1e3 * t:.1f} ms" if t < 1 else f"{t:.2f} s"


def run_size(suite: Suite, size: str):
    args = suite.args
    label, src_mesh, tgt_mesh = load_size(size, args.data)
    n = src_mesh.n_vertices
    rep = {"7k": args.repeats, "50k": max(1, args.repeats // 2)}.get(size, 1)
    rep_slow = 1 if size == "7k" else 0  # heavy peers: one call (no warm-up needed)
    print(f"== {size}: {label}, n = {n}, repeats = {rep}", flush=True)
    import igl

    V, Fc = np.asarray(src_mesh.vertices), np.asarray(src_mesh.faces)
    t_ours, (W, A), _ = timed(lambda: bsfjax.laplacian(src_mesh), rep)
    t_igl, _, _ = timed(lambda: (igl.cotmatrix(V, Fc),
                                 igl.massmatrix(V, Fc, igl.MASSMATRIX_TYPE_VORONOI)), rep)
    suite.add(size, n, "Laplacian assembly", t_ours, "libigl cotmatrix+massmatrix", t_igl,
              repeats=rep)

    rep_eig = 1 if size == "7k" else 0
    t_ours, sm, t1 = timed(lambda: bsfjax.spectrum_from_operators(W, A, K), rep_eig)
    Wc, Ac = W.tocsc(), A.tocsc()
    t_sc, _, _ = timed(lambda: scipy.sparse.linalg.eigsh(Wc, K, M=Ac, sigma=-0.01, which="LM"),
                       rep_eig)
    suite.add(size, n, f"spectrum k={K}", t_ours, "scipy eigsh (shift-invert)", t_sc,
              repeats=rep_eig or 1)
    sn = bsfjax.spectrum(tgt_mesh, K, cache_dir=args.cache)

    # sampling
    first = int(np.random.default_rng(0).integers(n))
    t_ours, centers, _ = timed(lambda: bsfjax.farthest_point_sampling(src_mesh, FRACTION), rep)
    n_c = len(centers)  # the number of samples FRACTION asks for
    t_np, _, _ = timed(lambda: numpy_fps(V, first, n_c), rep)
    suite.add(size, n, "farthest point sampling 5%", t_ours, "numpy loop", t_np, repeats=rep)

    # frame
    q = 3 * n_c
    dense_peer = n * q * 8 / 2**30 <= args.dense_peer_gib
    t_ours, frame, _ = timed(lambda: bsfjax.build_frame(sm, centers, TAUS, GAMMA), rep)
    kind = type(frame).__name__
    evecs = np.asarray(sm.evecs)
    area = sm.mass.sum()
    ghat = np.exp(-np.asarray(TAUS)[:, None] * area * (sm.evals - sm.evals[0]))
    coeffs_np = (ghat[:, None, :] * evecs[centers][None]).reshape(-1, K).T
    gcols = np.full(q, GAMMA)
    if dense_peer:
        t_np, (B_np, _), _ = timed(lambda: numpy_build(sm, centers), rep)
        peer_name = "numpy dense"
    else:
        t_np, B_np, _ = timed(lambda: blocked_build(evecs, coeffs_np, gcols), rep_slow)
        peer_name = "numpy column blocks → scipy CSC"
    suite.add(size, n, "build_frame", t_ours, peer_name, t_np, f"bsfjax {kind}, q={q}",
              repeats=rep)

    C_id = np.asarray(bsfjax.fmap_from_p2p(sm, sn, np.arange(sn.n_vertices)))
    t_ours, tframe, _ = timed(lambda: bsfjax.transfer_frame(frame, C_id, sn), rep)
    if dense_peer:
        t_np, Bt_np, _ = timed(lambda: numpy_transfer(coeffs_np, C_id, np.asarray(sn.evecs)), rep)
    else:
        t_np, Bt_np, _ = timed(lambda: blocked_build(np.asarray(sn.evecs), C_id @ coeffs_np, gcols),
                               rep_slow)
    suite.add(size, n, "transfer_frame (identity C)", t_ours, peer_name, t_np, repeats=rep)

    # coding
    F = random_regions(src_mesh, np.asarray(sm.mass), N_FUNCTIONS, seed=0)
    F32 = F.astype(np.float32)
    eps = (EPS_FRACTION * np.linalg.norm(F, axis=1)) ** 2
    Bd = np.asarray(B_np, np.float64) if dense_peer else None
    gram_fits = q * q * 8 <= DENSE_BUDGET_BYTES or kind == "Frame"
    pf = N_FUNCTIONS if size == "7k" else args.peer_functions
    sub = slice(0, pf)
    factor = N_FUNCTIONS / pf
    methods = {
        "lstsq": ({}, [("numpy.linalg.lstsq", lambda: np.linalg.lstsq(Bd, F.T, rcond=None)[0].T, 1)]),
        "omp": ({"sparsity": SPARSITY},
                [("sklearn orthogonal_mp", lambda: sk_omp(Bd, F, SPARSITY, False), 1),
                 ("sklearn orthogonal_mp(precompute=True)", lambda: sk_omp(Bd, F, SPARSITY, True), 1)]),
        "omp_error": ({"eps": eps, "max_atoms": MAX_ATOMS},
                      [("sklearn orthogonal_mp_gram(tol) per function",
                        lambda: sk_omp_error_gram(Bd, F[sub], eps[sub]), factor)]),
        "lasso": ({"lam": LAM}, [("sklearn Lasso per function", lambda: sk_lasso(Bd, F[sub], LAM),
                                  factor)]),
    }
    alpha_omp = None
    for method in h.name_list(args.methods):
        opts, peers = methods[method]
        if method in ("lstsq", "lasso") and not gram_fits:
            suite.add(size, n, f"encode {method}", None, "—", None,
                      f"q={q}: dense q×q Gram {q * q * 8 / 2**30:.1f} GiB (use omp)")
            continue
        rep_m = rep if (size == "7k" or method in ("omp",)) else 0  # heavy: one call
        t_ours, (A_ours, info), t_first = timed(
            lambda: bsfjax.encode(frame, F32, method, return_info=True, weights=None,
                                  **opts), rep_m)
        if method == "omp":
            alpha_omp = A_ours
        res = float(np.median(np.asarray(info.residual) / np.linalg.norm(F, axis=1)))
        for name, fn, fac in peers:
            if Bd is None:
                suite.add(size, n, f"encode {method}", t_ours, name, None,
                          f"ours rel. residual {res:.3f}; peer needs the dense float64 B "
                          f"({n * q * 8 / 2**30:.0f} GiB)", repeats=rep)
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                PEER_SETUP["s"] = 0.0
                t_p, A_p, _ = timed(fn, rep_slow)
            Fp = F[:A_p.shape[0]]
            peer_res = float(np.median(rel_residual(Bd, Fp, np.asarray(A_p))))
            suite.add(size, n, f"encode {method}", t_ours, name, (t_p, fac, PEER_SETUP["s"]),
                      f"median rel. residual ours {res:.3f} / peer {peer_res:.3f}"
                      + ("" if rep_m else "; ours one call incl. compile"), repeats=rep_m or 1)

    # functional map estimation and point map (k = 30)
    from pyFM.functional import FunctionalMapping
    from pyFM.spectral import FM_to_p2p

    dm, dn = (np.asarray(bsfjax.wks(s, 100, k=K)) for s in (sm, sn))
    t_ours, C30, _ = timed(lambda: bsfjax.estimate_fmap(sm, sn, dm, dn, k=K_FIT), rep)
    model = FunctionalMapping(pyfm_mesh(src_mesh, sm, W),
                              pyfm_mesh(tgt_mesh, sn, bsfjax.laplacian(tgt_mesh)[0]))
    model.preprocess(n_descr=100, descr_type=None, k_process=K, verbose=False)
    model.descr1, model.descr2 = dm, dn
    t_py, _, _ = timed(lambda: model.fit(K=K_FIT, verbose=False), max(1, rep // 2))
    suite.add(size, n, f"fmap estimation k={K_FIT}", t_ours, "pyFM fit", t_py, repeats=rep)
    sm30, sn30 = sm.truncate(K_FIT), sn.truncate(K_FIT)
    C30 = np.asarray(C30)
    t_ours, p_ours, _ = timed(lambda: bsfjax.fmap_to_p2p(C30, sm30, sn30), rep)
    t_py, p_py, _ = timed(lambda: FM_to_p2p(C30, sm30.evecs, sn30.evecs), max(1, rep // 2))
    agree = float(np.mean(np.asarray(p_ours) == np.asarray(p_py)))
    suite.add(size, n, f"fmap → point map k={K_FIT}", t_ours, "pyFM FM_to_p2p", t_py,
              f"same matches {100 * agree:.1f}%", repeats=rep)

    # whole pipeline after the eigensolve
    if alpha_omp is None:
        return

    def ours_pipeline():
        c = bsfjax.farthest_point_sampling(src_mesh, FRACTION)
        fr = bsfjax.build_frame(sm, c, TAUS, GAMMA)
        a = bsfjax.encode(fr, F32, "omp", sparsity=SPARSITY, weights=None)
        return bsfjax.decode(bsfjax.transfer_frame(fr, C_id, sn), a)

    t_ours, moved, _ = timed(ours_pipeline, rep)
    err = float(np.median(np.asarray(bsfjax.relative_error(F32, moved, sn.mass))))
    if not dense_peer:
        suite.add(size, n, "pipeline after eigensolve", t_ours, "numpy + sklearn", None,
                  f"transfer rel. error {err:.3f}; peer needs the dense float64 B", repeats=rep)
        return
    for pre in (False, True):
        def peer_pipeline():
            c = numpy_fps(V, first, n_c)
            B, coeffs = numpy_build(sm, c)
            a = sk_omp(np.asarray(B, np.float64), F, SPARSITY, pre)
            Bt = numpy_transfer(coeffs, C_id, np.asarray(sn.evecs))
            return a @ Bt.T.astype(np.float64)

        if size == "7k":  # both sides alternately, so that drifts of the machine hit both
            t_pair, t_p, moved_p = interleaved(ours_pipeline, peer_pipeline, rep)
        else:
            t_pair = t_ours
            t_p, moved_p, _ = timed(peer_pipeline, rep_slow)
        err_p = float(np.median(np.asarray(bsfjax.relative_error(F, moved_p, sn.mass))))
        name = "numpy + sklearn orthogonal_mp" + ("(precompute=True)" if pre else "")
        suite.add(size, n, "pipeline after eigensolve", t_pair, name, t_p,
                  f"100 functions; transfer rel. error ours {err:.3f} / peer {err_p:.3f}",
                  repeats=rep)


def markdown(rows, mach, sizes):
    out = [f"Machine: {mach}.  Median seconds (ms below 1 s); ratio = peer / bsfjax (> 1: bsfjax "
           "faster); bsfjax float32, peers float64.", "",
           "| size | n | stage | bsfjax | peer | peer time | ratio | note |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = "—" if r["ratio"] is None else f"{r['ratio']:.2f}×"
        out.append(f"| {r['size']} | {r['n']} | {r['stage']} | {fmt(r['bsfjax_s'])} | {r['peer']} "
                   f"| {fmt(r['peer_s'])} | {ratio} | {r['note']} |")
    return "\n".join(out) + "\n"


def main(argv=None):
    ap = h.parser(__doc__)
    h.add_out(ap, type=Path, help="folder for results.json/results.md")
    ap.add_argument("--sizes", default="7k,50k")
    h.add_data(ap)
    h.add_repeats(ap, 5)
    ap.add_argument("--methods", default="lstsq,omp,omp_error,lasso")
    ap.add_argument("--peer-functions", type=int, default=4,
                    help="functions given to per-function peers above 7k (time scaled to 100)")
    ap.add_argument("--dense-peer-gib", type=float, default=3.0,
                    help="largest dense float64 frame the numpy peer may form")
    h.add_cache(ap, h.TMP_CACHE, type=Path, help="spectrum cache folder (target shapes)")
    args = ap.parse_args(argv)
    sizes = h.name_list(args.sizes)
    h.require_data(*(args.data / "faust" / f"tr_reg_00{i}.off" for i in (0, 1) if "7k" in sizes),
                   *(args.data / "tosca_10k" / "cat" / f"cat{i}.off" for i in (0, 1)
                     if set(sizes) - {"7k"}))
    suite = Suite(args)
    mach = h.describe_machine()
    t0 = time.perf_counter()
    with PeakRSS() as mem:
        for size in sizes:
            run_size(suite, size)
            result = {"machine": mach, "sizes": sizes, "k": K, "fraction": FRACTION,
                      "taus": TAUS, "gamma": GAMMA, "sparsity": SPARSITY,
                      "n_functions": N_FUNCTIONS, "rows": suite.rows,
                      "wall_seconds": time.perf_counter() - t0}
            h.write_json(args.out / "results.json", result)
            h.write_text(args.out / "results.md", markdown(suite.rows, mach, sizes))
    result["peak_rss_gib"] = mem.peak / h.GIB
    h.write_json(args.out / "results.json", result)
    print(markdown(suite.rows, mach, sizes))
    print(f"wrote {args.out}/results.json and results.md ({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
