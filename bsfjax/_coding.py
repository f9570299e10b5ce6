r"""Sparse coding of functions in a Binary Sparse Frame (paper Sec. 5, Eqs. 6, 8, 9).

A frame is a binary matrix ``B`` of shape ``(n, q)`` (one atom per column).  Coding a function
``f`` (``(n,)``, or a batch ``(..., n)``) means finding coefficients ``α`` (``(..., q)``) with
``f ≈ α Bᵀ``; :func:`decode` maps them back.  Methods of :func:`encode`:

``"lstsq"``
    minimum-norm least squares ``α = B⁺ f`` (paper Eq. 6).
``"omp"``
    sparsity-constrained orthogonal matching pursuit, ``min ‖f − Bα‖ s.t. ‖α‖₀ ≤ S``
    (paper Eq. 9).
``"omp_error"``
    error-constrained OMP, ``min ‖α‖₀ s.t. ‖f − Bα‖² ≤ ε`` (paper Eq. 8), atom count capped.
``"lasso"``
    ``min ½‖f − Bα‖² + λ‖α‖₁`` by accelerated proximal gradient (``jaxopt``).

Every method works on the Gram matrix ``G = BᵀB`` (``q × q``) and the correlations ``Bᵀf``,
so the ``n × q`` frame is touched only by a few matrix products per batch, never inside an
iteration.  With ``weights`` the codes minimise a weighted error ``‖f − Bα‖²_W = Σᵢ wᵢ (f −
Bα)ᵢ²``, e.g. the area-weighted error ``‖·‖²_A`` of the paper's metrics (``weights="area"``):
this is plain coding after scaling the rows of ``B`` and ``f`` by ``√wᵢ``.

Everything after input validation is one jitted function with static shapes: a batch of ``m``
functions is coded together, and :func:`encode` also works under :func:`jax.vmap` (over
functions, or over a stack of frames of equal shape) and :func:`jax.jit` (value checks that
need concrete data are skipped for traced inputs; shape checks still run).
"""

from __future__ import annotations

import dataclasses
import math
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import warnings

with warnings.catch_warnings():  # jaxopt warns on import that it is unmaintained; it works
    warnings.filterwarnings("ignore", message="JAXopt is no longer maintained")
    from jaxopt import ProximalGradient
    from jaxopt.prox import prox_lasso

from ._devices import map_over_devices, n_devices
from ._memory import release_free_memory
from ._validate import check_finite, magnitude_limit
from ._errors import BSFError
from ._frame import DENSE_BUDGET_BYTES, Frame
from ._sparse_frame import (SparseFrame, atom_sums, atom_vertices, ell_gram_rows, ell_matmul,
                           ell_rmatmul)

__all__ = ["CodingInfo", "encode", "decode", "METHODS"]

METHODS = ("lstsq", "omp", "omp_error", "lasso")

#: Options of each method and their defaults (see :func:`encode`).
_DEFAULTS: dict[str, dict[str, Any]] = {
    "lstsq": {"rcond": None},
    "omp": {"sparsity": 10, "precompute": "auto"},
    "omp_error": {"eps": None, "max_atoms": 64, "precompute": "auto"},
    "lasso": {"lam": 0.01, "init": None, "maxiter": 10000, "tol": 1e-4, "target_atoms": None},
}

#: Fraction of ‖f‖ the default error bound of ``"omp_error"`` allows (paper: ε = ‖f‖/10).
EPS_FRACTION = 0.1


class CodingInfo(NamedTuple):
    """Per-function diagnostics of :func:`encode` (``return_info=True``); a pytree.

    Attributes:
        n_atoms: ``(...,)`` int32 number of nonzero coefficients (atoms used).
        residual: ``(...,)`` residual norm ``‖f − Bα‖`` (weighted norm ``‖·‖_W`` with
            ``weights``).
        converged: ``(...,)`` bool.  ``"omp"``: ``S`` atoms were selected, or the residual
            became orthogonal to every atom (nothing left to fit); false when OMP stopped
            early because the next atom was linearly dependent on the selected ones.
            ``"omp_error"``: the bound ``‖f − Bα‖² ≤ ε`` was met.  ``"lasso"``: the last
            FISTA step met ``tol`` within ``maxiter`` iterations.  ``"lstsq"``: always true.
    """

    n_atoms: jax.Array
    residual: jax.Array
    converged: jax.Array


# ----------------------------------------------------------------------------------------------
# Validation (plain Python, before tracing)
# ----------------------------------------------------------------------------------------------


def _is_traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _all_finite(x) -> bool:
    return bool(np.all(np.isfinite(np.asarray(x))))


def _unpack_frame(frame):
    """``(atoms, mass)`` from a :class:`Frame` (mass may be used for ``weights="area"``) or a
    plain ``(n, q)`` array (mass ``None``)."""
    if isinstance(frame, Frame):
        atoms, mass = frame.atoms, frame.mass
    elif hasattr(frame, "shape") or isinstance(frame, (list, tuple)):
        atoms, mass = frame, None
        if not _is_traced(atoms):
            atoms = np.asarray(atoms) if not isinstance(atoms, jax.Array) else atoms
            if not np.issubdtype(atoms.dtype, np.number) and atoms.dtype != np.bool_:
                raise BSFError(f"frame must be a bsfjax.Frame or a numeric (n, q) array, got "
                               f"dtype {atoms.dtype}")
            if not _all_finite(atoms):
                raise BSFError("frame (atoms) contains NaN or infinite values")
    else:
        raise BSFError(f"frame must be a bsfjax.Frame or an (n, q) array, got "
                       f"{type(frame).__name__}")
    if atoms.ndim != 2:
        raise BSFError(f"frame atoms must have shape (n, q), got {tuple(atoms.shape)}; for a "
                       "stack of frames use jax.vmap over encode")
    return atoms, mass


def _float_dtype(*arrays):
    """The working float dtype: the promoted input dtype, at least floating, canonicalized
    (float32 by default, float64 with ``jax_enable_x64``)."""
    dts = [np.dtype(a.dtype) for a in arrays if a is not None]
    dt = np.result_type(*[d if np.issubdtype(d, np.floating) else np.float32 for d in dts])
    return jax.dtypes.canonicalize_dtype(dt)


def _check_int(name, value, lo, hi, hi_label=None):
    bounds = f"[{lo}, {hi_label or hi}]"
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise BSFError(f"{name} must be an integer in {bounds}, got {value!r}")
    if not lo <= value <= hi:
        raise BSFError(f"{name} must be in {bounds}, got {value}")
    return int(value)


def _check_positive(name, value, allow_zero=False):
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    if not ok or not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        rel = ">= 0" if allow_zero else "> 0"
        raise BSFError(f"{name} must be a finite number {rel}, got {value!r}")
    return float(value)


