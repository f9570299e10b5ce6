"""Dense kernels of the block Lanczos basis of `bsfjax._spectral._eigensolver`. Owner of Cholesky
QR (`_cholqr`), block Gram–Schmidt against the older basis with the `ORTH_LEVEL` test
(`_orthonormalize`, `_project_out`, `_subtract`), the in-place rotation of a restart
(`_rotate_in_place`), the products ``K X`` and residual norms with ``K = D⁻¹ W D⁻¹``
(`_apply_K`, `_residual_norms`), and the memory-mapped storage of the basis (`_mapped_empty`,
`_release_after`).
"""

from __future__ import annotations

import mmap

import numpy as np
import scipy.linalg
import scipy.linalg.blas
import scipy.linalg.lapack
import scipy.sparse as sp

__all__ = ["ORTH_LEVEL"]


#: The orthogonality kept between a new block and the older basis columns, relative to the
#: block's norm.  It is measured for every block (one read of the basis) and restored by a
#: full Gram–Schmidt update (a second read) only when exceeded; between that and eps the
#: Lanczos recurrence is unaffected (semi-orthogonality needs ≤ √eps ≈ 1.5e-8).  Measured,
#: k = 100 at 111K vertices: the share is ~1e-13 after a full update and ~1e-9 after a
#: skipped one (``T`` amplifies it), so the blocks alternate and a third (b = 8) to a half
#: (b = 4) of them skip the update, with the same number of solves, eigenvalues equal to
#: 4e-15 and A-orthonormality 5e-13; 1e-10 behaved the same, 1e-8 stalled the convergence.
#: Not measuring the block after a full update at all (its share is ~1e-13) was tried: 30 %
#: less orthogonalization time, but the test sphere's eigenspaces drifted to a sine of 4e-6.
ORTH_LEVEL = 1e-12


def _cholqr(Z: np.ndarray, G: np.ndarray | None = None):
    """Cholesky QR, twice (``Z = Qn R``): two Gram products instead of Householder's column
    sweeps; ``R`` has a NaN diagonal when ``Z`` is numerically rank deficient.  ``G``: ``ZᵀZ``
    when the caller has it (saves the first Gram product); ``Z`` itself is left intact."""
    R = np.eye(Z.shape[1])
    Qn = np.asfortranarray(Z)
    for it in range(2):
        if G is None or it:
            G = Qn.T @ Qn
        L, info = scipy.linalg.lapack.dpotrf(G, lower=1, clean=1)
        if info != 0:
            return Z, np.full((Z.shape[1], Z.shape[1]), np.nan)
        # Qn ← Qn L⁻ᵀ on the column-major block (BLAS trsm, side = right); the first pass
        # writes a copy, so that Z stays intact for the caller's Householder fallback
        Qn = scipy.linalg.blas.dtrsm(1.0, L, Qn, side=1, lower=1, trans_a=1,
                                     overwrite_b=it > 0 or Qn is not Z)
        R = L.T @ R
    return Qn, R


def _subtract(Z: np.ndarray, Q: np.ndarray, c: np.ndarray) -> None:
    """``Z ← Z − Q c`` in place (``Z``, ``Q`` column-major: one BLAS ``gemm`` accumulating into
    ``Z``, no temporary)."""
    # f2py would silently copy a Z that is not column-major float64 and leave Z unchanged
    assert Z.flags.f_contiguous and Z.dtype == np.float64
    scipy.linalg.blas.dgemm(-1.0, Q, c, beta=1.0, c=Z, overwrite_c=1)


