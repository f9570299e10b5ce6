"""Laplace–Beltrami spectrum: the smallest ``k`` eigenpairs of ``W φ = λ A φ``.

Eigensolves run on the numpy/scipy side in float64 (shift-invert block Lanczos with a CHOLMOD
factor when the optional ``cholespy`` package is installed, ARPACK shift-invert Lanczos
otherwise; see `bsfjax._spectral._eigensolver`); the result is a
[`Spectrum`][bsfjax.Spectrum], a JAX pytree that every later stage takes as input.  Its arrays stay float64
numpy until they enter a jitted function, where JAX converts them to its default float dtype
(float32, or float64 under ``jax_enable_x64``).

This module owns computing spectra (`spectrum_from_operators`, `spectrum` with its cache,
`interval_spectrum`) and the choice of solver; the [`Spectrum`][bsfjax.Spectrum] type and its
rescaling live in `bsfjax._spectral._spectrum_type`.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from pathlib import Path

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg

from .._util import atomic_path
from ._eigensolver import block_lanczos, default_block
from ._factorize import has_cholmod
from .._util import BSFError, MeshError
from ._laplacian import MASS_TYPES, laplacian
from .._mesh import Mesh, n_components
from ._spectrum_type import Spectrum
from .._util import eigensolve_on_one_thread, one_blas_thread
from .._mesh import as_mesh

__all__ = ["spectrum", "spectrum_from_operators", "interval_operators", "interval_spectrum"]

#: Below this many vertices the generalized eigenproblem is solved densely (LAPACK).
DENSE_LIMIT = 600
_CACHE_VERSION = 2
#: ``method`` values of [`spectrum`][bsfjax.spectrum] / [`spectrum_from_operators`][bsfjax.spectrum_from_operators].
METHODS = ("auto", "block", "lanczos", "dense", "fast")
#: Relative residual ``‖Kψ − λψ‖ / λ_k`` of ``method="fast"`` (see [`spectrum_from_operators`][bsfjax.spectrum_from_operators]).
FAST_TOL = 1e-3


def _signs(evecs: np.ndarray) -> np.ndarray:
    """The sign of each column's entry of largest magnitude (the first one on a tie; +1 for
    a zero column): the sign convention that makes an eigenbasis reproducible.  From the
    columns' largest and smallest entries, so no ``n × k`` temporary is made."""
    cols = np.arange(evecs.shape[1])
    i_max, i_min = np.argmax(evecs, axis=0), np.argmin(evecs, axis=0)
    hi, lo = evecs[i_max, cols], -evecs[i_min, cols]
    signs = np.where((hi > lo) | ((hi == lo) & (i_max < i_min)), 1.0, -1.0)
    signs[(hi == 0) & (lo == 0)] = 1.0
    return signs


def _shift_invert(W: sp.csr_matrix, Am: sp.csr_matrix, sigma: float):
    """``(W − σA)⁻¹`` as a LinearOperator, factorized once for the whole Lanczos run.

    scipy's default (``splu`` with COLAMD ordering) treats the matrix as unsymmetric; ``W − σA``
    is symmetric positive definite for σ < 0, so a minimum-degree ordering of ``Aᵀ + A`` with
    diagonal pivoting (SuperLU's symmetric mode) is stable and has far less fill: 28 % fewer
    factor entries on a 40K-vertex mesh, each of the ~300 solves of a k = 100 run about 1.7×
    faster (``benchmarks/bench_spectrum.py``).
    """
    lu = scipy.sparse.linalg.splu((W - sigma * Am).tocsc(), permc_spec="MMD_AT_PLUS_A",
                                  options={"SymmetricMode": True})
    n = W.shape[0]
    return scipy.sparse.linalg.LinearOperator((n, n), matvec=lu.solve, dtype=np.float64)


