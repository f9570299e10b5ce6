"""Host Gram matrices of a [`bsfjax.SparseFrame`][bsfjax.SparseFrame]: ``BᵀWB`` as scipy CSR and OMP's Gram
rows from the atom lists and their 16-bit transpose.

Owner of: `_lists_to_scipy` (the lists as a scipy CSR ``B`` or ``diag(√w) B``) and
`EllGramSource` (OMP's host Gram rows).  Both work on the lists of a frame only (through the
kernels of `bsfjax._frame._ell`), so this module does not import the frame class: the public
`sparse_gram` lives next to [`SparseFrame`][bsfjax.SparseFrame] in
`bsfjax._frame._sparse_frame`, which imports this module (one way).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._util import release_free_memory
from ._ell import _row_chunks, atom_sums, atom_vertices, ell_gram_rows
from ._packed_lists import decode_host

__all__ = ["EllGramSource"]


def _lists_to_scipy(lists: np.ndarray, q: int, weights, segments=None) -> sp.csr_matrix:
    n = lists.shape[0]
    counts = np.zeros(n, np.int64)
    indices = []
    for s, e in _row_chunks(0, n, lists.shape[1]):
        block = decode_host(lists[s:e], None if segments is None else segments[s:e])
        valid = block < q
        counts[s:e] = valid.sum(axis=1)
        indices.append(block[valid])
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(counts, out=indptr[1:])
    data = np.ones(int(indptr[-1]))
    if weights is not None:
        data = np.repeat(np.sqrt(np.asarray(weights, np.float64)), counts)
    return sp.csr_matrix((data, np.concatenate(indices + [np.zeros(0, np.int32)]), indptr),
                         shape=(n, q))


class EllGramSource:
    """Gram rows ``b_kᵀ W B`` of a [`SparseFrame`][bsfjax.SparseFrame] from its own atom lists (host view) and
    their 16-bit transpose (`atom_vertices`): about ``nnz · 2`` bytes besides the lists,
    where a float64 scipy CSR and its transpose took ``nnz · 24``.

    Without weights the rows are the exact overlap counts; with weights each term is
    ``√w_v · √w_v`` summed in increasing ``v``, the products and order of scipy's
    ``diag(√w) B`` CSR product.
    """

    def __init__(self, frame, w64):  # frame: a SparseFrame (not imported: it imports this)
        self.lists = np.asarray(frame.atom_lists)  # on CPU a view of the device buffer
        seg = frame.atom_segments
        self.seg = None if seg is None else np.asarray(seg)
        self.av = atom_vertices(self.lists, frame.n_atoms, self.seg)
        if w64 is None:
            self.vals = None
        else:
            sw = np.sqrt(w64)
            self.vals = sw * sw

    def norms2(self) -> np.ndarray:
        """``(q,)`` float64 ``‖b_j‖²_W``."""
        if self.vals is None:
            return np.diff(self.av.indptr).astype(np.float64)
        return atom_sums(self.av, self.vals)

    def rows(self, ks) -> np.ndarray:
        return ell_gram_rows(self.lists, self.av, ks, self.vals, self.seg)

    def release(self) -> None:
        """Return the transpose's memory (see `bsfjax._util._memory`)."""
        self.av = self.lists = self.seg = None
        release_free_memory()
