r"""The device side of :func:`bsfjax.transfer_collection`: its jitted stages per bucket.

A bucket of equal-shaped (padded) targets runs the source's operators once per set of source
landmarks, then per target three jitted stages — the estimation problem, the map (the
``k × k`` solve and ZoomOut on the subsamples), the transfer (the point map over every vertex
and the method's ``prepare`` / ``carry``) — on each local device, ``batch`` targets at a time
under ``vmap``.  A target without landmarks arrives with its point map (chosen on the host
among :func:`bsfjax.estimate_map`'s starts): the map stage is skipped for it.  The host side
(reading, eigensolves, buckets, results) is :mod:`bsfjax._collection`.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._descriptors import _wks_jit
from ._estimation import FmapWeights, _cast, _energy, _setup, _Shape, _shape_ops, _solve, \
    _weights_array
from ._orientation import _Geometry
from ._fmap import _from_p2p, _size_schedule, _to_p2p, _zoomout_jit
from ._map_estimate import ORIENT_WEIGHT, WKS_VARIANCE, ZOOMOUT_STEP
from ._methods import Pair, SpectralProjection
from ._sampling import Subsample
from ._spectrum import Spectrum


class _Config(NamedTuple):
    """Everything static of the kernel (hashable: one compiled kernel per config and shape)."""

    method: object
    k: int  # map size
    k_map: int  # ZoomOut size
    k_spec: int  # eigenpairs per shape
    n_energies: int
    n_landmarks: int  # 0: orientation term instead
    chunk: int
    zoomout_chunk: int | None  # None: ZoomOut on every vertex, else on the subsamples


@functools.lru_cache(maxsize=64)
def _stages_for(cfg: _Config, batched: bool = False):
    """The jitted stages of a config (one set of function objects per config): the source's
    operators, then the three per-target stages — batched under ``vmap`` over a leading
    target axis when ``batched`` (the source arrays shared, each target's source operators its
    own, since they follow its landmarks).

    The map's solve and its ZoomOut on the subsamples see only ``k``-sized operators and
    ``s_b`` samples, so ``_map_stage`` compiles once for all size buckets; only the stages
    that touch every vertex (descriptors, final point map, the method) compile per bucket.
    Measured on six FAUST-like targets: the map stage's 1.4 s of compilation is saved for
    every bucket after the first (the two others take 1.9 s and 2.2–3.0 s per bucket)."""
    problem = functools.partial(_problem_stage, cfg=cfg)
    fmap = functools.partial(_map_stage, cfg=cfg)
    transfer = functools.partial(_transfer_stage, cfg=cfg)
    if batched:
        problem = jax.vmap(problem, in_axes=(None, 0, 0))
        fmap = jax.vmap(fmap)
        transfer = jax.vmap(transfer, in_axes=(None, 0, 0, 0))
    return (jax.jit(functools.partial(_source_ops_stage, cfg=cfg)), jax.jit(problem),
            jax.jit(fmap), jax.jit(transfer))


def _dispatch(cfg: _Config, replicated: list, items: list, source_ops: list,
              batch: int = 1) -> list:
    """Run the stages on up to ``d × batch`` targets of one bucket: targets ``[i·batch,
    (i+1)·batch)`` on local device ``i``, under ``vmap`` when ``batch > 1``.

    Every call is dispatched before any result is awaited, so the devices compute their
    targets at the same time (targets are independent: no communication).  A group short of
    ``batch`` targets runs at the full batch size (its last target repeated), so a target's
    result does not depend on the targets it is batched with.  Not a GSPMD or ``shard_map``
    program: ``shard_map`` trips lineax's structure check inside the estimation's solve.
    ``replicated[i]``: the source arrays already on device ``i``; ``source_ops[j]``: the
    source's share of item ``j``'s problem, on item ``j``'s device.  Returns per group its
    outputs and its number of real targets."""
    devices = jax.local_devices()
    _, problem, fmap, transfer = _stages_for(cfg, batch > 1)
    out = []
    for d, start in enumerate(range(0, len(items), batch)):
        its, ops = items[start:start + batch], source_ops[start:start + batch]
        n_real = len(its)
        if batch > 1:
            its, ops = its + its[-1:] * (batch - n_real), ops + ops[-1:] * (batch - n_real)
            it = jax.device_put(jax.tree.map(lambda *x: np.stack(x), *its), devices[d])
            op = jax.tree.map(lambda *x: jnp.stack(x), *ops)
        else:
            it, op = jax.device_put(its[0], devices[d]), ops[0]
        pb, zo = problem(replicated[d], it, op)
        C_ref = None if "p2p" in it else fmap(pb, zo)  # (a given point map: no map stage)
        out.append((transfer(replicated[d], it, pb, C_ref), n_real))
    return out


def _spectra(rep, it):
    """The pair's spectra, both at one area near 1 (:func:`bsfjax.unit_area_pair`: the source
    at its own unit-area factor, whatever the target)."""
    return _source_spectrum(rep), Spectrum(it["evals"], it["evecs"], it["mass"])


def _source_spectrum(rep):
    return Spectrum(rep["evals"], rep["evecs"], rep["mass"])


def _descriptors(s: Spectrum, lm, cfg: _Config):
    """WKS of the first ``k`` eigenpairs, and WKS at the landmarks ``lm`` when given (the
    single start of :func:`bsfjax.estimate_map`: variance ``WKS_VARIANCE``)."""
    k = cfg.k

    def w(landmarks):
        return _wks_jit(s.evals[:k], s.evecs[:, :k], s.mass, None, None, landmarks,
                        WKS_VARIANCE, n_energies=cfg.n_energies, area_normalize=True,
                        scaled=True)
    return w(None) if lm is None else jnp.concatenate([w(None), w(lm)], axis=1)


def _shape(s: Spectrum, geom: _Geometry | None, cfg: _Config, descr=None) -> _Shape:
    """A shape of the estimation problem: its first ``k`` eigenpairs, in the working dtype."""
    k = cfg.k
    return _cast(_Shape(s.evals[:k], s.evecs[:, :k], s.mass, descr, geom),
                 jnp.result_type(float))


def _geometry_of(arrays, cfg: _Config) -> _Geometry | None:
    """A shape's geometry for the orientation term (used without landmarks only)."""
    if cfg.n_landmarks:
        return None
    return _Geometry(arrays["faces"], arrays["K"], arrays["third_area"])


