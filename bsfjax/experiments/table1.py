"""Table 1 of Melzi 2019: approximation error (Eq. 14) against the basis size k.

Every method of `APPROX_METHODS` (all but ``p2p``, which has no approximation) codes the
random indicator functions of the source shapes of ``pairs`` pairs with ``k`` ∈ {10, 30, 50,
70, 90} eigenfunctions; the error is ``‖f − f̃‖_A / ‖f‖_A``.  Report: mean error per method
(rows) and k (columns).
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from . import _engine
from ._datasets import Dataset
from ._engine import APPROX_METHODS
from ._io import Report, pivot_markdown
from ._shapes import _check_ks, _check_methods, _errors, _functions, _groups, _k_needed, prepare_shapes

__all__ = ["DEFAULT_KS", "APPROX_METHODS", "approximation_experiment"]

#: The k of Tables 1 and 2.
DEFAULT_KS = (10, 30, 50, 70, 90)

DESCRIPTION = ("Approximation error (Eq. 14, square-root form ‖f − f̃‖_A / ‖f‖_A) on the "
               "source shapes, mean over functions and shapes.")


def approximation_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100,
                             ks=DEFAULT_KS, methods=APPROX_METHODS, params=None,
                             n_bsf=0.05, seed: int = 0, cache_dir=None,
                             progress: bool = True) -> list[dict]:
    """Table 1: approximation error on the source shapes of ``pairs`` pairs, per method and k.

    **Arguments:**

    - `dataset`: the ``--data`` folder (`load_dataset`).
    - `pairs`: number of pairs (their source shapes are coded).
    - `functions`: random indicators per shape.
    - `ks`: basis sizes.
    - `methods`: a subset of `APPROX_METHODS`.
    - `params`: engine settings (`._engine.settings`; ``None``: the paper's).
    - `n_bsf`: BSF centres (share of the vertices or count).
    - `seed`: seed of the pairs, the functions and the FPS.
    - `cache_dir`: eigenbasis cache folder.
    - `progress`: show progress bars.

    **Returns:**

    Rows ``{"shape", "k", "method", "function", "area_share", "error"}``.
    """
    params = _engine.settings() if params is None else params
    ks = _check_ks(ks)
    methods = _check_methods(methods, APPROX_METHODS)
    pair_ids = dataset.pairs(pairs, seed)
    shapes = prepare_shapes(dataset, [p[0] for p in pair_ids], k_max=_k_needed(ks, methods),
                            n_bsf=n_bsf, seed=seed, geodesics="geod" in methods,
                            cache_dir=cache_dir, progress=progress)
    rows = []
    groups = _groups(sorted(shapes), lambda i: (shapes[i].mesh.n_vertices,
                                                len(shapes[i].centers)))
    bar = tqdm(total=len(groups) * len(ks) * len(methods), desc="table1", disable=not progress)
    for grp in groups:
        F = np.stack([_functions(shapes[i], functions, seed) for i in grp])
        mass = np.stack([shapes[i].spectrum.mass for i in grp])
        share = (F * mass[:, None, :]).sum(-1) / mass.sum(-1)[:, None]
        for k in ks:
            for method in methods:
                bar.set_postfix_str(f"k={k} {method}")
                pair = _engine.stack([_engine.pair_input(
                    source=shapes[i].spectrum, centers=shapes[i].centers,
                    distances=shapes[i].distances if method == "geod" else None)
                    for i in grp])
                res = _engine.run_method(method, pair, F, k=k, settings=params, transfer=False)
                err = _errors(F, res.approximation, mass)
                for a, i in enumerate(grp):
                    rows += [{"shape": shapes[i].name, "k": k, "method": method, "function": j,
                              "area_share": float(share[a, j]), "error": float(err[a, j])}
                             for j in range(functions)]
                bar.update()
    bar.close()
    return rows


def run(dataset: Dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> list[dict]:
    """``reproduce``'s call: `approximation_experiment` with every method at ``ks``."""
    return approximation_experiment(dataset, pairs=pairs, functions=functions, ks=ks, seed=seed,
                                    cache_dir=cache_dir, progress=progress)


def report(rows: list[dict], ks) -> Report:
    """Mean error, method × k."""
    return Report(pivot_markdown(rows, "method", "k"))