def _check_options(method, options, q, lead_shape):
    """Split validated options into static (hashable) and dynamic (array) parts."""
    if not isinstance(method, str) or method not in _DEFAULTS:
        raise BSFError(f"method must be one of {METHODS}, got {method!r}")
    defaults = _DEFAULTS[method]
    unknown = sorted(set(options) - set(defaults))
    if unknown:
        raise BSFError(f"unknown option(s) {unknown} for method={method!r}; valid options: "
                       f"{sorted(defaults)} (plus weights, return_info)")
    opts = {**defaults, **options}
    for name in ("sparsity", "max_atoms"):  # defaults (not explicit values) adapt to tiny frames
        if name in defaults and name not in options:
            opts[name] = min(defaults[name], q)
    static: dict[str, Any] = {}
    dynamic: dict[str, Any] = {}
    if method == "lstsq":
        rcond = opts["rcond"]
        if rcond is not None:
            rcond = _check_positive("rcond", rcond, allow_zero=True)
            if rcond >= 1:
                raise BSFError(f"rcond must be in [0, 1), got {rcond}")
        dynamic["rcond"] = rcond
    if method in ("omp", "omp_error"):
        if opts["precompute"] not in ("auto", True, False):
            raise BSFError(f"precompute must be 'auto', True or False, got "
                           f"{opts['precompute']!r}")
        static["precompute"] = opts["precompute"]
    if method == "omp":
        static["n_steps"] = _check_int("sparsity", opts["sparsity"], 1, q, f"q={q}")
    if method == "omp_error":
        static["n_steps"] = _check_int("max_atoms", opts["max_atoms"], 1, q, f"q={q}")
        eps = opts["eps"]
        if eps is None or (isinstance(eps, str) and eps == "spams"):
            static["eps_mode"] = "relative" if eps is None else "spams"
        elif isinstance(eps, str):
            raise BSFError(f"eps must be None, 'spams', a number >= 0 or an array of shape "
                           f"{lead_shape}, got {eps!r}")
        else:
            if not _is_traced(eps):
                arr = np.asarray(eps)
                if not np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_:
                    raise BSFError(f"eps must be numeric, got {eps!r}")
                if not _all_finite(arr) or np.any(arr < 0):
                    bad = int(np.sum(~np.isfinite(arr) | (arr < 0)))
                    got = repr(eps) if arr.ndim == 0 else f"an array with {bad} such entries"
                    raise BSFError(f"eps must be finite and >= 0, got {got}")
            try:
                np.broadcast_shapes(np.shape(eps), lead_shape)
            except ValueError:
                raise BSFError(f"eps of shape {np.shape(eps)} does not broadcast to the "
                               f"functions' batch shape {lead_shape}") from None
            static["eps_mode"] = "absolute"
            dynamic["eps"] = eps
    if method == "lasso":
        dynamic["lam"] = _check_positive("lam", opts["lam"])
        target = opts["target_atoms"]
        if target is not None:
            target = _check_int("target_atoms", target, 1, q, f"q={q}")
            if "lam" in options:
                raise BSFError("give lam or target_atoms, not both (target_atoms chooses λ)")
            if opts["init"] is not None:
                raise BSFError("init cannot be combined with target_atoms (the bisection "
                               "starts from α = 0)")
        static["target_atoms"] = target
        static["maxiter"] = _check_int("maxiter", opts["maxiter"], 1, 10**9)
        static["tol"] = _check_positive("tol", opts["tol"])
        init = opts["init"]
        if init is not None:
            if tuple(np.shape(init)) != tuple(lead_shape) + (q,):
                raise BSFError(f"init must have shape {tuple(lead_shape) + (q,)}, got "
                               f"{tuple(np.shape(init))}")
            if not _is_traced(init) and not _all_finite(init):
                raise BSFError("init contains NaN or infinite values")
        dynamic["init"] = init
    return static, dynamic


def _check_weights(weights, mass, n):
    if weights is None:
        return None
    if isinstance(weights, str):
        if weights != "area":
            raise BSFError(f"weights must be None, 'area' or an array of shape ({n},), got "
                           f"{weights!r}")
        if mass is None:
            raise BSFError("weights='area' needs a bsfjax.Frame (it holds the vertex areas); "
                           "got a plain atom array — pass weights=mass explicitly")
        weights = mass
    if tuple(np.shape(weights)) != (n,):
        raise BSFError(f"weights must have shape ({n},), got {tuple(np.shape(weights))}")
    if not _is_traced(weights):
        w = np.asarray(weights)
        if not _all_finite(w) or np.any(w < 0) or not np.any(w > 0):
            raise BSFError("weights must be finite, >= 0 and not all zero")
    return weights


def _check_functions(f, n, name="f"):
    if not hasattr(f, "shape"):
        f = np.asarray(f)
    if f.ndim < 1:
        raise BSFError(f"{name} must have shape (..., n) with n = {n}, got a scalar")
    if f.shape[-1] != n:
        raise BSFError(f"{name} has length {f.shape[-1]} along its last axis, but the frame has "
                       f"n = {n} vertices (expected shape (..., {n}))")
    if not _is_traced(f):
        if not (np.issubdtype(f.dtype, np.number) or f.dtype == np.bool_):
            raise BSFError(f"{name} must be numeric, got dtype {f.dtype}")
        if not _all_finite(f):
            bad = int(np.sum(~np.isfinite(np.asarray(f))))
            raise BSFError(f"{name} contains {bad} NaN or infinite values")
    return f


def _check_magnitude(f, w, n, dtype):
    """Reject functions so large that ``Σ w f²`` or ``(Bᵀf)²`` overflow ``dtype`` (NaN codes)."""
    if _is_traced(f) or (w is not None and _is_traced(w)):
        return
    arr = np.asarray(f)
    if arr.size == 0:
        return
    big = float(np.max(np.abs(arr)))
    if w is not None:
        big *= math.sqrt(float(np.max(np.asarray(w))))
    limit = magnitude_limit(n, dtype)
    if big > limit:
        raise BSFError(f"f has values up to {big:.3g} (times sqrt(weight)), too large for "
                       f"{np.dtype(dtype).name} arithmetic on n = {n} vertices (limit "
                       f"{limit:.3g}): rescale f (codes are linear in f) or enable "
                       "jax_enable_x64")


def _empty_codes(lead, q: int, dtype, return_info: bool):
    """The result of coding an empty batch of leading shape ``lead`` (nothing to trace)."""
    alpha = jnp.zeros(lead + (q,), dtype)
    info = CodingInfo(jnp.zeros(lead, jnp.int32), jnp.zeros(lead, dtype), jnp.ones(lead, bool))
    return (alpha, info) if return_info else alpha


def _flatten_per_function(dynamic: dict, lead, m: int, q: int, dtype) -> None:
    """Give the per-function options (``eps`` broadcast to ``lead``, ``init`` ``(..., q)``) the
    flat batch axis ``m`` of the kernels, in place."""
    if "eps" in dynamic:
        dynamic["eps"] = jnp.reshape(jnp.broadcast_to(jnp.asarray(dynamic["eps"], dtype), lead),
                                     (m,))
    if dynamic.get("init") is not None:
        dynamic["init"] = jnp.reshape(jnp.asarray(dynamic["init"], dtype), (m, q))


