r"""Sparse coding of functions in a Binary Sparse Frame (paper Sec. 5): [`encode`][bsfjax.encode],
[`decode`][bsfjax.decode], the coder registry `CODERS` and `as_coder`.

Owner of: input validation (one path for every kind of frame and coder), the conversion of the
functions to a flat ``(m, n)`` batch, the host Gram-row registration of a call, the device
dispatch, and the one jitted kernel

    C = BᵀWF,  ‖f‖²_W,  α = coder._solve(frame, …),  [residuals ‖f − Bα‖_W]

that every coder runs in, with the frame as an operator ([`AbstractFrame`][bsfjax.AbstractFrame]).

Everything after input validation is one jitted function with static shapes: a batch of ``m``
functions is coded together, and [`encode`][bsfjax.encode] also works under `jax.vmap` (over
functions, or over a stack of dense frames of equal shape) and `jax.jit` (value checks
that need concrete data are skipped for traced inputs; shape checks still run).
"""

from __future__ import annotations

import dataclasses
import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._coders import AbstractCoder, CodingInfo
from .._frame import Frame
from .._util import map_over_devices, n_devices
from .._util import BSFError
from .._frame import HostGramRows
from ._lasso import Lasso
from ._lstsq import LeastSquares
from ._omp import OMP, ErrorOMP
from .._frame import AbstractFrame
from .._util import check_finite, is_traced, magnitude_limit, restore_scale, unit_scale, homogeneous

__all__ = ["CodingInfo", "encode", "decode", "CODERS", "as_coder"]

#: The coders by name: the one registry of the string shorthands of [`encode`][bsfjax.encode].
CODERS: dict[str, type[AbstractCoder]] = {"lstsq": LeastSquares, "omp": OMP,
                                          "omp_error": ErrorOMP, "lasso": Lasso}
#: The names of `CODERS`.


def as_coder(coder: str | AbstractCoder = "omp", **options) -> AbstractCoder:
    """A coder object from a name of `CODERS` and its options, or the coder itself.

    ``as_coder("omp", sparsity=20) == OMP(sparsity=20)``.  Options are only accepted with a
    name (a coder object already holds its options).

    **Arguments:**

    - `coder`: ``"lstsq"``, ``"omp"``, ``"omp_error"``, ``"lasso"`` or an
      [`AbstractCoder`][bsfjax.AbstractCoder].
    - `**options`: fields of that coder (an unknown name is an error).
    """
    if isinstance(coder, AbstractCoder):
        if options:
            raise BSFError(f"options {sorted(options)} given with a coder object "
                           f"{type(coder).__name__}: set them as its fields instead (options "
                           "are only taken with a coder name)")
        return coder
    if not isinstance(coder, str) or coder not in CODERS:
        raise BSFError(f"method must be one of {tuple(CODERS)} or a coder object (e.g. "
                       f"bsfjax.OMP(...)), got {coder!r}")
    cls = CODERS[coder]
    valid = sorted(f.name for f in dataclasses.fields(cls))
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise BSFError(f"unknown option(s) {unknown} for method={coder!r}; valid options: "
                       f"{valid} (plus return_info)")
    return cls(**options)


# ----------------------------------------------------------------------------------------------
# Validation (plain Python, before tracing)
# ----------------------------------------------------------------------------------------------


def _as_frame(frame) -> AbstractFrame:
    """A frame, or a plain ``(n, q)`` atom array wrapped as a [`Frame`][bsfjax.Frame] without areas."""
    if isinstance(frame, AbstractFrame):
        if isinstance(frame, Frame) and np.ndim(frame.atoms) != 2:
            raise BSFError(f"frame atoms must have shape (n, q), got "
                           f"{tuple(np.shape(frame.atoms))}; for a stack of frames use "
                           "jax.vmap over encode")
        return frame
    if not (hasattr(frame, "shape") or isinstance(frame, (list, tuple))):
        raise BSFError(f"frame must be a bsfjax.Frame, a bsfjax.SparseFrame or an (n, q) array, "
                       f"got {type(frame).__name__}")
    atoms = frame
    if not is_traced(atoms):
        atoms = atoms if isinstance(atoms, jax.Array) else np.asarray(atoms)
        if not np.issubdtype(atoms.dtype, np.number) and atoms.dtype != np.bool_:
            raise BSFError(f"frame must be a bsfjax.Frame or a numeric (n, q) array, got "
                           f"dtype {atoms.dtype}")
        if not bool(np.all(np.isfinite(np.asarray(atoms)))):
            raise BSFError("frame (atoms) contains NaN or infinite values")
    if atoms.ndim != 2:
        raise BSFError(f"frame atoms must have shape (n, q), got {tuple(atoms.shape)}; for a "
                       "stack of frames use jax.vmap over encode")
    q = atoms.shape[1]
    return Frame(atoms=atoms, coeffs=np.zeros((0, q)), taus=np.zeros(q),
                 centers=np.zeros(q, np.int32), mass=None)


