"""Input checks shared by the public entry points (run before anything is traced).

Each helper raises [`bsfjax.BSFError`][bsfjax.BSFError] with a message that names the argument and the
offending value; traced values (inside ``jit``/``vmap``) cannot be inspected and pass through.
"""

from __future__ import annotations

import math
import numbers

import jax
import numpy as np

from ._errors import BSFError

__all__ = ["require_triangles", "is_traced", "check_finite", "check_real", "check_int", "magnitude_limit",
           "check_indices", "compact_labels", "check_source_mesh", "unit_scale", "restore_scale",
           "pow2_scale", "homogeneous"]


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


def _given(arr: np.ndarray, i: int) -> str:
    """Element ``i`` of ``arr`` as the user wrote it (``uint64`` stays unsigned, floats keep
    their fraction)."""
    return str(arr.reshape(-1)[i].item())


def non_integer_entry(arr, *, negative: bool = True) -> int | None:
    """Flat index of the first entry of a numeric array that is not a finite integer an int64
    holds (or is negative, unless ``negative``), or ``None``: the value as read, before a
    cast would wrap it around."""
    a = np.asarray(arr).reshape(-1)
    bad = ~np.isfinite(a) | (np.mod(a, 1) != 0) | (np.abs(a) >= 2.0 ** 63)
    if not negative:
        bad |= a < 0
    return int(np.argmax(bad)) if bad.any() else None


def check_indices(idx, name: str, n: int, *, what: str = "vertex indices",
                  allow_empty: bool = False) -> np.ndarray:
    """Concrete integer indices in ``[0, n)`` as an ``int64`` numpy array.

    Negative indices are an error (numpy and JAX would wrap them around to the last vertex),
    floats are an error even when whole (a float index is usually a wrong file or column), and
    every message prints the offending value as given (a ``uint64`` 2⁶⁴−1 is not shown as −1).
    """
    try:
        arr = np.asarray(idx)
    except (TypeError, ValueError) as exc:
        raise BSFError(f"{name} must be an array of {what}, got {type(idx).__name__} "
                       f"({exc})") from None
    if arr.dtype == np.bool_ or not np.issubdtype(arr.dtype, np.integer):
        sample = f" (first: {_given(arr, 0)})" if arr.size and arr.dtype != object else ""
        raise BSFError(f"{name} must be integer {what}, got dtype {arr.dtype}{sample}")
    if arr.size == 0:
        if allow_empty:
            return arr.astype(np.int64)
        raise BSFError(f"{name} is empty: expected {what}")
    bad = (arr < 0) | (arr >= n)
    if bad.any():
        first = int(np.argmax(bad.reshape(-1)))
        raise BSFError(f"{name} must be {what} in [0, {n}), found {int(bad.sum())} outside "
                       f"(first: {name}[{first}] = {_given(arr, first)}; range "
                       f"[{arr.min().item()}, {arr.max().item()}])")
    return arr.astype(np.int64)


def compact_labels(labels, name: str = "labels") -> tuple[np.ndarray, np.ndarray]:
    """``(ids, codes)``: the distinct labels in increasing order and each entry's position
    among them (``labels == ids[codes]``), so that per-label arrays have ``len(ids)`` rows
    whatever the label values (an id of 10¹² must not allocate 10¹² rows)."""
    lab = np.asarray(labels)
    if lab.dtype == np.bool_ or not np.issubdtype(lab.dtype, np.integer):
        raise BSFError(f"{name} must be integers, got dtype {lab.dtype}")
    if lab.size == 0:
        raise BSFError(f"{name} is empty")
    if lab.min() < 0:
        raise BSFError(f"{name} must be >= 0, got min {lab.min().item()}")
    ids, codes = np.unique(lab, return_inverse=True)
    return ids, codes.reshape(lab.shape).astype(np.int64)


