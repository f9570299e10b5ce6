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
the time. What makes that pass cheap: the basis is column-major (a block is one
contiguous slice), each Gram–Schmidt update is one ``gemm`` accumulating in place, the norms
come from the block's Gram matrix, and the update against the older columns, whose share is
rounding-sized, is applied only when it exceeds `ORTH_LEVEL` (one read of the basis
instead of two for a third to a half of the blocks). With that pass cheaper, the small block
(b = 4 for k = 100) and a basis with room for the whole Krylov space (no restart) win.  Fresh
memory is slow to fault in on the benchmark machine, so the basis lives in its own
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

This module owns the solver (`block_lanczos`, its default block size and the probe for missed
eigenvalues); its dense basis kernels live in `bsfjax._spectral._block_basis`, the
factorizations in `bsfjax._spectral._factorize`.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from .._util import BSFError
from ._block_basis import (
    _apply_K, _mapped_empty, _orthonormalize, _release_after, _residual_norms,
    _rotate_in_place,
)
from ._factorize import factorize, has_cholmod

__all__ = ["MissedEigenvalue", "block_lanczos", "default_block"]


#: The true relative residual every returned pair must reach when ``tol`` is below it.  The
#: Krylov estimate (exact arithmetic) must reach ``tol``; what is computed from the float64
#: Ritz vectors has a rounding floor of ~1e-9 (errors of the solves, amplified by the spread of
#: ``θ``), so a ``tol`` under that floor would otherwise never be confirmed.
ACCEPT = 1e-6

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


def block_lanczos(W: sp.csr_matrix, a: np.ndarray, k: int, sigma: float, *,
                  tol: float = 1e-8, block: int | None = None, basis: int | None = None,
                  max_restarts: int = 12, backend: str = "auto", keep: int | None = None):
    """``(evals, evecs, info)``: the ``k`` smallest eigenpairs of ``W φ = λ A φ``, ascending,
    eigenvectors A-orthonormal.

    **Arguments:**

    - `W`: ``(n, n)`` sparse symmetric positive semidefinite stiffness.
    - `a`: ``(n,)`` positive diagonal of the mass matrix ``A``.
    - `k`: number of eigenpairs, ``1 <= k``, with ``k + 2·block <= n``.
    - `sigma`: shift below the smallest eigenvalue (``W − σA`` positive definite).
    - `tol`: relative residual ``‖K ψ − λ ψ‖ / λ_k`` every pair must reach by the Krylov
      estimate; the residual recomputed from the float64 vectors must then be below
      ``max(tol, ACCEPT)``.
    - `block`: block size ``b`` (right-hand sides per solve); default `default_block`.
    - `basis`: basis size ``m`` at which a thick restart happens; default ``k + max(3k, 6b)``,
      capped at ``n − b``: room for the whole Krylov space that k = 50 … 200 needed
      on real meshes (3.8k … 2.7k vectors at b = 4), so that a restart (a product of the
      basis with the Ritz vectors, and the information it drops) is the exception.
      Only the columns written are touched in memory.
    - `max_restarts`: restarts before giving up ([`BSFError`][bsfjax.BSFError], never a partial result).
    - `backend`: linear solver, see `factorize`.
    - `keep`: Ritz vectors kept at a restart; default ``k + 2(m − k)/5``.

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
