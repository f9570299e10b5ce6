"""Table 5 of Melzi 2019: transfer error on TOSCA classes with estimated ``k × k`` maps
(k ∈ {10, 30}), for two BSF parameter sets (`PARAMETER_SETS`).

``pairs`` pairs are taken *per class* (a ``--data`` folder with class subfolders, e.g.
``tosca_5k/``); maps are estimated from WKS + WKS at 5 landmarks with descriptor
commutativity.  Methods without BSF parameters run once (``param_set = "-"``).  Report: mean
error per (method, parameter set) and (class, k).
"""

from __future__ import annotations

from ._datasets import Dataset
from ._engine import PARAMETER_SETS, PLAIN_METHODS, TRANSFER_METHODS
from .._util import BSFError
from ._io import Report, pivot_markdown
from ._shapes import _Maps, _check_ks, _check_methods, _k_needed, prepare_shapes
from .table2 import _transfer_rows

__all__ = ["PARAMETER_SETS", "tosca_experiment"]

DEFAULT_KS = (10, 30)
DESCRIPTION = ("Transfer error with estimated maps (WKS + 5 landmarks, descriptor "
               "commutativity), per class, k and parameter set.")


def tosca_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100, ks=DEFAULT_KS,
                     methods=TRANSFER_METHODS, parameter_sets=None, seed: int = 0,
                     cache_dir=None, progress: bool = True) -> list[dict]:
    """Table 5: transfer with estimated ``k × k`` maps per class, for each parameter set.

    ``pairs`` is the number of pairs *per class*.  Methods without BSF parameters (``std``,
    ``std2``, ``p2p``, ``prod``) run once and are reported with ``param_set = "-"``.

    **Arguments:**

    - `dataset`: the ``--data`` folder with class subfolders (`load_dataset`).
    - `pairs`: number of pairs per class.
    - `functions`: random indicators per source shape.
    - `ks`: basis sizes (square estimated maps).
    - `methods`: a subset of `TRANSFER_METHODS`.
    - `parameter_sets`: ``{name: {"n_bsf": ..., "params": settings}}``; ``None``:
      `PARAMETER_SETS`.
    - `seed`: seed of the pairs, the functions and the FPS.
    - `cache_dir`: eigenbasis cache folder.
    - `progress`: show progress bars.

    **Returns:**

    Rows of `transfer_experiment` (``maps = "estimated"``) plus ``"param_set"``.
    """
    ks = _check_ks(ks)
    methods = _check_methods(methods, TRANSFER_METHODS)
    sets = PARAMETER_SETS if parameter_sets is None else parameter_sets
    everything = dataset.pairs(None, seed)
    pair_ids = [p for g in dataset.groups
                for p in [q for q in everything if dataset.shapes[q[0]].group == g][:pairs]]
    if not pair_ids:
        raise BSFError(f"{dataset.root}: no class has two shapes to pair")
    k_max = max(_k_needed(ks, methods), 50)
    plain = [m for m in methods if m in PLAIN_METHODS]
    framed = [m for m in methods if m not in plain]
    rows = []
    shapes = None
    for name, cfg in sets.items():
        shapes = prepare_shapes(dataset, [i for p in pair_ids for i in p], k_max=k_max,
                                n_bsf=cfg["n_bsf"], seed=seed, geodesics="geod" in methods,
                                cache_dir=cache_dir, progress=progress)
        fmaps = _Maps(dataset, shapes, pair_ids, "estimated", k_max)
        todo = framed + (plain if name == next(iter(sets)) else [])
        for m in todo:
            tag = name if m in framed else "-"
            rows += _transfer_rows(dataset, shapes, fmaps, pair_ids, functions, seed,
                                   [(k, k) for k in ks], [m], cfg["params"],
                                   f"table5 {tag}", progress,
                                   extra={"maps": "estimated", "param_set": tag})
    return rows


def run(dataset: Dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> list[dict]:
    """``reproduce``'s call: `tosca_experiment` (``pairs`` per class)."""
    return tosca_experiment(dataset, pairs=pairs, functions=functions, ks=ks, seed=seed,
                            cache_dir=cache_dir, progress=progress)


def report(rows: list[dict], ks) -> Report:
    """Mean error, (method, parameter set) × (class, k)."""
    return Report(pivot_markdown(rows, ("method", "param_set"), ("class", "k")))
