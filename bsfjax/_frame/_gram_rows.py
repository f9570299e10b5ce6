r"""Gram rows of a frame computed on the host, cached per [`bsfjax.encode`][bsfjax.encode] call.

Owner of: the registry that lets a jitted coder ask the host for rows
``G[k, :] = b_kᵀ W B`` of ``G = BᵀWB`` (`jax.pure_callback`), and the float64 transport
of such rows.  The row *sources* belong to the frames: a CSR copy of a concrete sparse enough
dense frame (``_dense_frame.py``) or the atom lists of a sparse frame (``_sparse_frame.py``),
each an object with ``rows(ks) -> (len(ks), q) float64``.

A jitted kernel cannot hold host arrays, so each [`encode`][bsfjax.encode] call registers its source
under an integer token that the kernel passes to `HostGramRows.rows` (the compiled
kernel is shared by all frames of equal shapes).  Within one registration every row is
computed once: functions of a batch share many atoms (100 FAUST regions, 10 steps: 1000
selections of 436 distinct atoms), so each call computes only the rows it has not seen, up to
`ROW_CACHE_BYTES` of kept rows.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["HostGramRows", "host_gram_rows", "split64", "host_callback_dtype"]

#: Memory for the Gram rows one [`encode`][bsfjax.encode] call keeps on the host (float64): 256 MiB, e.g.
#: all 1032 rows of a FAUST frame (8 MiB) or ~500 rows at q = 67K atoms.
ROW_CACHE_BYTES = 2**28


def split64(g: np.ndarray, dtype):
    """A float64 host array as the callback result for ``dtype``: float32 for float32, else a
    float32 pair ``hi + lo`` (exact to ~1e-14).  JAX canonicalizes a callback's float64 result
    to float32 when it runs in a thread outside a ``jax.enable_x64`` context."""
    hi = g.astype(np.float32)
    if np.dtype(dtype) != np.float64:
        return hi
    return hi, (g - hi).astype(np.float32)


def host_callback_dtype(shape, dtype):
    """The result spec of a callback returning `split64` of a ``shape`` array."""
    part = jax.ShapeDtypeStruct(shape, jnp.float32)
    return (part, part) if jnp.dtype(dtype) == jnp.float64 else part


def join64(out, dtype):
    """Inverse of `split64` inside a trace."""
    if jnp.dtype(dtype) == jnp.float64:
        return out[0].astype(dtype) + out[1].astype(dtype)
    return out


class _Registration(NamedTuple):
    source: Any  # an object with rows(ks) -> (len(ks), q) float64
    dtype: np.dtype
    cache: dict  # atom -> float64 row computed in this registration


class HostGramRows:
    """The registry of host row sources (see the module docstring)."""

    _live: dict[int, _Registration] = {}
    _next = 0

    @classmethod
    def register(cls, source, dtype) -> int:
        cls._next += 1
        cls._live[cls._next] = _Registration(source, np.dtype(dtype), {})
        return cls._next

    @classmethod
    def release(cls, token: int) -> None:
        cls._live.pop(token, None)

    @classmethod
    def rows(cls, token, k):
        source, dtype, cache = cls._live[int(token)]
        k = np.asarray(k).reshape(-1)
        uniq, inv = np.unique(k, return_inverse=True)
        # callbacks of several devices may run concurrently: dict reads/writes are atomic, and
        # a row computed twice by a race is the same row
        new = np.asarray([a for a in uniq.tolist() if a not in cache], np.int64)
        if new.size:
            g_new = source.rows(new)
            if (len(cache) + new.size) * g_new.shape[1] * 8 <= ROW_CACHE_BYTES:
                cache.update(zip(new.tolist(), g_new))
            else:  # too many to keep: this call's rows only
                got = dict(zip(new.tolist(), g_new))
                g = np.stack([got[a] if a in got else cache[a] for a in uniq.tolist()])[inv]
                return split64(g, dtype)
        g = np.stack([cache[a] for a in uniq.tolist()])[inv]
        return split64(g, dtype)


def host_gram_rows(token, q: int, dtype):
    """``rows(k)`` ``(b,) -> (b, q)``: rows of ``BᵀWB`` of the source registered under
    ``token`` (a traced int32), fetched through `jax.pure_callback`."""

    def rows(k):
        out = jax.pure_callback(HostGramRows.rows, host_callback_dtype((k.shape[0], q), dtype),
                                token, k)
        return join64(out, dtype)

    return rows
