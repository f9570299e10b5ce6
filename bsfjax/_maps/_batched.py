r"""The map side of the batched stages of [`bsfjax.transfer_collection`][bsfjax.transfer_collection].

Per bucket of equal-shaped (padded) targets: the source's share of the estimation problem once
per set of source landmarks, then per target the estimation problem, the map (the ``k × k``
solve and ZoomOut on the subsamples) and the point map over every vertex.  The stages are
composed, jitted and batched with the transfer methods in ``bsfjax._pipeline``.
"""
from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from ._descriptors import _wks_jit
from ._estimation import FmapWeights, _weights_array
from ._fmap_problem import _setup, _Shape, _shape_ops
from ._fmap_solve import _energy, _solve
from ._orientation import _cast, _Geometry
from ._fmap import _from_p2p, _size_schedule, _to_p2p, _zoomout_jit
from ._guide import guided_zoomout
from .._sampling import Subsample
from .._spectral import Spectrum


class StageConfig(NamedTuple):
    """Everything static of the kernel (hashable: one compiled kernel per config and shape)."""

    method: object
    k: int  # map size
    k_map: int  # ZoomOut size
    k_spec: int  # eigenpairs per shape
    n_energies: int
    n_landmarks: int  # 0: orientation term instead
    chunk: int
    zoomout_chunk: int | None  # None: ZoomOut on every vertex, else on the subsamples
    # the single start's fields of the collection's MapEstimator
    wks_variance: float
    orient_weight: float
    zoomout_step: int
    guide_weight: float = 0.0  # the landmark guidance of ZoomOut (`bsfjax._maps._guide`)


def spectra(rep, it):
    """The pair's spectra, both at one area near 1 (`bsfjax.unit_area_pair`: the source
    at its own unit-area factor, whatever the target)."""
    return _source_spectrum(rep), Spectrum(it["evals"], it["evecs"], it["mass"])


def _source_spectrum(rep):
    return Spectrum(rep["evals"], rep["evecs"], rep["mass"])


def _descriptors(s: Spectrum, lm, cfg: StageConfig):
    """WKS of the first ``k`` eigenpairs, and WKS at the landmarks ``lm`` when given (the
    single start of [`MapEstimator`][bsfjax.MapEstimator]: its ``wks_variance``)."""
    k = cfg.k

    def w(landmarks):
        return _wks_jit(s.evals[:k], s.evecs[:, :k], s.mass, None, None, landmarks,
                        cfg.wks_variance, n_energies=cfg.n_energies, area_normalize=True,
                        scaled=True)
    return w(None) if lm is None else jnp.concatenate([w(None), w(lm)], axis=1)


def _shape(s: Spectrum, geom: _Geometry | None, cfg: StageConfig, descr=None) -> _Shape:
    """A shape of the estimation problem: its first ``k`` eigenpairs, in the working dtype."""
    k = cfg.k
    return _cast(_Shape(s.evals[:k], s.evecs[:, :k], s.mass, descr, geom),
                 jnp.result_type(float))


def _geometry_of(arrays, cfg: StageConfig) -> _Geometry | None:
    """A shape's geometry for the orientation term (used without landmarks only)."""
    if cfg.n_landmarks:
        return None
    return _Geometry(arrays["faces"], arrays["K"], arrays["third_area"])


def source_ops_stage(rep, lm_m, *, cfg: StageConfig):
    """The source's share of the estimation problem (`_shape_ops`: descriptors and their
    operators) with source landmarks ``lm_m``: once for all the targets that share them, not
    once per target (0.06 s of the problem stage's 0.10 s on a 5.5K-vertex target)."""
    src = _source_spectrum(rep)
    return _shape_ops(_shape(src, _geometry_of(rep, cfg), cfg, _descriptors(src, lm_m, cfg)),
                      normalize_descriptors=True)


