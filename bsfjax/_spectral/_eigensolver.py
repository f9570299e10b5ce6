"""Thick-restart block Lanczos with shift-invert: the smallest ``k`` eigenpairs of ``W φ = λ A φ``.

With ``A = D²`` diagonal and ``ψ = D φ`` the pencil becomes the symmetric standard problem
``K ψ = λ ψ``, ``K = D⁻¹ W D⁻¹``.  Shift-invert with ``σ < λ₁`` maps the wanted eigenvalues to
the largest ones of

    T = (K − σ I)⁻¹ = D (W − σ A)⁻¹ D,        θ = 1 / (λ − σ),

and a block Krylov space of ``T`` is built with one sparse factorization of ``W − σA`` applied
to a whole block of ``b`` right-hand sides at a time.  Against ARPACK's single-vector Lanczos
(``scipy.sparse.linalg.eigsh``) this changes two costs:

* the orthogonalization of each new block against the basis ``Q`` (``n × m``) is a few matrix
  products instead of ``b`` matrix–vector passes over ``Q``: the basis is read from memory
  about ``b`` times less often (ARPACK's passes are half its time at ``n = 10⁵``);
* with a Cholesky factor (CHOLMOD, the optional ``cholespy`` package: a simplicial factor
  with a nested-dissection ordering) a block of right-hand sides is solved faster per vector
  than one at a time, since each sweep of the factor serves four of them (111K-vertex cat,
  this 2-core machine: 6.5–8 ms per vector in blocks of 4–12, 19–25 ms alone; scipy's
  SuperLU 53 ms, no gain from blocks).  MKL's PARDISO (``pypardiso``, supernodal, two
  threads) was measured and not taken: 8 ms per vector in blocks of 12, a 0.8 s factor
  against CHOLMOD's 1.1 s, for a dependency of several hundred MB.

The price: a block Krylov space needs more solves than ARPACK's single-vector one (332 against
~300 for k = 100 at b = 4), and the orthogonalization, bound by memory bandwidth, is a third of
the time. What makes that pass cheap (stop 25): the basis is column-major (a block is one
contiguous slice), each Gram–Schmidt update is one ``gemm`` accumulating in place, the norms
come from the block's Gram matrix, and the update against the older columns, whose share is
rounding-sized, is applied only when it exceeds `ORTH_LEVEL` (one read of the basis
instead of two for a third to a half of the blocks). With that pass cheaper, the small block
(b = 4 for k = 100) and a basis with room for the whole Krylov space (no restart) win.  Fresh
memory is slow to fault in on the benchmark machine, so (stop 26) the basis lives in its own
anonymous map without huge pages, the Ritz vectors are written over it and returned in place,
and no ``n × k`` temporary is made: 3.0–3.1× ARPACK at 111K vertices and 3.2× at 445K over
three runs (``docs/benchmarks.md``).  Tried and dropped: a float32 copy of ``Q`` for the
reorthogonalization (``T`` amplifies its errors; no convergence), larger blocks (more solves,
no cheaper per vector past ~16), shifts closer to the spectrum (no change), CHOLMOD calls of
four columns each (level in the loop), a supernodal factor (cvxopt's CHOLMOD: a 2 s factor at
445K against 6–8 s, but its solve runs one column at a time, 3–4× slower per vector) with a
hand-written triangular solve on it (numba; slower than CHOLMOD's simplicial solve); a helper
process with its own factor solving half of each block (two processes scale in isolation,
19 ms per vector each, but not inside the solver, where OpenBLAS's spinning idle thread takes
the second core: no gain); the Gram–Schmidt products split by rows over Python threads with a
one-thread BLAS (scipy's BLAS wrappers keep the GIL, and numpy's strided products are slower:
orthogonalization 5.9 → 8.0 s at 445K).

Projected matrix and restart.  Every time ``T`` is applied to a block ``X`` of the basis, the
Gram–Schmidt coefficients ``C = Qᵀ T X`` and the triangular factor ``R`` of the remainder
(``T X − Q C = Q_new R``) are the column block of ``H = Qᵀ T Q`` for ``X`` (mirrored, since
``H`` is symmetric), so ``H`` is known exactly for the expanded columns without any further
product.  When the basis is full, Rayleigh–Ritz (``eigh(H)``) gives Ritz pairs ``(θ_i, Q s_i)``;
the ``q`` best ones replace the basis (thick restart: they need no new solve, their images are
``θ_i y_i + Q_new (R s_i)``), the unexpanded block ``Q_new`` follows them, and the expansion
continues.  Converged Ritz vectors stay in the basis and are never applied ``T`` to again
(implicit locking).

Convergence.  The residual of a Ritz pair follows from the Krylov relation without forming
it: ``T y − θ y = Q_new g`` (``g = H[new, :] s``), hence ``K y − λ y = −(K − σ) Q_new g / θ``,
one product of ``W`` with the ``b`` columns of ``Q_new``.  This exact-arithmetic estimate is
evaluated every few blocks (spaced by the observed decay), so the last cycle stops as soon
as all of the first ``k`` pairs satisfy ``‖r_i‖ ≤ tol · λ_k``; the residuals are then
recomputed from the float64 vectors (``≤ max(tol, ACCEPT) · λ_k`` required).  Eigenvalue
errors are ≤ ``‖r_i‖`` (Bauer–Fike) and in practice ≈ ``‖r_i‖² / gap``; eigenvectors are
within an angle ``‖r_i‖ / gap`` of the eigenspace, and A-orthonormal to rounding (Ritz
vectors of an orthonormal basis).  A last probe (`_missed_eigenvalues`) looks for an
eigenvalue below ``λ_k`` that the Krylov space skipped (an exact multiplicity above ``b``).
"""