def _project_out(Z: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """``c = Qᵀ Z`` and ``Z ← Z − Q c`` in place; returns ``c``."""
    c = scipy.linalg.blas.dgemm(1.0, Q, Z, trans_a=1)
    _subtract(Z, Q, c)
    return c


def _column_norms(G: np.ndarray) -> np.ndarray:
    """The column norms of ``Z`` from its Gram matrix ``G = ZᵀZ``."""
    return np.sqrt(np.maximum(np.diag(G), 0.0))


def _mapped_empty(n: int, m: int) -> tuple[np.ndarray, mmap.mmap]:
    """An uninitialized column-major ``n × m`` float64 array in its own anonymous memory map,
    and the map.

    numpy asks the kernel for transparent huge pages on large arrays; on the benchmark
    machine the first touch of such memory stalls (page compaction: 1.7–2.7 s for the
    445K-vertex basis of 330 columns, 1.2 GB, in a new process) where ordinary pages took
    0.45–1.2 s, with the same speed of the products over it afterwards (72–73 ms per
    ``Qᵀ Z``).  The map is lazily backed, so only the columns written are ever touched, and
    it is released with the array."""
    flags = getattr(mmap, "MAP_PRIVATE", 0) | getattr(mmap, "MAP_ANONYMOUS", 0)
    buf = mmap.mmap(-1, max(n * m, 1) * 8, **({"flags": flags} if flags else {}))
    return np.frombuffer(buf, np.float64, count=n * m).reshape((n, m), order="F"), buf


def _release_after(buf: mmap.mmap, nbytes: int) -> None:
    """Give the memory of ``buf`` past its first ``nbytes`` back to the system (the mapping
    stays, reading zeros there): the basis's first ``k`` columns are returned as the
    eigenvectors, and the columns after them need not stay resident."""
    start = -(-nbytes // mmap.PAGESIZE) * mmap.PAGESIZE
    if hasattr(buf, "madvise") and hasattr(mmap, "MADV_DONTNEED") and start < len(buf):
        buf.madvise(mmap.MADV_DONTNEED, start, len(buf) - start)


def _apply_K(W: sp.csr_matrix, d: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``K X = D⁻¹ W D⁻¹ X`` for a block ``X`` of any layout (rows made contiguous for the
    sparse product)."""
    KX = W @ np.divide(X, d[:, None], order="C")
    KX /= d[:, None]
    return KX


def _residual_norms(W: sp.csr_matrix, d: np.ndarray, Y: np.ndarray, lam: np.ndarray):
    """``‖K y_i − λ_i y_i‖`` for the columns of ``Y`` (``K = D⁻¹ W D⁻¹``), a few columns at a
    time: temporaries of ≤ 16 MB, which the allocator reuses, instead of ``n × k`` ones (each
    a fresh mapping to fault in: 0.6–1 s per 357 MB array at 445K vertices on the benchmark
    machine)."""
    n, k = Y.shape
    chunk = max(1, (1 << 21) // n)
    res = np.empty(k)
    for j in range(0, k, chunk):
        Yj = Y[:, j:j + chunk]
        R = _apply_K(W, d, Yj)
        R -= Yj * lam[j:j + chunk]
        res[j:j + chunk] = np.sqrt(np.einsum("ij,ij->j", R, R))
    return res


def _orthonormalize(Z: np.ndarray, Q: np.ndarray, lo: int, rng: np.random.Generator):
    """``(C, Qn, R)`` with ``Z = Q C + Qn R``, ``Qn`` orthonormal and ⟂ ``Q``; columns of ``Z``
    that are (numerically) in ``span Q`` are replaced by random directions with ``R = 0``.
    ``Z`` (column-major) is overwritten.

    Gram–Schmidt against ``Q[:, lo:]`` (the last blocks, the only ones ``Z`` is not
    orthogonal to in exact arithmetic: the Lanczos recurrence), then a second pass against
    the whole ``Q`` (the local part's second pass, where the cancellation is, and the full
    reorthogonalization against the older columns, removing what rounding left; a float32
    copy of ``Q`` for this pass was tried and breaks convergence: ``T`` amplifies what it
    leaves).  That second pass is most of the cost: one read of ``Q`` for its coefficients,
    and a second for the update only when the older columns' share exceeds
    `ORTH_LEVEL` (else the local share alone is subtracted).  Norms come from the
    ``b × b`` Gram matrices (one read of ``Z`` each), which Cholesky QR reuses.
    """
    Z = np.asfortranarray(Z)  # (no copy for the solver's blocks, which are column-major)
    C = np.zeros((Q.shape[1], Z.shape[1]))
    norm0 = _column_norms(Z.T @ Z)
    if lo < Q.shape[1]:
        C[lo:] = _project_out(Z, Q[:, lo:])
    # second pass: its coefficients against the whole basis (one read of Q); the older
    # columns' share is subtracted only when it is above ORTH_LEVEL · ‖Z‖ (a second read of
    # Q), else only the local one
    c = scipy.linalg.blas.dgemm(1.0, Q, Z, trans_a=1)
    zn = _column_norms(Z.T @ Z)
    if lo and np.all(np.abs(c[:lo]).max(axis=0) <= ORTH_LEVEL * zn):
        _subtract(Z, Q[:, lo:], c[lo:])
        C[lo:] += c[lo:]  # (the older share, ≤ ORTH_LEVEL, stays in the new block)
    else:
        _subtract(Z, Q, c)
        C += c
    G = Z.T @ Z
    ratio = _column_norms(G) / np.maximum(norm0, 1e-300)
    if ratio.min() < 1e-3:  # strong cancellation: what is left may lean on Q; pass again
        C += _project_out(Z, Q)
        G = Z.T @ Z
        ratio = _column_norms(G) / np.maximum(norm0, 1e-300)
    Qn, R = _cholqr(Z, G)
    bad = ~np.isfinite(np.diag(R)) | (ratio <= 1e-11)
    if bad.any():  # breakdown: an invariant subspace was found; go on with new directions
        Qn, R = np.linalg.qr(Z)  # Householder, stable on a rank-deficient block
        bad = (np.abs(np.diag(R)) <= 1e-11 * np.maximum(norm0, 1e-300)) | (ratio <= 1e-11)
        R[bad, :] = 0.0
        Y = rng.standard_normal((Z.shape[0], int(bad.sum())))
        for _ in range(2):
            Y -= Q @ (Q.T @ Y)
            Y -= Qn[:, ~bad] @ (Qn[:, ~bad].T @ Y)
        Qn[:, bad] = np.linalg.qr(Y)[0]
        for _ in range(2):  # the kept columns of a rank-deficient block: clean against Q
            c = Q.T @ Qn
            Qn -= Q @ c
        Qr, Rr = np.linalg.qr(Qn)  # ≈ Qn up to signs (Qn was orthonormal): keep Qn's signs
        Qn = Qr * np.sign(np.diag(Rr))
    return C, Qn, R


def _rotate_in_place(Q: np.ndarray, m: int, S: np.ndarray, rows: int = 32768) -> None:
    """``Q[:, :q] ← Q[:, :m] S`` (``S``: ``m × q``, ``q <= m``) in place, a slab of rows at a
    time: each slab of the product needs only the same rows of ``Q``, so no ``n × q``
    temporary is made (at 445K vertices and q = 180 that was 0.6 GB and a copy into ``Q``)."""
    q = S.shape[1]
    for r in range(0, Q.shape[0], rows):
        Q[r:r + rows, :q] = Q[r:r + rows, :m] @ S
