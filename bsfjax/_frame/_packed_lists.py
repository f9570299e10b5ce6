r"""16-bit atom lists: the storage of [`bsfjax.SparseFrame`][bsfjax.SparseFrame]'s lists (half of int32).

Owner of: packing int32 atom lists into 16 bits and decoding them back (host and traced).

Each vertex's list is sorted, so the high bits ``j >> 16`` of its atoms never decrease along
the list: storing, per vertex, where each of them starts is enough to drop them from every
entry.  A list of ``q`` atoms (padding ``q`` included, ``S = q >> 16``) is stored as::

    lists[v, d]    = j_d(v) & 0xFFFF                                   (n, D) uint16
    segments[v, h] = #{d : j_d(v) < (h + 1) · 2¹⁶}     h = 0 … S − 1     (n, S) int32
    j_d(v)         = lists[v, d] + 2¹⁶ · #{h : d ≥ segments[v, h]}

With ``q < 2¹⁶`` (``S = 0``) the lists are the atoms themselves and ``segments`` is ``None``.
On the 445K-vertex TOSCA cat (q = 66 876, S = 1) the lists take 1.73 GiB instead of 3.45, the
segments 1.7 MB.  Lists of any other integer dtype with ``segments=None`` are plain atom lists
(hand-made frames): every function here accepts them.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

__all__ = ["SEGMENT_BITS", "n_segments", "pack_lists", "decode_host", "decode_traced"]

#: Bits of an atom index stored per entry.
SEGMENT_BITS = 16
_MASK = (1 << SEGMENT_BITS) - 1


def n_segments(q: int) -> int:
    """``S = q >> 16``: the columns of ``segments`` for ``q`` atoms (padding ``q`` included)."""
    return int(q) >> SEGMENT_BITS


def pack_lists(lists: np.ndarray, q: int, rows: int = 2**16):
    """``(lists16, segments)`` of int atom lists ``(n, D)`` (sorted rows, padded with ``q``);
    ``segments`` is ``None`` for ``q < 2¹⁶``.  Host, in row chunks (no int64 temporaries)."""
    lists = np.asarray(lists)
    n, width = lists.shape
    s_cols = n_segments(q)
    out = np.empty((n, width), np.uint16)
    seg = np.empty((n, s_cols), np.int32) if s_cols else None
    for a in range(0, n, rows):
        block = lists[a:a + rows]
        out[a:a + rows] = block & _MASK
        for h in range(s_cols):
            seg[a:a + rows, h] = (block < ((h + 1) << SEGMENT_BITS)).sum(axis=1)
    return out, seg


def decode_host(lists: np.ndarray, segments) -> np.ndarray:
    """int32 atoms of packed rows ``lists`` ``(r, D)`` with their ``segments`` ``(r, S)`` (or
    ``None``: the rows as int32)."""
    ids = np.asarray(lists).astype(np.int32)
    if segments is not None and segments.shape[-1]:
        d = np.arange(ids.shape[-1], dtype=np.int32)
        seg = np.asarray(segments)
        for h in range(seg.shape[-1]):  # in place where the mask holds: no int32 temporary
            np.add(ids, 1 << SEGMENT_BITS, out=ids, where=d >= seg[..., h:h + 1])
    return ids


def decode_traced(lists, segments):
    """`decode_host` for traced (or device) arrays."""
    ids = lists.astype(jnp.int32)
    if segments is not None and segments.shape[-1]:
        d = jnp.arange(ids.shape[-1], dtype=jnp.int32)
        for h in range(segments.shape[-1]):
            ids = ids + ((d >= segments[..., h:h + 1]).astype(jnp.int32) << SEGMENT_BITS)
    return ids