from __future__ import annotations

import mmap
import time

import numpy as np
import scipy.linalg
import scipy.linalg.blas
import scipy.linalg.lapack
import scipy.sparse as sp
import scipy.sparse.linalg

from .._util import BSFError

__all__ = ["MissedEigenvalue", "block_lanczos", "default_block", "factorize", "has_cholmod"]


#: The true relative residual every returned pair must reach when ``tol`` is below it.  The
#: Krylov estimate (exact arithmetic) must reach ``tol``; what is computed from the float64
#: Ritz vectors has a rounding floor of ~1e-9 (errors of the solves, amplified by the spread of
#: ``θ``), so a ``tol`` under that floor would otherwise never be confirmed.
ACCEPT = 1e-6

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


class MissedEigenvalue(BSFError):
    """The converged pairs are not the smallest ones: a probe found a direction below λ_k."""


def _missed_eigenvalues(T, W, d, Y, YKY, lam, b, rng, steps: int = 2) -> int:
    """How many eigenvalues below ``λ_k`` the converged Ritz pairs ``(lam, Y)`` skipped.

    A Krylov method can converge to ``k`` true eigenpairs that are not the ``k`` smallest: a
    multiplicity above the block size is only found through rounding.  Probe: ``b`` random
    directions, deflated against ``Y`` and sharpened by ``steps`` applications of ``T``, then
    Rayleigh–Ritz on ``[Y, probe]`` (``YKY = Yᵀ K Y`` is given: the caller has it from the
    Krylov relation).  By min–max, a Ritz value of that space below ``λ_k (1 − 10⁻⁴)``
    beyond those of ``Y`` proves an eigenvalue was missed (the margin covers the ``"fast"``
    tolerance); none found is evidence, not proof (as for ARPACK).
    """
    P = rng.standard_normal((Y.shape[0], b))
    for _ in range(steps):
        P -= Y @ (Y.T @ P)
        P = T(np.linalg.qr(P)[0])
    P -= Y @ (Y.T @ P)
    P -= Y @ (Y.T @ P)
    P = np.linalg.qr(P)[0]
    KP = _apply_K(W, d, P)
    # [Y, P] is orthonormal (Y: Ritz vectors of an orthonormal basis; P ⟂ Y twice), so the
    # projected pencil is standard; its blocks from the products already at hand
    YKP = Y.T @ KP
    H = np.block([[YKY, YKP], [YKP.T, P.T @ KP]])
    mu = scipy.linalg.eigh(0.5 * (H + H.T), eigvals_only=True)
    cut = lam[-1] * (1 - 1e-4)
    return max(0, int(np.sum(mu < cut)) - int(np.sum(lam < cut)))