def _source_ops_stage(rep, lm_m, *, cfg: _Config):
    """The source's share of the estimation problem (:func:`_shape_ops`: descriptors and their
    operators) with source landmarks ``lm_m``: once for all the targets that share them, not
    once per target (0.06 s of the problem stage's 0.10 s on a 5.5K-vertex target)."""
    src = _source_spectrum(rep)
    return _shape_ops(_shape(src, _geometry_of(rep, cfg), cfg, _descriptors(src, lm_m, cfg)),
                      normalize_descriptors=True)


def _problem_stage(rep, it, ops_m, *, cfg: _Config):
    """Per bucket: the descriptors' estimation problem (``k``-sized operators; the source's
    share ``ops_m`` from :func:`_source_ops_stage`) and ZoomOut's inputs (the eigenvector rows
    of the subsamples and their cell weights)."""
    dt = jnp.result_type(float)
    km = cfg.k_map
    src, tgt = _spectra(rep, it)
    weights = FmapWeights() if cfg.n_landmarks else FmapWeights(orient=ORIENT_WEIGHT)
    sn = _shape(tgt, _geometry_of(it, cfg), cfg,
                _descriptors(tgt, it.get("landmarks_target"), cfg))
    sm = _shape(src, None, cfg)  # its descriptors' operators (orientation too): ops_m
    pb = _setup(sm, sn, jnp.asarray(_weights_array(weights), dt), lap_kind="resolvent",
                gamma=jnp.asarray(0.5, dt), normalize_descriptors=True, normalize_weights=True,
                orient_sign=1.0, ops_m=ops_m)
    zo_m, zo_n = src.evecs[:, :km].astype(dt), tgt.evecs[:, :km].astype(dt)
    w_n = tgt.mass.astype(dt)
    if cfg.zoomout_chunk is not None:  # padded samples: weight 0 (no cell names them)
        idx_n = it["zo_indices"]
        w_n = Subsample(idx_n, it["zo_cells"]).weights(w_n)
        zo_m, zo_n = zo_m[rep["zo_indices"]], zo_n[idx_n]
    return pb, (zo_m, zo_n, w_n)


def _map_stage(pb, zo, *, cfg: _Config):
    """The functional map: the estimate ``C₀`` (``k × k``), then ZoomOut ``k → k_map`` in steps
    of ``ZOOMOUT_STEP`` on the subsamples, as :func:`bsfjax.estimate_map`.  Free of the vertex
    count when ZoomOut runs on subsamples."""
    dt = jnp.result_type(float)
    rtol, atol = (1e-10, 1e-12) if dt == jnp.float64 else (1e-4, 1e-6)
    C0 = _solve(pb, rtol=rtol, atol=atol, max_steps=8)
    k, km = cfg.k, cfg.k_map
    if km <= k:
        return C0
    zo_m, zo_n, w_n = zo
    sizes = _size_schedule(k, km, ZOOMOUT_STEP, -(-(km - k) // ZOOMOUT_STEP))
    chunk = cfg.chunk if cfg.zoomout_chunk is None else cfg.zoomout_chunk
    return _zoomout_jit(C0, zo_m, zo_n, w_n, sizes_n=sizes, sizes_m=sizes, chunk=chunk,
                        adjoint=False)


def _transfer_stage(rep, it, pb, C_ref, *, cfg: _Config):
    """Per bucket: the point map of ``C_ref`` over every vertex, its ``k × k`` map and energy,
    and the method's transfer through the one engine's ``prepare`` / ``carry``."""
    dt = jnp.result_type(float)
    k, km = cfg.k, cfg.k_map
    src, tgt = _spectra(rep, it)
    phi_m, phi_n = src.evecs.astype(dt), tgt.evecs.astype(dt)
    if "p2p" in it:  # without landmarks: estimate_map's point map, chosen among its starts
        p2p = it["p2p"]
    else:
        p2p = _to_p2p(C_ref, phi_m[:, :km], phi_n[:, :km], cfg.chunk, False,
                      jnp.sum(tgt.mass > 0))  # (the padding's chunks are skipped)
    C = _from_p2p(p2p, phi_m[:, :k], phi_n[:, :k], tgt.mass.astype(dt))
    energy = _energy(C, pb)
    method = cfg.method
    full = getattr(method, "full_spectra", False)
    two_k = isinstance(method, SpectralProjection) and method.factor == 2
    samples = None
    if cfg.zoomout_chunk is not None:  # "refined" continues on ZoomOut's samples
        samples = (Subsample(rep["zo_indices"], rep["zo_cells"]),
                   Subsample(it["zo_indices"], it["zo_cells"]))
    pair = Pair(source=src if full or two_k else src.truncate(k),
                target=tgt if full else tgt.truncate(k), C=C, p2p=p2p,
                centers=rep.get("centers"), distances=rep.get("distances"), samples=samples)
    F = rep["F"].astype(dt)
    _, carry, _ = method.prepare(pair, F, k)
    return {"values": carry(C), "p2p": p2p, "C": C, "energy": energy}
