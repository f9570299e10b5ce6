"""The experiments of Melzi 2019 as library functions returning tidy tables, and ``reproduce``.

Each experiment returns a list of flat ``dict`` rows (one per function × method × setting, a
"tidy" table that :func:`write_csv` writes and :func:`summarize` aggregates):

* ``table1`` — approximation error (Eq. 14) vs k ∈ {10, 30, 50, 70, 90}:
  :func:`approximation_experiment`;
* ``table2`` — transfer error (Eq. 15) with ground-truth maps, same k: :func:`transfer_experiment`;
* ``fig7`` — transfer error as k_N grows, k_M ∈ {10, 30, 50}: :func:`kn_experiment`;
* ``table3`` — frame build time (geod, heat, ours): :func:`frame_time_experiment`;
* ``table4`` — time to transfer one function with estimated maps: :func:`transfer_time_experiment`;
* ``table5`` — TOSCA classes, estimated 10×10 and 30×30 maps, two parameter sets:
  :func:`tosca_experiment`;
* ``fig10`` — dependence on the n_BSF share, FPS distance, γ, ε and S: :func:`parameter_experiment`;
* ``sparse`` (beyond the paper) — approximation and transfer error (ground-truth and estimated
  maps) against the number of non-zeros, paper scales vs ``taus="adaptive"`` vs the projection
  with as many coefficients: :func:`sparse_experiment`.

Errors are the square-root form ``‖f − f̃‖_A / ‖f‖_A`` (:func:`bsfjax.relative_error`).
Test functions are random connected indicators covering 5–25 % of the area
(:func:`bsfjax.random_indicators`), drawn on each source shape from ``seed``.  Settings are the
paper's: n_BSF = 5 % of the vertices by Euclidean farthest point sampling, τ ∈ {0.001, 0.005,
0.01} (unit-area convention), γ = 0.75, OMP S = 10, ``omp_error`` ε = ‖f‖/10
(:class:`bsfjax.baselines.Params`).  Ground-truth maps are ``C = Φ_Nᵀ A_N Π Φ_M``
(:func:`bsfjax.fmap_from_p2p`); the ``p2p`` baseline uses the point map recovered from the same
``k × k`` map (:func:`bsfjax.fmap_to_p2p`), so every method sees the same information.
Estimated maps (tables 4–5) minimise descriptor preservation + Laplacian and descriptor
commutativity (:func:`bsfjax.estimate_fmap`) with WKS descriptors plus WKS at 5 landmarks
(chosen by farthest point sampling on the target, paired through the ground truth).

All pairs of one size are stacked and every method runs on all pairs × functions in one jitted
``vmap`` (:func:`bsfjax.baselines.run_baseline`); only methods, settings and groups of
differently sized pairs are Python loops.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import platform
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from ._files import atomic_path
from ._baselines import CODERS, METHODS, PairInput, Params, run_baseline
from ._datasets import Dataset, load_dataset
from ._descriptors import wks
from ._errors import BSFError
from ._encode import decode, encode
from ._estimation import estimate_fmap
from ._fmap import fmap_from_p2p, fmap_to_p2p
from ._frame import build_frame, transfer_frame
from ._highlevel import estimate_map
from ._geodesics import geodesic_distances
from ._indicators import random_indicators
from ._metrics import relative_error
from ._sampling import farthest_point_sampling
from ._spectrum import Spectrum, spectrum

__all__ = [
    "EXPERIMENTS", "DEFAULT_KS", "APPROX_METHODS", "TRANSFER_METHODS", "PARAMETER_SETS",
    "ShapeData", "prepare_shapes", "approximation_experiment", "transfer_experiment",
    "kn_experiment", "frame_time_experiment", "transfer_time_experiment", "tosca_experiment",
    "parameter_experiment", "sparse_experiment", "SPARSITIES", "SPARSE_FRAMES", "summarize", "pivot_markdown", "write_csv", "reproduce",
]

EXPERIMENTS = ("table1", "table2", "fig7", "table3", "table4", "table5", "fig10", "sparse")
DEFAULT_KS = (10, 30, 50, 70, 90)
APPROX_METHODS = tuple(m for m in METHODS if m != "p2p")
TRANSFER_METHODS = METHODS
#: fig7's methods: those whose transfer depends on k_N alone through C.
KN_METHODS = ("std",) + CODERS
#: Table 5's two BSF parameter sets.  "paper": the paper's defaults.  "wide": larger, fewer
#: overlapping atoms (τ doubled, γ = 0.6), which should suit the coarse 10×10 estimated maps.
PARAMETER_SETS = {
    "paper": {"n_bsf": 0.05, "params": Params()},
    "wide": {"n_bsf": 0.05, "params": Params(taus=(2e-3, 1e-2, 2e-2), gamma=0.6)},
}
#: fig10's sweeps (one parameter at a time around the paper's defaults).
SWEEPS = {
    "n_bsf": (0.01, 0.025, 0.05, 0.1),
    "fps": ("euclidean", "geodesic", "biharmonic"),
    "gamma": (0.5, 0.6, 0.75, 0.85, 0.95),
    "eps": (0.05, 0.1, 0.2, 0.3),
    "sparsity": (2, 5, 10, 20, 40),
}
N_LANDMARKS = 5


# --------------------------------------------------------------------------- shape preparation


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
    """Spectra (``k_max`` eigenpairs), FPS centres and optional geodesic distances per shape."""
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


def _stack(items):
    return jax.tree.map(lambda *x: np.stack([np.asarray(v) for v in x]), *items)


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


def _pair_input(shapes, maps: _Maps, pairs, method: str, k: int, k_n: int) -> PairInput:
    """Stacked :class:`PairInput` of ``pairs`` for ``method`` at sizes ``(k_n, k)``."""
    items = []
    for p in pairs:
        s, t = shapes[p[0]], shapes[p[1]]
        C = maps(p, k, k_n)
        items.append(PairInput(
            source=s.spectrum, target=t.spectrum, C=C,
            C2=maps(p, 2 * k, 2 * k_n) if method == "std2" else None,
            p2p=(np.asarray(fmap_to_p2p(C, s.spectrum.truncate(k), t.spectrum.truncate(k_n)))
                 if method == "p2p" else None),
            centers=s.centers, distances=s.distances if method == "geod" else None))
    return _stack(items)


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


# --------------------------------------------------------------------------- table 1 / table 2


def approximation_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100,
                             ks=DEFAULT_KS, methods=APPROX_METHODS, params: Params = Params(),
                             n_bsf=0.05, seed: int = 0, cache_dir=None,
                             progress: bool = True) -> list[dict]:
    """Table 1: approximation error on the source shapes of ``pairs`` pairs, per method and k.

    Rows: ``{"shape", "k", "method", "function", "area_share", "error"}``.
    """
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
                pair = _stack([PairInput(source=shapes[i].spectrum, centers=shapes[i].centers,
                                         distances=shapes[i].distances
                                         if method == "geod" else None) for i in grp])
                res = run_baseline(method, pair, F, k=k, params=params, transfer=False)
                err = _errors(F, res.approximation, mass)
                for a, i in enumerate(grp):
                    rows += [{"shape": shapes[i].name, "k": k, "method": method, "function": j,
                              "area_share": float(share[a, j]), "error": float(err[a, j])}
                             for j in range(functions)]
                bar.update()
    bar.close()
    return rows


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
                res = run_baseline(method, pair, F, k=k, params=params)
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
                        ks=DEFAULT_KS, methods=TRANSFER_METHODS, params: Params = Params(),
                        maps: str = "gt", n_bsf=0.05, seed: int = 0, cache_dir=None,
                        progress: bool = True, approximation: bool = False) -> list[dict]:
    """Table 2 (``maps="gt"``) or its estimated-map version (``maps="estimated"``): transfer
    error on ``pairs`` pairs with square ``k × k`` maps.

    Rows: ``{"source", "target", "class", "k", "k_target", "method", "function", "error"}``
    (plus ``"approx_error"`` with ``approximation=True``).
    """
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


def kn_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100,
                  k_sources=(10, 30, 50), k_targets=(10, 20, 30, 40, 50, 60, 70, 80, 90, 100),
                  methods=KN_METHODS, params: Params = Params(), n_bsf=0.05, seed: int = 0,
                  cache_dir=None, progress: bool = True) -> list[dict]:
    """Fig. 7: transfer error with ground-truth ``(k_N, k_M)`` maps as ``k_N`` grows."""
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
                res = run_baseline(method, pair, F, k=k, params=params, k_targets=k_targets)
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


# --------------------------------------------------------------------------- table 3 / table 4


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


def frame_time_experiment(dataset: Dataset, *, pairs: int = 2, ks=(30, 90),
                          params: Params = Params(), n_bsf=0.05, seed: int = 0, cache_dir=None,
                          repeats: int = 3, progress: bool = True) -> list[dict]:
    """Table 3: time to build the frames (geod, heat, ours) on the source shapes.

    ``ours``: :func:`bsfjax.build_frame` (Algorithm 1).  ``heat``: the same kernels, saturated.
    ``geod``: heat-method geodesic distances from the ``n_BSF`` centres, thresholded at the 3
    radii (the radii themselves are taken as given).  The eigenbasis (shared by ours and heat)
    is timed separately as ``eigenbasis``.  Times are medians of ``repeats`` runs after one
    warm-up (compilation) run; rows also give the first-call time.
    """
    from ._baselines import _saturate  # the same saturation as the baseline

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
            ours = lambda: build_frame(sk, ctr, params.taus, params.gamma).atoms  # noqa: E731

            def heat():
                fr = build_frame(sk, ctr, params.taus, params.gamma)
                return _saturate(jnp.asarray(sk.evecs, fr.coeffs.dtype) @ fr.coeffs,
                                 params.gamma)

            for name, fn in (("heat", heat), ("ours", ours)):
                first, med = _timeit(fn, repeats)
                rows.append({**base, "method": name, "k": k,
                             "n_atoms": len(params.taus) * len(ctr), "first_s": first,
                             "time_s": med})
    return rows


def transfer_time_experiment(dataset: Dataset, *, pairs: int = 2, ks=(10, 30),
                             methods=TRANSFER_METHODS, params: Params = Params(), n_bsf=0.05,
                             seed: int = 0, cache_dir=None, repeats: int = 3,
                             progress: bool = True) -> list[dict]:
    """Table 4: time to transfer one function with an estimated map, per method.

    The timed call is the whole method given the two spectra and the map: for ours the frame
    build, its transfer, the coding and the decoding; for ``p2p`` the conversion of the map to
    a point map and the pull-back; for ``geod`` the geodesic distances from the centres too.
    The map estimation is timed once per pair as ``fmap (estimate_fmap)``.
    """
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
                    pair = PairInput(s.spectrum, t.spectrum, C, C2, p2p, s.centers, dist)
                    return run_baseline(method, pair, f, k=k, params=params).transferred

                first, med = _timeit(call, repeats)
                rows.append({**base, "k": k, "method": method, "first_s": first,
                             "time_s": med})
                bar.update()
    bar.close()
    return rows


# --------------------------------------------------------------------------- table 5 / fig 10


def tosca_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100, ks=(10, 30),
                     methods=TRANSFER_METHODS, parameter_sets=None, seed: int = 0,
                     cache_dir=None, progress: bool = True) -> list[dict]:
    """Table 5: transfer with estimated ``k × k`` maps per class, for each parameter set.

    ``pairs`` is the number of pairs *per class*.  Methods without BSF parameters (``std``,
    ``std2``, ``p2p``, ``prod``) run once and are reported with ``param_set = "-"``.
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
    plain = [m for m in methods if m in ("std", "std2", "p2p", "prod")]
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


