"""Error metrics of the paper's experiments (Melzi 2019, Eqs. 14 and 15).

Everything in bsfjax reports the **square-root form** of the area-weighted relative error,

    E(f, f̃) = √(Σ_i A_i (f_i − f̃_i)²) / √(Σ_i A_i f_i²)  =  ‖f − f̃‖_A / ‖f‖_A,

i.e. the discrete version of ``(∫ (f − f̃)² / ∫ f²)^{1/2}``.  Eq. 14 (approximation) compares a
function with its reconstruction on the same shape; Eq. 15 (transfer) compares the ground-truth
image ``f ∘ T`` on the target with the transferred estimate, weighted by the *target's* areas.
Squaring ``E`` gives the ratio of integrals if that form is wanted.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._util import BSFError
from .._util import pow2_scale

__all__ = ["relative_error"]


def _check(x, name: str):
    if isinstance(x, jax.core.Tracer):
        return x
    if not hasattr(x, "shape") or not hasattr(x, "dtype"):
        try:
            x = np.asarray(x)
        except (TypeError, ValueError) as exc:
            raise BSFError(f"{name} must be a numeric array, got {type(x).__name__}") from exc
    if not (np.issubdtype(x.dtype, np.number) or x.dtype == np.bool_) \
            or np.issubdtype(x.dtype, np.complexfloating):
        raise BSFError(f"{name} must be a real numeric array, got dtype {x.dtype}")
    if x.ndim < 1:
        raise BSFError(f"{name} must have shape (..., n), got a scalar")
    if not np.all(np.isfinite(np.asarray(x))):
        raise BSFError(f"{name} contains NaN or infinite values")
    return x


@jax.jit
def _relative_error(reference, estimate, mass):
    dt = jnp.result_type(reference, estimate, mass, jnp.float32)
    f = jnp.asarray(reference, dt)
    e = jnp.asarray(estimate, dt)
    w = jnp.asarray(mass, dt)
    # The ratio is invariant to scaling f, f̃ (together) and A, so both are divided by their
    # largest magnitude first: squares of large values cannot overflow, nor small ones
    # underflow to a spurious 0/0.  The scales are restored for the absolute error below.
    s = jnp.maximum(jnp.max(jnp.abs(f), axis=-1), jnp.max(jnp.abs(e), axis=-1))
    s = jnp.where(s > 0, s, 1.0)
    ws = jnp.max(w, axis=-1)
    ws = jnp.where(ws > 0, ws, 1.0)
    f = f / s[..., None]
    d = e / s[..., None] - f
    w = w / ws[..., None]
    # f may still be tiny beside f̃ (f = 1e-30, f̃ = 1): both are divided by f's own largest
    # entry too, or the squares of f would underflow to a spurious zero norm (|d| ≤ 2 and
    # |f| ≥ the smallest normal number after the flush below, so d / sf stays in range)
    sf = jnp.max(jnp.abs(f), axis=-1)
    pos = sf > 0
    sf = jnp.where(pos, sf, 1.0)[..., None]
    ratio = _norm(d / sf, w) / jnp.where(pos, _norm(f / sf, w), 1.0)
    # ‖f‖_A = 0: the ratio is undefined; report the absolute error ‖f̃‖_A instead (0 when the
    # estimate is also zero), never 0/0 = NaN; a ratio beyond the dtype's range is its maximum
    return jnp.where(pos, jnp.minimum(ratio, jnp.finfo(dt).max),
                     _norm(d, w) * s * jnp.sqrt(ws))


def _norm(x, w):
    """``‖x‖_A``, scaled by the largest entry of ``x``: no square overflows or underflows."""
    m = jnp.max(jnp.abs(x), axis=-1)
    m = jnp.where(m > 0, m, 1.0)
    return m * jnp.sqrt(jnp.sum(w * (x / m[..., None]) ** 2, axis=-1))


def relative_error(reference, estimate, mass) -> jax.Array:
    r"""Area-weighted relative error ``‖f − f̃‖_A / ‖f‖_A`` (square-root form of Eqs. 14/15).

    .. math::  E = \sqrt{\textstyle\sum_i A_i (f_i - \tilde f_i)^2} \big/
               \sqrt{\textstyle\sum_i A_i f_i^2}

    **Arguments:**

    - `reference`: ``(..., n)`` the true functions ``f`` (for a transfer: ``f ∘ T`` on the
      target).
    - `estimate`: ``(..., n)`` the approximations / transferred functions ``f̃``; broadcasts
      against ``reference``.
    - `mass`: ``(n,)`` (or broadcastable ``(..., n)``) vertex areas ``A_i ≥ 0`` of the shape the
      functions live on (``Spectrum.mass``).

    **Returns:**

    ``(...)`` errors, one per function, in the promoted float dtype.  It is the **square
    root** of the ratio of integrals (square it for the paper's ratio form).  Zero-norm
    rule: where ``‖f‖_A = 0`` the result is the absolute error ``‖f̃‖_A`` (so ``0`` when both
    vanish), never NaN or inf.  ``f`` counts as zero when it is below the working dtype's
    smallest normal number relative to ``max(|f|, |f̃|)`` (1e-38 in float32: ``f = 1e-205``
    beside ``f̃ = 1``); a ratio beyond the dtype's range is its largest value.

    **Raises:**

    - `BSFError`: non-numeric / non-finite inputs, mismatched last axes, negative or all-zero
      mass (checked before tracing when the inputs are concrete).

    Works under ``jit`` / ``vmap`` with traced inputs (value checks are then skipped).
    """
    reference = _check(reference, "reference")
    estimate = _check(estimate, "estimate")
    mass = _check(mass, "mass")
    n = reference.shape[-1]
    if estimate.shape[-1] != n or mass.shape[-1] != n:
        raise BSFError(f"reference, estimate and mass must share the last axis (n vertices), got "
                       f"shapes {tuple(reference.shape)}, {tuple(estimate.shape)}, "
                       f"{tuple(mass.shape)}")
    try:
        np.broadcast_shapes(tuple(reference.shape), tuple(estimate.shape), tuple(mass.shape))
    except ValueError:
        raise BSFError(f"reference {tuple(reference.shape)}, estimate {tuple(estimate.shape)} and "
                       f"mass {tuple(mass.shape)} do not broadcast") from None
    if not isinstance(mass, jax.core.Tracer):
        m = np.asarray(mass)
        if np.any(m < 0) or not np.all(np.any(m > 0, axis=-1)):
            raise BSFError("mass must be >= 0 with at least one positive vertex area")
    if any(isinstance(x, jax.core.Tracer) for x in (reference, estimate, mass)):
        return _relative_error(reference, estimate, mass)
    # concrete inputs: the unit-scale rescaling of _relative_error done first, on the host in
    # float64, so float64 values beyond the float32 range survive the cast
    dt = jax.dtypes.canonicalize_dtype(np.result_type(reference.dtype, estimate.dtype,
                                                      mass.dtype, np.float32))
    f, e, w = (np.asarray(x, np.float64) for x in (reference, estimate, mass))
    s = pow2_scale(np.maximum(np.max(np.abs(f), axis=-1), np.max(np.abs(e), axis=-1)))
    ws = pow2_scale(np.max(w, axis=-1), even=True)  # exact rescalings (powers of 2 and 4)
    f, e, w = f / s[..., None], e / s[..., None], w / ws[..., None]
    # XLA's CPU flushes subnormals to zero: so do we, so that the zero-norm rule below sees
    # the f the computation sees
    tiny = np.finfo(dt).tiny
    f, e = (np.where(np.abs(x) < tiny, 0.0, x) for x in (f, e))
    out = _relative_error(jnp.asarray(f, dt), jnp.asarray(e, dt), jnp.asarray(w, dt))
    # the absolute-error rule where f is zero in the working dtype: restore its units
    zero = ~np.any(f != 0, axis=-1)
    unit = np.minimum(np.where(zero, s * np.sqrt(ws), 1.0), np.finfo(dt).max)
    return out * jnp.asarray(unit, dt)