def _float_dtype(*dtypes):
    """The working float dtype: the promoted input dtype, at least floating, canonicalized
    (float32 by default, float64 with ``jax_enable_x64``)."""
    dts = [np.dtype(d) for d in dtypes]
    dt = np.result_type(*[d if np.issubdtype(d, np.floating) else np.float32 for d in dts])
    return jax.dtypes.canonicalize_dtype(dt)


def _check_functions(f, n, name="f"):
    if not hasattr(f, "shape"):
        f = np.asarray(f)
    if f.ndim < 1:
        raise BSFError(f"{name} must have shape (..., n) with n = {n}, got a scalar")
    if f.shape[-1] != n:
        raise BSFError(f"{name} has length {f.shape[-1]} along its last axis, but the frame has "
                       f"n = {n} vertices (expected shape (..., {n}))")
    if not is_traced(f):
        if not (np.issubdtype(f.dtype, np.number) or f.dtype == np.bool_):
            raise BSFError(f"{name} must be numeric, got dtype {f.dtype}")
        check_finite(f, name)
    return f


def _resolve_weights(weights, mass, n):
    """The coder's ``weights`` as ``None`` or an ``(n,)`` array (``"area"``: the frame's mass,
    unit weights for a plain atom array)."""
    if weights is None:
        return None
    if isinstance(weights, str):  # "area" (checked by the coder)
        return mass
    if tuple(np.shape(weights)) != (n,):
        raise BSFError(f"weights must have shape ({n},), got {tuple(np.shape(weights))}")
    return weights


def _check_magnitude(f, w, n, dtype):
    """Reject functions so large that ``Σ w f²`` or ``(BᵀWf)²`` overflow ``dtype`` (NaN codes)."""
    if is_traced(f) or (w is not None and is_traced(w)):
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


def _cast(frame: AbstractFrame, dtype) -> AbstractFrame:
    """The frame with its float arrays in the working ``dtype`` (integer lists unchanged)."""
    def cast(x):
        if x is None or not jnp.issubdtype(jnp.result_type(x), jnp.floating):
            return x
        return jnp.asarray(x, dtype)
    return jax.tree.map(cast, frame)


# ----------------------------------------------------------------------------------------------
# Public API
# ----------------------------------------------------------------------------------------------


def encode(frame: AbstractFrame | Float[Array, "n q"], f: Float[Array, "*batch n"],
           method: str | AbstractCoder = "omp", *, return_info: bool = False, **options):
    r"""Sparse (or least-squares) coefficients of functions ``f`` in a frame: ``f ≈ Bα``.

    ``encode(frame, f, "omp", sparsity=20)`` is ``encode(frame, f, OMP(sparsity=20))``: a
    name of `CODERS` with its options, or a coder object (then no options).

    **Arguments:**

    - `frame`: a [`Frame`][bsfjax.Frame], a [`SparseFrame`][bsfjax.SparseFrame] (any
      [`AbstractFrame`][bsfjax.AbstractFrame]), or a plain ``(n, q)`` atom array (no vertex areas:
      ``weights="area"`` then means unit weights).
    - `f`: ``(..., n)`` functions (any leading batch shape; bool/int are converted).
    - `method`: a coder — [`LeastSquares`][bsfjax.LeastSquares] (``"lstsq"``, paper Eq. 6),
      [`OMP`][bsfjax.OMP] (``"omp"``, default, Eq. 9), [`ErrorOMP`][bsfjax.ErrorOMP]
      (``"omp_error"``, Eq. 8) or [`Lasso`][bsfjax.Lasso] (``"lasso"``).
    - `return_info`: also return a [`CodingInfo`][bsfjax.CodingInfo].
    - `**options`: the coder's fields, with a coder name only; among them ``weights``
      (default ``"area"``: the codes minimise ``‖f − Bα‖_A``; ``None``: Euclidean; or an
      ``(n,)`` array).

    **Returns:**

    ``α`` of shape ``(..., q)``, or ``(α, info)`` with ``return_info=True``.
    """
    coder = as_coder(method, **options)
    if not isinstance(return_info, bool):
        raise BSFError(f"return_info must be a bool, got {return_info!r}")
    frame = _as_frame(frame)
    n, q = frame.n_vertices, frame.n_atoms
    f = _check_functions(f, n)
    lead = tuple(f.shape[:-1])
    w = _resolve_weights(coder.weights, frame.mass, n)
    dtype = _float_dtype(f.dtype, frame.dtype)
    # coders are homogeneous in f (Lasso's λ is relative): code f / max|f| and scale the codes
    # back, so 1e-30 or 1e30 in float32 code like 1 (not with an absolute eps or a warm start)
    unit, scale = (unit_scale(f, dtype) if homogeneous(coder)
                   else (jnp.asarray(f, dtype), None))
    _check_magnitude(f if scale is None else unit, w, n, dtype)
    m = int(np.prod(lead, dtype=np.int64))
    source = coder._host_source(frame, w, m)
    static, rep, per = coder._options(frame, w, lead, m, dtype, host=source is not None)
    if m == 0:  # empty batch: nothing to trace
        alpha = jnp.zeros(lead + (q,), dtype)
        info = CodingInfo(jnp.zeros(lead, jnp.int32), jnp.zeros(lead, dtype),
                          jnp.ones(lead, bool))
        return (alpha, info) if return_info else alpha
    F = jnp.reshape(unit, (m, n))
    wv = None if w is None else jnp.asarray(w, dtype)
    token = None
    if source is not None:
        token = HostGramRows.register(source, dtype)
        rep["gram_token"] = jnp.asarray(token, jnp.int32)
    entry = _Entry(type(coder), tuple(sorted(static.items())), return_info)
    try:
        alpha, info = _run_batch(entry, (_cast(frame, dtype), wv, rep), (F, per), m)
        if token is not None:
            alpha = jax.block_until_ready(alpha)
    finally:
        if token is not None:
            HostGramRows.release(token)
            if hasattr(source, "release"):
                source.release()
    alpha = restore_scale(jnp.reshape(alpha, lead + (q,)), scale)
    if not return_info:
        return alpha
    info = jax.tree.map(lambda x: jnp.reshape(x, lead), info)
    if scale is not None:
        info = info._replace(residual=info.residual * jnp.asarray(scale, info.residual.dtype))
    return alpha, info


