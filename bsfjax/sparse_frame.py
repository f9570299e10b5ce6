r"""Sparse Binary Sparse Frames: the atoms as per-vertex atom lists, O(nnz) memory.

Owner of: ``SparseFrame`` and the sparse products of a frame (``B x``, ``Bᵀ y``, ``BᵀWB``).

A dense frame stores ``B`` ``(n, q)``; at 111K vertices and q = 16.7K atoms that is 7.4 GB in
float32 although only ~2 % of the entries are 1.  A :class:`SparseFrame` stores, for every
vertex ``v``, the sorted list of atoms that contain it, padded with ``q`` to a common length
``D = max_v |{j : B_vj = 1}|`` (the ELLPACK layout of ``B``)::

    atom_lists[v, d] = j_d(v)  (j_1 < j_2 < … , then q … q)       B_vj = 1  ⇔  j ∈ atom_lists[v]

On real meshes ``D`` is close to the mean row count (each vertex is covered by about the same
number of atoms; max/mean ≈ 1.3 on the TOSCA cat, ≈ 2 on FAUST), so the padding wastes
little, whereas per-atom lists would pad every atom to the largest one (10× the mean).  Products (chunked over vertex
blocks so that no ``(n, q)`` or ``(nnz, m)`` array is formed):

    (B X)_v   = Σ_d X[j_d(v)]                 gather-sum    (X ``(q, m)``)
    (Bᵀ Y)_j  = Σ_{v : j ∈ lists(v)} Y_v        scatter-add   (Y ``(n, m)``)
    BᵀWB       scipy CSR product on the host (exact integer counts for W = I)

The atoms are built from the same band-limited kernels ``g = Φ a`` as the dense frame
(``frame.py``) in blocks of whole columns, in one pass over ``Φ``: ``O(n k q)`` flops like the
dense build, ``O(n · block + nnz)`` memory.
"""

from __future__ import annotations

from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from .errors import BSFError

__all__ = ["SparseFrame", "sparse_atoms", "ell_matmul", "ell_rmatmul", "sparse_gram"]

#: Kernel values per column block of the build (``n × block`` live at a time).
_BUILD_ELEMS = 2**24
#: Elements (``rows × D × m``) gathered or scattered per block of a product.
_PRODUCT_ELEMS = 2**22


class SparseFrame(eqx.Module):
    """A Binary Sparse Frame whose atoms are stored as per-vertex atom lists (see module doc).

    Same fields and column order as :class:`bsfjax.Frame` except ``atoms``:

    Attributes:
        atom_lists: ``(n, D)`` int32, the atoms containing each vertex in increasing order,
            padded with ``q``.
        coeffs: ``(k, q)`` spectral coefficients of each atom's kernel.
        taus, centers, mass, gammas, tau_convention: as in :class:`bsfjax.Frame`.
    """

    atom_lists: jax.Array
    coeffs: jax.Array
    taus: jax.Array
    centers: jax.Array
    mass: jax.Array
    gammas: jax.Array | None = None
    tau_convention: str = eqx.field(static=True, default="unit_area")

    @property
    def n_vertices(self) -> int:
        return int(self.atom_lists.shape[-2])

    @property
    def n_atoms(self) -> int:
        return int(self.coeffs.shape[-1])

    @property
    def nnz(self) -> int:
        """Number of ones of ``B``."""
        return int(jnp.sum(self.atom_lists < self.n_atoms))

    @property
    def effective_taus(self) -> jax.Array:
        if self.tau_convention == "raw":
            return self.taus
        return self.taus * jnp.sum(self.mass, axis=-1, keepdims=True)

    def todense(self, dtype=None) -> jax.Array:
        """The ``(n, q)`` 0/1 matrix ``B`` (only for frames that fit in memory)."""
        dtype = dtype or jax.dtypes.canonicalize_dtype(jnp.float64)
        n, q = self.n_vertices, self.n_atoms
        rows = jnp.broadcast_to(jnp.arange(n)[:, None], self.atom_lists.shape)
        return jnp.zeros((n, q + 1), dtype).at[rows, self.atom_lists].set(1)[:, :q]

    def atom_columns(self, js) -> np.ndarray:
        """Dense 0/1 columns ``B[:, js]`` ``(n, len(js))`` (host; ``O(n · D)`` per column)."""
        lists = np.asarray(self.atom_lists)
        return np.stack([(lists == int(j)).any(axis=1) for j in np.atleast_1d(js)],
                        axis=1).astype(np.float32)

    def to_scipy(self, weights=None) -> sp.csr_matrix:
        """``B`` (or ``diag(√w) B`` with ``weights``) as a float64 scipy CSR matrix (host)."""
        lists = np.asarray(self.atom_lists)
        n, q = lists.shape[0], self.n_atoms
        valid = lists < q
        counts = valid.sum(axis=1)
        indptr = np.zeros(n + 1, np.int64)
        np.cumsum(counts, out=indptr[1:])
        data = np.ones(int(indptr[-1]))
        if weights is not None:
            data = np.repeat(np.sqrt(np.asarray(weights, np.float64)), counts)
        return sp.csr_matrix((data, lists[valid], indptr), shape=(n, q))


# --------------------------------------------------------------------------- build


def _blocks(x: jax.Array, nb: int, fill) -> jax.Array:
    """Pad axis 0 of ``x`` to a multiple of ``nb`` with ``fill`` and reshape to blocks."""
    pad = -x.shape[0] % nb
    x = jnp.pad(x, [(0, pad)] + [(0, 0)] * (x.ndim - 1), constant_values=fill)
    return x.reshape((-1, nb) + x.shape[1:])


