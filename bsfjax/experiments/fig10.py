"""Fig. 10 of Melzi 2019: dependence of the BSF coders on one setting at a time, at k = 30 with
ground-truth maps: the centre share n_BSF, the farthest-point-sampling distance, γ, ``omp_error``'s
ε and ``omp``'s S (`SWEEPS`, around the paper's defaults).

Report: per setting, the mean transfer and approximation errors per method and value, one
figure panel per setting (solid: transfer, dashed: approximation), and the spread (max − min of
the mean transfer error over the values) per method and setting.
"""

from __future__ import annotations

from . import _engine
from ._datasets import Dataset
from ._engine import CODERS
from .._util import BSFError
from ._io import Report, _curve, pivot_markdown, summarize
from ._shapes import _Maps, prepare_shapes
from .table2 import _transfer_rows

__all__ = ["SWEEPS", "parameter_experiment"]

#: fig10's sweeps (one parameter at a time around the paper's defaults).
SWEEPS = {
    "n_bsf": (0.01, 0.025, 0.05, 0.1),
    "fps": ("euclidean", "geodesic", "biharmonic"),
    "gamma": (0.5, 0.6, 0.75, 0.85, 0.95),
    "eps": (0.05, 0.1, 0.2, 0.3),
    "sparsity": (2, 5, 10, 20, 40),
}
DEFAULT_KS = (30,)
DESCRIPTION = ("Dependence of the BSF coders on one setting at a time (k = 30, ground-truth "
               "maps).")


def parameter_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100, k: int = 30,
                         sweeps=None, seed: int = 0, cache_dir=None,
                         progress: bool = True) -> list[dict]:
    """Fig. 10: approximation and ground-truth-map transfer error of the BSF coders at ``k``
    while one setting varies around the paper's defaults (`SWEEPS`): the centre share
    n_BSF, the FPS distance, γ (all four coders), ε (``omp_error``) and S (``omp``).

    **Arguments:**

    - `dataset`: the ``--data`` folder (`load_dataset`).
    - `pairs`: number of pairs.
    - `functions`: random indicators per source shape.
    - `k`: basis size (square ground-truth maps).
    - `sweeps`: a sub-dict of `SWEEPS` (``None``: all of it).
    - `seed`: seed of the pairs, the functions and the FPS.
    - `cache_dir`: eigenbasis cache folder.
    - `progress`: show progress bars.

    **Returns:**

    Rows ``{"parameter", "value", "method", "source", "target", "function", "error",
    "approx_error", ...}`` (``value`` as a string).
    """
    sweeps = SWEEPS if sweeps is None else sweeps
    bad = set(sweeps) - set(SWEEPS)
    if bad:
        raise BSFError(f"unknown sweep(s) {sorted(bad)}; valid: {sorted(SWEEPS)}")
    pair_ids = dataset.pairs(pairs, seed)
    idx = [i for p in pair_ids for i in p]
    base_shapes = prepare_shapes(dataset, idx, k_max=k, seed=seed, cache_dir=cache_dir,
                                 progress=progress)
    fmaps = _Maps(dataset, base_shapes, pair_ids, "gt", k)
    rows = []
    for param, values in sweeps.items():
        for value in values:
            shapes, params, methods = base_shapes, _engine.settings(), CODERS
            if param == "n_bsf":
                shapes = prepare_shapes(dataset, idx, k_max=k, n_bsf=value, seed=seed,
                                        cache_dir=cache_dir)
            elif param == "fps":
                shapes = prepare_shapes(dataset, idx, k_max=k, fps=value, seed=seed,
                                        cache_dir=cache_dir)
            elif param == "gamma":
                params = _engine.settings(gamma=value)
            elif param == "eps":
                params, methods = _engine.settings(eps_fraction=value), ("omp_error",)
            elif param == "sparsity":
                params, methods = _engine.settings(sparsity=value), ("omp",)
            fmaps.shapes = shapes
            rows += _transfer_rows(dataset, shapes, fmaps, pair_ids, functions, seed,
                                   [(k, k)], methods, params, f"fig10 {param}={value}",
                                   progress, extra={"parameter": param, "value": str(value)},
                                   approximation=True)
    return rows


def run(dataset: Dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> list[dict]:
    """``reproduce``'s call: `parameter_experiment` at ``k = ks[0]``, every sweep."""
    return parameter_experiment(dataset, pairs=pairs, functions=functions, k=ks[0], seed=seed,
                                cache_dir=cache_dir, progress=progress)


def _spread_markdown(rows) -> str:
    summ = summarize(rows, ("parameter", "method", "value"))
    out: dict = {}
    for s in summ:
        out.setdefault((s["method"], s["parameter"]), []).append(s["mean"])
    spread = [{"method": m, "parameter": p, "spread": max(v) - min(v)}
              for (m, p), v in out.items()]
    return pivot_markdown(spread, "method", "parameter", value="spread")


def report(rows: list[dict], ks) -> Report:
    """Per setting: transfer and approximation error tables and a panel; then the spreads."""
    parts = []
    summ = summarize(rows, ("parameter", "method", "value"))
    asumm = summarize(rows, ("parameter", "method", "value"), "approx_error")
    panels = []
    for param in dict.fromkeys(r["parameter"] for r in rows):
        sub = [r for r in rows if r["parameter"] == param]
        parts.append(f"## {param}: transfer error\n\n"
                     + pivot_markdown(sub, "method", "value") + "\n\n"
                     + f"## {param}: approximation error\n\n"
                     + pivot_markdown(sub, "method", "value", value="approx_error"))
        ms = list(dict.fromkeys(r["method"] for r in sub))
        lines = {m: _curve(summ, {"parameter": param, "method": m}, "value") for m in ms}
        lines.update({f"{m} (approx)": _curve(asumm, {"parameter": param, "method": m},
                                              "value") for m in ms})
        panels.append((param, param, lines, True))
    md = "Dashed lines in the figure: approximation error; solid: transfer error.\n\n" \
        + "\n\n".join(parts) + "\n\n## spread (max − min of the mean transfer error over " \
        "the values)\n\n" + _spread_markdown(rows)
    return Report(md, panels)
