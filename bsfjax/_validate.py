"""Input checks shared by the public entry points (run before anything is traced).

Each helper raises :class:`bsfjax.BSFError` with a message that names the argument and the
offending value; traced values (inside ``jit``/``vmap``) cannot be inspected and pass through.
"""

from __future__ import annotations

import math
import numbers

import jax
import numpy as np

from ._errors import BSFError

__all__ = ["is_traced", "check_finite", "check_real", "check_int", "magnitude_limit"]


def is_traced(x) -> bool:
    """Whether ``x`` is an abstract value of a JAX transformation (no concrete data)."""
    return isinstance(x, jax.core.Tracer)


def check_finite(x, name: str) -> None:
    """Raise unless the concrete array ``x`` holds real numbers that are all finite."""
    if is_traced(x):
        return
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise BSFError(f"{name} must be a numeric array, got {type(x).__name__} ({exc})") from None
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_) \
            or np.issubdtype(arr.dtype, np.complexfloating):
        raise BSFError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
    if bad:
        raise BSFError(f"{name} contains {bad} NaN or infinite values")


def check_real(value, name: str, *, positive: bool = False) -> float:
    """A finite real number (``> 0`` with ``positive``) as a ``float``; bools are rejected."""
    ok = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
    if not ok or not math.isfinite(value) or (positive and value <= 0):
        what = "a positive finite number" if positive else "a finite number"
        raise BSFError(f"{name} must be {what}, got {value!r}")
    return float(value)


def check_int(value, name: str, lo: int, hi: int | None = None) -> int:
    """An ``int`` in ``[lo, hi]`` (``hi=None``: no upper bound); bools and floats are rejected."""
    bounds = f"[{lo}, {hi}]" if hi is not None else f">= {lo}"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise BSFError(f"{name} must be an integer {bounds}, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        raise BSFError(f"{name} must be an integer {bounds}, got {value}")
    return int(value)


def magnitude_limit(n: int, dtype) -> float:
    """Largest ``max |f|`` for which sums of ``n`` products of such values (norms ``Σ f²``,
    correlations ``Bᵀf`` and their squares) stay finite in ``dtype``: ``√max / (10 n)``."""
    return math.sqrt(float(np.finfo(dtype).max)) / (10.0 * max(int(n), 1))