def _shaped_codes(alpha, info, lead, return_info: bool):
    """The kernels' flat ``(m, q)`` codes (and info) back in the caller's leading shape."""
    alpha = jnp.reshape(alpha, lead + (alpha.shape[-1],))
    if not return_info:
        return alpha
    return alpha, jax.tree.map(lambda x: jnp.reshape(x, lead), info)


# ----------------------------------------------------------------------------------------------
# Public API
# ----------------------------------------------------------------------------------------------


def encode(frame, f, method: str = "omp", *, weights=None, return_info: bool = False,
           **options):
    r"""Sparse (or least-squares) coefficients of functions ``f`` in the frame: ``f ≈ α Bᵀ``.

    Args:
        frame: a :class:`~bsfjax.Frame` (its ``atoms`` ``B`` of shape ``(n, q)`` are used, and
            its ``mass`` for ``weights="area"``) or a plain ``(n, q)`` array of atoms.
        f: ``(..., n)`` functions (any leading batch shape; bool/int are converted).
        method: ``"lstsq"``, ``"omp"`` (default), ``"omp_error"`` or ``"lasso"``.
        weights: ``None`` (Euclidean ``‖·‖₂``), ``"area"`` (the frame's vertex areas, so the
            code minimises ``‖f − Bα‖²_A``) or an ``(n,)`` array of nonnegative weights ``w``
            (minimise ``Σᵢ wᵢ (f − Bα)ᵢ²``).  Atom norms, the OMP error bound and the lasso
            scale are then all measured in that norm.
        return_info: also return a :class:`CodingInfo`.
        **options: per method (an unknown name is an error):

            ``"lstsq"`` — ``rcond`` (default ``√(10·eps)`` of the dtype): singular values of
            ``B`` below ``rcond · s_max`` count as zero.  The solution is ``α = V Λ⁺ Vᵀ Bᵀf``
            from the eigendecomposition ``G = BᵀB = V Λ Vᵀ`` (then one step of iterative
            refinement against ``B``), i.e. numpy's ``lstsq`` computed through ``G``; since
            ``G``'s eigenvalues ``s²`` carry an absolute error ``~eps·s_max²``, singular values
            below ``~√eps·s_max`` cannot be told from zero, hence the default (numpy's own
            ``max(n, q)·eps`` is below that resolution).  Binary frames are often rank deficient
            (duplicate atoms); the minimum-norm solution is returned.

            ``"omp"`` — ``sparsity`` ``S`` (default ``min(10, q)``, ``1 ≤ S ≤ q``): at most
            ``S`` atoms; ``precompute`` (``"auto"``): form the full ``q × q`` Gram matrix
            (``True``, ``O(n q²)`` once) or only the Gram rows of the selected atoms
            (``False``, ``O(n q)`` per step and function); ``"auto"`` forms it when
            ``2 · batch · S ≥ q`` — except for a concrete, sparse enough frame (binary atoms),
            whose selected Gram rows are then cheaper to compute on the host from a CSR copy
            of ``B`` (``O(|supp b_k| · D)`` per row) than the ``n q²`` GEMM.

            ``"omp_error"`` — ``eps``: bound on the **squared** residual ``‖f − Bα‖² ≤ ε``
            (SPAMS' convention), a number or an array broadcasting to the batch shape ``...``.
            Default ``None``: ``ε = (‖f‖/10)²`` per function, i.e. the paper's "``ε = ‖f‖/10``"
            read as a bound on the residual *norm* — a 10 % relative error, invariant to the
            scale of ``f``, to the mesh resolution and to ``weights``.  ``eps="spams"`` uses
            ``ε = ‖f‖/10`` on the squared residual, as a literal SPAMS call ``mexOMP(…,
            eps=‖f‖/10)`` would (not scale invariant: stricter for larger ``‖f‖``).  At least
            one atom is selected unless ``‖f‖² ≤ ε``.  ``max_atoms`` (default ``min(64, q)``)
            caps the atom count, since the bound is often unreachable (``info.converged`` says
            which functions met it); ``precompute`` as for ``"omp"``.

            ``"lasso"`` — ``lam`` (default 0.01): ``λ = lam · ‖Bᵀf‖∞`` per function, so the
            same ``lam`` means the same relative sparsity pressure whatever the scale of ``f``
            (``λ ≥ ‖Bᵀf‖∞`` is the smallest value giving ``α = 0``, so ``lam ≥ 1`` gives 0);
            ``init``: ``(..., q)`` warm start (e.g. the solution for a nearby ``lam``);
            ``target_atoms``: instead of ``lam``, choose ``lam`` per function by bisection
            so that the code has at most that many non-zeros (as many as the bisection finds;
            ``info.n_atoms`` says how many);
            ``maxiter`` (10000) and ``tol`` (1e-4): FISTA with step ``1/L`` (``L ≥ λ_max(G)``)
            stops, per function, when one iteration changes the coefficients by
            ``√L·‖Δα‖ ≤ tol·‖f‖`` — a bound on the change of the approximation ``‖BΔα‖``
            relative to ``‖f‖``.  On FAUST frames the defaults reach the optimum objective to
            ~1e-5 relative.

    Returns:
        ``α`` of shape ``(..., q)``, or ``(α, info)`` with ``return_info=True``.

    OMP (both kinds) selects atoms on the ℓ2-normalised columns ``D = B / ‖b_j‖`` — what SPAMS,
    used by the paper, and scikit-learn's ``orthogonal_mp`` assume — and maps the coefficients
    back, ``α_j = β_j / ‖b_j‖``.  It is the Batch-OMP of Rubinstein, Zibulevsky & Elad (2008):
    Gram matrix, progressive Cholesky factor (kept as its inverse, so every update is a small
    batched matrix product), a fixed maximum number of masked steps.  Empty atoms are never
    selected, no atom is selected twice, and a function stops early when its best correlation
    satisfies ``c² ≤ eps·‖f‖²`` (nothing left to fit at this precision) or when the best atom
    is linearly dependent on the selected ones.  Large batches are processed in chunks of
    about 1M buffered numbers (``chunk · steps · q``), which bounds memory and keeps the
    per-step work in cache.
    """
    if isinstance(frame, SparseFrame):
        return _encode_sparse(frame, f, method, weights, return_info, options)
    atoms, mass = _unpack_frame(frame)
    n, q = int(atoms.shape[0]), int(atoms.shape[1])
    f = _check_functions(f, n)
    lead = tuple(f.shape[:-1])
    static, dynamic = _check_options(method, options, q, lead)
    w = _check_weights(weights, mass, n)
    if not isinstance(return_info, bool):
        raise BSFError(f"return_info must be a bool, got {return_info!r}")
    dtype = _float_dtype(f, atoms)
    _check_magnitude(f, w, n, dtype)
    m = int(np.prod(lead, dtype=np.int64))
    F = jnp.reshape(jnp.asarray(f, dtype), (m, n))
    B = jnp.asarray(atoms, dtype)
    sqrt_w = None if w is None else jnp.sqrt(jnp.asarray(w, dtype))
    _flatten_per_function(dynamic, lead, m, q, dtype)
    static["info"] = return_info  # the residuals cost one more n·q product: only on request
    if method in ("omp", "omp_error"):
        pre = static.pop("precompute")
        # Gram: one n·q² GEMM; rows: n·q·m per step.  Measured crossover (FAUST, q ≈ 1000,
        # 2 cores) near m·steps ≈ q/2, the GEMM being the more efficient of the two.
        static["gram"] = bool(pre) if pre != "auto" else 2 * m * static["n_steps"] >= q
        static["chunk"] = max(1, min(m, _OMP_CHUNK_ELEMS // (static["n_steps"] * q)))
        if pre == "auto" and static["gram"] and m > 0 and not (_is_traced(atoms) or _is_traced(F)):
            token = _host_rows_token(atoms, w, dtype, m * static["n_steps"])
            if token is not None:  # a sparse (e.g. binary) frame: Gram rows from the host
                static["gram"] = "host"
                dynamic["gram_token"] = jnp.asarray(token, jnp.int32)
    if m == 0:  # empty batch: nothing to trace
        return _empty_codes(lead, q, dtype, return_info)
    try:
        alpha, info = _run_batch(_BatchEntry(False, method, tuple(sorted(static.items()))),
                                 (B, sqrt_w), F, dynamic)
        if "gram_token" in dynamic:
            alpha = jax.block_until_ready(alpha)
    finally:
        if "gram_token" in dynamic:
            _HostGramRows.release(int(dynamic["gram_token"]))
    return _shaped_codes(alpha, info, lead, return_info)


def decode(frame, alpha) -> jax.Array:
    r"""Functions ``f = α Bᵀ`` (``(..., n)``) from coefficients ``α`` (``(..., q)``).

    ``frame`` is a :class:`~bsfjax.Frame`, a :class:`~bsfjax.SparseFrame` (gather-sum over each
    vertex's atoms, never densified) or a plain ``(n, q)`` atom array.
    """
    if isinstance(frame, SparseFrame):
        q = frame.n_atoms
        if not hasattr(alpha, "shape"):
            alpha = np.asarray(alpha)
        if alpha.ndim < 1 or alpha.shape[-1] != q:
            raise BSFError(f"alpha must have shape (..., q) with q = {q} atoms, got "
                           f"{tuple(alpha.shape)}")
        dtype = _float_dtype(alpha, frame.coeffs)
        lead = tuple(alpha.shape[:-1])
        A = jnp.reshape(jnp.asarray(alpha, dtype), (-1, q))
        return jnp.reshape(ell_matmul(frame.atom_lists, A.T).T, lead + (frame.n_vertices,))
    atoms, _ = _unpack_frame(frame)
    q = int(atoms.shape[1])
    if not hasattr(alpha, "shape"):
        alpha = np.asarray(alpha)
    if alpha.ndim < 1 or alpha.shape[-1] != q:
        raise BSFError(f"alpha must have shape (..., q) with q = {q} atoms, got "
                       f"{tuple(alpha.shape)}")
    check_finite(alpha, "alpha")
    dtype = _float_dtype(alpha, atoms)
    return _decode(jnp.asarray(atoms, dtype), jnp.asarray(alpha, dtype))


@jax.jit
def _decode(B: jax.Array, alpha: jax.Array) -> jax.Array:
    return jnp.einsum("...q,nq->...n", alpha, B)


# ----------------------------------------------------------------------------------------------
# Dispatch: one device, or the function axis split over all devices
# ----------------------------------------------------------------------------------------------

#: Options that hold one value per function (split with the functions across devices).
_PER_FUNCTION = ("eps", "init")


@dataclasses.dataclass(frozen=True)
class _BatchEntry:
    """The batch kernel for one (frame kind, method, static options): hashable, so that its
    multi-device wrapper is compiled once."""

    sparse: bool
    method: str
    static: tuple

    def __call__(self, replicated, per_function):
        frame_args, dyn_rep = replicated
        F, dyn_per = per_function
        dynamic = {**dyn_rep, **dyn_per}
        if self.sparse:
            lists, w, gram, norms2 = frame_args
            return _encode_sparse_batch(lists, F, w, gram, norms2, dynamic, method=self.method,
                                        static=self.static)
        B, sqrt_w = frame_args
        return _encode_batch(B, F, sqrt_w, dynamic, method=self.method, static=self.static)


def _run_batch(entry: _BatchEntry, frame_args, F, dynamic):
    """Run ``entry`` on the ``(m, n)`` functions ``F``.  With several JAX devices (and at least
    one function per device, outside any trace) the functions are split evenly over them
    (:func:`bsfjax._devices.map_over_devices`); each device codes its functions with the same
    kernel, so the result is the single-device one."""
    per = {k: v for k, v in dynamic.items() if k in _PER_FUNCTION and v is not None}
    rep = {k: v for k, v in dynamic.items() if k not in per}
    m = F.shape[0]
    d = n_devices()
    if d > 1 and m >= d and not _is_traced(F):
        return map_over_devices(entry, (frame_args, rep), (F, per), m)
    return entry((frame_args, rep), (F, per))


# ----------------------------------------------------------------------------------------------
# Jitted batch implementation: B (n, q), F (m, n)
# ----------------------------------------------------------------------------------------------


def _omp_bound(method, static, dynamic, fnorm2):
    """``(m,)`` squared-residual bound ε of each function: ``−∞`` for ``"omp"`` (never reached,
    so S steps run), else ``omp_error``'s bound in its ``eps_mode``."""
    if method == "omp":
        return jnp.full(fnorm2.shape, -jnp.inf, fnorm2.dtype)
    if static["eps_mode"] == "relative":
        return (EPS_FRACTION**2) * fnorm2
    if static["eps_mode"] == "spams":
        return EPS_FRACTION * jnp.sqrt(fnorm2)
    return dynamic["eps"]


@partial(jax.jit, static_argnames=("method", "static"))
def _encode_batch(B, F, sqrt_w, dynamic, *, method, static):
    static = dict(static)
    if sqrt_w is not None:  # weighted inner product <u, v>_W = Σ w u v
        B = B * sqrt_w[:, None]
        F = F * sqrt_w
    C = F @ B  # (m, q) correlations Bᵀf, the only n-sized work besides the Gram matrix
    fnorm2 = jnp.sum(F * F, axis=1)
    if method == "lstsq":
        alpha = _lstsq(B, F, C, dynamic["rcond"])
        converged = jnp.ones(F.shape[0], bool)
    elif method in ("omp", "omp_error"):
        eps = _omp_bound(method, static, dynamic, fnorm2)
        alpha, n_sel, exhausted = _omp(B, C, fnorm2, eps, static["n_steps"], static["gram"],
                                       static["chunk"], dynamic.get("gram_token"))
        if method == "omp":
            converged = (n_sel == static["n_steps"]) | exhausted
    elif static["target_atoms"] is None:  # lasso with a given λ
        alpha, err = _lasso(_gram(B), C, fnorm2, dynamic["lam"], dynamic["init"],
                            static["maxiter"], static["tol"])
        converged = err <= static["tol"]
    else:  # lasso, λ per function for a target number of atoms
        alpha, err = _lasso_target(_gram(B), C, fnorm2, static["target_atoms"], static["maxiter"],
                                   static["tol"])
        converged = err <= static["tol"]
    if not static["info"]:
        return alpha, None
    R = F - alpha @ B.T
    res2 = jnp.sum(R * R, axis=1)
    if method == "omp_error":
        converged = res2 <= eps
    info = CodingInfo(n_atoms=jnp.sum(alpha != 0, axis=1, dtype=jnp.int32),
                      residual=jnp.sqrt(res2), converged=converged)
    return alpha, info


# ----------------------------------------------------------------------------------------------
# Sparse frames: the same algorithms on BᵀWB (host, scipy CSR) and ELL products of B
# ----------------------------------------------------------------------------------------------


def _encode_sparse(frame: SparseFrame, f, method, weights, return_info, options):
    """:func:`encode` for a :class:`SparseFrame`.

    OMP needs only the Gram rows ``G[k, :] = b_kᵀ W B`` of the atoms it selects (at most
    ``steps`` per function).  They are computed on the host when selected, from the frame's
    atom lists and their 16-bit transpose (``O(|supp b_k| · D)`` each, via
    :func:`jax.pure_callback`; see :class:`_EllGramSource`), so
    the ``q × q`` Gram matrix is never formed — its full product would cost ``Σ_v D_v²``,
    e.g. ~50 G operations at 160K vertices.  ``lstsq``/``lasso`` do need ``G`` dense (host
    CSR product, then densified) and so are limited to frames with ``q² · 8`` bytes within
    :data:`~bsfjax._frame.DENSE_BUDGET_BYTES`.  Correlations ``BᵀWf`` and residuals use the
    chunked ELL products of ``sparse_frame.py``.  Needs a concrete frame.
    """
    n, q = frame.n_vertices, frame.n_atoms
    if _is_traced(frame.atom_lists):
        raise BSFError("encode with a SparseFrame needs a concrete frame (its Gram rows are "
                       "formed on the host): call it outside jit/vmap or use a dense Frame")
    f = _check_functions(f, n)
    lead = tuple(f.shape[:-1])
    static, dynamic = _check_options(method, options, q, lead)
    w = _check_weights(weights, frame.mass, n)
    if not isinstance(return_info, bool):
        raise BSFError(f"return_info must be a bool, got {return_info!r}")
    dtype = _float_dtype(f, frame.coeffs)
    m = int(np.prod(lead, dtype=np.int64))
    if method in ("lstsq", "lasso") and q * q * 8 > DENSE_BUDGET_BYTES:
        raise BSFError(f"method={method!r} needs the dense q × q Gram matrix (q = {q}: "
                       f"{q * q * 8 / 2**30:.1f} GiB > DENSE_BUDGET_BYTES); use 'omp' or "
                       "'omp_error' for frames this large")
    if m == 0:
        return _empty_codes(lead, q, dtype, return_info)
    w64 = None if w is None else np.asarray(w, np.float64)
    token = None
    static["info"] = return_info
    if method in ("omp", "omp_error"):
        static.pop("precompute")  # Gram rows come from the host either way
        static["chunk"] = max(1, min(m, _OMP_CHUNK_ELEMS // (static["n_steps"] * q)))
        source = _EllGramSource(frame, w64)
        norms2 = source.norms2()
        token = _HostGramRows.register(source, dtype)
        gram = jnp.asarray(token, jnp.int32)
    else:
        Bs = frame.to_scipy(w64)  # diag(√w) B, float64 CSR (n, q); q² fits the dense budget
        norms2 = np.asarray(Bs.multiply(Bs).sum(axis=0)).ravel()
        gram = jnp.asarray((Bs.T @ Bs).toarray(), dtype)
    _flatten_per_function(dynamic, lead, m, q, dtype)
    F = jnp.reshape(jnp.asarray(f, dtype), (m, n))
    wv = jnp.ones(n, dtype) if w is None else jnp.asarray(w, dtype)
    try:
        alpha, info = _run_batch(_BatchEntry(True, method, tuple(sorted(static.items()))),
                                 (frame.atom_lists, wv, gram, jnp.asarray(norms2, dtype)), F,
                                 dynamic)
        alpha = jax.block_until_ready(alpha)
    finally:
        if token is not None:
            _HostGramRows.release(token)
            release_free_memory()  # the transpose and row temporaries (see bsfjax._memory)
    return _shaped_codes(alpha, info, lead, return_info)


#: Cost of one sparse multiply-add of a host Gram row relative to one GEMM flop (measured on 2
#: cores: ~3.4 ns vs ~6 ps).  A dense frame gets its OMP Gram rows from a host CSR copy when
#: ``rows · (nnz/q) · (nnz/n) · _HOST_ROW_COST < n q²`` (the Gram GEMM), e.g. FAUST binary
#: frames (2.5 % nonzeros) coding 100 functions with S = 10, but not with 256 steps.
_HOST_ROW_COST = 500


def _host_rows_token(atoms, w, dtype, rows: int):
    """Register a CSR copy of ``diag(√w) B`` if its Gram rows are cheaper than the Gram GEMM;
    the token, or ``None``."""
    Bh = np.asarray(atoms)
    n, q = Bh.shape
    # row-major: sorted by vertex, then atom (on the bool mask: ~4× faster than on floats)
    flat = np.flatnonzero(Bh != 0)
    nnz = flat.size
    if rows * (nnz / q) * (nnz / n) * _HOST_ROW_COST >= n * q * q:
        return None
    r, c = np.divmod(flat, q)
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(r, minlength=n), out=indptr[1:])
    Bs = sp.csr_matrix((Bh.reshape(-1)[flat].astype(np.float64), c.astype(np.int32), indptr),
                       shape=(n, q))
    if w is not None:
        Bs = sp.diags(np.sqrt(np.asarray(w, np.float64))) @ Bs
    return _HostGramRows.register(_CsrGramSource(Bs), dtype)


def _host_gram_rows(token, inv_norm, dtype):
    """``gram_rows(k)`` for :func:`_omp_loop`: rows of ``DᵀD`` from the host (callback).

    The callback returns float32 (JAX canonicalizes a callback's float64 result to float32
    when it runs in a thread outside a ``jax.enable_x64`` context); in float64 the rows come
    as a float32 pair ``hi + lo``, exact to ~1e-14.
    """
    q = inv_norm.shape[0]
    wide = jnp.dtype(dtype) == jnp.float64

    def gram_rows(k):  # (b,) -> (b, q)
        part = jax.ShapeDtypeStruct((k.shape[0], q), jnp.float32)
        out = jax.pure_callback(_HostGramRows.rows, (part, part) if wide else part, token, k)
        g = out[0].astype(dtype) + out[1].astype(dtype) if wide else out
        return g * inv_norm[k][:, None] * inv_norm[None, :]

    return gram_rows


class _CsrGramSource:
    """Gram rows ``(Bs[:, k])ᵀ Bs`` of a scipy CSR ``Bs = diag(√w) B`` (the dense-frame path:
    a CSR copy of a concrete ``(n, q)`` frame)."""

    def __init__(self, Bs):
        self.BT, self.B = Bs.T.tocsr(), Bs.tocsr()

    def rows(self, ks) -> np.ndarray:
        return (self.BT[ks] @ self.B).toarray()


class _EllGramSource:
    """Gram rows ``b_kᵀ W B`` of a :class:`SparseFrame` from its own atom lists (host view) and
    their 16-bit transpose (:func:`~bsfjax._sparse_frame.atom_vertices`): about ``nnz · 2``
    bytes besides the lists, where a float64 scipy CSR and its transpose took ``nnz · 24``.

    Without weights the rows are the exact overlap counts; with weights each term is
    ``√w_v · √w_v`` summed in increasing ``v``, the products and order of scipy's
    ``diag(√w) B`` CSR product.
    """

    def __init__(self, frame: SparseFrame, w64):
        self.lists = np.asarray(frame.atom_lists)  # on CPU a view of the device buffer
        self.av = atom_vertices(self.lists, frame.n_atoms)
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
        return ell_gram_rows(self.lists, self.av, ks, self.vals)


class _Registration(NamedTuple):
    source: Any  # _CsrGramSource or _EllGramSource
    dtype: np.dtype
    cache: dict  # atom -> float64 row computed in this registration


class _HostGramRows:
    """Rows ``G[k, :] = (WB)[:, k]ᵀ B`` of a sparse frame's Gram matrix, computed on the host.

    A jitted kernel cannot hold host arrays, so each :func:`encode` call registers a row
    source (:class:`_EllGramSource` for a :class:`SparseFrame`, :class:`_CsrGramSource` for a
    dense frame) under an integer token that the kernel passes to :func:`rows` through
    :func:`jax.pure_callback` (the compiled kernel is shared by all frames of equal shapes).
    Within one registration every row is computed once: functions of a batch share many atoms
    (100 FAUST regions, 10 steps: 1000 selections of 436 distinct atoms), so each call computes
    only the rows it has not seen, up to :data:`_ROW_CACHE_BYTES` of kept rows.
    """

    _live: dict[int, _Registration] = {}
    _next = 0

    @classmethod
    def register(cls, source, dtype) -> int:
        cls._next += 1
        cls._live[cls._next] = _Registration(source, np.dtype(dtype), {})
        return cls._next

    @classmethod
    def release(cls, token: int) -> None:
        cls._live.pop(token, None)

    @classmethod
    def rows(cls, token, k):
        source, dtype, cache = cls._live[int(token)]
        k = np.asarray(k).reshape(-1)
        uniq, inv = np.unique(k, return_inverse=True)
        # callbacks of several devices may run concurrently: dict reads/writes are atomic, and
        # a row computed twice by a race is the same row
        new = np.asarray([a for a in uniq.tolist() if a not in cache], np.int64)
        if new.size:
            g_new = source.rows(new)
            if (len(cache) + new.size) * g_new.shape[1] * 8 <= _ROW_CACHE_BYTES:
                cache.update(zip(new.tolist(), g_new))
            else:  # too many to keep: this call's rows only
                got = dict(zip(new.tolist(), g_new))
                g = np.stack([got[a] if a in got else cache[a] for a in uniq.tolist()])[inv]
                return cls._split(g, dtype)
        g = np.stack([cache[a] for a in uniq.tolist()])[inv]
        return cls._split(g, dtype)

    @staticmethod
    def _split(g, dtype):
        hi = g.astype(np.float32)
        if dtype != np.float64:
            return hi
        return hi, (g - hi).astype(np.float32)


#: Memory for the Gram rows one :func:`encode` call keeps on the host (float64): 256 MiB, e.g.
#: all 1032 rows of a FAUST frame (8 MiB) or ~500 rows at q = 67K atoms.
_ROW_CACHE_BYTES = 2**28


@partial(jax.jit, static_argnames=("method", "static"))
def _encode_sparse_batch(lists, F, w, gram, norms2, dynamic, *, method, static):
    """``lists`` ``(n, D)``, ``F`` ``(m, n)``, ``w`` ``(n,)``; ``gram``: the host token of the
    Gram rows (OMP, see :class:`_HostGramRows`) or the dense ``BᵀWB`` (lstsq, lasso)."""
    static = dict(static)
    m = F.shape[0]
    q = norms2.shape[0]

    def Bt(Y):  # rows (m, n) -> rows of Bᵀ W y (m, q)
        return ell_rmatmul(lists, (Y * w).T, q).T

    def Bx(A):  # rows (m, q) -> rows of B α (m, n)
        return ell_matmul(lists, A.T).T

    C = Bt(F)
    fnorm2 = jnp.sum(w * F * F, axis=1)
    if method == "lstsq":
        alpha = _lstsq_gram(gram, C, lambda a: Bt(F - Bx(a)), norms2 > 0, dynamic["rcond"])
        converged = jnp.ones(m, bool)
    elif method in ("omp", "omp_error"):
        eps = _omp_bound(method, static, dynamic, fnorm2)
        valid = norms2 > 0
        inv_norm = jnp.where(valid, 1.0 / jnp.sqrt(jnp.where(valid, norms2, 1.0)), 0.0)

        gram_rows = _host_gram_rows(gram, inv_norm, F.dtype)
        alpha, n_sel, exhausted = _omp_loop(gram_rows, inv_norm, valid, C, fnorm2, eps,
                                            static["n_steps"], static["chunk"])
        if method == "omp":
            converged = (n_sel == static["n_steps"]) | exhausted
    elif static.get("target_atoms") is None:
        alpha, err = _lasso(gram, C, fnorm2, dynamic["lam"], dynamic["init"],
                            static["maxiter"], static["tol"])
        converged = err <= static["tol"]
    else:
        alpha, err = _lasso_target(gram, C, fnorm2, static["target_atoms"], static["maxiter"],
                                   static["tol"])
        converged = err <= static["tol"]
    if not static["info"]:
        return alpha, None
    R = F - Bx(alpha)
    res2 = jnp.sum(w * R * R, axis=1)
    if method == "omp_error":
        converged = res2 <= eps
    info = CodingInfo(n_atoms=jnp.sum(alpha != 0, axis=1, dtype=jnp.int32),
                      residual=jnp.sqrt(res2), converged=converged)
    return alpha, info


def _gram(B):
    """``G = BᵀB`` (q, q).  In float64, a 0/1 frame (unweighted binary atoms) has integer
    ``G ≤ n``, exact in float32 when ``n < 2²⁴``: that GEMM is about twice as fast, so it is
    used whenever the atoms are 0/1 (checked at run time; weighted rows are not)."""
    if B.dtype != jnp.float64 or B.shape[0] >= 2**24:
        return B.T @ B
    binary = jnp.all((B == 0) | (B == 1))
    return jax.lax.cond(binary, lambda B: _gram32(B).astype(B.dtype), lambda B: B.T @ B, B)


def _gram32(B):
    B32 = B.astype(jnp.float32)
    return B32.T @ B32


def _lstsq(B, F, C, rcond):
    """Minimum-norm least squares via the eigendecomposition of ``G = BᵀB``."""
    return _lstsq_gram(_gram(B), C, lambda alpha: (F - alpha @ B.T) @ B,
                       jnp.any(B != 0, axis=0), rcond)


def _lstsq_gram(G, C, resid_corr, nonempty, rcond):
    """``α = G⁺ C`` rows, refined once with ``resid_corr(α) = Bᵀ(f − Bα)`` rows."""
    dtype = G.dtype
    if rcond is None:
        rcond = math.sqrt(10 * float(jnp.finfo(dtype).eps))
    lam, V = jnp.linalg.eigh(G)
    keep = lam > (rcond * rcond) * lam[-1]  # s_i > rcond·s_max (lam ≥ 0 up to rounding)
    inv = jnp.where(keep, 1.0 / jnp.where(keep, lam, 1.0), 0.0)

    def solve(rhs):  # G⁺ rhs for rows of rhs (m, q)
        return ((rhs @ V) * inv) @ V.T

    alpha = solve(C)
    # One step of iterative refinement with the residual computed against B itself: the
    # normal equations lose accuracy as κ(B)², the refined solution only as κ(B).  The update
    # stays in the range of G⁺, so the solution keeps minimum norm.
    alpha = alpha + solve(resid_corr(alpha))
    # Empty atoms are exactly 0 in the minimum-norm solution; the eigenvectors only get that
    # to rounding, so make it exact (and n_atoms meaningful).
    return jnp.where(nonempty, alpha, 0.0)


#: Functions are coded in chunks whose OMP buffers (``chunk × steps × q`` Gram rows) hold about
#: this many numbers, so that they stay in cache and memory stays bounded for any batch size
#: (and a chunk whose functions all stopped ends its loop early).  Measured on FAUST, q = 1032,
#: 256 steps, 100 functions: 2²⁰ is 2–3× faster than 2²² in float32 and float64.
_OMP_CHUNK_ELEMS = 2**20


def _omp(B, C, fnorm2, eps, n_steps: int, gram, chunk: int, token=None):
    """Batch-OMP on the normalised atoms; returns ``(alpha, n_selected, exhausted)``.

    B ``(n, q)``, C = Bᵀf ``(m, q)``, fnorm2 ``(m,)``, eps ``(m,)`` bound on the squared residual
    (``-inf``: none); ``chunk`` functions at a time (``lax.map``).  Per function and step
    ``t`` (``I`` the selected atoms, ``D = B/‖b‖``)::

        k   = argmax |c| over atoms not selected and not empty      c = Dᵀr, the correlations
        w   = L⁻¹ G_{I,k};  d² = 1 − ‖w‖²                            L Lᵀ = G_II (Cholesky)
        L⁻¹ ← [[L⁻¹, 0], [−wᵀL⁻¹/d, 1/d]];  y ← [y, (c0_k − wᵀy)/d]   y = L⁻¹ (Dᵀf)_I
        β   = L⁻ᵀ y;  c = c0 − G_{:,I} β;  ‖r‖² = ‖f‖² − ‖y‖²

    A function stops (and stays stopped) when no atom is left, ``c_k² ≤ eps·‖f‖²``,
    ``‖r‖² ≤ ε``, or ``d² ≤ 100·eps`` (atom ``k`` dependent on ``I``); so a function still
    running at step ``t`` has exactly ``t`` atoms, and every update writes slot ``t``.

    ``gram``: ``True`` (the full ``BᵀB``, one GEMM), ``False`` (rows ``Dᵀd_k`` on the device)
    or ``"host"`` (rows of the host CSR matrix registered under ``token``).
    """
    norms = jnp.sqrt(jnp.sum(B * B, axis=0))
    valid = norms > 0
    inv_norm = jnp.where(valid, 1.0 / jnp.where(valid, norms, 1.0), 0.0)
    if gram == "host":
        gram_rows = _host_gram_rows(token, inv_norm, B.dtype)
    elif gram:
        Gn = _gram(B) * inv_norm[:, None] * inv_norm[None, :]

        def gram_rows(k):  # (b,) -> (b, q) rows of DᵀD
            return Gn[k]
    else:
        Dn = B * inv_norm

        def gram_rows(k):  # only the selected atoms' rows: O(n q) per function
            return Dn[:, k].T @ Dn

    return _omp_loop(gram_rows, inv_norm, valid, C, fnorm2, eps, n_steps, chunk)


def _omp_loop(gram_rows, inv_norm, valid, C, fnorm2, eps, n_steps: int, chunk: int):
    """The Batch-OMP iterations of :func:`_omp` given ``gram_rows(k)`` ``(b,) -> (b, q)`` rows
    of the normalised Gram matrix ``DᵀD`` and the inverse atom norms (0 for empty atoms)."""
    dtype = C.dtype
    m, q = C.shape
    T = n_steps
    tiny = jnp.finfo(dtype).eps
    tol_dep = 100 * jnp.finfo(dtype).eps
    slots = jnp.arange(T)

    def run(args):  # one chunk of b functions
        c0, fnorm2, eps = args
        b = c0.shape[0]
        rows = jnp.arange(b)

        def cond(state):
            t, *_, done, _res2 = state
            return (t < T) & ~jnp.all(done)

        def body(state):
            t, idx, Linv, y, gsel, c, avail, n_sel, exhausted, done, res2 = state
            score = jnp.where(avail, jnp.abs(c), -1.0)
            k = jnp.argmax(score, axis=1).astype(jnp.int32)
            ck = c[rows, k]
            none_left = score[rows, k] < 0
            fitted = ck * ck <= tiny * fnorm2  # residual orthogonal to all atoms (or f = 0)
            stop = done | none_left | fitted | (res2 <= eps)
            g = gram_rows(k)  # (b, q)
            gI = jnp.where(slots < t, jnp.take_along_axis(g, idx, axis=1), 0.0)
            w = jnp.einsum("bij,bj->bi", Linv, gI)  # L⁻¹ G_{I,k}
            d2 = g[rows, k] - jnp.sum(w * w, axis=1)  # squared distance of atom k to span(D_I)
            act = ~stop & (d2 > tol_dep)
            d = jnp.sqrt(jnp.where(act, d2, 1.0))
            new_row = -jnp.einsum("bi,bij->bj", w, Linv) / d[:, None]
            new_row = jnp.where(slots == t, 1.0 / d[:, None], new_row)
            y_new = (c0[rows, k] - jnp.sum(w * y, axis=1)) / d

            def put(buf, new):  # write slot t of the running functions (in place)
                old = jax.lax.dynamic_index_in_dim(buf, t, axis=1, keepdims=False)
                sel = jnp.where(act.reshape((b,) + (1,) * (new.ndim - 1)), new, old)
                return jax.lax.dynamic_update_index_in_dim(buf, sel, t, axis=1)

            Linv, y, gsel, idx = put(Linv, new_row), put(y, y_new), put(gsel, g), put(idx, k)
            avail = avail.at[rows, k].set(avail[rows, k] & ~act)
            beta = jnp.einsum("bji,bj->bi", Linv, y)  # β = L⁻ᵀ y = G_II⁻¹ (Dᵀf)_I
            c = c0 - jnp.einsum("bi,biq->bq", beta, gsel)  # Dᵀ r
            res2 = jnp.where(act, res2 - y_new * y_new, res2)
            exhausted = exhausted | (~done & (fitted | none_left))
            return (t + 1, idx, Linv, y, gsel, c, avail, n_sel + act, exhausted, done | ~act,
                    res2)

        state = (
            jnp.asarray(0),
            jnp.zeros((b, T), jnp.int32),
            jnp.broadcast_to(jnp.eye(T, dtype=dtype), (b, T, T)),
            jnp.zeros((b, T), dtype),
            jnp.zeros((b, T, q), dtype),
            c0,
            jnp.broadcast_to(valid, (b, q)),
            jnp.zeros(b, jnp.int32),
            jnp.zeros(b, bool),
            jnp.zeros(b, bool),
            fnorm2,
        )
        _, idx, Linv, y, _, _, _, n_sel, exhausted, _, _ = jax.lax.while_loop(cond, body, state)
        beta = jnp.einsum("bji,bj->bi", Linv, y)
        coef = jnp.where(slots < n_sel[:, None], beta * inv_norm[idx], 0.0)
        alpha = jnp.zeros((b, q), dtype).at[rows[:, None], idx].add(coef)
        return alpha, n_sel, exhausted

    args = (C * inv_norm, fnorm2, eps)  # c0 = Dᵀf
    if chunk >= m:
        return run(args)
    pad = -m % chunk  # zero functions: they stop at once
    args = jax.tree.map(lambda x: jnp.pad(x, [(0, pad)] + [(0, 0)] * (x.ndim - 1)), args)
    out = jax.lax.map(run, jax.tree.map(lambda x: x.reshape((-1, chunk) + x.shape[1:]), args))
    return jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:])[:m], out)