def _eigensolve(W, a, Am, k: int, sigma, method: str, chosen: bool):
    """The solver's ``(evals, evecs)`` (``method`` resolved; ``chosen``: the user named it)."""
    n = W.shape[0]
    if method == "dense":
        evals, evecs = scipy.linalg.eigh(W.toarray(), np.diag(a), subset_by_index=[0, k - 1])
    else:
        if sigma is None:
            scale = float(W.diagonal().mean() / a.mean())  # ~ largest eigenvalues' scale
            sigma = -1e-6 * scale
        try:
            evals = None
            # the block solver needs σ below the spectrum (W − σA positive definite): W is
            # positive semidefinite, so any σ < 0 is; a user's σ >= 0 goes to ARPACK
            if method in ("block", "fast") and sigma < 0:
                try:
                    evals, evecs, _ = block_lanczos(W, a, k, sigma,
                                                    tol=FAST_TOL if method == "fast" else 1e-8)
                except (BSFError, RuntimeError) as exc:  # a missed multiplicity, no
                    # convergence, or W − σA not positive definite (σ above λ₁): ARPACK
                    if chosen:
                        warnings.warn(f"{exc}; falling back to method='lanczos'", stacklevel=3)
            if evals is None:
                v0 = np.random.default_rng(0).standard_normal(n)  # fixed start: deterministic
                evals, evecs = scipy.sparse.linalg.eigsh(W.tocsc(), k=k, M=Am.tocsc(),
                                                         sigma=sigma, which="LM", v0=v0,
                                                         OPinv=_shift_invert(W, Am, sigma))
        except scipy.sparse.linalg.ArpackNoConvergence as exc:  # (a RuntimeError too)
            raise BSFError(f"eigensolver did not converge for k={k} ({exc})") from None
        except RuntimeError as exc:  # W − σA singular: σ is an eigenvalue
            raise BSFError(f"eigensolver failed with sigma={sigma!r} ({exc}); W - sigma*A must "
                           "be non-singular, choose another shift") from None
    return evals, evecs