def default_block(k: int) -> int:
    """Default block size ``b`` for ``k`` eigenpairs: the multiple of 4 nearest ``k / 24``,
    between 4 and 16 (4 for k ≤ 143, 8 for k = 200).

    Small blocks make the Krylov space of a given size reach higher polynomial degree (fewer
    solves in all; the space needed for k = 100 on the 111K-vertex cat: 332 vectors at
    b = 4, 408 at b = 8, 492 at b = 12), large ones need fewer block steps, each of which
    reads the basis for its reorthogonalization.  Since that pass reads the older columns
    once (twice only when their share exceeds `ORTH_LEVEL`), small blocks win on large
    meshes, where a solve costs most: k = 100 at 445K vertices, 29.3 s at b = 4 against 41.4 s
    at b = 8 (at 111K level: 6.9 s against 7.2 s); k = 200 at 111K, 13.3 s at b = 8 against
    14.7 s at b = 4.  Multiples of 4, because cholespy's CHOLMOD factor is simplicial and its
    solve sweeps the factor once per four right-hand sides (6 cost as much as 8).
    """
    return int(4 * np.clip(round(k / 96), 1, 4))


def has_cholmod() -> bool:
    """Whether the optional CHOLMOD backend (the ``cholespy`` package) can be imported."""
    try:
        import cholespy  # noqa: F401
    except ImportError:
        return False
    return True


