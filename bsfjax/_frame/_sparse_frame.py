r"""Sparse Binary Sparse Frames: the atoms as per-vertex atom lists, O(nnz) memory.

Owner of: ``SparseFrame``, the build of its atom lists (`sparse_atom_lists`, `_ListBuilder`)
and `sparse_gram` (``BᵀWB``); the kernels of the products (``B x``, ``Bᵀ y``, Gram rows) live
in `bsfjax._frame._ell`, the host Gram sources in `bsfjax._frame._sparse_gram`.

A dense frame stores ``B`` ``(n, q)``; at 111K vertices and q = 16.7K atoms that is 7.4 GB in
float32 although only ~2 % of the entries are 1.  A [`SparseFrame`][bsfjax.SparseFrame] stores, for every
vertex ``v``, the sorted list of atoms that contain it, padded with ``q`` to a common length
``D = max_v |{j : B_vj = 1}|`` (the ELLPACK layout of ``B``)::

    atom_lists[v, d] = j_d(v)  (j_1 < j_2 < … , then q … q)       B_vj = 1  ⇔  j ∈ atom_lists[v]

stored in 16 bits (`bsfjax._frame._packed_lists`: the low bits, plus per vertex where each
``2¹⁶`` block of atom indices starts when ``q ≥ 2¹⁶``), half the memory of int32.

On real meshes ``D`` is close to the mean row count (each vertex is covered by about the same
number of atoms; max/mean ≈ 1.3 on the TOSCA cat, ≈ 2 on FAUST), so the padding wastes
little, whereas per-atom lists would pad every atom to the largest one (10× the mean).  Products (chunked over vertex
blocks so that no ``(n, q)`` or ``(nnz, m)`` array is formed):

    (B X)_v   = Σ_d X[j_d(v)]                 gather-sum    (X ``(q, m)``)
    (Bᵀ Y)_j  = Σ_{v : j ∈ lists(v)} Y_v        scatter-add   (Y ``(n, m)``)
    BᵀWB       scipy CSR product on the host (exact integer counts for W = I)
    G[k, :]    one row of BᵀWB on the host: a bincount of the lists of supp b_k, found in the
               16-bit transpose of the lists (`atom_vertices`; OMP's Gram rows)

The atoms are built from the same band-limited kernels ``g = Φ a`` as the dense frame
(``frame.py``) in blocks of whole columns, in one pass over ``Φ``: ``O(n k q)`` flops like the
dense build, ``O(n · block + nnz)`` memory: the lists are appended to in vertex chunks
(`_ListBuilder`) and handed to JAX without a copy on CPU; the products slice the lists
in place (no padded copy).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

from jaxtyping import Array, Float, Int

from . import _operator
from ._binarize import mask_block
from ._ell import _block_counts, atom_vertices, ell_matmul, ell_rmatmul
from .._util import BSFError
from ._gram_rows import host_callback_dtype, join64, split64
from .._util import release_free_memory
from ._packed_lists import SEGMENT_BITS, decode_host, decode_traced, n_segments, pack_lists
from ._operator import AbstractFrame
from ._sparse_gram import EllGramSource, _lists_to_scipy

__all__ = ["SparseFrame", "sparse_atoms", "sparse_atom_lists", "sparse_gram"]

#: Kernel values per column block of the build (``n × block`` live at a time).
_BUILD_ELEMS = 2**24


class SparseFrame(AbstractFrame):
    """A Binary Sparse Frame whose atoms are stored as per-vertex atom lists (see module doc).

    Same fields and column order as [`bsfjax.Frame`][bsfjax.Frame] except ``atoms``:

    **Attributes:**

    - `atom_lists`: ``(n, D)``, the atoms containing each vertex in increasing order, padded
      with ``q``: uint16 as built, their low 16 bits when ``atom_segments`` is given
      (`bsfjax._frame._packed_lists`); any integer dtype for hand-made lists.
    - `coeffs`: ``(k, q)`` spectral coefficients of each atom's kernel.
    - `taus`, `centers`, `mass`, `gammas`, `tau_convention`, `columns`: as in [`bsfjax.Frame`][bsfjax.Frame].
    - `atom_segments`: ``(n, S)`` int32, ``S = q >> 16``, or ``None`` (``q < 2¹⁶`` or plain
      lists): per vertex, the number of its atoms below ``(h + 1) · 2¹⁶``.
    """

    atom_lists: Int[Array, "n D"]
    coeffs: Float[Array, "k q"]
    taus: Float[Array, " q"]
    centers: Int[Array, " q"]
    mass: Float[Array, " n"] | None
    gammas: Float[Array, " q"] | None = None
    tau_convention: str = eqx.field(static=True, default="unit_area")
    columns: Int[Array, " q"] | None = None
    atom_segments: Int[Array, "n S"] | None = None

    @property
    def n_vertices(self) -> int:
        return int(self.atom_lists.shape[-2])

    @property
    def n_atoms(self) -> int:
        return int(self.coeffs.shape[-1])

    @property
    def dtype(self):
        return self.coeffs.dtype

    @property
    def nnz(self) -> int:
        """Number of ones of ``B``."""
        return int(np.asarray(_block_counts(self.atom_lists, self.n_atoms, self.atom_segments)
                              ).sum(dtype=np.int64))

    def host_lists(self, rows=slice(None)) -> np.ndarray:
        """int32 atom lists of ``rows`` on the host, decoded (`bsfjax._frame._packed_lists`)."""
        seg = self.atom_segments
        return decode_host(np.asarray(self.atom_lists)[rows],
                           None if seg is None else np.asarray(seg)[rows])

    # ---------------------------------------------------------------- products

    def apply(self, alpha):
        return ell_matmul(self.atom_lists, alpha.T, self.atom_segments).T

    def apply_transpose(self, y, w=None):
        return ell_rmatmul(self.atom_lists, (y if w is None else y * w).T, self.n_atoms,
                           self.atom_segments).T

    def column_norms2(self, w=None):
        n = self.n_vertices
        ones = jnp.ones((n, 1), self.dtype if w is None else w.dtype)
        return ell_rmatmul(self.atom_lists, ones if w is None else w[:, None],
                           self.n_atoms, self.atom_segments)[:, 0]

    def gram(self, w=None):
        """``BᵀWB`` dense, from the host CSR product (`sparse_gram`) through a callback;
        only for ``q² · 8`` bytes within `DENSE_BUDGET_BYTES`."""
        q = self.n_atoms
        if q * q * 8 > _operator.DENSE_BUDGET_BYTES:
            raise BSFError(f"this coder needs the dense q × q Gram matrix (q = {q}: "
                           f"{q * q * 8 / 2**30:.1f} GiB > DENSE_BUDGET_BYTES); use OMP or "
                           "ErrorOMP ('omp', 'omp_error') for frames this large")
        dtype = self.dtype if w is None else jnp.result_type(self.dtype, w)

        def host(lists, seg, w):
            Bs = _lists_to_scipy(np.asarray(lists), q, None if w is None else np.asarray(w),
                                 None if seg is None else np.asarray(seg))
            return split64((Bs.T @ Bs).toarray(), dtype)

        out = jax.pure_callback(host, host_callback_dtype((q, q), dtype), self.atom_lists,
                                self.atom_segments, w)
        return join64(out, dtype)

    def gram_rows(self, ks, w=None):
        onehot = jax.nn.one_hot(ks, self.n_atoms, dtype=self.dtype if w is None else w.dtype)
        return self.apply_transpose(self.apply(onehot), w)

    def host_gram_source(self, w, n_rows: int):
        """Always: rows from the lists and their 16-bit transpose (`EllGramSource`)."""
        return EllGramSource(self, None if w is None else np.asarray(w, np.float64))

    # ---------------------------------------------------------------- structure

    def todense(self, dtype=None) -> jax.Array:
        """The ``(n, q)`` 0/1 matrix ``B`` (only for frames that fit in memory)."""
        dtype = dtype or jax.dtypes.canonicalize_dtype(jnp.float64)
        n, q = self.n_vertices, self.n_atoms
        lists = decode_traced(self.atom_lists, self.atom_segments)
        rows = jnp.broadcast_to(jnp.arange(n)[:, None], lists.shape)
        return jnp.zeros((n, q + 1), dtype).at[rows, lists].set(1)[:, :q]

    def atom_columns(self, js) -> np.ndarray:
        """Dense 0/1 columns ``B[:, js]`` ``(n, len(js))`` (host; ``O(n · D)`` per column)."""
        lists = self.host_lists()
        return np.stack([(lists == int(j)).any(axis=1) for j in np.atleast_1d(js)],
                        axis=1).astype(np.float32)

    def supports_equal(self, a, b):
        """From the transpose of the lists (`atom_vertices`): ``O(nnz)`` once."""
        av = atom_vertices(self.atom_lists, self.n_atoms, self.atom_segments)
        return np.array([np.array_equal(av.vertices(int(i)), av.vertices(int(j)))
                         for i, j in zip(np.asarray(a), np.asarray(b))], bool)

    def support_hashes(self, r):
        return ell_rmatmul(self.atom_lists, jnp.asarray(r, jnp.uint32).T, self.n_atoms,
                           self.atom_segments).T

    def nonempty(self):
        n = self.n_vertices
        return ell_rmatmul(self.atom_lists, jnp.ones((n, 1), jnp.int32), self.n_atoms,
                           self.atom_segments)[:, 0] > 0

    def select_columns(self, cols, columns=None):
        """Columns ``cols`` (increasing): the lists renumbered, dropped atoms moved to the
        padding and each row re-sorted (the kept atoms keep their order), width cut to the
        new largest count."""
        cols = np.asarray(cols)
        q = self.n_atoms
        new = np.full(q + 1, cols.size, np.int32)
        new[cols] = np.arange(cols.size, dtype=np.int32)
        lists = np.sort(new[self.host_lists()], axis=1)
        width = max(1, int((lists < cols.size).sum(axis=1).max(initial=0)))
        lists, seg = pack_lists(lists[:, :width], cols.size)
        return SparseFrame(atom_lists=jnp.asarray(lists), atom_segments=_device(seg),
                           coeffs=self.coeffs[:, cols], taus=self.taus[cols],
                           centers=self.centers[cols], mass=self.mass,
                           gammas=None if self.gammas is None else self.gammas[cols],
                           tau_convention=self.tau_convention, columns=columns)

    def pull_back(self, p2p, coeffs, mass):
        seg = self.atom_segments
        return SparseFrame(atom_lists=jnp.asarray(self.atom_lists)[p2p], coeffs=coeffs,
                           atom_segments=None if seg is None else jnp.asarray(seg)[p2p],
                           taus=self.taus, centers=self.centers, mass=mass, gammas=self.gammas,
                           tau_convention=self.tau_convention, columns=self.columns)

    def rebinarized(self, evecs, coeffs, mass):
        dtype = coeffs.dtype
        ev = jnp.asarray(evecs[:, :coeffs.shape[0]], dtype)  # one (n, k_N) copy, not two
        lists, seg = sparse_atom_lists(ev, coeffs, self.gammas)
        return SparseFrame(atom_lists=lists, atom_segments=seg, coeffs=coeffs,
                           taus=self.taus, centers=self.centers, mass=mass, gammas=self.gammas,
                           tau_convention=self.tau_convention, columns=self.columns)

    def to_scipy(self, weights=None) -> sp.csr_matrix:
        """``B`` (or ``diag(√w) B`` with ``weights``) as a float64 scipy CSR matrix (host)."""
        seg = self.atom_segments
        return _lists_to_scipy(np.asarray(self.atom_lists), self.n_atoms,
                               None if weights is None else np.asarray(weights, np.float64),
                               None if seg is None else np.asarray(seg))


def _device(seg):
    return None if seg is None else jnp.asarray(seg)


# --------------------------------------------------------------------------- build


def sparse_atoms(evecs, coeffs, gammas) -> jax.Array:
    """The int32 ``(n, D)`` lists of `sparse_atom_lists`, decoded (twice the memory of
    the packed lists the frames keep)."""
    lists, seg = sparse_atom_lists(evecs, coeffs, gammas)
    return jnp.asarray(decode_host(np.asarray(lists), None if seg is None else np.asarray(seg)))


def sparse_atom_lists(evecs, coeffs, gammas):
    """``(n, D)`` packed atom lists and their segments (`bsfjax._frame._packed_lists`) of
    ``B = [|g| ≥ γ · max_v |g|]`` for ``g = evecs @ coeffs`` (the rule of
    `bsfjax._frame._binarize.kernel_mask`), never forming the ``(n, q)`` matrix.

    One pass over blocks of whole columns (atoms), ``n × cb ≈ 2²⁴`` kernel values each: the
    device computes a block's mask (and its column maxima) while the host turns the previous
    one into (vertex, atom) pairs (``numpy.nonzero``, row-major) and appends them to each
    vertex's list (`_ListBuilder`); blocks come in increasing atom order, so the lists
    stay sorted.  ``evecs`` ``(n, k)``, ``coeffs`` ``(k, q)``, ``gammas`` ``(q,)``; concrete
    arrays (``D`` is data dependent).  An all-zero frame gets ``D = 1`` (every entry ``q``).
    Peak host memory: the final (16-bit) lists plus one vertex chunk (see
    `_ListBuilder`).  Returns ``(lists, segments)``: uint16 ``(n, D)`` and ``(n, S)``
    int32 or ``None`` (``q < 2¹⁶``).
    """
    # what earlier stages freed but glibc kept (e.g. XLA's input conversions: 0.3–0.6 GiB at
    # 445K vertices) goes back before the lists take their ~n·D·2 bytes
    release_free_memory()
    evecs, coeffs, gammas = jnp.asarray(evecs), jnp.asarray(coeffs), jnp.asarray(gammas)
    n, q = evecs.shape[0], coeffs.shape[1]
    cb = int(max(1, min(q, _BUILD_ELEMS // max(n, 1))))
    n_blocks = -(-q // cb)
    pad = n_blocks * cb - q  # zero columns: empty atoms, beyond q, never stored
    cblocks = jnp.pad(coeffs, ((0, 0), (0, pad))).T.reshape(n_blocks, cb, -1)
    gblocks = jnp.pad(gammas.astype(coeffs.dtype), (0, pad)).reshape(n_blocks, cb)
    lists = _ListBuilder(n, q)

    def collect(b, mask):
        r, c = np.nonzero(np.asarray(mask))
        keep = c + b * cb < q
        lists.append(r[keep], (c[keep] + b * cb).astype(np.int32))

    pending = None
    for b in range(n_blocks):
        mask = mask_block(evecs, cblocks[b].T, gblocks[b])  # dispatched asynchronously
        if pending is not None:
            collect(*pending)
        pending = (b, mask)
    collect(*pending)
    del pending, mask
    out, seg = lists.finish_packed()
    release_free_memory()  # the per-block temporaries (see bsfjax._util._memory)
    # The aligned host buffer becomes the device array without a copy on CPU (device_put
    # aliases 64-byte aligned numpy memory); jnp.asarray would copy it.
    return jax.device_put(out), _device(seg)


#: Vertex chunks of the lists under construction (each grows on its own; see _ListBuilder).
_BUILD_CHUNKS = 32
#: Slots added at least when a chunk grows (as rows of its transposed layout).
_GROW_SLOTS = 64


def _aligned_empty(shape, dtype, align: int = 64) -> np.ndarray:
    """Uninitialised C-contiguous array whose data starts on an ``align``-byte boundary (XLA's
    CPU client then shares numpy memory instead of copying it)."""
    dtype = np.dtype(dtype)
    size = int(np.prod(shape, dtype=np.int64))
    raw = np.empty(size * dtype.itemsize + align, np.uint8)
    off = -raw.ctypes.data % align
    return raw[off:off + size * dtype.itemsize].view(dtype).reshape(shape)


class _ListBuilder:
    """Per-vertex sorted atom lists built by appending, with no growth copies of the whole,
    in 16 bits (`bsfjax._frame._packed_lists`; ``segments`` counted as the atoms arrive).

    The final width ``D`` (the largest count) is known only after the last block, and
    re-padding one ``(n, W)`` array each time ``W`` grows would hold two copies.  So the
    vertices are split into `_BUILD_CHUNKS` chunks, each stored transposed, ``(W_c,
    n_c)``: slot ``d`` of every vertex of the chunk is one contiguous row, and growing ``W_c``
    appends rows in place (``ndarray.resize``: ``realloc``, which remaps pages instead of
    copying a large block).  `finish` writes the ``(n, D)`` lists chunk by chunk and
    frees each chunk as it goes, so the peak is about one copy of the lists.
    """

    def __init__(self, n: int, q: int):
        self.n, self.q = n, q
        step = max(1, -(-n // _BUILD_CHUNKS))
        self.bounds = np.append(np.arange(0, n, step), n)
        self.pad = q & ((1 << SEGMENT_BITS) - 1)  # the padding q, packed
        self.chunks = [np.full((0, e - s), self.pad, np.uint16)
                       for s, e in zip(self.bounds[:-1], self.bounds[1:])]
        self.fill = np.zeros(n, np.int64)  # entries stored per vertex so far
        self.seg = np.zeros((n, n_segments(q)), np.int32)

    def append(self, r: np.ndarray, c: np.ndarray) -> None:
        """Append atoms ``c`` to vertices ``r`` (``r`` nondecreasing, ``c`` larger than every
        atom stored so far, increasing within each vertex)."""
        cnt = np.bincount(r, minlength=self.n)
        for h in range(self.seg.shape[1]):  # atoms arrive in increasing blocks: the last block
            below = c < ((h + 1) << SEGMENT_BITS)  # with atoms below a bound sets its count
            if below.any():
                self.seg[:, h] = self.fill + np.bincount(r[below], minlength=self.n)
        first = np.cumsum(cnt) - cnt  # index in r of each vertex's first entry
        slot = self.fill[r] + np.arange(r.size) - first[r]
        cuts = np.searchsorted(r, self.bounds)
        for i, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
            if a == b:
                continue
            need = int(slot[a:b].max()) + 1
            if need > self.chunks[i].shape[0]:
                self._grow(i, max(need, self.chunks[i].shape[0] + _GROW_SLOTS))
            self.chunks[i][slot[a:b], r[a:b] - self.bounds[i]] = c[a:b] & 0xFFFF
        self.fill += cnt

    def _grow(self, i: int, slots: int) -> None:
        chunk = self.chunks[i]
        old = chunk.shape[0]
        # the chunk is private to this builder (no views exist), so resizing in place is safe
        chunk.resize((slots, chunk.shape[1]), refcheck=False)
        chunk[old:] = self.pad

    def finish(self) -> np.ndarray:
        """The ``(n, D)`` int32 lists, 64-byte aligned; the builder is emptied."""
        lists, seg = self.finish_packed()
        out = _aligned_empty(lists.shape, np.int32)
        out[...] = decode_host(lists, seg)
        return out

    def finish_packed(self):
        """``(lists, segments)``: the ``(n, D)`` uint16 lists, 64-byte aligned, and the
        ``(n, S)`` segments or ``None``; the builder is emptied."""
        width = max(1, int(self.fill.max(initial=0)))
        out = _aligned_empty((self.n, width), np.uint16)
        for i, (s, e) in enumerate(zip(self.bounds[:-1], self.bounds[1:])):
            chunk, self.chunks[i] = self.chunks[i], None
            have = min(width, chunk.shape[0])
            for v in range(0, e - s, 256):  # transpose in column panels (cache friendly)
                out[s + v:s + min(v + 256, e - s), :have] = chunk[:have, v:v + 256].T
            out[s:e, have:] = self.pad
            del chunk  # freed before the next chunk is written
        seg, self.seg = self.seg, None
        return out, (seg if seg.shape[1] else None)


# --------------------------------------------------------------------------- Gram matrix


def sparse_gram(frame: SparseFrame, weights=None) -> sp.csr_matrix:
    """``G = Bᵀ W B`` ``(q, q)`` as float64 scipy CSR (host; ``W = diag(weights)`` or ``I``).

    Unweighted entries are the exact overlap counts ``|supp b_i ∩ supp b_j|``.  Cost
    ``Σ_v D_v²`` (``D_v`` atoms at vertex ``v``), memory ``O(nnz(G))``.
    """
    if not isinstance(frame, SparseFrame):
        raise BSFError(f"frame must be a bsfjax.SparseFrame, got {type(frame).__name__}")
    B = frame.to_scipy(weights)
    return (B.T.tocsr() @ B).tocsr()