def _spectral_bound(G, iters: int = 30):
    """An upper bound ``L ≥ λ_max(G)`` for symmetric ``G``.

    Collatz–Wielandt: for the entrywise ``|G|`` (with ``ρ(G) ≤ ρ(|G|)``) and any positive
    ``x``, ``ρ(|G|) ≤ maxᵢ (|G|x)ᵢ / xᵢ``; a few power iterations make ``x`` close to the Perron
    vector, so the bound is nearly tight, and it stays a guaranteed bound (unlike the power
    estimate itself, which is a lower bound).  Binary frames have ``G ≥ 0``.
    """
    M = jnp.abs(G)
    x = jnp.ones(G.shape[0], G.dtype)

    def step(x, _):
        y = M @ x
        return y / jnp.maximum(jnp.max(y), jnp.finfo(G.dtype).tiny), None

    x, _ = jax.lax.scan(step, x, None, length=iters)
    x = x + 1e-3  # keep every entry positive (x is normalised to max 1)
    bound = jnp.max((M @ x) / x)
    return jnp.where(bound > 0, bound, 1.0)


#: Bisection steps of ``target_atoms`` (on log λ in [log LAM_MIN, 0]) and its lower end.
LASSO_TARGET_STEPS = 14
LASSO_LAM_MIN = 1e-4


