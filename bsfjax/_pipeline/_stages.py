r"""The device side of [`bsfjax.transfer_collection`][bsfjax.transfer_collection]: its jitted stages per bucket.

A bucket of equal-shaped (padded) targets runs the source's operators once per set of source
landmarks, then per target three jitted stages — the estimation problem, the map (the
``k × k`` solve and ZoomOut on the subsamples), the transfer (the point map over every vertex
and the method's ``prepare`` / ``carry``) — on each local device, ``batch`` targets at a time
under ``vmap``.  A target without landmarks arrives with its point map (chosen on the host
among [`bsfjax.estimate_map`][bsfjax.estimate_map]'s starts): the map stage is skipped for it.  The map stages
are in ``bsfjax._maps._batched``; the host side (reading, eigensolves, buckets, results) is
``bsfjax._pipeline._collection``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._maps import (StageConfig, check_fmap_memory, map_stage, point_map_stage, problem_stage,
                     source_ops_stage, spectra)
from .._sampling import Subsample
from .._transfer import Pair, SpectralProjection
from .._util import check_int


def capped_batch(batch: int, k: int, n_targets: int | None = None) -> int:
    """``batch`` checked and capped at ``n_targets`` per local device: a group short of
    ``batch`` runs at the full batch size (`dispatch_stages`), so 2 targets at ``batch=1000``
    held 1000 copies (19 GB).  The ``batch`` dense ``k² × k²`` systems of one device are then
    checked against the memory available (`bsfjax._maps.check_fmap_memory`), before any work."""
    check_int(batch, "batch", 1)
    if n_targets is not None:
        batch = max(1, min(batch, -(-n_targets // len(jax.local_devices()))))
    check_fmap_memory(k, batch)
    return batch


@functools.lru_cache(maxsize=64)
def stages_for(cfg: StageConfig, batched: bool = False):
    """The jitted stages of a config (one set of function objects per config): the source's
    operators, then the three per-target stages — batched under ``vmap`` over a leading
    target axis when ``batched`` (the source arrays shared, each target's source operators its
    own, since they follow its landmarks).

    The map's solve and its ZoomOut on the subsamples see only ``k``-sized operators and
    ``s_b`` samples, so ``map_stage`` compiles once for all size buckets; only the stages
    that touch every vertex (descriptors, final point map, the method) compile per bucket.
    Measured on six FAUST-like targets: the map stage's 1.4 s of compilation is saved for
    every bucket after the first (the two others take 1.9 s and 2.2–3.0 s per bucket)."""
    problem = functools.partial(problem_stage, cfg=cfg)
    fmap = functools.partial(map_stage, cfg=cfg)
    transfer = functools.partial(transfer_stage, cfg=cfg)
    if batched:
        problem = jax.vmap(problem, in_axes=(None, 0, 0))
        fmap = jax.vmap(fmap)
        transfer = jax.vmap(transfer, in_axes=(None, 0, 0, 0))
    return (jax.jit(functools.partial(source_ops_stage, cfg=cfg)), jax.jit(problem),
            jax.jit(fmap), jax.jit(transfer))


def dispatch_stages(cfg: StageConfig, replicated: list, items: list, source_ops: list,
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
    _, problem, fmap, transfer = stages_for(cfg, batch > 1)
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


def transfer_stage(rep, it, pb, C_ref, *, cfg: StageConfig):
    """Per bucket: the point map of ``C_ref`` over every vertex, its ``k × k`` map and energy,
    and the method's transfer through the one engine's ``prepare`` / ``carry``."""
    dt = jnp.result_type(float)
    k = cfg.k
    src, tgt = spectra(rep, it)
    p2p, C, energy = point_map_stage(rep, it, pb, C_ref, cfg=cfg)
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
