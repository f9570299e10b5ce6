"""Benchmark: BSF transfer options with an estimated map, and float64 cross-checks.

On FAUST pairs from ``../shared/data/faust`` (the ``reproduce`` pairs, seed 0), k = 50,
``taus="adaptive"`` (pruned) and the paper's scales, area-weighted OMP with S = 30 (and
least squares), random indicators as in every experiment.  The map is estimated as in the
``sparse`` experiment (:func:`bsfjax.estimate_map`: WKS + 5 landmarks paired by the
ground truth, ZoomOut to 2k).  Transfer options compared on the target:

* ``binary``  — paper Eq. 11–12 with the estimated C (``transfer_frame``);
* ``p2p``     — the atoms pulled back through the refined point map (``transfer_frame(p2p=)``);
* ``soft a-b`` — the transported kernel ``|g_N| / max|g_N|`` mapped linearly from [a, b] to
  [0, 1] (a soft threshold instead of ``≥ γ``), same code α;
* ``refit``   — the code's support kept, its coefficients re-fitted on the target to the
  spectral transfer ``Φ_N C Φ_Mᵀ A f`` (area-weighted least squares on the transferred atoms).

Float64 cross-check (``--sklearn``): scikit-learn's ``orthogonal_mp`` on the same √A-scaled,
column-normalised atoms.  It stops early ("linear dependence in the dictionary") on part of the
functions; on the others (``*_sklearn_full_steps`` of them) the largest difference of the
approximation errors is ``*_sklearn_max_diff_full``.

    python benchmarks/bench_sparse.py --pairs 2 --functions 20 --out bench_sparse.json
"""

from __future__ import annotations

import json
import time

import numpy as np

import _harness as h
import bsfjax
from bsfjax.experiments import N_LANDMARKS, _functions, load_dataset, prepare_shapes
from bsfjax import estimate_map


def err(ref, est, mass) -> float:
    return float(np.mean(np.asarray(bsfjax.relative_error(ref, np.asarray(est), mass))))


