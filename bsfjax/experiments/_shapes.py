"""Shapes, test functions and functional maps shared by the experiments.

* `ShapeData` / `prepare_shapes`: a dataset shape with its spectrum, its n_BSF
  centres (farthest point sampling) and, for the ``geod`` baseline, geodesic distances;
* ``_functions``: the test functions of a shape, random connected indicators covering 5–25 %
  of the area ([`bsfjax.random_indicators`][bsfjax.random_indicators]), one random stream per (seed, shape);
* ``_Maps``: ground-truth maps ``C = Φ_Nᵀ A_N Π Φ_M`` ([`bsfjax.fmap_from_p2p`][bsfjax.fmap_from_p2p], one big
  map per pair, sliced) or estimated ones ([`bsfjax.estimate_fmap`][bsfjax.estimate_fmap] with WKS + WKS at
  `N_LANDMARKS` landmarks, chosen by farthest point sampling on the target and paired
  through the ground truth);
* ``_pair_input``: the stacked engine input of a group of pairs (``p2p`` gets the point map
  recovered from the same ``k × k`` map, [`bsfjax.fmap_to_p2p`][bsfjax.fmap_to_p2p], so that every method sees
  the same information);
* argument checks (``_check_ks``, ``_check_methods``) and grouping of equal-sized pairs
  (``_groups``: pairs of one size run under one ``vmap``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np
from tqdm.auto import tqdm

from . import _engine
from ._datasets import Dataset
from .._maps import wks
from .._util import BSFError
from .._maps import estimate_fmap
from .._maps import fmap_from_p2p, fmap_to_p2p
from .._sampling import geodesic_distances
from .._metrics import random_indicators
from .._metrics import relative_error
from .._sampling import farthest_point_sampling
from .._spectral import Spectrum, spectrum

__all__ = ["ShapeData", "prepare_shapes", "N_LANDMARKS"]

#: Landmarks of the estimated maps' descriptors (WKS at these vertices).
N_LANDMARKS = 5


@dataclasses.dataclass
class ShapeData:
    """A shape ready for the experiments: its dataset entry, spectrum, BSF centres, and (for
    ``geod``) the geodesic distances from the centres."""

    index: int
    name: str
    group: str
    mesh: object
    spectrum: Spectrum
    centers: np.ndarray
    distances: np.ndarray | None = None


def prepare_shapes(dataset: Dataset, indices: Sequence[int], *, k_max: int, n_bsf=0.05,
                   fps: str = "euclidean", seed: int = 0, geodesics: bool = False,
                   cache_dir=None, progress: bool = False) -> dict[int, ShapeData]:
    """Spectra (``k_max`` eigenpairs), FPS centres and optional geodesic distances per shape.

    **Arguments:**

    - `dataset`: the loaded ``--data`` folder (`load_dataset`).
    - `indices`: the shapes (indices into ``dataset.shapes``; duplicates are fine).
    - `k_max`: eigenpairs to compute (at most the vertex count).
    - `n_bsf`: BSF centres, a share of the vertices (float) or a count (int).
    - `fps`: farthest point sampling distance: ``"euclidean"``, ``"geodesic"``, ``"biharmonic"``.
    - `seed`: FPS seed.
    - `geodesics`: also compute heat-method geodesic distances from the centres (``geod``).
    - `cache_dir`: eigenbasis cache folder (``None``: no cache).
    - `progress`: show a progress bar.

    **Returns:**

    ``{index: ShapeData}``.
    """
    out = {}
    for i in tqdm(sorted(set(indices)), desc="shapes", disable=not progress, leave=False):
        e = dataset.shapes[i]
        if k_max > e.n_vertices:
            raise BSFError(f"{e.path}: k={k_max} eigenpairs asked for but the mesh has only "
                           f"{e.n_vertices} vertices")
        spec = spectrum(e.mesh, k_max, cache_dir=cache_dir)
        ctr = farthest_point_sampling(e.mesh, n_bsf, metric=fps, seed=seed,
                                      spectrum=spec if fps == "biharmonic" else None)
        dist = geodesic_distances(e.mesh, ctr, method="heat") if geodesics else None
        out[i] = ShapeData(i, e.name, e.group, e.mesh, spec, ctr, dist)
    return out


def _functions(shape: ShapeData, count: int, seed: int) -> np.ndarray:
    # one stream per (seed, shape) so that adding shapes does not change the others' functions
    return random_indicators(shape.mesh, count, seed=int(seed) * 1009 + shape.index,
                             mass=shape.spectrum.mass)


def _groups(keys: Sequence, size_of: Callable) -> list[list]:
    """Split ``keys`` into runs of equal ``size_of(key)`` (stackable for vmap)."""
    out: dict = {}
    for key in keys:
        out.setdefault(size_of(key), []).append(key)
    return list(out.values())


def _errors(reference, estimate, mass) -> np.ndarray:
    return np.asarray(relative_error(reference, estimate, mass[:, None, :]))


# --------------------------------------------------------------------------- maps


class _Maps:
    """Functional maps per pair and size: ground truth (sliced from one big map) or estimated
    (one estimation per size, cached)."""

    def __init__(self, dataset, shapes, pairs, kind: str, k_max: int):
        self.dataset, self.shapes, self.kind, self.k_max = dataset, shapes, kind, k_max
        self.gt = {p: dataset.ground_truth(*p) for p in pairs}
        self._big: dict = {}
        self._est: dict = {}
        self._descr: dict = {}

    def __call__(self, pair, k_m: int, k_n: int) -> np.ndarray:
        src, tgt = self.shapes[pair[0]].spectrum, self.shapes[pair[1]].spectrum
        if self.kind == "gt":
            if pair not in self._big:  # Φ_Nᵀ A Π Φ_M truncates exactly: compute it once
                self._big[pair] = np.asarray(fmap_from_p2p(src, tgt, self.gt[pair]))
            return self._big[pair][:k_n, :k_m]
        key = (pair, k_m, k_n)
        if key not in self._est:
            d_m, d_n = self.descriptors(pair)
            self._est[key] = np.asarray(estimate_fmap(src, tgt, d_m, d_n, k=(k_m, k_n)))
        return self._est[key]

    def descriptors(self, pair):
        """WKS (50 energies) and WKS at 5 landmarks, from the first ≤ 50 eigenpairs."""
        if pair not in self._descr:
            s, t = self.shapes[pair[0]], self.shapes[pair[1]]
            lm_n = farthest_point_sampling(t.mesh, N_LANDMARKS, seed=0)
            lm_m = self.gt[pair][lm_n]
            k = min(50, s.spectrum.k, t.spectrum.k)
            d = [np.concatenate([np.asarray(wks(x.spectrum, 50, k=k)),
                                 np.asarray(wks(x.spectrum, 50, k=k, landmarks=lm))], axis=1)
                 for x, lm in ((s, lm_m), (t, lm_n))]
            self._descr[pair] = tuple(d)
        return self._descr[pair]


def _pair_input(shapes, maps: _Maps, pairs, method: str, k: int, k_n: int):
    """Stacked engine input (`._engine.pair_input`) of ``pairs`` for ``method`` at sizes
    ``(k_n, k)``."""
    items = []
    for p in pairs:
        s, t = shapes[p[0]], shapes[p[1]]
        C = maps(p, k, k_n)
        items.append(_engine.pair_input(
            source=s.spectrum, target=t.spectrum, C=C,
            C2=maps(p, 2 * k, 2 * k_n) if method == "std2" else None,
            p2p=(np.asarray(fmap_to_p2p(C, s.spectrum.truncate(k), t.spectrum.truncate(k_n)))
                 if method == "p2p" else None),
            centers=s.centers, distances=s.distances if method == "geod" else None))
    return _engine.stack(items)


def _check_ks(ks, name="ks") -> tuple[int, ...]:
    try:
        ks = tuple(int(k) for k in ks)
    except (TypeError, ValueError):
        raise BSFError(f"{name} must be a sequence of positive ints, got {ks!r}") from None
    if not ks or min(ks) < 2:
        raise BSFError(f"{name} must be non-empty ints >= 2, got {ks!r}")
    return ks


def _check_methods(methods, allowed) -> tuple[str, ...]:
    methods = tuple(methods)
    bad = [m for m in methods if m not in allowed]
    if bad or not methods:
        raise BSFError(f"methods must be a non-empty subset of {allowed}, got {methods!r}")
    return methods


def _k_needed(ks, methods) -> int:
    return max(ks) * (2 if "std2" in methods else 1)