def factorize(M: sp.spmatrix, backend: str = "auto"):
    """A solver ``X ↦ M⁻¹ X`` for a symmetric positive definite sparse ``M`` and a 1-D or 2-D
    ``X``, factorized once.

    Arguments:
        M: ``(n, n)`` sparse symmetric positive definite matrix.
        backend: ``"cholmod"`` (supernodal Cholesky from the optional ``cholespy`` package,
            fast for blocks of right-hand sides), ``"superlu"`` (scipy's ``splu`` with a
            minimum-degree ordering of ``Mᵀ + M`` and diagonal pivoting, one column at a time),
            or ``"auto"`` (CHOLMOD when installed).
    """
    if backend not in ("auto", "cholmod", "superlu"):
        raise BSFError(f"backend must be 'auto', 'cholmod' or 'superlu', got {backend!r}")
    if backend == "auto":
        backend = "cholmod" if has_cholmod() else "superlu"
    n = M.shape[0]
    if backend == "cholmod":
        try:
            import cholespy
        except ImportError:
            raise BSFError("backend='cholmod' needs the optional cholespy package "
                           "(pip install 'bsfjax[fast]')") from None
        Mc = sp.csr_matrix(M, dtype=np.float64)
        Mc.sort_indices()
        try:
            chol = cholespy.CholeskySolverD(n, Mc.indptr.astype(np.int32),
                                            Mc.indices.astype(np.int32),
                                            np.ascontiguousarray(Mc.data),
                                            cholespy.MatrixType.CSR)
        except (RuntimeError, ValueError) as exc:
            raise RuntimeError(f"Cholesky factorization failed ({exc})") from None

        def solve(X):
            X = np.ascontiguousarray(X, dtype=np.float64)
            out = np.empty_like(X)
            chol.solve(X, out)
            return out
        return solve
    lu = scipy.sparse.linalg.splu(sp.csc_matrix(M, dtype=np.float64),
                                  permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
    return lu.solve


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


def block_lanczos(W: sp.csr_matrix, a: np.ndarray, k: int, sigma: float, *,
                  tol: float = 1e-8, block: int | None = None, basis: int | None = None,
                  max_restarts: int = 12, backend: str = "auto", keep: int | None = None):
    """``(evals, evecs, info)``: the ``k`` smallest eigenpairs of ``W φ = λ A φ``, ascending,
    eigenvectors A-orthonormal.

    Arguments:
        W: ``(n, n)`` sparse symmetric positive semidefinite stiffness.
        a: ``(n,)`` positive diagonal of the mass matrix ``A``.
        k: number of eigenpairs, ``1 <= k``, with ``k + 2·block <= n``.
        sigma: shift below the smallest eigenvalue (``W − σA`` positive definite).
        tol: relative residual ``‖K ψ − λ ψ‖ / λ_k`` every pair must reach by the Krylov
            estimate; the residual recomputed from the float64 vectors must then be below
            ``max(tol, ACCEPT)``.
        block: block size ``b`` (right-hand sides per solve); default `default_block`.
        basis: basis size ``m`` at which a thick restart happens; default ``k + max(3k, 6b)``,
            capped at ``n − b``: room for the whole Krylov space that k = 50 … 200 needed
            on real meshes (3.8k … 2.7k vectors at b = 4), so that a restart (a product of the
            basis with the Ritz vectors, and the information it drops) is the exception.
            Only the columns written are touched in memory.
        max_restarts: restarts before giving up ([`BSFError`][bsfjax.BSFError], never a partial result).
        backend: linear solver, see `factorize`.
        keep: Ritz vectors kept at a restart; default ``k + 2(m − k)/5``.

    Convergence is checked every ``check_every`` blocks from the Krylov relation (one product
    of ``W`` with the unexpanded block), so the last cycle stops as soon as all ``k`` pairs
    are converged.  Raises `MissedEigenvalue` when the probe of
    `_missed_eigenvalues` finds a skipped eigenvalue.  ``info`` holds ``solves``
    (right-hand sides solved), ``restarts``, ``backend``, ``residual`` (the largest relative
    residual returned) and ``seconds`` (factor, solves, orthogonalization, Rayleigh–Ritz).
    """
    n = W.shape[0]
    b = int(block) if block is not None else default_block(k)
    if b < 1 or k + 2 * b > n:
        raise BSFError(f"block_lanczos needs k + 2*block <= n, got k={k}, block={b}, n={n}")
    m = int(basis) if basis is not None else k + max(3 * k, 6 * b)
    m = min(m, n - b)
    keep = min(int(keep) if keep else k + 2 * (m - k) // 5, m - b)  # kept at a restart
    if keep < k:
        raise BSFError(f"basis={m} is too small for k={k} and block={b} (need >= k + 2*block)")
    t_start = time.perf_counter()
    d = np.sqrt(a)
    M = (W - sigma * sp.diags(a)).tocsr()
    chosen = backend if backend != "auto" else ("cholmod" if has_cholmod() else "superlu")
    solve = factorize(M, chosen)
    rng = np.random.default_rng(0)  # fixed start block and breakdown directions: deterministic

    def T(X):  # rows contiguous for the solver, columns for the orthogonalization
        Y = solve(np.multiply(d[:, None], X, order="C")).reshape(X.shape)
        return np.multiply(d[:, None], Y, order="F")

    Q, Qmap = _mapped_empty(n, m + b)  # columns contiguous: blocks are written and read
    H = np.zeros((m + b, m + b))

    def put(j, X):
        Q[:, j:j + X.shape[1]] = X

    put(0, np.linalg.qr(rng.standard_normal((n, b)))[0])
    n_exp, n_cols, solves, restarts, lo, blocks = 0, b, 0, 0, 0, 0
    next_check, last = 0, None  # block count of the next check; (blocks, max estimate)
    timing = dict(factor=time.perf_counter() - t_start, solve=0.0, orth=0.0, rayleigh_ritz=0.0)

    def estimates(theta, S):
        # exact residuals of the Ritz pairs from the Krylov relation: T y − θ y = Q_new g with
        # g = H[new, :] s, and K y − λ y = −(K − σ) Q_new g / θ (one product with W)
        Qnew = Q[:, n_exp:n_cols]
        KQ = _apply_K(W, d, Qnew) - sigma * Qnew
        G = H[n_exp:n_cols, :n_exp] @ S[:, :k]
        r2 = np.einsum("ij,ij->j", G, (KQ.T @ KQ) @ G)
        return np.sqrt(np.maximum(r2, 0.0)) / np.abs(theta[:k]), KQ, G

    checked = -1  # basis size at the last convergence check
    while True:
        full = n_cols + (n_cols - n_exp) > m + b
        rotated = 0  # Ritz vectors written over Q[:, :rotated] by a failed confirmation
        if not full:  # expand the next unexpanded block
            X = Q[:, n_exp:n_cols]
            t0 = time.perf_counter()
            Z = T(X)
            t1 = time.perf_counter()
            solves += X.shape[1]
            C, Qn, R = _orthonormalize(Z, Q[:, :n_cols], lo, rng)
            timing["solve"] += t1 - t0
            timing["orth"] += time.perf_counter() - t1
            lo = n_exp
            H[:n_cols, n_exp:n_cols] = C
            H[n_exp:n_cols, :n_cols] = C.T
            blk = H[n_exp:n_cols, n_exp:n_cols]
            H[n_exp:n_cols, n_exp:n_cols] = 0.5 * (blk + blk.T)
            new = Qn.shape[1]
            put(n_cols, Qn)
            H[n_cols:n_cols + new, n_exp:n_cols] = R
            H[n_exp:n_cols, n_cols:n_cols + new] = R.T
            n_exp, n_cols = n_cols, n_cols + new
            blocks += 1
            if n_exp < k + b or blocks < next_check:
                continue
        if checked != n_exp:  # Rayleigh–Ritz and the convergence check
            t0 = time.perf_counter()
            checked = n_exp
            theta, S = scipy.linalg.eigh(H[:n_exp, :n_exp])
            theta, S = theta[::-1], S[:, ::-1]  # largest θ = smallest λ first
            lam = sigma + 1.0 / theta[:keep]
            scale_k = max(abs(lam[k - 1]), np.finfo(float).tiny)
            est, KQ, G = estimates(theta, S)
            est /= scale_k
            # next check: where the geometric decay of the largest residual since the last
            # check reaches tol (each check costs an eigh of H and a product with W)
            gap = 2
            if last is not None and 0 < est.max() < last[1] and blocks > last[0]:
                rate = (est.max() / last[1]) ** (1.0 / (blocks - last[0]))
                gap = int(np.clip(0.8 * np.log(tol / est.max()) / np.log(rate), 1, 8))
            next_check, last = blocks + gap, (blocks, float(est.max()))
            if np.all(est <= tol):  # confirm with the true residuals
                # the Ritz vectors in place, Q[:, :k] ← Q S[:, :k] (no n × k temporary:
                # fresh memory is slow to fault in); should the confirmation fail, this is
                # a thick restart that keeps k vectors
                _rotate_in_place(Q, n_exp, np.ascontiguousarray(S[:, :k]))
                rotated = k
                Y = Q[:, :k]
                res = _residual_norms(W, d, Y, lam[:k]) / scale_k
                if np.all(res <= max(tol, ACCEPT)):
                    timing["rayleigh_ritz"] += time.perf_counter() - t0
                    # Yᵀ K Y = Λ + Yᵀ R from the Krylov relation R = −(K − σ) Q_new G Θ⁻¹
                    # (one read of Y, b columns, instead of K applied to all of Y)
                    YKY = np.diag(lam[:k]) - (Y.T @ KQ) @ (G / theta[:k])
                    missed = _missed_eigenvalues(T, W, d, Y, YKY, lam[:k], b, rng)
                    if missed:
                        raise MissedEigenvalue(
                            f"block Lanczos missed {missed} eigenvalue(s) below λ_k = "
                            f"{lam[k - 1]:.6g} (a multiplicity above block={b}?)")
                    info = dict(solves=solves, restarts=restarts, backend=chosen,
                                residual=float(res.max()), seconds=timing)
                    # the eigenvectors φ = D⁻¹ y in place: the first k columns of the basis,
                    # whose other columns are released (no new n × k array to fault in)
                    np.divide(Y, d[:, None], out=Y)
                    _release_after(Qmap, Y.nbytes)
                    return lam[:k], Y, info
            timing["rayleigh_ritz"] += time.perf_counter() - t0
        if not (full or rotated):
            continue
        if restarts >= max_restarts:
            raise BSFError(f"block Lanczos did not converge for k={k} in {max_restarts} "
                           f"restarts (largest relative residual {est.max():.2e} > tol={tol:g})")
        # thick restart: the best Ritz vectors (`keep` of them, or the k already written
        # by a failed confirmation), then the unexpanded block
        t0 = time.perf_counter()
        nk = rotated or keep
        coupling = H[n_exp:n_cols, :n_exp] @ S[:, :nk]
        tail = Q[:, n_exp:n_cols].copy()  # (columns past nk: a rotation leaves them intact)
        nb = tail.shape[1]
        if not rotated:
            _rotate_in_place(Q, n_exp, np.ascontiguousarray(S[:, :nk]))
        H[:] = 0.0
        H[:nk, :nk] = np.diag(theta[:nk])
        put(nk, tail)
        H[nk:nk + nb, :nk] = coupling
        H[:nk, nk:nk + nb] = coupling.T
        n_exp, n_cols, lo = nk, nk + nb, 0
        checked = -1  # a new basis: no check of it yet (n_exp may repeat an earlier value)
        restarts += 1
        timing["rayleigh_ritz"] += time.perf_counter() - t0
