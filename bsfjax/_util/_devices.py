"""Spreading independent batch items (functions, shape pairs) over the available JAX devices.

Every batched stage of bsfjax treats the items of its leading axis independently, so a batch
of ``m`` items is padded to a multiple of the device count ``d`` and cut into ``d`` equal
slices; each device runs the unchanged single-device kernel on its slice
(`jax.shard_map` over a 1-D device mesh), with no communication.  Padding items are
zeros (or copies of the last item) and are sliced off.  With one device nothing changes.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

__all__ = ["n_devices", "device_mesh", "pad_leading", "shard_leading", "map_over_devices"]


def n_devices() -> int:
    """Number of devices of the default backend."""
    return jax.device_count()


@functools.lru_cache(maxsize=8)
def device_mesh(axis: str) -> Mesh:
    """A 1-D mesh over all devices of the default backend, named ``axis``."""
    return Mesh(np.asarray(jax.devices()), (axis,))


def pad_leading(x, multiple: int, mode: str = "zeros"):
    """Pad axis 0 of ``x`` to a multiple of ``multiple`` (zeros, or ``"edge"``: the last item)."""
    x = jnp.asarray(x)
    pad = -x.shape[0] % multiple
    if not pad:
        return x
    fill = jnp.repeat(x[-1:], pad, axis=0) if mode == "edge" else jnp.zeros((pad,) + x.shape[1:],
                                                                          x.dtype)
    return jnp.concatenate([x, fill], axis=0)


def shard_leading(x, axis: str):
    """Place ``x`` with axis 0 split across `device_mesh` (``axis``)."""
    spec = PartitionSpec(axis, *([None] * (jnp.ndim(x) - 1)))
    return jax.device_put(x, NamedSharding(device_mesh(axis), spec))


def map_over_devices(fn, replicated, per_item, m: int):
    """``fn(replicated, per_item)`` with the leading axis (length ``m``) of every ``per_item``
    leaf and of every output split over the devices; outputs are cut back to ``m`` items.

    ``fn`` must treat items independently and be hashable (a module-level function or a
    ``functools.partial`` of one with hashable arguments), so that the sharded, jitted wrapper
    is built once per ``fn``.
    """
    d = n_devices()
    per_item = jax.tree.map(lambda x: shard_leading(pad_leading(x, d), "items"), per_item)
    out = _sharded(fn, d)(replicated, per_item)
    return jax.tree.map(lambda x: x[:m], out)


@functools.lru_cache(maxsize=128)
def _sharded(fn, d: int):
    del d  # part of the cache key: a new device count needs a new mesh
    P = PartitionSpec
    return jax.jit(jax.shard_map(fn, mesh=device_mesh("items"), in_specs=(P(), P("items")),
                                 out_specs=P("items"), check_vma=False))
