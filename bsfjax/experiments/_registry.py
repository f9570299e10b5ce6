"""The registry of experiments and `reproduce`, which runs one of them by name.

An `Experiment` names a module's two functions: ``run`` (the uniform call
``run(dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> rows``) and ``report``
(``report(rows, ks) -> Report``: Markdown, optional figure panels, optional settings line).
`reproduce` looks the name up in `EXPERIMENTS`, runs it, and writes the files; the
``bsfjax reproduce`` command takes its choices from `EXPERIMENTS`.
"""

from __future__ import annotations

import dataclasses
import json
import platform
import time
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from .._util import BSFError
from . import fig7, fig10, segmentation, sparse, table1, table2, table3, table4, table5
from ._datasets import load_dataset
from ._io import PAPER_SETTINGS, Report, _header, _line_plot, _write_text, write_csv

__all__ = ["Experiment", "EXPERIMENTS", "reproduce"]


@dataclasses.dataclass(frozen=True)
class Experiment:
    """One entry of the registry.

    **Attributes:**

    - `name`: the ``bsfjax reproduce`` name (also the stem of the output files).
    - `description`: what ``NAME.md`` shows (its first paragraph).
    - `run`: ``run(dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> rows``.
    - `default_ks`: the k list when ``reproduce`` gets none.
    - `report`: ``report(rows, ks) -> Report``.
    - `uses_functions`: whether ``functions`` matters (else left out of the metadata).
    """

    name: str
    description: str
    run: Callable[..., list[dict]]
    default_ks: tuple[int, ...]
    report: Callable[[list[dict], tuple[int, ...]], Report]
    uses_functions: bool = True
    #: ``run`` takes ``segmentation=`` (a template segmentation file) and needs it
    uses_segmentation: bool = False


def _entry(name: str, module, **kw) -> Experiment:
    """The registry entry of an experiment module (its ``DESCRIPTION``, ``run``,
    ``DEFAULT_KS`` and ``report``)."""
    return Experiment(name, module.DESCRIPTION, module.run, tuple(module.DEFAULT_KS),
                      module.report, **kw)


#: name → `Experiment`, in the order of ``bsfjax reproduce --help``.
EXPERIMENTS: dict[str, Experiment] = {e.name: e for e in (
    _entry("table1", table1),
    _entry("table2", table2),
    _entry("fig7", fig7),
    _entry("table3", table3, uses_functions=False),
    _entry("table4", table4, uses_functions=False),
    _entry("table5", table5),
    _entry("fig10", fig10),
    _entry("sparse", sparse),
    _entry("segmentation", segmentation, uses_functions=False, uses_segmentation=True),
)}


def reproduce(name: str, data, out, *, pairs: int = 2, functions: int = 100, seed: int = 0,
              ks=None, cache_dir=None, progress: bool = True, segmentation=None) -> dict:
    """Run one experiment on a ``--data`` folder and write ``NAME.csv``, ``NAME.md``,
    ``NAME.json`` (and ``NAME.png`` for figures) into ``out``.

    **Arguments:**

    - `name`: a key of `EXPERIMENTS`.
    - `data`: the ``--data`` folder (`load_dataset`).
    - `out`: output folder.
    - `pairs`: number of pairs (table5: per class).
    - `functions`: random indicators per shape.
    - `seed`: seed of the pairs, the functions and the FPS.
    - `ks`: the experiment's k list (default: the entry's ``default_ks``; fig7: the k_M list;
      fig10, sparse: the first entry is the k).
    - `cache_dir`: eigenbasis cache folder (default ``out/.spectra``).
    - `progress`: show progress bars.
    - `segmentation`: template segmentation file (experiments that use one: ``segmentation``).

    **Returns:**

    ``{"rows", "files", "seconds"}``.
    """
    exp = EXPERIMENTS.get(name) if isinstance(name, str) else None
    if exp is None:
        raise BSFError(f"experiment must be one of {tuple(EXPERIMENTS)}, got {name!r}")
    for arg, v in (("pairs", pairs), ("functions", functions)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise BSFError(f"{arg} must be a positive int, got {v!r}")
    out = Path(out)
    cache_dir = out / ".spectra" if cache_dir is None else Path(cache_dir)
    dataset = load_dataset(data)
    t0 = time.perf_counter()
    meta = {"data": str(Path(data)), "shapes in folder": len(dataset.shapes),
            "pairs": pairs, "functions per shape": functions, "seed": seed,
            "settings": PAPER_SETTINGS,
            "jax": jax.__version__, "backend": jax.default_backend(),
            "machine": platform.machine()}
    if not exp.uses_functions:
        del meta["functions per shape"]
    ks = tuple(ks) if ks else exp.default_ks
    extra = {}
    if exp.uses_segmentation:
        extra["segmentation"] = segmentation
        meta["segmentation"] = str(segmentation)
    elif segmentation is not None:
        raise BSFError(f"experiment {name!r} takes no segmentation")
    rows = exp.run(dataset, pairs=pairs, functions=functions, ks=ks, seed=seed,
                   cache_dir=cache_dir, progress=progress, **extra)
    rep = exp.report(rows, ks)
    if rep.settings is not None:
        meta["settings"] = rep.settings
    stem = out / name
    files = []
    if rep.figure is not None:
        files.append(rep.figure(stem.with_suffix(".png")))
    elif rep.panels is not None:
        files.append(_line_plot(rep.panels, stem.with_suffix(".png")))
    seconds = time.perf_counter() - t0
    meta["wall time (s)"] = round(seconds, 1)
    files.insert(0, write_csv(rows, stem.with_suffix(".csv")))
    files.insert(1, _write_text(_header(name, exp.description, meta) + "\n" + rep.markdown
                                + "\n", stem.with_suffix(".md")))
    _write_text(json.dumps({"experiment": name, **{k: str(v) for k, v in meta.items()}},
                           indent=1), out / f"{name}.json")
    return {"rows": rows, "files": files, "seconds": seconds}


def cli(args) -> int:
    """``bsfjax reproduce NAME --data DIR --out DIR [...]`` (see `reproduce`)."""
    ks = None
    if args.k:
        try:
            ks = tuple(int(v) for v in str(args.k).split(","))
        except ValueError:
            raise BSFError(f"--k must be comma-separated integers, got {args.k!r}") from None
    res = reproduce(args.name, args.data, args.out, pairs=args.pairs, functions=args.functions,
                    seed=args.seed, ks=ks, cache_dir=args.cache, progress=not args.no_progress,
                    segmentation=args.segmentation)
    print(f"{args.name}: {len(res['rows'])} rows in {res['seconds']:.1f} s; wrote "
          + ", ".join(str(f) for f in res["files"]))
    return 0