def _lasso_target(G, C, fnorm2, target: int, maxiter: int, tol: float):
    r"""Lasso whose relative λ is chosen per function so that ``‖α‖₀ ≤ target``, as large a
    support as bisection finds.

    ``lam = 1`` gives ``α = 0`` (feasible).  Bisection on ``log lam`` ∈ ``[log 1e-4, 0]``
    (:data:`LASSO_TARGET_STEPS` steps, each a warm-started FISTA solve, G formed once): a step
    whose solution has at most ``target`` non-zeros becomes the new feasible end.  The result
    is the solution at the smallest feasible λ tried (the support size is not monotone in λ in
    general, so ``n_atoms`` may fall short of ``target``; it never exceeds it)."""
    L = _spectral_bound(G)
    m, q = C.shape
    lo = jnp.full((m,), math.log(LASSO_LAM_MIN), C.dtype)
    hi = jnp.zeros((m,), C.dtype)
    best = jnp.zeros_like(C)
    err = jnp.zeros((m,), C.dtype)

    def step(_, state):
        lo, hi, best, err = state
        mid = 0.5 * (lo + hi)
        a, e = _lasso_solve(G, L, C, fnorm2, jnp.exp(mid), best, maxiter, tol)
        feas = jnp.sum(a != 0, axis=1) <= target
        return (jnp.where(feas, lo, mid), jnp.where(feas, mid, hi),
                jnp.where(feas[:, None], a, best), jnp.where(feas, e, err))

    _, _, best, err = jax.lax.fori_loop(0, LASSO_TARGET_STEPS, step, (lo, hi, best, err))
    return best, err


