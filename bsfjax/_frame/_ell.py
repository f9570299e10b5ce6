r"""ELL kernels of per-vertex atom lists: the products ``B X``, ``Bᵀ Y`` and the host transpose.
Owner of `ell_matmul`, `ell_rmatmul` (and the row-blocking helpers and `_block_counts` they
share) on the device, and on the host `AtomVertices` / `atom_vertices` (the 16-bit CSC
structure of ``B``: ``supp b_j`` per atom), `atom_sums`, `ell_gram_rows` and `_row_chunks`
(the host passes' chunking).  These kernels see only the ``(n, D)`` lists (packed or plain,
`bsfjax._frame._packed_lists`), never a frame object, so `bsfjax._frame._sparse_gram` and
`bsfjax._frame._sparse_frame` both build on them and the dependency runs one way:
``_ell`` ← ``_sparse_gram`` ← ``_sparse_frame``.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from ._packed_lists import decode_host, decode_traced

__all__ = ["ell_matmul", "ell_rmatmul", "AtomVertices", "atom_vertices", "atom_sums",
           "ell_gram_rows"]

#: Elements (``rows × D × m``) gathered or scattered per block of a product.
_PRODUCT_ELEMS = 2**22


# --------------------------------------------------------------------------- products


def _product_rows(n: int, width: int, m: int) -> int:
    return int(max(1, min(n, _PRODUCT_ELEMS // max(width * m, 1))))


def _block_start(i, nb: int, n: int):
    """First row of block ``i`` of ``nb`` rows: ``i · nb``, except that the last block is moved
    back to end at row ``n`` (it then overlaps its predecessor).  Slicing the unpadded lists
    this way avoids the padded copy of the whole ``(n, D)`` array that blocking would need."""
    return jnp.minimum(i * nb, n - nb)


def _rows(atom_lists, segments, s, nb: int):
    """int32 atoms of rows ``s … s + nb`` (decoded from the packed lists)."""
    rows = jax.lax.dynamic_slice_in_dim(atom_lists, s, nb)
    seg = None if segments is None else jax.lax.dynamic_slice_in_dim(segments, s, nb)
    return decode_traced(rows, seg)


@jax.jit
def ell_matmul(atom_lists: jax.Array, X: jax.Array, segments=None) -> jax.Array:
    """``B X``: ``(n, m)`` from ``X`` ``(q, m)`` (gather-sum over each vertex's atoms);
    ``segments`` of packed lists (`bsfjax._frame._packed_lists`) or ``None``."""
    n, width = atom_lists.shape
    m = X.shape[1]
    Xp = jnp.concatenate([X, jnp.zeros((1,) + X.shape[1:], X.dtype)])  # row q: padding
    if n == 0:
        return jnp.zeros((0, m), X.dtype)
    nb = _product_rows(n, width, m)

    def block(i, out):  # the overlapping rows of the last block get the same values again
        s = _block_start(i, nb, n)
        rows = _rows(atom_lists, segments, s, nb)
        return jax.lax.dynamic_update_slice_in_dim(out, jnp.sum(Xp[rows], axis=1), s, axis=0)

    return jax.lax.fori_loop(0, -(-n // nb), block, jnp.zeros((n, m), X.dtype))


@partial(jax.jit, static_argnames="q")
def _block_counts(atom_lists: jax.Array, q: int, segments=None) -> jax.Array:
    """Entries ``< q`` of each row block (int32 per block, summed in int64 by the caller).  A
    loop over blocks: ``jnp.sum(atom_lists < q)`` may materialise the ``(n, D)`` mask (0.9 GB
    at 445K vertices)."""
    n, width = atom_lists.shape
    if n == 0:
        return jnp.zeros(0, jnp.int32)
    nb = _product_rows(n, width, 1)

    def block(i, counts):
        s = _block_start(i, nb, n)
        rows = _rows(atom_lists, segments, s, nb)
        fresh = (s + jnp.arange(nb) >= i * nb)[:, None]  # not counted by the previous block
        return counts.at[i].set(jnp.sum((rows < q) & fresh, dtype=jnp.int32))

    n_blocks = -(-n // nb)
    return jax.lax.fori_loop(0, n_blocks, block, jnp.zeros(n_blocks, jnp.int32))


@partial(jax.jit, static_argnames="q")
def ell_rmatmul(atom_lists: jax.Array, Y: jax.Array, q: int, segments=None) -> jax.Array:
    """``Bᵀ Y``: ``(q, m)`` from ``Y`` ``(n, m)`` (scatter-add of each vertex's row)."""
    n, width = atom_lists.shape
    m = Y.shape[1]
    acc = jnp.zeros((q + 1, m), Y.dtype)  # row q collects the padding
    if n == 0:
        return acc[:q]
    nb = _product_rows(n, width, m)

    def step(i, acc):
        s = _block_start(i, nb, n)
        rows = _rows(atom_lists, segments, s, nb)
        y = jax.lax.dynamic_slice_in_dim(Y, s, nb)
        # rows of the last block that its predecessor already added go to the padding row
        rows = jnp.where((s + jnp.arange(nb) >= i * nb)[:, None], rows, q)
        upd = jnp.broadcast_to(y[:, None, :], rows.shape + (m,))
        return acc.at[rows].add(upd, mode="drop")

    return jax.lax.fori_loop(0, -(-n // nb), step, acc)[:q]


# --------------------------------------------------------------------------- host transpose

#: ELL entries (or transposed entries) per chunk of the host passes below.
_HOST_CHUNK_ELEMS = 2**23


def _row_chunks(lo: int, hi: int, width: int):
    """Row ranges covering ``[lo, hi)`` of about `_HOST_CHUNK_ELEMS` entries each."""
    step = max(1, _HOST_CHUNK_ELEMS // max(width, 1))
    return [(s, min(s + step, hi)) for s in range(lo, hi, step)]


#: Vertices per panel of `AtomVertices` (``2**_PANEL_BITS``; 16 bits fit uint16).
_PANEL_BITS = 16


class AtomVertices(NamedTuple):
    """The transpose of the atom lists (the CSC structure of ``B``) in 16-bit panels.

    ``supp b_j`` (increasing) is stored in ``lo[indptr[j]:indptr[j+1]]`` as offsets within
    panels of ``2**16`` vertices: entries ``starts[j, p] … starts[j, p+1]`` lie in panel ``p``
    (vertex ``= p · 2**16 + lo``).  Half the memory of int32 indices (``nnz · 2`` bytes plus
    ``q × (panels + 1)`` offsets): the host Gram rows of OMP need it next to the lists.
    """

    indptr: np.ndarray  # (q + 1,) int64
    starts: np.ndarray  # (q, panels + 1) int64, starts[:, -1] = indptr[1:]
    lo: np.ndarray  # (nnz,) uint16

    def vertices(self, j: int) -> np.ndarray:
        """``supp b_j``: ``(|supp b_j|,)`` int64 vertex indices, increasing."""
        a, b = int(self.indptr[j]), int(self.indptr[j + 1])
        hi = np.repeat(np.arange(self.starts.shape[1] - 1, dtype=np.int64) << _PANEL_BITS,
                       np.diff(self.starts[j]))
        return self.lo[a:b] + hi


def atom_vertices(atom_lists, q: int, segments=None) -> AtomVertices:
    """`AtomVertices` of the lists: ``supp b_j`` for every atom, sorted.

    A counting sort in row chunks of about `_HOST_CHUNK_ELEMS` entries, each within one
    panel: every chunk is transposed by scipy (``csr_tocsc``, O(entries), int8 data) and its
    vertices are written after those of the earlier chunks, so each atom's vertices stay
    sorted.  Memory: the result plus per-chunk buffers; no array of all entries wider than 16
    bits, no float data.
    """
    lists = np.asarray(atom_lists)  # on CPU a view of the device buffer, not a copy
    seg = None if segments is None else np.asarray(segments)
    n, width = lists.shape

    def rows(s, e):
        return decode_host(lists[s:e], None if seg is None else seg[s:e])

    panel = 1 << _PANEL_BITS
    n_panels = max(1, -(-n // panel))
    counts = np.zeros(q + 1, np.int64)
    for s, e in _row_chunks(0, n, width):
        counts += np.bincount(rows(s, e).ravel(), minlength=q + 1)
    indptr = np.zeros(q + 1, np.int64)
    np.cumsum(counts[:q], out=indptr[1:])
    lo = np.empty(int(indptr[-1]), np.uint16 if _PANEL_BITS <= 16 else np.uint32)
    starts = np.empty((q, n_panels + 1), np.int64)
    nxt = indptr[:-1].copy()  # next free slot of each atom
    for p in range(n_panels):
        starts[:, p] = nxt
        for s, e in _row_chunks(p * panel, min(n, (p + 1) * panel), width):
            block = rows(s, e)
            valid = block < q
            ptr = np.zeros(e - s + 1, np.int64)
            np.cumsum(valid.sum(axis=1), out=ptr[1:])
            atoms = block[valid]
            csc = sp.csr_matrix((np.ones(atoms.size, np.int8), atoms, ptr),
                                shape=(e - s, q)).tocsc()
            per = np.diff(csc.indptr)
            dest = np.repeat(nxt - csc.indptr[:-1], per) + np.arange(csc.nnz)
            lo[dest] = csc.indices + (s - p * panel)
            nxt += per
    starts[:, n_panels] = nxt
    return AtomVertices(indptr, starts, lo)


def atom_sums(av: AtomVertices, vals: np.ndarray) -> np.ndarray:
    """``(q,)`` float64 ``s_j = Σ_{v ∈ supp b_j} vals[v]``, summed in increasing ``v`` (the
    order of scipy's CSR products), in chunks of whole atoms."""
    q = av.indptr.size - 1
    out = np.zeros(q, np.float64)
    step = max(1, int(q * _HOST_CHUNK_ELEMS // max(int(av.indptr[-1]), 1)))
    for a in range(0, q, step):
        b = min(a + step, q)
        verts = np.concatenate([av.vertices(j) for j in range(a, b)] + [np.zeros(0, np.int64)])
        owner = np.repeat(np.arange(b - a), np.diff(av.indptr[a:b + 1]))
        out[a:b] = np.bincount(owner, weights=vals[verts], minlength=b - a)
    return out


def ell_gram_rows(atom_lists, av: AtomVertices, ks, vals=None, segments=None) -> np.ndarray:
    """Rows ``G[k, :] = Σ_{v ∈ supp b_k} vals[v] · B[v, :]`` ``(len(ks), q)`` float64 (host).

    ``vals = None``: the overlap counts ``|supp b_k ∩ supp b_j|`` (exact), else the weighted
    rows of ``BᵀWB`` with ``vals = w`` (summed in increasing ``v``).  Each row is a
    ``bincount`` over the lists of the vertices of atom ``k`` (from `atom_vertices`):
    ``O(|supp b_k| · D)``, in vertex chunks of about `_HOST_CHUNK_ELEMS` entries so that
    a large atom needs no ``|supp| × D`` int64 buffer (the weighted row of such an atom then
    adds the chunks' partial sums).
    """
    lists = np.asarray(atom_lists)
    seg = None if segments is None else np.asarray(segments)
    q = av.indptr.size - 1
    width = lists.shape[1]
    step = max(1, _HOST_CHUNK_ELEMS // max(width, 1))
    out = np.zeros((len(ks), q + 1), np.float64)  # column q: the padding
    for i, k in enumerate(np.asarray(ks, np.int64).tolist()):
        supp = av.vertices(k)
        for s in range(0, supp.size, step):
            verts = supp[s:s + step]
            wts = None if vals is None else np.repeat(vals[verts], width)
            ids = decode_host(lists[verts], None if seg is None else seg[verts])
            out[i] += np.bincount(ids.ravel(), weights=wts, minlength=q + 1)
    return out[:, :q]
