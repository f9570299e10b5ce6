"""Table 3 of Melzi 2019: time to build the frames — geodesic balls (``geod``), saturated heat
kernels (``heat``) and the Binary Sparse Frame (``ours``) — on the source shapes.

Times are medians of ``repeats`` calls after one warm-up (compilation) call; the eigenbasis,
which ``heat`` and ``ours`` need and ``geod`` does not, is timed separately.  Report: median
seconds per (method, k) and shape.
"""

from __future__ import annotations

import math
import time

import jax
import numpy as np
from tqdm.auto import tqdm

from . import _engine
from ._datasets import Dataset
from ._io import Report, pivot_markdown
from ._shapes import _check_ks
from .._sampling import geodesic_distances
from .._sampling import farthest_point_sampling
from .._spectral import spectrum

__all__ = ["frame_time_experiment"]

DEFAULT_KS = (30, 90)
DESCRIPTION = "Frame build time in seconds (median of repeats after a warm-up call)."


def _timeit(fn, repeats: int = 3) -> tuple[float, float]:
    """(first call, median of ``repeats`` further calls) wall-clock seconds."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return first, float(np.median(times))


def frame_time_experiment(dataset: Dataset, *, pairs: int = 2, ks=DEFAULT_KS, params=None,
                          n_bsf=0.05, seed: int = 0, cache_dir=None, repeats: int = 3,
                          progress: bool = True) -> list[dict]:
    """Table 3: time to build the frames (geod, heat, ours) on the source shapes.

    ``ours``: [`bsfjax.build_frame`][bsfjax.build_frame] (Algorithm 1).  ``heat``: the same kernels, saturated.
    ``geod``: heat-method geodesic distances from the ``n_BSF`` centres, thresholded at the 3
    radii (the radii themselves are taken as given).  The eigenbasis (shared by ours and heat)
    is timed separately as ``eigenbasis``.  Times are medians of ``repeats`` runs after one
    warm-up (compilation) run; rows also give the first-call time.

    **Arguments:**

    - `dataset`: the ``--data`` folder (`load_dataset`).
    - `pairs`: number of pairs (their source shapes are timed).
    - `ks`: basis sizes of ``heat`` and ``ours`` (the eigenbasis is computed at the largest).
    - `params`: engine settings (`._engine.settings`; ``None``: the paper's).
    - `n_bsf`: BSF centres (share of the vertices or count).
    - `seed`: seed of the pairs and the FPS.
    - `cache_dir`: unused (the eigenbasis is timed, so never read from a cache).
    - `repeats`: timed calls after the warm-up.
    - `progress`: show a progress bar.

    **Returns:**

    Rows ``{"shape", "n_vertices", "n_centers", "method", "k", "n_atoms", "first_s",
    "time_s"}``.
    """
    params = _engine.settings() if params is None else params
    ks = _check_ks(ks)
    pair_ids = dataset.pairs(pairs, seed)
    rows = []
    srcs = sorted({p[0] for p in pair_ids})
    for i in tqdm(srcs, desc="table3", disable=not progress):
        e = dataset.shapes[i]
        t0 = time.perf_counter()
        spec = spectrum(e.mesh, max(ks))
        t_spec = time.perf_counter() - t0
        ctr = farthest_point_sampling(e.mesh, n_bsf, seed=seed)
        base = {"shape": e.name, "n_vertices": e.n_vertices, "n_centers": len(ctr)}
        rows.append({**base, "method": "eigenbasis", "k": max(ks), "n_atoms": 0,
                     "first_s": t_spec, "time_s": t_spec})
        radii = np.asarray([0.05, 0.1, 0.15]) * math.sqrt(e.mesh.area)

        def geod():
            D = geodesic_distances(e.mesh, ctr, method="heat")
            return (D[None] <= radii[:, None, None]).reshape(-1, D.shape[1]).T

        first, med = _timeit(geod, repeats)
        rows.append({**base, "method": "geod", "k": 0, "n_atoms": 3 * len(ctr),
                     "first_s": first, "time_s": med})
        for k in ks:
            sk = spec.truncate(k)
            ours = lambda: _engine.frame_atoms(sk, ctr, params)  # noqa: E731
            heat = lambda: _engine.heat_frame(sk, ctr, params)  # noqa: E731
            for name, fn in (("heat", heat), ("ours", ours)):
                first, med = _timeit(fn, repeats)
                rows.append({**base, "method": name, "k": k,
                             "n_atoms": _engine.n_atoms(params, len(ctr)), "first_s": first,
                             "time_s": med})
    return rows


def run(dataset: Dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> list[dict]:
    """``reproduce``'s call: `frame_time_experiment` (``functions`` is not used)."""
    return frame_time_experiment(dataset, pairs=pairs, ks=ks, seed=seed, cache_dir=cache_dir,
                                 progress=progress)


def report(rows: list[dict], ks) -> Report:
    """Median seconds, (method, k) × shape."""
    return Report(pivot_markdown(rows, ("method", "k"), "shape", value="time_s",
                                 fmt="{:.4f}"))
