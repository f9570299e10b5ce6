"""Sparse factorizations for the shift-invert solves. Owner of `factorize` (CHOLMOD from the
optional ``cholespy`` package, or scipy's SuperLU in symmetric mode) and `has_cholmod`, which
says whether the CHOLMOD backend is installed.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg

from .._util import BSFError

__all__ = ["factorize", "has_cholmod"]


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

    **Arguments:**

    - `M`: ``(n, n)`` sparse symmetric positive definite matrix.
    - `backend`: ``"cholmod"`` (supernodal Cholesky from the optional ``cholespy`` package,
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