@jax.jit
def _mask_block(evecs, coeffs, gammas):
    """``(n, cb)`` bool atoms of a block of whole columns: ``|g| ≥ γ · max_v |g|``, ``g = Φ a``
    (the rule and product of ``frame._binarize``; an all-zero column gives an empty atom)."""
    g = jnp.matmul(evecs, coeffs, precision=jax.lax.Precision.HIGHEST)
    m = jnp.maximum(jnp.max(g, axis=0), -jnp.min(g, axis=0))
    return (jnp.abs(g) >= gammas * m) & (m > 0)


def sparse_atoms(evecs, coeffs, gammas) -> jax.Array:
    """``(n, D)`` atom lists of ``B = [|g| ≥ γ · max_v |g|]`` for ``g = evecs @ coeffs`` (the
    dense rule of :func:`bsfjax.frame._binarize`), never forming the ``(n, q)`` matrix.

    One pass over blocks of whole columns (atoms), ``n × cb ≈ 2²⁴`` kernel values each: the
    device computes a block's mask (and its column maxima) while the host turns the previous
    one into (vertex, atom) pairs (``numpy.nonzero``, row-major) and appends them to each
    vertex's list; blocks come in increasing atom order, so the lists stay sorted.  ``evecs``
    ``(n, k)``, ``coeffs`` ``(k, q)``, ``gammas`` ``(q,)``; concrete arrays (``D`` is data
    dependent).  An all-zero frame gets ``D = 1`` (every entry ``q``).
    """
    evecs, coeffs, gammas = jnp.asarray(evecs), jnp.asarray(coeffs), jnp.asarray(gammas)
    n, q = evecs.shape[0], coeffs.shape[1]
    cb = int(max(1, min(q, _BUILD_ELEMS // max(n, 1))))
    n_blocks = -(-q // cb)
    pad = n_blocks * cb - q  # zero columns: empty atoms, beyond q, never stored
    cblocks = jnp.pad(coeffs, ((0, 0), (0, pad))).T.reshape(n_blocks, cb, -1)
    gblocks = jnp.pad(gammas.astype(coeffs.dtype), (0, pad)).reshape(n_blocks, cb)
    lists = np.full((n, 16), q, np.int32)
    fill = np.zeros(n, np.int64)  # entries stored per vertex so far

    def collect(b, mask, lists):
        r, c = np.nonzero(np.asarray(mask))
        keep = c + b * cb < q
        r, c = r[keep], (c[keep] + b * cb).astype(np.int32)
        cnt = np.bincount(r, minlength=n)
        need = int((fill + cnt).max(initial=0))
        if need > lists.shape[1]:  # grow the padded width geometrically
            width = max(need, int(1.5 * lists.shape[1]))
            lists = np.pad(lists, ((0, 0), (0, width - lists.shape[1])), constant_values=q)
        first = np.cumsum(cnt) - cnt  # index in r of each vertex's first entry
        lists[r, fill[r] + np.arange(r.size) - first[r]] = c
        fill[:] += cnt
        return lists

    pending = None
    for b in range(n_blocks):
        mask = _mask_block(evecs, cblocks[b].T, gblocks[b])  # dispatched asynchronously
        if pending is not None:
            lists = collect(*pending, lists)
        pending = (b, mask)
    lists = collect(*pending, lists)
    return jnp.asarray(lists[:, :max(1, int(fill.max(initial=0)))])


# --------------------------------------------------------------------------- products


def _product_rows(n: int, width: int, m: int) -> int:
    return int(max(1, min(n, _PRODUCT_ELEMS // max(width * m, 1))))


@jax.jit
def ell_matmul(atom_lists: jax.Array, X: jax.Array) -> jax.Array:
    """``B X``: ``(n, m)`` from ``X`` ``(q, m)`` (gather-sum over each vertex's atoms)."""
    n, width = atom_lists.shape
    Xp = jnp.concatenate([X, jnp.zeros((1,) + X.shape[1:], X.dtype)])  # row q: padding
    nb = _product_rows(n, width, X.shape[1])
    out = jax.lax.map(lambda rows: jnp.sum(Xp[rows], axis=1), _blocks(atom_lists, nb, X.shape[0]))
    return out.reshape(-1, X.shape[1])[:n]


@partial(jax.jit, static_argnames="q")
def ell_rmatmul(atom_lists: jax.Array, Y: jax.Array, q: int) -> jax.Array:
    """``Bᵀ Y``: ``(q, m)`` from ``Y`` ``(n, m)`` (scatter-add of each vertex's row)."""
    n, width = atom_lists.shape
    m = Y.shape[1]
    nb = _product_rows(n, width, m)
    lists = _blocks(atom_lists, nb, q)
    ys = _blocks(Y, nb, 0.0)

    def step(acc, blk):
        rows, y = blk
        upd = jnp.broadcast_to(y[:, None, :], rows.shape + (m,))
        return acc.at[rows].add(upd, mode="drop"), None

    acc = jnp.zeros((q + 1, m), Y.dtype)
    return jax.lax.scan(step, acc, (lists, ys))[0][:q]


def sparse_gram(frame: SparseFrame, weights=None) -> sp.csr_matrix:
    """``G = Bᵀ W B`` ``(q, q)`` as float64 scipy CSR (host; ``W = diag(weights)`` or ``I``).

    Unweighted entries are the exact overlap counts ``|supp b_i ∩ supp b_j|``.  Cost
    ``Σ_v D_v²`` (``D_v`` atoms at vertex ``v``), memory ``O(nnz(G))``.
    """
    if not isinstance(frame, SparseFrame):
        raise BSFError(f"frame must be a bsfjax.SparseFrame, got {type(frame).__name__}")
    B = frame.to_scipy(weights)
    return (B.T.tocsr() @ B).tocsr()
