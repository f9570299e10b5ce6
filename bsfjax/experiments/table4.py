"""Table 4 of Melzi 2019: time to transfer one function with an estimated ``k × k`` map, per
method.

The timed call is the whole method given the two spectra and the map (for ours: frame build,
frame transfer, coding and decoding); the map estimation itself is timed once per pair and k
as ``fmap (estimate_fmap)``.  Report: median seconds per method and k.
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from . import _engine
from ._datasets import Dataset
from ._engine import TRANSFER_METHODS
from ._io import Report, pivot_markdown
from ._shapes import _Maps, _check_ks, _check_methods, _functions, _k_needed, prepare_shapes
from .table3 import _timeit
from .._maps import estimate_fmap
from .._maps import fmap_to_p2p
from .._sampling import geodesic_distances

__all__ = ["transfer_time_experiment"]

DEFAULT_KS = (10, 30)
DESCRIPTION = ("Time in seconds to transfer one function with an estimated map "
               "(median after a warm-up call; whole method given the spectra and the map).")


def transfer_time_experiment(dataset: Dataset, *, pairs: int = 2, ks=DEFAULT_KS,
                             methods=TRANSFER_METHODS, params=None, n_bsf=0.05,
                             seed: int = 0, cache_dir=None, repeats: int = 3,
                             progress: bool = True) -> list[dict]:
    """Table 4: time to transfer one function with an estimated map, per method.

    The timed call is the whole method given the two spectra and the map: for ours the frame
    build, its transfer, the coding and the decoding; for ``p2p`` the conversion of the map to
    a point map and the pull-back; for ``geod`` the geodesic distances from the centres too.
    The map estimation is timed once per pair as ``fmap (estimate_fmap)``.

    **Arguments:**

    - `dataset`: the ``--data`` folder (`load_dataset`).
    - `pairs`: number of pairs.
    - `ks`: basis sizes (square estimated maps).
    - `methods`: a subset of `TRANSFER_METHODS`.
    - `params`: engine settings (`._engine.settings`; ``None``: the paper's).
    - `n_bsf`: BSF centres (share of the vertices or count).
    - `seed`: seed of the pairs, the function and the FPS.
    - `cache_dir`: eigenbasis cache folder.
    - `repeats`: timed calls after the warm-up.
    - `progress`: show a progress bar.

    **Returns:**

    Rows ``{"source", "target", "n_source", "k", "method", "first_s", "time_s"}``.
    """
    params = _engine.settings() if params is None else params
    ks = _check_ks(ks)
    methods = _check_methods(methods, TRANSFER_METHODS)
    pair_ids = dataset.pairs(pairs, seed)
    shapes = prepare_shapes(dataset, [i for p in pair_ids for i in p],
                            k_max=max(_k_needed(ks, methods), 50), n_bsf=n_bsf, seed=seed,
                            cache_dir=cache_dir, progress=progress)
    fmaps = _Maps(dataset, shapes, pair_ids, "estimated", _k_needed(ks, methods))
    rows = []
    bar = tqdm(total=len(pair_ids) * len(ks) * (len(methods) + 1), desc="table4",
               disable=not progress)
    for p in pair_ids:
        s, t = shapes[p[0]], shapes[p[1]]
        f = _functions(s, 1, seed)
        base = {"source": s.name, "target": t.name, "n_source": s.mesh.n_vertices}
        fmaps.descriptors(p)
        for k in ks:
            d_m, d_n = fmaps.descriptors(p)
            first, med = _timeit(lambda: estimate_fmap(s.spectrum, t.spectrum, d_m, d_n, k=k),
                                 repeats)
            rows.append({**base, "k": k, "method": "fmap (estimate_fmap)", "first_s": first,
                         "time_s": med})
            bar.update()
            C = fmaps(p, k, k)
            C2 = fmaps(p, 2 * k, 2 * k) if "std2" in methods else None
            for method in methods:
                def call(method=method):
                    p2p = dist = None
                    if method == "p2p":
                        p2p = np.asarray(fmap_to_p2p(C, s.spectrum.truncate(k),
                                                     t.spectrum.truncate(k)))
                    if method == "geod":
                        dist = geodesic_distances(s.mesh, s.centers, method="heat")
                    pair = _engine.pair_input(s.spectrum, t.spectrum, C, C2, p2p, s.centers,
                                              dist)
                    return _engine.run_method(method, pair, f, k=k, settings=params).transferred

                first, med = _timeit(call, repeats)
                rows.append({**base, "k": k, "method": method, "first_s": first,
                             "time_s": med})
                bar.update()
    bar.close()
    return rows


def run(dataset: Dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> list[dict]:
    """``reproduce``'s call: `transfer_time_experiment` (one function per pair)."""
    return transfer_time_experiment(dataset, pairs=pairs, ks=ks, seed=seed,
                                    cache_dir=cache_dir, progress=progress)


def report(rows: list[dict], ks) -> Report:
    """Median seconds, method × k."""
    return Report(pivot_markdown(rows, "method", "k", value="time_s", fmt="{:.4f}"))