def decode(frame: AbstractFrame | Float[Array, "n q"],
           alpha: Float[Array, "*batch q"]) -> Float[Array, "*batch n"]:
    r"""Functions ``f = Bα`` (``(..., n)``) from coefficients ``α`` (``(..., q)``).

    **Arguments:**

    - `frame`: a [`Frame`][bsfjax.Frame], a [`SparseFrame`][bsfjax.SparseFrame] (gather-sum over each
      vertex's atoms, never densified) or a plain ``(n, q)`` atom array.
    - `alpha`: ``(..., q)`` finite codes.
    """
    frame = _as_frame(frame)
    q = frame.n_atoms
    if not hasattr(alpha, "shape"):
        alpha = np.asarray(alpha)
    if alpha.ndim < 1 or alpha.shape[-1] != q:
        raise BSFError(f"alpha must have shape (..., q) with q = {q} atoms, got "
                       f"{tuple(alpha.shape)}")
    check_finite(alpha, "alpha")
    dtype = _float_dtype(alpha.dtype, frame.dtype)
    lead = tuple(alpha.shape[:-1])
    unit, scale = unit_scale(alpha, dtype)  # Bα is linear: decode at unit scale, scale back
    out = _decode(_cast(frame, dtype), jnp.reshape(unit, (-1, q)))
    if scale is not None and out.size:
        # the largest |f_v| the codes reach, in float64 before the cast back to dtype
        big = np.max(np.abs(np.asarray(out, np.float64)), axis=-1) * scale.reshape(-1)
        if not np.all(big <= np.finfo(dtype).max):
            raise BSFError(f"alpha decodes to values up to {float(np.max(big)):.3g}, beyond "
                           f"the {np.dtype(dtype).name} range (max "
                           f"{float(np.finfo(dtype).max):.3g}): rescale alpha or enable "
                           "jax_enable_x64")
        out = out * jnp.asarray(scale.reshape(-1), dtype)[:, None]
    return jnp.reshape(out, lead + (frame.n_vertices,))


@jax.jit
def _decode(frame, A):
    return frame.apply(A)


# ----------------------------------------------------------------------------------------------
# The kernel, on one device or with the function axis split over all devices
# ----------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class _Entry:
    """The batch kernel for one (coder class, static options): hashable, so that its
    multi-device wrapper is compiled once."""

    cls: type
    static: tuple
    info: bool

    def __call__(self, replicated, per_function):
        frame, w, rep = replicated
        F, per = per_function
        return _encode_batch(frame, F, w, {**rep, **per}, cls=self.cls, static=self.static,
                             info=self.info)


def _run_batch(entry: _Entry, replicated, per_function, m: int):
    """Run ``entry``; with several JAX devices (and at least one function per device, outside
    any trace) the functions are split evenly over them
    (`bsfjax._util.map_over_devices`); each device codes its functions with the same
    kernel, so the result is the single-device one."""
    d = n_devices()
    if d > 1 and m >= d and not is_traced(per_function[0]):
        return map_over_devices(entry, replicated, per_function, m)
    return entry(replicated, per_function)


@partial(jax.jit, static_argnames=("cls", "static", "info"))
def _encode_batch(frame, F, w, dyn, *, cls, static, info):
    C = frame.apply_transpose(F, w)  # (m, q) correlations BᵀWf
    fnorm2 = jnp.sum(F * F if w is None else F * F * w, axis=1)
    alpha, converged = cls._solve(frame, F, w, C, fnorm2, dict(static), dyn)
    if not info:
        return alpha, None
    R = F - frame.apply(alpha)
    res2 = jnp.sum(R * R if w is None else R * R * w, axis=1)
    if callable(converged):
        converged = converged(res2)
    return alpha, CodingInfo(n_atoms=jnp.sum(alpha != 0, axis=1, dtype=jnp.int32),
                             residual=jnp.sqrt(res2), converged=converged)

