"""Fig. 7 of Melzi 2019: transfer error with rectangular ground-truth ``(k_N × k_M)`` maps as
the target basis size ``k_N`` grows, for ``k_M`` ∈ {10, 30, 50}.

The functions are coded once on the source per ``(k_M, method)`` and transferred through each
``C[:k_N]`` (exact truncation of the ground-truth map).  Only the methods whose transfer
depends on ``k_N`` through ``C`` alone (`KN_METHODS`: ``std`` and the BSF coders) take
part.  Report: mean error per (k_M, method) and k_N, one figure panel per k_M.
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from . import _engine
from ._datasets import Dataset
from ._engine import KN_METHODS, TRANSFER_METHODS
from ._io import Report, _curve, pivot_markdown, summarize
from ._shapes import _Maps, _check_ks, _check_methods, _errors, _functions, _groups, _pair_input, prepare_shapes

__all__ = ["KN_METHODS", "kn_experiment"]

DEFAULT_KS = (10, 30, 50)
DESCRIPTION = "Transfer error with ground-truth (k_N × k_M) maps as k_N grows."


def kn_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100,
                  k_sources=DEFAULT_KS, k_targets=(10, 20, 30, 40, 50, 60, 70, 80, 90, 100),
                  methods=KN_METHODS, params=None, n_bsf=0.05, seed: int = 0,
                  cache_dir=None, progress: bool = True) -> list[dict]:
    """Fig. 7: transfer error with ground-truth ``(k_N, k_M)`` maps as ``k_N`` grows.

    **Arguments:**

    - `dataset`: the ``--data`` folder (`load_dataset`).
    - `pairs`: number of pairs.
    - `functions`: random indicators per source shape.
    - `k_sources`: the source sizes ``k_M``.
    - `k_targets`: the target sizes ``k_N``.
    - `methods`: a subset of the methods other than ``std2`` and ``p2p``.
    - `params`: engine settings (`._engine.settings`; ``None``: the paper's).
    - `n_bsf`: BSF centres (share of the vertices or count).
    - `seed`: seed of the pairs, the functions and the FPS.
    - `cache_dir`: eigenbasis cache folder.
    - `progress`: show progress bars.

    **Returns:**

    Rows ``{"source", "target", "class", "k", "k_target", "method", "function", "error",
    "maps"}`` (``k`` is ``k_M``).
    """
    params = _engine.settings() if params is None else params
    k_sources, k_targets = _check_ks(k_sources, "k_sources"), _check_ks(k_targets, "k_targets")
    methods = _check_methods(methods, tuple(m for m in TRANSFER_METHODS
                                            if m not in ("std2", "p2p")))
    pair_ids = dataset.pairs(pairs, seed)
    shapes = prepare_shapes(dataset, [i for p in pair_ids for i in p],
                            k_max=max(max(k_sources), max(k_targets)), n_bsf=n_bsf, seed=seed,
                            geodesics="geod" in methods, cache_dir=cache_dir, progress=progress)
    fmaps = _Maps(dataset, shapes, pair_ids, "gt", max(k_targets))
    rows = []
    groups = _groups(pair_ids, lambda p: (shapes[p[0]].mesh.n_vertices,
                                          shapes[p[1]].mesh.n_vertices,
                                          len(shapes[p[0]].centers)))
    bar = tqdm(total=len(groups) * len(k_sources) * len(methods), desc="fig7",
               disable=not progress)
    for grp in groups:
        F = np.stack([_functions(shapes[p[0]], functions, seed) for p in grp])
        ref = np.stack([F[a][:, fmaps.gt[p]] for a, p in enumerate(grp)])
        mass_n = np.stack([shapes[p[1]].spectrum.mass for p in grp])
        for k in k_sources:
            for method in methods:
                bar.set_postfix_str(f"k_M={k} {method}")
                # one code on the source per (k_M, method); one transfer per C[:k_N]
                pair = _pair_input(shapes, fmaps, grp, method, k, max(k_targets))
                res = _engine.run_method(method, pair, F, k=k, settings=params,
                                         k_targets=k_targets)
                for kn, trans in zip(k_targets, res.transferred):
                    err = _errors(ref, trans, mass_n)
                    rows += [{"source": shapes[p[0]].name, "target": shapes[p[1]].name,
                              "class": shapes[p[0]].group, "k": k, "k_target": kn,
                              "method": method, "function": j, "error": float(err[a, j]),
                              "maps": "gt"}
                             for a, p in enumerate(grp) for j in range(functions)]
                bar.update()
    bar.close()
    return rows


def run(dataset: Dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> list[dict]:
    """``reproduce``'s call: `kn_experiment` with ``ks`` as the k_M list."""
    return kn_experiment(dataset, pairs=pairs, functions=functions, k_sources=ks, seed=seed,
                         cache_dir=cache_dir, progress=progress)


def report(rows: list[dict], ks) -> Report:
    """Mean error per (k_M, method) × k_N; one panel per k_M (error against k_N)."""
    md = pivot_markdown(rows, ("k", "method"), "k_target")
    summ = summarize(rows, ("k", "method", "k_target"))
    panels = [(f"k_M = {km}", "k_N", {m: _curve(summ, {"k": km, "method": m}, "k_target")
                                      for m in dict.fromkeys(r["method"] for r in rows)},
               False) for km in dict.fromkeys(r["k"] for r in rows)]
    return Report(md, panels)