def problem_stage(rep, it, ops_m, *, cfg: StageConfig):
    """Per bucket: the descriptors' estimation problem (``k``-sized operators; the source's
    share ``ops_m`` from `source_ops_stage`) and ZoomOut's inputs (the eigenvector rows
    of the subsamples and their cell weights)."""
    dt = jnp.result_type(float)
    km = cfg.k_map
    src, tgt = spectra(rep, it)
    weights = FmapWeights() if cfg.n_landmarks else FmapWeights(orient=cfg.orient_weight)
    sn = _shape(tgt, _geometry_of(it, cfg), cfg,
                _descriptors(tgt, it.get("landmarks_target"), cfg))
    sm = _shape(src, None, cfg)  # its descriptors' operators (orientation too): ops_m
    pb = _setup(sm, sn, jnp.asarray(_weights_array(weights), dt), lap_kind="resolvent",
                gamma=jnp.asarray(0.5, dt), normalize_descriptors=True, normalize_weights=True,
                orient_sign=1.0, ops_m=ops_m)
    zo_m, zo_n = src.evecs[:, :km].astype(dt), tgt.evecs[:, :km].astype(dt)
    w_n = tgt.mass.astype(dt)
    g_m, g_n = it.get("guide_source"), it.get("guide_target")  # (with landmarks)
    if cfg.zoomout_chunk is not None:  # padded samples: weight 0 (no cell names them)
        idx_n = it["zo_indices"]
        w_n = Subsample(idx_n, it["zo_cells"]).weights(w_n)
        zo_m, zo_n = zo_m[rep["zo_indices"]], zo_n[idx_n]
        if g_m is not None:
            g_m, g_n = g_m[rep["zo_indices"]], g_n[idx_n]
    guide = None if g_m is None else (g_m.astype(dt), g_n.astype(dt))
    return pb, (zo_m, zo_n, w_n, guide)


def map_stage(pb, zo, *, cfg: StageConfig):
    """The functional map: the estimate ``C₀`` (``k × k``), then ZoomOut ``k → k_map`` in steps
    of ``cfg.zoomout_step`` on the subsamples (guided by the landmarks' distances when the
    target carries them), as [`MapEstimator`][bsfjax.MapEstimator].  Free of the vertex
    count when ZoomOut runs on subsamples."""
    dt = jnp.result_type(float)
    rtol, atol = (1e-10, 1e-12) if dt == jnp.float64 else (1e-4, 1e-6)
    C0 = _solve(pb, rtol=rtol, atol=atol, max_steps=8)
    k, km = cfg.k, cfg.k_map
    if km <= k:
        return C0
    zo_m, zo_n, w_n, guide = zo
    step = cfg.zoomout_step
    sizes = _size_schedule(k, km, step, -(-(km - k) // step))
    chunk = cfg.chunk if cfg.zoomout_chunk is None else cfg.zoomout_chunk
    if guide is not None and cfg.guide_weight > 0:  # as MapEstimator with given landmarks
        return guided_zoomout(C0, zo_m, zo_n, w_n, *guide, sizes=sizes, chunk=chunk,
                              weight=cfg.guide_weight)
    return _zoomout_jit(C0, zo_m, zo_n, w_n, sizes_n=sizes, sizes_m=sizes, chunk=chunk,
                        adjoint=False)


def point_map_stage(rep, it, pb, C_ref, *, cfg: StageConfig):
    """Per bucket: the point map of ``C_ref`` over every vertex, and its ``k × k`` map and
    energy (the given point map instead when the target carries one)."""
    dt = jnp.result_type(float)
    k, km = cfg.k, cfg.k_map
    src, tgt = spectra(rep, it)
    phi_m, phi_n = src.evecs.astype(dt), tgt.evecs.astype(dt)
    if "p2p" in it:  # without landmarks: estimate_map's point map, chosen among its starts
        p2p = it["p2p"]
    else:
        p2p = _to_p2p(C_ref, phi_m[:, :km], phi_n[:, :km], cfg.chunk, False,
                      jnp.sum(tgt.mass > 0))  # (the padding's chunks are skipped)
    C = _from_p2p(p2p, phi_m[:, :k], phi_n[:, :k], tgt.mass.astype(dt))
    return p2p, C, _energy(C, pb)