def spectrum_from_operators(W, A, k: int, *, sigma: float | None = None,
                            method: str = "auto") -> Spectrum:
    """Smallest ``k`` eigenpairs of ``W φ = λ A φ`` for any domain (mesh, curve, point cloud).

    **Arguments:**

    - `W`: ``(n, n)`` symmetric positive semidefinite stiffness (sparse or dense).
    - `A`: ``(n, n)`` diagonal positive mass matrix (sparse or dense), or its diagonal ``(n,)``.
    - `k`: number of eigenpairs, ``1 <= k <= n``.
    - `sigma`: shift for shift-invert.  Default ``−10⁻⁶ · mean(W_ii) / mean(A_ii)``: a
      small negative number, relative to the operator's own scale (so it is invariant to
      the units of the mesh), that makes ``W − σA`` positive definite while keeping the
      smallest eigenvalues nearest to the shift, so they converge first.
    - `method`: the eigensolver.

        * ``"auto"`` (default): ``"dense"`` when ``n <= DENSE_LIMIT``, else ``"block"``
          when the optional CHOLMOD backend (``pip install 'bsfjax[fast]'``, the
          ``cholespy`` package) is installed and ``n ≥ BLOCK_MIN_VERTICES`` (20K) or
          ``k ≥ BLOCK_MIN_K`` (45), else ``"lanczos"``; where the block solver fails (a
          multiplicity above its block size) ``"auto"`` goes on with ``"lanczos"``
          silently.
        * ``"block"``: block Lanczos on ``(W − σA)⁻¹`` (`._eigensolver`),
          exact: every pair reaches ``‖Kψ − λψ‖ ≤ 10⁻⁸ λ_k`` by the Krylov estimate and
          ``≤ 10⁻⁶ λ_k`` recomputed (``K = A^-½ W A^-½``, ``ψ = A^½ φ``); on the TOSCA cat
          (111K / 445K vertices, k = 100) eigenvalues agree with ARPACK's to 4e-13 / 8e-13
          relative and the eigenspaces to a principal-angle sine of 1.4e-6, at 3.0–3.1× /
          3.2× ARPACK's speed with CHOLMOD (``docs/benchmarks.md``).  Without
          CHOLMOD it uses scipy's SuperLU, which solves one column at a time: slower than
          ``"lanczos"``.
          Shapes with exact eigenvalue multiplicities above the block size (spheres,
          symmetric toy meshes) may make it miss or not converge; ``spectrum`` then warns
          and falls back to ``"lanczos"`` (a probe checks for missed eigenvalues).
        * ``"lanczos"``: ARPACK shift-invert Lanczos (``scipy.sparse.linalg.eigsh``) with a
          SuperLU factor — the solver of earlier versions.
        * ``"dense"``: LAPACK on dense matrices (``O(n³)``: small ``n`` only).
        * ``"fast"``: the block solver stopped at ``‖Kψ − λψ‖ ≤ 10⁻³ λ_k`` (``FAST_TOL``),
          for users who want speed over exactness.  Error bounds: eigenvalue error
          ``≤ ‖r‖`` (Bauer–Fike), in practice ``≈ ‖r‖² / gap``; eigenvector angle
          ``≤ ‖r‖ / gap`` to the eigenspace.  Measured on the TOSCA cat (k = 100): the
          largest recomputed residual was 8.6e-4 (111K) / 5.3e-4 (445K) λ_k, eigenvalues
          within 3.5e-13 / 7.0e-13 relative of ARPACK's, eigenspaces of the first
          25/50/100 vectors within a principal-angle sine of 1.2e-6 (the residual lies in
          high frequencies, far from the wanted eigenvalues), and the BSF transfer error of
          ``bench_large.py`` unchanged (``docs/benchmarks.md``); it is only
          1.0–1.2× faster than ``"block"`` there, because the block method converges
          abruptly.

    Uses a fixed start (deterministic).  Eigenvectors are A-orthonormalized and sign-fixed.
    Non-convergence raises [`BSFError`][bsfjax.BSFError] (never a partial result).
    """
    if not isinstance(method, str) or method not in METHODS:
        raise BSFError(f"method must be one of {METHODS}, got {method!r}")
    try:
        W = sp.csr_matrix(W, dtype=np.float64) if not sp.issparse(W) \
            else W.tocsr().astype(np.float64)
        a = np.asarray(A.diagonal() if sp.issparse(A) else (np.diag(A) if np.ndim(A) == 2 else A),
                       dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise BSFError(f"W and A must be real numeric matrices ({exc})") from None
    n = W.shape[0]
    if W.ndim != 2 or W.shape != (n, n) or n == 0:
        raise BSFError(f"W must be a non-empty square matrix, got shape {W.shape}")
    if a.shape != (n,):
        raise BSFError(f"A must be ({n}, {n}) or its diagonal ({n},), got shape {np.shape(A)}")
    if not np.all(np.isfinite(a)) or not np.all(np.isfinite(W.data)):
        raise BSFError("W and A must be finite (found NaN or inf)")
    if np.any(a <= 0):
        raise BSFError(f"A must have a positive diagonal; {int(np.sum(a <= 0))} entries are <= 0")
    asym = abs(W - W.T).max() if W.nnz else 0.0
    if asym > 1e-10 * max(abs(W).max(), np.finfo(float).tiny):
        raise BSFError(f"W must be symmetric, found |W - W^T| up to {asym:.3g}")
    if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or not 1 <= k <= n:
        raise BSFError(f"k must be an integer in [1, n={n}], got {k!r}")
    if sigma is not None and (isinstance(sigma, (bool, np.bool_))
                              or not isinstance(sigma, (int, float, np.integer, np.floating))
                              or not np.isfinite(sigma)):
        raise BSFError(f"sigma must be a finite number or None, got {sigma!r}")
    Am = sp.diags(a).tocsr()
    chosen = method != "auto"  # a fallback from a solver the user named is worth a warning
    method = _resolve_method(method, n, k)
    with one_blas_thread(eigensolve_on_one_thread(n)):  # (_threads: spinning BLAS threads)
        evals, evecs = _eigensolve(W, a, Am, k, sigma, method, chosen)
    # the eigenvectors are the solvers' own fresh arrays: sorted, normalized and signed in
    # place (at 445K vertices each n × k copy is 357 MB of fresh memory, ~0.5 s to fault in)
    norms = np.sqrt(np.einsum("ij,i,ij->j", evecs, a, evecs))  # NaN / inf propagate here
    if not (np.isfinite(evals).all() and np.isfinite(norms).all() and (norms > 0).all()):
        raise BSFError("the eigensolver returned NaN or inf (ill-conditioned W or A)")
    order = np.argsort(evals, kind="stable")
    if np.any(order != np.arange(len(order))):
        evals, evecs, norms = evals[order], evecs[:, order], norms[order]
    evecs /= norms  # (then the sign: the same arithmetic as a copy would do, to the bit)
    evecs *= _signs(evecs)
    evals = np.maximum(evals, 0.0)
    return Spectrum(evals=evals, evecs=evecs, mass=a)


#: ``method="auto"`` takes the block solver from this many vertices on.  Measured
#: (block solver against ARPACK, best of two, 2 cores): k = 100, 6.9K vertices 0.37 s against
#: 0.46 s, 10K 0.53 s against 0.71 s, 27.9K 1.45 s against 3.19 s; k = 30, 6.9K 0.15 s against
#: 0.11 s, 10K 0.21 s against 0.19 s, 27.9K 0.59 s against 0.63 s.  From 20K it is as fast at
#: small k and much faster at large k; below, it wins at large k only (`BLOCK_MIN_K`).
BLOCK_MIN_VERTICES = 20_000

#: ... and for any size from this many eigenpairs on.  Measured (median of 4, 2
#: cores; ARPACK / block): k = 100, 2.0K vertices 0.18 / 0.11 s, 3.4K 0.25 / 0.25, 4.1K 0.28 /
#: 0.25, 5.0K 0.36 / 0.23, 5.5K 0.36 / 0.26, 6.9K 0.45 / 0.32; k = 60, 2.0K 0.12 / 0.08, 3.4K
#: 0.19 / 0.14, 5.0K 0.22 / 0.15, 5.5K 0.22 / 0.22, 6.9K 0.28 / 0.24; k = 45, 4.1K 0.14 / 0.11,
#: 5.0K 0.18 / 0.12, 6.9K 0.22 / 0.17; k = 30 mixed (4.1K 0.085 / 0.103, 5.0K 0.13 / 0.10).  The
#: eigenvectors equal ARPACK's to 1 − |cos| ≤ 4e-15 and the eigenvalues to 1.3e-14 λ_k (k =
#: 100, 4.1K–6.9K meshes; the 54 accuracies of ``bench_segmentation.py --quick-maps``, which
#: use ``refined``'s 100 eigenpairs, are equal to the last digit).
BLOCK_MIN_K = 45


def _resolve_method(method: str, n: int, k: int) -> str:
    """The solver ``method="auto"`` (or an explicit one) runs for ``n`` vertices and ``k``."""
    if n <= DENSE_LIMIT or k >= n - 1:
        return "dense"  # small problems: LAPACK (and ARPACK needs k < n - 1)
    if method == "auto":
        big = n >= BLOCK_MIN_VERTICES or k >= BLOCK_MIN_K
        return "block" if big and has_cholmod() else "lanczos"
    if method in ("block", "fast") and k + 2 * default_block(k) > n:
        return "lanczos"  # the block basis would not fit: ARPACK needs fewer vectors
    return method


def _cache_key(mesh: Mesh, k: int, mass: str, robust: bool, method: str = "lanczos") -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    h.update(repr((_CACHE_VERSION, int(k), mass, bool(robust), method)).encode())
    return h.hexdigest()


def _checksum(evals, evecs, mass) -> str:
    h = hashlib.sha256()
    for arr in (evals, evecs, mass):
        h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    return h.hexdigest()


def _load_cached(path: Path, n: int, k: int) -> Spectrum | None:
    """A cached spectrum if the file is intact, else ``None`` (with a warning if corrupt)."""
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            evals, evecs, mass = z["evals"], z["evecs"], z["mass"]
            stored = str(z["checksum"])
        ok = (evals.shape == (k,) and evecs.shape == (n, k) and mass.shape == (n,)
              and stored == _checksum(evals, evecs, mass))
    except Exception:
        ok = False
    if not ok:
        warnings.warn(f"spectrum cache file {path} is corrupt; recomputing", stacklevel=3)
        return None
    return Spectrum(evals=evals, evecs=evecs, mass=mass)


def spectrum(mesh: Mesh, k: int, *, mass: str = "mixed", robust: bool = False,
             cache_dir: str | os.PathLike | None = None, method: str = "auto") -> Spectrum:
    """The first ``k`` Laplace–Beltrami eigenpairs of ``mesh``.

    Solves ``W φ = λ A φ`` with the cotangent stiffness and lumped mass of [`laplacian`][bsfjax.laplacian]
    (shift-invert block Lanczos or ARPACK Lanczos; dense LAPACK for tiny meshes; ``method`` as
    in [`spectrum_from_operators`][bsfjax.spectrum_from_operators], ``"fast"`` for an approximation).  With ``cache_dir``
    the result is stored in ``cache_dir/<sha256 of vertices, faces, k, options>.npz`` (the
    options include the solver that ran), written atomically and
    checksummed; a corrupt cache file is recomputed, never trusted, and a cache that cannot be
    written (read-only folder, full disk) only gives a warning.

    A mesh with ``c`` connected components has ``c`` zero eigenvalues; a warning says so.
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    if not isinstance(mesh, Mesh):
        raise MeshError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    n = mesh.n_vertices
    if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or not 1 <= k <= n:
        where = f" (mesh {mesh.name})" if mesh.name else ""
        raise BSFError(f"k must be an integer in [1, n_vertices={n}], got {k!r}{where}")
    if mass not in MASS_TYPES:
        raise BSFError(f"mass must be one of {MASS_TYPES}, got {mass!r}")
    if not isinstance(method, str) or method not in METHODS:
        raise BSFError(f"method must be one of {METHODS}, got {method!r}")
    path = None
    if cache_dir is not None:
        if not isinstance(cache_dir, (str, os.PathLike)) or Path(cache_dir).is_file():
            raise BSFError(f"cache_dir must be a folder path, got {cache_dir!r}")
        solver = _resolve_method(method, n, k)
        path = Path(cache_dir) / f"{_cache_key(mesh, k, mass, robust, solver)}.npz"
        cached = _load_cached(path, n, k)
        if cached is not None:
            return cached
    comps = n_components(mesh)  # of a point cloud: of its k-nearest-neighbour graph
    if comps > 1:
        where = f"{mesh.name}: " if mesh.name else ""
        warnings.warn(f"{where}mesh has {comps} connected components, so its first {comps} "
                      "eigenvalues are 0 (one constant eigenvector per component)", stacklevel=2)
    W, A = laplacian(mesh, mass=mass, robust=robust)
    result = spectrum_from_operators(W, A, k, method=method)
    if path is not None:
        try:
            with atomic_path(path, immediate=True) as tmp, open(tmp, "wb") as fh:
                np.savez(fh, evals=result.evals, evecs=result.evecs, mass=result.mass,
                         checksum=np.array(_checksum(result.evals, result.evecs, result.mass)))
        except (OSError, BSFError) as exc:  # a full disk or read-only cache must not lose the result
            warnings.warn(f"could not write spectrum cache file {path} ({exc}); continuing "
                          "without caching it", stacklevel=2)
    return result


def interval_operators(n: int, length: float = 1.0) -> tuple[sp.csr_matrix, np.ndarray]:
    """Linear finite elements on ``[0, length]`` with ``n`` equispaced nodes (Neumann ends).

    Stiffness ``W = (1/h)·tridiag(−1, 2, −1)`` with 1 on the two end diagonals; lumped mass ``h``
    inside and ``h/2`` at the ends.
    """
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 2:
        raise BSFError(f"n must be an integer >= 2, got {n!r}")
    if isinstance(length, (bool, np.bool_)) \
            or not isinstance(length, (int, float, np.integer, np.floating)) \
            or not np.isfinite(length) or length <= 0:
        raise BSFError(f"length must be positive and finite, got {length!r}")
    h = length / (n - 1)
    main = np.full(n, 2.0 / h)
    main[[0, -1]] = 1.0 / h
    off = np.full(n - 1, -1.0 / h)
    W = sp.diags([off, main, off], [-1, 0, 1]).tocsr()
    a = np.full(n, h)
    a[[0, -1]] = h / 2
    return W, a


def interval_spectrum(n: int, k: int, length: float = 1.0) -> Spectrum:
    """Neumann Laplacian spectrum of the interval ``[0, length]`` sampled at ``n`` nodes.

    The 1D domain of the paper's Fig. 1 and Fig. 5.  Eigenvalues converge to ``(π l / L)²``,
    ``l = 0, 1, …``; eigenvectors to ``√(2/L) cos(π l x / L)`` (and ``1/√L`` for ``l = 0``).
    Node ``i`` sits at ``x = i · length / (n − 1)``.
    """
    W, a = interval_operators(n, length)
    return spectrum_from_operators(W, a, k)
