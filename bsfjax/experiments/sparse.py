"""Beyond the paper: approximation and transfer error against the number of
non-zeros, with the paper's BSF scales and with ``taus="adaptive"``, against the spectral
projection with as many coefficients.

Transfers use the ground-truth map (paper Eq. 11–12) and an estimated map (WKS + 5 landmarks
+ ZoomOut, [`bsfjax.estimate_map`][bsfjax.estimate_map]), whose BSF transfer is done both by re-binarization
and through the refined point map.  Report: the target ratios against the projection, error and
non-zero
tables, one figure with three panels (approximation, GT-map transfer, estimated-map
transfer).
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from . import _engine
from ._datasets import Dataset
from .._util import BSFError
from .._maps import fmap_from_p2p
from .._maps import estimate_map
from ._io import Report, _curve, pivot_markdown, summarize
from .._sampling import farthest_point_sampling
from ._shapes import N_LANDMARKS, _check_ks, _errors, _functions, prepare_shapes

__all__ = ["SPARSITIES", "SPARSE_FRAMES", "sparse_experiment"]

DEFAULT_KS = (50,)
DESCRIPTION = ("Beyond the paper: approximation and transfer error against the number of "
               "non-zeros S (omp) or coefficients (std), paper scales vs adaptive scales; "
               "ground-truth and estimated (WKS + 5 landmarks + ZoomOut) maps.")

#: Numbers of non-zeros of the ``sparse`` experiment (OMP's S; the projection's coefficients).
SPARSITIES = (5, 10, 20, 30, 50)
#: Frames of the ``sparse`` experiment: name → (taus, prune).  "paper" is the paper's frame
#: exactly; "adaptive" the 6 scales of [`bsfjax.adaptive_taus`][bsfjax.adaptive_taus], pruned.
SPARSE_FRAMES = {"paper": ((1e-3, 5e-3, 1e-2), False), "adaptive": ("adaptive", True)}


def sparse_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100, k: int = 50,
                      sparsities=SPARSITIES, lasso_targets=(), n_bsf=0.05, seed: int = 0,
                      cache_dir=None, progress: bool = True) -> list[dict]:
    """Error against the number of non-zeros: paper frame, adaptive frame, projection.

    Per pair (source ``M``, target ``N``) and function ``f`` (random indicators, as
    everywhere), at basis size ``k``:

    * ``std``: projection on the first ``s`` eigenfunctions, ``s`` ∈ ``sparsities`` (its
      number of coefficients), transferred with ``C[:s, :s]``;
    * ``omp`` with ``sparsity = S`` ∈ ``sparsities`` on each frame of `SPARSE_FRAMES`
      (n_BSF centres, γ = 0.75, area-weighted coding), and ``lstsq`` on each frame (all atoms,
      ``sparsity = "all"``), plus ``lasso`` with ``target_atoms`` ∈ ``lasso_targets``;
    * transfer with the ground-truth map (``maps = "gt"``, paper Eq. 11–12 re-binarization)
      and with an estimated map (``maps = "estimated"``: [`bsfjax.estimate_map`][bsfjax.estimate_map],
      WKS + 5 landmarks — FPS on ``N``, paired by the ground truth — ZoomOut to ``2k``), whose
      BSF transfer is done both ways, ``frame_transfer = "binary"`` (Eq. 11–12 with the
      estimated ``C``) and ``"p2p"`` (atoms pulled back through the refined point map).

    **Arguments:**

    - `dataset`: the ``--data`` folder (`load_dataset`).
    - `pairs`: number of pairs.
    - `functions`: random indicators per source shape.
    - `k`: basis size (int ≥ 2).
    - `sparsities`: OMP's S values and the projection's coefficient counts (each ≤ k; the
      projection also runs with all k).
    - `lasso_targets`: atom counts of the lasso runs (``target_atoms``); empty: no lasso.
    - `n_bsf`: BSF centres (share of the vertices or count).
    - `seed`: seed of the pairs, the functions and the FPS.
    - `cache_dir`: eigenbasis cache folder.
    - `progress`: show a progress bar.

    **Returns:**

    Rows ``{"source", "target", "class", "k", "frame", "method", "sparsity", "nonzeros",
    "maps", "frame_transfer", "function", "approx_error", "error"}`` (``frame = "-"`` and
    ``frame_transfer = "-"`` for ``std``).
    """
    sparsities = _check_ks(sparsities, "sparsities") if len(tuple(sparsities)) else ()
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 2:
        raise BSFError(f"k must be an int >= 2, got {k!r}")
    if any(s > k for s in sparsities):
        raise BSFError(f"sparsities must be <= k = {k} (the projection has k coefficients), "
                       f"got {sparsities}")
    lasso_targets = tuple(int(t) for t in lasso_targets)
    pair_ids = dataset.pairs(pairs, seed)
    shapes = prepare_shapes(dataset, [i for p in pair_ids for i in p], k_max=2 * k,
                            n_bsf=n_bsf, seed=seed, cache_dir=cache_dir, progress=progress)
    rows: list[dict] = []
    for a, b in tqdm(pair_ids, desc="sparse", disable=not progress):
        s, t = shapes[a], shapes[b]
        gt = dataset.ground_truth(a, b)
        F = _functions(s, functions, seed)
        ref = F[:, gt]
        sk, tk = s.spectrum.truncate(k), t.spectrum.truncate(k)
        mm, mn = np.asarray(sk.mass), np.asarray(tk.mass)
        C_gt = np.asarray(fmap_from_p2p(sk, tk, gt))
        lm_n = farthest_point_sampling(t.mesh, N_LANDMARKS, seed=0)
        est = estimate_map(s.spectrum, t.spectrum, k=k, landmarks=(gt[lm_n], lm_n),
                           refine_to=2 * k)
        base = {"source": s.name, "target": t.name, "class": s.group, "k": k}

        def add(frame_name, method, sparsity, nonzeros, approx, transfers, ft):
            e_app = _errors(F[None], np.asarray(approx)[None], mm[None])[0]
            for (maps, trans_kind), est_f in transfers.items():
                err = _errors(ref[None], np.asarray(est_f)[None], mn[None])[0]
                rows.extend({**base, "frame": frame_name, "method": method,
                             "sparsity": sparsity, "nonzeros": int(nonzeros[j]),
                             "maps": maps, "frame_transfer": trans_kind if ft else "-",
                             "function": j, "approx_error": float(e_app[j]),
                             "error": float(err[j])} for j in range(functions))

        phi, psi = np.asarray(sk.evecs), np.asarray(tk.evecs)
        coef = (F * mm) @ phi  # Φᵀ A f
        for n in sorted(set(sparsities) | {k}):
            approx = coef[:, :n] @ phi[:, :n].T
            add("-", "std", n, np.full(functions, n), approx,
                {("gt", "-"): (coef[:, :n] @ C_gt[:n, :n].T) @ psi[:, :n].T,
                 ("estimated", "-"): (coef[:, :n] @ est.C[:n, :n].T) @ psi[:, :n].T}, False)
        for name, (taus, prune) in SPARSE_FRAMES.items():
            frame = _engine.build_frame(sk, s.centers, taus, 0.75, prune=prune)
            carry = _engine.transfer_frame
            targets = {("gt", "binary"): carry(frame, C_gt, tk),
                       ("estimated", "binary"): carry(frame, est.C, tk),
                       ("estimated", "p2p"): carry(frame, est.C, tk, p2p=est.p2p)}
            codes = [("omp", S, {"sparsity": S}) for S in sparsities]
            codes += [("lasso", T, {"target_atoms": T, "maxiter": 2000})
                      for T in lasso_targets]
            codes.append(("lstsq", "all", {}))
            for method, sparsity, opts in codes:
                alpha, info = _engine.encode(frame, F, method, weights="area",
                                             return_info=True, **opts)
                add(name, method, sparsity, np.asarray(info.n_atoms),
                    _engine.decode(frame, alpha),
                    {key: _engine.decode(tf, alpha) for key, tf in targets.items()}, True)
    return rows


def _sparse_claims(rows, k: int) -> str:
    """The target ratios against the projection with k coefficients, from the rows (means
    over all pairs and functions)."""
    def mean(value, **filt):
        v = [r[value] for r in rows if all(r[a] == b for a, b in filt.items())]
        return float(np.mean(v)) if v else float("nan")

    std_app = mean("approx_error", method="std", sparsity=k, maps="gt")
    std_gt = mean("error", method="std", sparsity=k, maps="gt")
    std_est = mean("error", method="std", sparsity=k, maps="estimated")
    lines = ["| quantity | value | projection (k coefficients) | change |", "|---|---|---|---|"]

    def line(label, v, ref):
        lines.append(f"| {label} | {v:.3f} | {ref:.3f} | {100 * (v - ref) / ref:+.1f} % |")

    if any(r["method"] == "omp" and r["sparsity"] == 30 for r in rows):
        line("E_app, adaptive, omp S = 30", mean("approx_error", frame="adaptive",
                                                 method="omp", sparsity=30, maps="gt"), std_app)
        line("E_tran GT map, adaptive, omp S = 30",
             mean("error", frame="adaptive", method="omp", sparsity=30, maps="gt"), std_gt)
        for ft in ("binary", "p2p"):
            line(f"E_tran estimated map, adaptive, omp S = 30, {ft}",
                 mean("error", frame="adaptive", method="omp", sparsity=30, maps="estimated",
                      frame_transfer=ft), std_est)
    line("E_app, adaptive, lstsq", mean("approx_error", frame="adaptive", method="lstsq",
                                        maps="gt"), std_app)
    line("E_app, paper, lstsq", mean("approx_error", frame="paper", method="lstsq",
                                     maps="gt"), std_app)
    return "\n".join(lines)


def _sparse_markdown(rows, k: int) -> str:
    app = [r for r in rows if r["maps"] == "gt"]
    return ("## The issue's targets (means over pairs and functions)\n\n" + _sparse_claims(rows, k)
            + "\n\n## approximation error\n\n"
            + pivot_markdown(app, ("frame", "method"), "sparsity", value="approx_error")
            + "\n\n## mean number of non-zeros\n\n"
            + pivot_markdown(app, ("frame", "method"), "sparsity", value="nonzeros",
                             fmt="{:.1f}", best=None)
            + "\n\n## transfer error\n\n"
            + pivot_markdown(rows, ("maps", "frame_transfer", "frame", "method"), "sparsity")
            + "\n\n## per pair, S = 30 / k coefficients\n\n"
            + pivot_markdown([r for r in rows if r["sparsity"] in (30, k, "all")],
                             ("maps", "frame_transfer", "frame", "method", "sparsity"),
                             ("source", "target")))


def _sparse_panels(rows):
    panels = []
    for title, value, filt in (("approximation", "approx_error", {"maps": "gt"}),
                               ("transfer, GT map", "error", {"maps": "gt"}),
                               ("transfer, estimated map", "error", {"maps": "estimated"})):
        sub = [r for r in rows if all(r[a] == b for a, b in filt.items())
               and r["method"] in ("std", "omp")]
        summ = summarize(sub, ("frame", "method", "frame_transfer", "sparsity"), value)
        lines = {}
        for key in dict.fromkeys((r["frame"], r["method"], r["frame_transfer"]) for r in sub):
            if title != "transfer, estimated map" and key[2] == "p2p":
                continue
            label = "std" if key[1] == "std" else f"{key[0]} omp" + (
                f" ({key[2]})" if filt["maps"] == "estimated" else "")
            lines[label] = _curve(summ, dict(zip(("frame", "method", "frame_transfer"), key)),
                                  "sparsity")
        panels.append((title, "non-zeros S / coefficients", lines, False))
    return panels


def run(dataset: Dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> list[dict]:
    """``reproduce``'s call: `sparse_experiment` at ``k = ks[0]``, the sparsities ≤ k."""
    k = ks[0]
    return sparse_experiment(dataset, pairs=pairs, functions=functions, k=k,
                             sparsities=[v for v in SPARSITIES if v <= k], seed=seed,
                             cache_dir=cache_dir, progress=progress)


def report(rows: list[dict], ks) -> Report:
    """The target ratios, error / non-zero tables, three panels; a k-specific settings line."""
    k = ks[0]
    settings = (f"k = {k}, n_BSF = 5 % (Euclidean FPS), γ = 0.75, area-weighted "
                "coding; frames: paper τ = (0.001, 0.005, 0.01) and "
                "taus='adaptive' (6 scales, pruned)")
    return Report(_sparse_markdown(rows, k), _sparse_panels(rows), settings)