def check_source_mesh(mesh, n_vertices: int, mass, name: str = "mesh",
                      role: str = "source") -> None:
    """Raise unless ``mesh`` (a [`bsfjax.Mesh`][bsfjax.Mesh] or ``(n, 3)`` points) is the shape whose
    spectrum has ``n_vertices`` vertices and areas ``mass``: the vertex count must match, and
    for a Mesh its total area must equal ``Σ mass`` (a pose of the same template has the same
    count but another area).  ``role``: which of the pair's shapes it is, for the messages."""
    if hasattr(mesh, "faces") and hasattr(mesh, "vertices"):
        nv = int(np.shape(mesh.vertices)[0])
    else:
        shape = np.shape(mesh)
        if len(shape) != 2:
            raise BSFError(f"{name} must be a bsfjax.Mesh or (n, d) points, got shape {shape}")
        nv = shape[0]
    if nv != n_vertices:
        raise BSFError(f"{name} has {nv} vertices but the {role} spectrum has {n_vertices}: "
                       f"{name}= must be the {role} mesh")
    if not hasattr(mesh, "faces") or mass is None or is_traced(mass):
        return
    if getattr(mesh, "is_point_cloud", False) or getattr(mesh, "from_cloud", False):
        return  # (its area is the Laplacian's lumped area: the count check is what is cheap)
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces)
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                axis=1).sum()
    total = float(np.sum(np.asarray(mass, np.float64)))
    if not math.isclose(area, total, rel_tol=1e-4):
        raise BSFError(f"{name} has total area {area:.6g} but the {role} spectrum's areas sum "
                       f"to {total:.6g}: {name}= must be the {role} mesh (the one the {role} "
                       "spectrum was computed on)")


def require_triangles(mesh, why: str) -> None:
    """Raise [`BSFError`][bsfjax.BSFError] with the one line ``why`` (what needs triangles,
    and what to do instead) when ``mesh`` is a point cloud (a
    [`bsfjax.PointCloud`][bsfjax.PointCloud]); the file's name is appended."""
    if getattr(mesh, "is_point_cloud", False):
        where = f" ({mesh.name})" if getattr(mesh, "name", None) else ""
        raise BSFError(f"{why}{where}")


def unit_scale(f, dtype):
    """``(f / s, s)``: each function (last axis) divided by its largest magnitude ``s`` (rounded
    up to a power of two, see `pow2_scale`), on the
    host in float64 *before* the cast to ``dtype``, so that values of any magnitude (1e-30 or
    1e30 in float32) reach the kernels at unit scale: squares neither overflow nor underflow,
    and every method, being homogeneous of degree 1 in ``f``, gives ``s ·`` (its unit-scale
    result).  ``s`` is 1 for an all-zero function, and ``None`` (no rescaling) for traced
    ``f``."""
    import jax.numpy as jnp

    if is_traced(f):
        return jnp.asarray(f, dtype), None
    f64 = np.asarray(f, np.float64)
    if f64.ndim == 0 or f64.size == 0:
        return jnp.asarray(f64, dtype), None
    s = pow2_scale(np.max(np.abs(f64), axis=-1))
    return jnp.asarray(f64 / s[..., None], dtype), s


def pow2_scale(x, *, even: bool = False) -> np.ndarray:
    """The power of two nearest above ``x`` (``x`` > 0; 1 where ``x`` is 0), or with ``even`` the
    nearest power of four.  Dividing by a power of two is exact in floating point, so rescaled
    inputs of ordinary magnitude give bit-identical results to unrescaled ones."""
    x = np.asarray(x, np.float64)
    pos = x > 0
    if even:
        e = 2 * np.round(np.log2(np.where(pos, x, 1.0)) / 2).astype(np.int64)
    else:
        e = np.frexp(np.where(pos, x, 1.0))[1].astype(np.int64)
    return np.where(pos, np.ldexp(1.0, e), 1.0)


def homogeneous(obj) -> bool:
    """Whether a coder (or a method with a ``coder``) gives ``s·α`` for ``s·f``: not with an
    absolute residual bound (``ErrorOMP(eps=…)``, ``eps="spams"``) or a warm start (``init``),
    which fix a scale; then `unit_scale` is skipped."""
    for o in (obj, getattr(obj, "coder", None)):
        if o is not None and (getattr(o, "eps", None) is not None
                              or getattr(o, "init", None) is not None):
            return False
    return True


def restore_scale(x, s):
    """``x · s`` per function (inverse of `unit_scale`), in ``x``'s dtype; ``x`` may be
    ``None`` or a tuple of arrays."""
    if s is None or x is None:
        return x
    if isinstance(x, tuple):
        return tuple(restore_scale(v, s) for v in x)
    import jax.numpy as jnp

    return x * jnp.asarray(s, x.dtype)[..., None]