def main(argv=None) -> dict:
    ap = h.parser(__doc__)
    h.add_data(ap, "faust", type=str, help="FAUST folder")
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--functions", type=int, default=20)
    ap.add_argument("--k", type=int, default=50)
    ap.add_argument("--sparsity", type=int, default=30)
    ap.add_argument("--sklearn", action="store_true", help="float64 OMP cross-check")
    h.add_cache(ap, None, help="eigenbasis cache folder")
    h.add_out(ap, required=False, help="JSON output")
    args = ap.parse_args(argv)
    h.require_data(args.data)
    ds = load_dataset(args.data)
    pairs = ds.pairs(args.pairs, 0)
    k, S = args.k, args.sparsity
    shapes = prepare_shapes(ds, [i for p in pairs for i in p], k_max=2 * k,
                            cache_dir=args.cache)
    results = []
    for a, b in pairs:
        s, t = shapes[a], shapes[b]
        gt = ds.ground_truth(a, b)
        F = _functions(s, args.functions, 0)
        ref = F[:, gt]
        sk, tk = s.spectrum.truncate(k), t.spectrum.truncate(k)
        mm, mn = np.asarray(sk.mass), np.asarray(tk.mass)
        phi, psi = np.asarray(sk.evecs, np.float64), np.asarray(tk.evecs, np.float64)
        lm_n = bsfjax.farthest_point_sampling(t.mesh, N_LANDMARKS, seed=0)
        t0 = time.perf_counter()
        est = estimate_map(s.spectrum, t.spectrum, k=k, landmarks=(gt[lm_n], lm_n),
                           refine_to=2 * k)
        t_map = time.perf_counter() - t0
        C = np.asarray(est.C, np.float64)
        coef = (F * mm) @ phi
        spectral = (coef @ C.T) @ psi.T
        row = {"pair": f"{s.name}->{t.name}", "map_s": round(t_map, 2),
               "std_app": err(F, coef @ phi.T, mm), "std_est": err(ref, spectral, mn)}
        for name, taus in (("paper", (1e-3, 5e-3, 1e-2)), ("adaptive", "adaptive")):
            fr = bsfjax.build_frame(sk, s.centers, taus, prune=name == "adaptive")
            for meth, opt in (("omp", {"sparsity": S}), ("lstsq", {})):
                tag = f"{name}_{meth}"
                alpha = np.asarray(bsfjax.encode(fr, F, meth, weights="area", **opt),
                                   np.float64)
                row[f"{tag}_app"] = err(F, bsfjax.decode(fr, alpha), mm)
                row[f"{tag}_binary"] = err(ref, bsfjax.decode(
                    bsfjax.transfer_frame(fr, C, tk), alpha), mn)
                row[f"{tag}_p2p"] = err(ref, bsfjax.decode(
                    bsfjax.transfer_frame(fr, C, tk, p2p=est.p2p), alpha), mn)
                g = np.abs(psi @ (C @ np.asarray(fr.coeffs, np.float64)))
                g = g / np.where(g.max(axis=0) > 0, g.max(axis=0), 1.0)
                for lo, hi in ((0.6, 0.9), (0.5, 1.0)):
                    soft = np.clip((g - lo) / (hi - lo), 0.0, 1.0)
                    row[f"{tag}_soft{lo}-{hi}"] = err(ref, alpha @ soft.T, mn)
                if meth == "omp":
                    Bn = np.asarray(bsfjax.transfer_frame(fr, C, tk).atoms, np.float64)
                    w = np.sqrt(mn)[:, None]
                    out = np.zeros_like(spectral)
                    for j in range(len(F)):
                        idx = np.flatnonzero(alpha[j])
                        x = np.linalg.lstsq(Bn[:, idx] * w, spectral[j] * w[:, 0], rcond=None)[0]
                        out[j] = Bn[:, idx] @ x
                    row[f"{tag}_refit"] = err(ref, out, mn)
                    if args.sklearn:
                        from sklearn.linear_model import orthogonal_mp

                        B = np.asarray(fr.atoms, np.float64) * np.sqrt(mm)[:, None]
                        nrm = np.linalg.norm(B, axis=0)
                        nz = nrm > 0
                        beta = orthogonal_mp(B[:, nz] / nrm[nz], (F * np.sqrt(mm)).T,
                                             n_nonzero_coefs=S)
                        a64 = np.zeros((fr.n_atoms, len(F)))
                        a64[nz] = beta / nrm[nz, None]
                        e64 = np.asarray(bsfjax.relative_error(
                            F, (np.asarray(fr.atoms, np.float64) @ a64).T, mm))
                        e32 = np.asarray(bsfjax.relative_error(
                            F, np.asarray(bsfjax.decode(fr, alpha)), mm))
                        # scikit-learn stops early ("linear dependence") on some functions;
                        # where it runs all S steps the two OMPs must agree
                        full = np.count_nonzero(a64, axis=0) == S
                        row[f"{tag}_app_sklearn"] = float(np.mean(e64))
                        row[f"{tag}_sklearn_full_steps"] = float(np.sum(full))
                        row[f"{tag}_sklearn_max_diff_full"] = (
                            float(np.max(np.abs(e64 - e32)[full])) if full.any() else 0.0)
        results.append(row)
        print(json.dumps({kk: (round(v, 4) if isinstance(v, float) else v)
                          for kk, v in row.items()}, indent=None), flush=True)
    keys = [kk for kk in results[0] if kk != "pair"]
    mean = {kk: float(np.mean([r[kk] for r in results])) for kk in keys}
    print("mean:", json.dumps({kk: round(v, 4) for kk, v in mean.items()}))
    out = {"k": k, "sparsity": S, "functions": args.functions, "pairs": results, "mean": mean}
    if args.out:
        h.write_json(args.out, out, indent=1)
    return out


if __name__ == "__main__":
    main()