def _lasso(G, C, fnorm2, lam, init, maxiter: int, tol: float):
    return _lasso_solve(G, _spectral_bound(G), C, fnorm2, lam, init, maxiter, tol)


def _lasso_solve(G, L, C, fnorm2, lam, init, maxiter: int, tol: float):
    r"""``min_α ½αᵀGα − αᵀc + λ‖α‖₁`` per row ``c`` of ``C``, ``λ = lam·‖c‖∞``.

    Solved in normalised coordinates ``α = s·z`` with ``s = ‖f‖ / √L`` (``L ≥ λ_max(G)``):
    dividing the objective by ``s²L`` gives ``min_z ½ zᵀ(G/L)z − zᵀĉ + λ̂‖z‖₁`` with
    ``ĉ = c / (‖f‖√L)`` (``‖ĉ‖∞ ≤ 1``) and ``λ̂ = λ / (‖f‖√L)``.  Its gradient is 1-Lipschitz, so
    FISTA runs with step 1, and a step ``‖Δz‖`` bounds the change of the approximation,
    ``‖BΔα‖ ≤ √L‖Δα‖ = ‖f‖·‖Δz‖``: ``tol`` is relative to ``‖f‖`` and scale free.
    """
    Gh = G / L
    fnorm = jnp.sqrt(fnorm2)
    has = fnorm > 0
    denom = jnp.where(has, fnorm, 1.0) * jnp.sqrt(L)
    Ch = C / denom[:, None]
    lam_h = lam * jnp.max(jnp.abs(Ch), axis=1)
    scale = jnp.where(has, fnorm / jnp.sqrt(L), 0.0)
    if init is None:
        Z0 = jnp.zeros_like(C)
    else:
        Z0 = jnp.where(has[:, None], init / jnp.where(has, scale, 1.0)[:, None], 0.0)

    def value_and_grad(z, ch):
        h = Gh @ z
        return jnp.dot(z, 0.5 * h - ch), h - ch

    # unroll=False: jaxopt's default here (implicit_diff off) is a scan of maxiter lax.cond
    # steps, which never exits early and, under vmap, broadcasts G to (m, q, q) every step.
    solver = ProximalGradient(fun=value_and_grad, value_and_grad=True, prox=prox_lasso,
                              stepsize=1.0, maxiter=maxiter, tol=tol, acceleration=True,
                              implicit_diff=False, unroll=False)

    def one(z0, l1, ch):
        res = solver.run(z0, l1, ch)
        return res.params, res.state.error

    # vmap (not one joint problem) so every function has its own stopping test.
    Z, err = jax.vmap(one)(Z0, lam_h, Ch)
    return Z * scale[:, None], err
