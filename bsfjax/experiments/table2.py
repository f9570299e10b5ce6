"""Table 2 of Melzi 2019: transfer error (Eq. 15) with ground-truth ``k × k`` maps.

The random indicators of the source shape of each pair are coded by every method of
`TRANSFER_METHODS` and carried to the target by the ground-truth functional map
``C = Φ_Nᵀ A_N Π Φ_M``; the error ``‖f∘T − f̃_N‖_A / ‖f∘T‖_A`` is measured on the target.
`transfer_experiment` also runs with estimated maps (``maps="estimated"``), and
``_transfer_rows`` — the loop over groups of equal-sized pairs, sizes and methods — is shared
with Table 5 and Fig. 10.
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from . import _engine
from ._datasets import Dataset
from ._engine import TRANSFER_METHODS
from .._util import BSFError
from ._io import Report, pivot_markdown
from ._shapes import _Maps, _check_ks, _check_methods, _errors, _functions, _groups, _k_needed, _pair_input, prepare_shapes
from .table1 import DEFAULT_KS

__all__ = ["TRANSFER_METHODS", "transfer_experiment"]

DESCRIPTION = ("Transfer error (Eq. 15, square-root form) with ground-truth k × k maps, mean "
               "over functions and pairs.")


def _transfer_rows(dataset, shapes, maps, pair_ids, functions, seed, settings, methods, params,
                   desc, progress, extra=None, approximation=False):
    """Run ``methods`` on every ``(k, k_n)`` of ``settings`` for all pairs; tidy rows."""
    rows = []
    groups = _groups(pair_ids, lambda p: (shapes[p[0]].mesh.n_vertices,
                                          shapes[p[1]].mesh.n_vertices,
                                          len(shapes[p[0]].centers)))
    bar = tqdm(total=len(groups) * len(settings) * len(methods), desc=desc, disable=not progress)
    for grp in groups:
        F = np.stack([_functions(shapes[p[0]], functions, seed) for p in grp])
        ref = np.stack([F[a][:, maps.gt[p]] for a, p in enumerate(grp)])  # f ∘ T on N
        mass_m = np.stack([shapes[p[0]].spectrum.mass for p in grp])
        mass_n = np.stack([shapes[p[1]].spectrum.mass for p in grp])
        for k, k_n in settings:
            for method in methods:
                bar.set_postfix_str(f"k={k},{k_n} {method}")
                pair = _pair_input(shapes, maps, grp, method, k, k_n)
                res = _engine.run_method(method, pair, F, k=k, settings=params)
                err = _errors(ref, res.transferred, mass_n)
                aerr = (_errors(F, res.approximation, mass_m)
                        if approximation and res.approximation is not None else None)
                for a, p in enumerate(grp):
                    for j in range(functions):
                        row = {"source": shapes[p[0]].name, "target": shapes[p[1]].name,
                               "class": shapes[p[0]].group, "k": k, "k_target": k_n,
                               "method": method, "function": j, "error": float(err[a, j])}
                        if approximation:
                            row["approx_error"] = (float(aerr[a, j]) if aerr is not None
                                                   else float("nan"))
                        rows.append({**row, **(extra or {})})
                bar.update()
    bar.close()
    return rows


def transfer_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100,
                        ks=DEFAULT_KS, methods=TRANSFER_METHODS, params=None,
                        maps: str = "gt", n_bsf=0.05, seed: int = 0, cache_dir=None,
                        progress: bool = True, approximation: bool = False) -> list[dict]:
    """Table 2 (``maps="gt"``) or its estimated-map version (``maps="estimated"``): transfer
    error on ``pairs`` pairs with square ``k × k`` maps.

    **Arguments:**

    - `dataset`: the ``--data`` folder (`load_dataset`).
    - `pairs`: number of pairs.
    - `functions`: random indicators per source shape.
    - `ks`: basis sizes (square maps).
    - `methods`: a subset of `TRANSFER_METHODS`.
    - `params`: engine settings (`._engine.settings`; ``None``: the paper's).
    - `maps`: ``"gt"`` (ground truth) or ``"estimated"`` (WKS + 5 landmarks).
    - `n_bsf`: BSF centres (share of the vertices or count).
    - `seed`: seed of the pairs, the functions and the FPS.
    - `cache_dir`: eigenbasis cache folder.
    - `progress`: show progress bars.
    - `approximation`: also report the approximation error on the source.

    **Returns:**

    Rows ``{"source", "target", "class", "k", "k_target", "method", "function", "error",
    "maps"}`` (plus ``"approx_error"`` with ``approximation=True``, NaN for ``p2p``).
    """
    params = _engine.settings() if params is None else params
    ks = _check_ks(ks)
    methods = _check_methods(methods, TRANSFER_METHODS)
    if maps not in ("gt", "estimated"):
        raise BSFError(f"maps must be 'gt' or 'estimated', got {maps!r}")
    pair_ids = dataset.pairs(pairs, seed)
    shapes = prepare_shapes(dataset, [i for p in pair_ids for i in p],
                            k_max=max(_k_needed(ks, methods), 50 if maps == "estimated" else 2),
                            n_bsf=n_bsf, seed=seed, geodesics="geod" in methods,
                            cache_dir=cache_dir, progress=progress)
    fmaps = _Maps(dataset, shapes, pair_ids, maps, _k_needed(ks, methods))
    return _transfer_rows(dataset, shapes, fmaps, pair_ids, functions, seed,
                          [(k, k) for k in ks], methods, params,
                          "table2" if maps == "gt" else "transfer", progress,
                          extra={"maps": maps}, approximation=approximation)


def run(dataset: Dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> list[dict]:
    """``reproduce``'s call: `transfer_experiment` (ground-truth maps, every method)."""
    return transfer_experiment(dataset, pairs=pairs, functions=functions, ks=ks, seed=seed,
                               cache_dir=cache_dir, progress=progress)


def report(rows: list[dict], ks) -> Report:
    """Mean error, method × k."""
    return Report(pivot_markdown(rows, "method", "k"))