def parameter_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100, k: int = 30,
                         sweeps=None, seed: int = 0, cache_dir=None,
                         progress: bool = True) -> list[dict]:
    """Fig. 10: approximation and ground-truth-map transfer error of the BSF coders at ``k``
    while one setting varies around the paper's defaults (:data:`SWEEPS`): the centre share
    n_BSF, the FPS distance, γ (all four coders), ε (``omp_error``) and S (``omp``).

    Rows: ``{"parameter", "value", "method", "source", "target", "function", "error",
    "approx_error"}``.
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
            shapes, params, methods = base_shapes, Params(), CODERS
            if param == "n_bsf":
                shapes = prepare_shapes(dataset, idx, k_max=k, n_bsf=value, seed=seed,
                                        cache_dir=cache_dir)
            elif param == "fps":
                shapes = prepare_shapes(dataset, idx, k_max=k, fps=value, seed=seed,
                                        cache_dir=cache_dir)
            elif param == "gamma":
                params = Params(gamma=value)
            elif param == "eps":
                params, methods = Params(eps_fraction=value), ("omp_error",)
            elif param == "sparsity":
                params, methods = Params(sparsity=value), ("omp",)
            fmaps.shapes = shapes
            rows += _transfer_rows(dataset, shapes, fmaps, pair_ids, functions, seed,
                                   [(k, k)], methods, params, f"fig10 {param}={value}",
                                   progress, extra={"parameter": param, "value": str(value)},
                                   approximation=True)
    return rows


# --------------------------------------------------------------------------- sparse (beyond)

#: Numbers of non-zeros of the ``sparse`` experiment (OMP's S; the projection's coefficients).
SPARSITIES = (5, 10, 20, 30, 50)
#: Frames of the ``sparse`` experiment: name → (taus, prune).  "paper" is the paper's frame
#: exactly; "adaptive" the 6 scales of :func:`bsfjax.adaptive_taus`, pruned.
SPARSE_FRAMES = {"paper": ((1e-3, 5e-3, 1e-2), False), "adaptive": ("adaptive", True)}


def sparse_experiment(dataset: Dataset, *, pairs: int = 2, functions: int = 100, k: int = 50,
                      sparsities=SPARSITIES, lasso_targets=(), n_bsf=0.05, seed: int = 0,
                      cache_dir=None, progress: bool = True) -> list[dict]:
    """Error against the number of non-zeros: paper frame, adaptive frame, projection.

    Per pair (source ``M``, target ``N``) and function ``f`` (random indicators, as
    everywhere), at basis size ``k``:

    * ``std``: projection on the first ``s`` eigenfunctions, ``s`` ∈ ``sparsities`` (its
      number of coefficients), transferred with ``C[:s, :s]``;
    * ``omp`` with ``sparsity = S`` ∈ ``sparsities`` on each frame of :data:`SPARSE_FRAMES`
      (n_BSF centres, γ = 0.75, area-weighted coding), and ``lstsq`` on each frame (all atoms,
      ``sparsity = "all"``), plus ``lasso`` with ``target_atoms`` ∈ ``lasso_targets``;
    * transfer with the ground-truth map (``maps = "gt"``, paper Eq. 11–12 re-binarization)
      and with an estimated map (``maps = "estimated"``: :func:`bsfjax.highlevel.estimate_map`,
      WKS + 5 landmarks — FPS on ``N``, paired by the ground truth — ZoomOut to ``2k``), whose
      BSF transfer is done both ways, ``frame_transfer = "binary"`` (Eq. 11–12 with the
      estimated ``C``) and ``"p2p"`` (atoms pulled back through the refined point map).

    Rows: ``{"source", "target", "class", "k", "frame", "method", "sparsity", "nonzeros",
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
            frame = build_frame(sk, s.centers, taus, 0.75, prune=prune)
            targets = {("gt", "binary"): transfer_frame(frame, C_gt, tk),
                       ("estimated", "binary"): transfer_frame(frame, est.C, tk),
                       ("estimated", "p2p"): transfer_frame(frame, est.C, tk, p2p=est.p2p)}
            codes = [("omp", S, {"sparsity": S}) for S in sparsities]
            codes += [("lasso", T, {"target_atoms": T, "maxiter": 2000})
                      for T in lasso_targets]
            codes.append(("lstsq", "all", {}))
            for method, sparsity, opts in codes:
                alpha, info = encode(frame, F, method, weights="area", return_info=True,
                                     **opts)
                add(name, method, sparsity, np.asarray(info.n_atoms), decode(frame, alpha),
                    {key: decode(tf, alpha) for key, tf in targets.items()}, True)
    return rows


def _sparse_claims(rows, k: int) -> str:
    """The issue's "must show" ratios, from the rows (means over all pairs and functions)."""
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


# --------------------------------------------------------------------------- tables and files


def summarize(rows: Sequence[dict], by: Sequence[str], value: str = "error") -> list[dict]:
    """Mean, standard deviation, median and count of ``value`` per group of ``by`` columns
    (groups in first-seen order)."""
    groups: dict = {}
    for r in rows:
        groups.setdefault(tuple(r[b] for b in by), []).append(r[value])
    out = []
    for key, vals in groups.items():
        v = np.asarray(vals, dtype=np.float64)
        v = v[np.isfinite(v)]
        out.append({**dict(zip(by, key)), "mean": float(v.mean()) if v.size else float("nan"),
                    "std": float(v.std()) if v.size else float("nan"),
                    "median": float(np.median(v)) if v.size else float("nan"), "n": int(v.size)})
    return out


def pivot_markdown(rows: Sequence[dict], index: str | Sequence[str], columns: str | Sequence[str],
                   value: str = "error", stat: str = "mean", fmt: str = "{:.3f}",
                   best: str | None = "min") -> str:
    """A Markdown table: one row per ``index`` value, one column per ``columns`` value, cells the
    ``stat`` of ``value``; the best cell of each column in bold (``best="min"``/``"max"``)."""
    index = (index,) if isinstance(index, str) else tuple(index)
    columns = (columns,) if isinstance(columns, str) else tuple(columns)
    summ = summarize(rows, index + columns, value)
    ridx = list(dict.fromkeys(tuple(s[i] for i in index) for s in summ))
    cidx = list(dict.fromkeys(tuple(s[c] for c in columns) for s in summ))
    cell = {(tuple(s[i] for i in index), tuple(s[c] for c in columns)): s[stat] for s in summ}
    bests = {}
    for c in cidx:
        vals = [cell[(r, c)] for r in ridx if (r, c) in cell and np.isfinite(cell[(r, c)])]
        if vals and best:
            bests[c] = min(vals) if best == "min" else max(vals)
    head = " / ".join(index) + " \\ " + " / ".join(columns)
    lines = ["| " + head + " | " + " | ".join(", ".join(map(str, c)) for c in cidx) + " |",
             "|---" * (len(cidx) + 1) + "|"]
    for r in ridx:
        cells = []
        for c in cidx:
            v = cell.get((r, c))
            if v is None or not np.isfinite(v):
                cells.append("–")
            else:
                s = fmt.format(v)
                cells.append(f"**{s}**" if bests.get(c) == v else s)
        lines.append("| " + ", ".join(map(str, r)) + " | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_csv(rows: Sequence[dict], path) -> Path:
    """Write tidy rows (union of keys as header) atomically; returns the path."""
    path = Path(path)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=keys)
            w.writeheader()
            w.writerows(rows)
    return path


def _write_text(text: str, path) -> Path:
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return path


def _line_plot(panels, path, ylabel="mean relative error"):
    """``panels``: list of (title, xlabel, {label: (xs, ys)}, categorical) → one PNG."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.2 * len(panels), 3.6), dpi=110)
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    bases = list(dict.fromkeys(lb.removesuffix(" (approx)") for _, _, ls, _ in panels
                               for lb in ls))
    colour = {b: f"C{i % 10}" for i, b in enumerate(bases)}  # one colour per method
    for ax, (title, xlabel, lines, categorical) in zip(axes, panels):
        for label, (xs, ys) in lines.items():
            x = np.arange(len(xs)) if categorical else np.asarray(xs, float)
            approx = label.endswith(" (approx)")
            ax.plot(x, ys, marker="o", ms=3, label=label, ls="--" if approx else "-",
                    color=colour[label.removesuffix(" (approx)")])
            if categorical:
                ax.set_xticks(x, [str(v) for v in xs])
        ax.set_title(title)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    axes[0].set_ylabel(ylabel)
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return path


def _curve(summ, filt, x):
    pts = [(s[x], s["mean"]) for s in summ if all(s[k] == v for k, v in filt.items())]
    return [p[0] for p in pts], [p[1] for p in pts]


def _header(name: str, meta: dict) -> str:
    desc = {
        "table1": "Approximation error (Eq. 14, square-root form ‖f − f̃‖_A / ‖f‖_A) on the "
                  "source shapes, mean over functions and shapes.",
        "table2": "Transfer error (Eq. 15, square-root form) with ground-truth k × k maps, mean "
                  "over functions and pairs.",
        "fig7": "Transfer error with ground-truth (k_N × k_M) maps as k_N grows.",
        "table3": "Frame build time in seconds (median of repeats after a warm-up call).",
        "table4": "Time in seconds to transfer one function with an estimated map "
                  "(median after a warm-up call; whole method given the spectra and the map).",
        "table5": "Transfer error with estimated maps (WKS + 5 landmarks, descriptor "
                  "commutativity), per class, k and parameter set.",
        "fig10": "Dependence of the BSF coders on one setting at a time (k = 30, ground-truth "
                 "maps).",
        "sparse": "Beyond the paper: approximation and transfer error against the number of "
                  "non-zeros S (omp) or coefficients (std), paper scales vs adaptive scales; "
                  "ground-truth and estimated (WKS + 5 landmarks + ZoomOut) maps.",
    }[name]
    m = "\n".join(f"- {k}: {v}" for k, v in meta.items())
    return f"# {name}\n\n{desc}\n\n{m}\n"


def reproduce(name: str, data, out, *, pairs: int = 2, functions: int = 100, seed: int = 0,
              ks=None, cache_dir=None, progress: bool = True) -> dict:
    """Run one experiment on a ``--data`` folder and write ``NAME.csv``, ``NAME.md`` (and
    ``NAME.png`` for figures) into ``out``; returns ``{"rows", "files", "seconds"}``.

    ``ks`` overrides the experiment's k list (fig7: the k_M list; fig10: its single k is the
    first entry).  ``cache_dir`` (default ``out/.spectra``) caches the eigenbases.
    """
    if name not in EXPERIMENTS:
        raise BSFError(f"experiment must be one of {EXPERIMENTS}, got {name!r}")
    for arg, v in (("pairs", pairs), ("functions", functions)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise BSFError(f"{arg} must be a positive int, got {v!r}")
    out = Path(out)
    cache_dir = out / ".spectra" if cache_dir is None else Path(cache_dir)
    dataset = load_dataset(data)
    t0 = time.perf_counter()
    kw = dict(seed=seed, cache_dir=cache_dir, progress=progress)
    meta = {"data": str(Path(data)), "shapes in folder": len(dataset.shapes),
            "pairs": pairs, "functions per shape": functions, "seed": seed,
            "settings": "n_BSF = 5 % (Euclidean FPS), τ = (0.001, 0.005, 0.01) unit-area, "
                        "γ = 0.75, S = 10, ε = ‖f‖/10, area-weighted coding",
            "jax": jax.__version__, "backend": jax.default_backend(),
            "machine": platform.machine()}
    if name in ("table3", "table4"):
        del meta["functions per shape"]  # timings use no (table 3) or one (table 4) function
    files = []
    stem = out / name
    if name == "table1":
        rows = approximation_experiment(dataset, pairs=pairs, functions=functions,
                                        ks=ks or DEFAULT_KS, **kw)
        md = pivot_markdown(rows, "method", "k")
    elif name == "table2":
        rows = transfer_experiment(dataset, pairs=pairs, functions=functions,
                                   ks=ks or DEFAULT_KS, **kw)
        md = pivot_markdown(rows, "method", "k")
    elif name == "fig7":
        rows = kn_experiment(dataset, pairs=pairs, functions=functions,
                             k_sources=ks or (10, 30, 50), **kw)
        md = pivot_markdown(rows, ("k", "method"), "k_target")
        summ = summarize(rows, ("k", "method", "k_target"))
        panels = [(f"k_M = {km}", "k_N", {m: _curve(summ, {"k": km, "method": m}, "k_target")
                                          for m in dict.fromkeys(r["method"] for r in rows)},
                   False) for km in dict.fromkeys(r["k"] for r in rows)]
        files.append(_line_plot(panels, stem.with_suffix(".png")))
    elif name == "table3":
        rows = frame_time_experiment(dataset, pairs=pairs, ks=ks or (30, 90), **kw)
        md = pivot_markdown(rows, ("method", "k"), "shape", value="time_s", fmt="{:.4f}")
    elif name == "table4":
        rows = transfer_time_experiment(dataset, pairs=pairs, ks=ks or (10, 30), **kw)
        md = pivot_markdown(rows, "method", "k", value="time_s", fmt="{:.4f}")
    elif name == "table5":
        rows = tosca_experiment(dataset, pairs=pairs, functions=functions, ks=ks or (10, 30),
                                **kw)
        md = pivot_markdown(rows, ("method", "param_set"), ("class", "k"))
    elif name == "sparse":
        k = (ks or (50,))[0]
        meta["settings"] = (f"k = {k}, n_BSF = 5 % (Euclidean FPS), γ = 0.75, area-weighted "
                            "coding; frames: paper τ = (0.001, 0.005, 0.01) and "
                            "taus='adaptive' (6 scales, pruned)")
        rows = sparse_experiment(dataset, pairs=pairs, functions=functions, k=k,
                                 sparsities=[v for v in SPARSITIES if v <= k], **kw)
        md = _sparse_markdown(rows, k)
        files.append(_line_plot(_sparse_panels(rows), stem.with_suffix(".png")))
    else:  # fig10
        rows = parameter_experiment(dataset, pairs=pairs, functions=functions,
                                    k=(ks or (30,))[0], **kw)
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
        files.append(_line_plot(panels, stem.with_suffix(".png")))
    seconds = time.perf_counter() - t0
    meta["wall time (s)"] = round(seconds, 1)
    files.insert(0, write_csv(rows, stem.with_suffix(".csv")))
    files.insert(1, _write_text(_header(name, meta) + "\n" + md + "\n", stem.with_suffix(".md")))
    _write_text(json.dumps({"experiment": name, **{k: str(v) for k, v in meta.items()}},
                           indent=1), out / f"{name}.json")
    return {"rows": rows, "files": files, "seconds": seconds}


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


def _spread_markdown(rows) -> str:
    summ = summarize(rows, ("parameter", "method", "value"))
    out: dict = {}
    for s in summ:
        out.setdefault((s["method"], s["parameter"]), []).append(s["mean"])
    spread = [{"method": m, "parameter": p, "spread": max(v) - min(v)}
              for (m, p), v in out.items()]
    return pivot_markdown(spread, "method", "parameter", value="spread")


def cli(args) -> int:
    """``bsfjax reproduce NAME --data DIR --out DIR [...]`` (see :func:`reproduce`)."""
    ks = None
    if args.k:
        try:
            ks = tuple(int(v) for v in str(args.k).split(","))
        except ValueError:
            raise BSFError(f"--k must be comma-separated integers, got {args.k!r}") from None
    res = reproduce(args.name, args.data, args.out, pairs=args.pairs, functions=args.functions,
                    seed=args.seed, ks=ks, cache_dir=args.cache, progress=not args.no_progress)
    print(f"{args.name}: {len(res['rows'])} rows in {res['seconds']:.1f} s; wrote "
          + ", ".join(str(f) for f in res["files"]))
    return 0
