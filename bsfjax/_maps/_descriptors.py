"""Spectral point descriptors: heat and wave kernel signatures, and their landmark versions.

From a spectrum (λ_l, φ_l) ``l = 1..k`` of a shape with total area ``S``:

* **HKS** (Sun, Ovsjanikov & Guibas 2009): ``HKS(x, t) = Σ_l e^{−t λ_l} φ_l(x)²``.
* **WKS** (Aubry, Schlickewei & Cremers 2011): for log-energy ``e``,
  ``WKS(x, e) = Σ_l exp(−(e − log λ_l)² / 2σ²) φ_l(x)²``; zero eigenvalues (constants) are
  left out.
* **Landmark** versions centre the kernel at a vertex ``y`` instead of the diagonal:
  ``Σ_l w_l φ_l(y) φ_l(x)`` with the same weights ``w_l`` (a heat kernel ``k_t(y, ·)``, or a
  "wave" function of energy ``e`` around ``y``).

Conventions (those of pyFM, which descend from Aubry's code):

* ``scaled=True`` divides each column by ``Σ_l w_l`` (Aubry's normalization ``C_e``), so the
  scales or energies weigh alike.
* Automatic HKS times: ``n_times`` log-spaced in ``[4 ln 10 / λ_k, 4 ln 10 / λ₂]``.
* Automatic WKS energies: ``e_min = log λ₂``, ``e_max = log λ_k``, ``σ = variance·(e_max − e_min)
  / n_energies`` and ``n_energies`` equispaced energies in ``[e_min + 2σ, e_max − 2σ]``
  (``variance = 7``).  Aubry's original uses σ = 6 energy steps and ``e_max / 1.02`` instead.
* ``area_normalize=True`` (default) evaluates everything on the shape rescaled to unit area,
  λ ↦ λ·S and φ ↦ φ·√S.  Descriptors then do not depend on the size of the shape, and times
  ``t`` or energies ``e`` given by the caller mean the same on every shape.  With automatic
  times/energies this changes each column only by the constant factor ``S`` (before
  ``scaled``), so it does not change what a functional map estimated from L2-normalized
  descriptors sees.

Everything is batched: a stacked ``Spectrum`` (leading batch axes on ``evals``, ``evecs`` and
``mass``) gives stacked descriptors.  Column order of landmark descriptors is landmark-major:
column ``l * n_scales + s`` is scale ``s`` centred at landmark ``l`` (as in pyFM).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._util import check_real
from .._util import BSFError
from .._spectral import Spectrum

__all__ = ["hks", "wks", "hks_times", "wks_energies"]

#: Eigenvalues below this fraction of the largest are treated as 0 (constant eigenfunctions).
ZERO_EIG_RTOL = 1e-8


# --------------------------------------------------------------------------- validation


def _check(spectrum, name="spectrum") -> tuple[int, int, tuple[int, ...]]:
    if not isinstance(spectrum, Spectrum):
        raise BSFError(f"{name} must be a bsfjax.Spectrum, got {type(spectrum).__name__}")
    shape = np.shape(spectrum.evecs)
    if len(shape) < 2:
        raise BSFError(f"{name}.evecs must be (..., n, k), got shape {shape}")
    *batch, n, k = shape
    if k < 2:
        raise BSFError(f"{name} needs at least 2 eigenpairs for automatic scales, got k={k}")
    return n, k, tuple(batch)


def _check_nonzero(spectrum, k: int, what: str) -> None:
    """Automatic scales (and every WKS weight) need a non-zero eigenvalue besides λ₁."""
    ev = np.abs(np.asarray(spectrum.evals)[..., :k], dtype=np.float64)
    top = ev.max(axis=-1, keepdims=True)
    ok = np.any((ev > ZERO_EIG_RTOL * top) & (top > 0), axis=-1)
    if not np.all(ok):
        raise BSFError(f"{what} needs a non-zero eigenvalue among the first k={k}, but "
                       f"{int(np.size(ok) - np.count_nonzero(ok))} spectrum(s) have only zero "
                       "eigenvalues (a constant basis): use a larger k")


def _check_count(value, name: str) -> int:
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
        raise BSFError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _check_landmarks(landmarks, n: int, batch: tuple[int, ...]) -> np.ndarray | None:
    if landmarks is None:
        return None
    lm = np.asarray(landmarks)
    if lm.ndim == 0:
        lm = lm[None]
    if not np.issubdtype(lm.dtype, np.integer):
        raise BSFError(f"landmarks must be integer vertex indices, got dtype {lm.dtype}")
    if lm.shape[-1] == 0:
        raise BSFError("landmarks must hold at least one vertex index")
    if lm.ndim > 1 and lm.shape[:-1] != batch:
        raise BSFError(f"landmarks must be (p,) or (*batch, p) with batch {batch}, got {lm.shape}")
    if lm.min() < 0 or lm.max() >= n:
        raise BSFError(f"landmarks must be vertex indices in [0, {n}), found range "
                       f"[{lm.min()}, {lm.max()}]")
    return lm.astype(np.int32)


def _check_k(k, k_avail: int) -> int:
    if k is None:
        return k_avail
    if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or not 2 <= k <= k_avail:
        raise BSFError(f"k must be an integer in [2, {k_avail}] (eigenpairs available), got {k!r}")
    return int(k)


def _as_floats(values, name: str) -> np.ndarray:
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise BSFError(f"{name} must be numbers, got {values!r}") from None


def _scales(values, name: str, batch: tuple[int, ...]) -> np.ndarray:
    arr = _as_floats(values, name)
    if arr.ndim == 0:
        arr = arr[None]
    if arr.shape[-1] == 0 or not np.all(np.isfinite(arr)):
        raise BSFError(f"{name} must be a non-empty array of finite numbers, got {values!r}")
    if arr.ndim > 1 and arr.shape[:-1] != batch:
        raise BSFError(f"{name} must be (T,) or (*batch, T) with batch {batch}, got {arr.shape}")
    return arr


# --------------------------------------------------------------------------- jitted core


def _prepare(evals, evecs, mass, area_normalize: bool):
    """Float arrays, optionally rescaled to unit area: λ·S and φ·√S (S = Σ mass)."""
    dt = jnp.result_type(float)
    evals = jnp.abs(jnp.asarray(evals, dt))  # tiny negative round-off of λ₁ = 0
    evecs = jnp.asarray(evecs, dt)
    if area_normalize:
        area = jnp.sum(jnp.asarray(mass, dt), axis=-1)
        evals = evals * area[..., None]
        evecs = evecs * jnp.sqrt(area)[..., None, None]
    return evals, evecs


def _nonzero(evals):
    """Mask of the non-constant eigenpairs and the smallest non-zero eigenvalue, per shape."""
    keep = evals > ZERO_EIG_RTOL * jnp.max(evals, axis=-1, keepdims=True)
    lam_min = jnp.min(jnp.where(keep, evals, jnp.inf), axis=-1)
    return keep, lam_min


def _auto_times(evals, n_times: int):
    """``n_times`` log-spaced times in [4 ln10 / λ_max, 4 ln10 / λ_min⁺] per shape."""
    _, lam_min = _nonzero(evals)
    lo = jnp.log(4 * math.log(10) / jnp.max(evals, axis=-1))
    hi = jnp.log(4 * math.log(10) / lam_min)
    frac = jnp.linspace(0.0, 1.0, n_times)
    return jnp.exp(lo[..., None] + (hi - lo)[..., None] * frac)


def _auto_energies(evals, n_energies: int, variance: float):
    """Equispaced log-energies and σ per shape (pyFM / Aubry convention, see module doc)."""
    _, lam_min = _nonzero(evals)
    e_min = jnp.log(lam_min)
    e_max = jnp.log(jnp.max(evals, axis=-1))
    # a single distinct non-zero eigenvalue (k = 2, or a degenerate spectrum) has no energy
    # range: one e-fold instead, never σ = 0 (0/0 in the weights)
    span = jnp.where(e_max > e_min, e_max - e_min, 1.0)
    sigma = variance * span / n_energies
    frac = jnp.linspace(0.0, 1.0, n_energies)
    lo, hi = e_min + 2 * sigma, e_max - 2 * sigma
    return lo[..., None] + (hi - lo)[..., None] * frac, sigma


def _signature(weights, evecs, landmarks, scaled: bool):
    """Σ_l w_{s,l} φ_l(x)² (or φ_l(y) φ_l(x) for landmarks y).

    weights: (..., S, k); evecs: (..., n, k); landmarks: None, (p,) or (..., p).
    Returns (..., n, S) or (..., n, p·S) landmark-major.
    """
    if scaled:  # a column whose weights all underflow to 0 stays 0 (not 0/0 = NaN)
        total = jnp.sum(weights, axis=-1, keepdims=True)
        weights = weights / jnp.where(total > 0, total, 1.0)
    if landmarks is None:
        return jnp.einsum("...sk,...nk->...ns", weights, evecs * evecs)
    if landmarks.ndim == 1:
        at = evecs[..., landmarks, :]  # (..., p, k)
    else:
        at = jnp.take_along_axis(evecs, landmarks[..., :, None], axis=-2)
    out = jnp.einsum("...sk,...pk,...nk->...nps", weights, at, evecs)
    return out.reshape(*out.shape[:-2], -1)


@functools.partial(jax.jit, static_argnames=("n_times", "area_normalize", "scaled"))
def _hks_jit(evals, evecs, mass, times, landmarks, *, n_times, area_normalize, scaled):
    evals, evecs = _prepare(evals, evecs, mass, area_normalize)
    if times is None:
        times = _auto_times(evals, n_times)
    times = jnp.asarray(times, evals.dtype)
    weights = jnp.exp(-times[..., :, None] * evals[..., None, :])  # (..., T, k)
    return _signature(weights, evecs, landmarks, scaled)


@functools.partial(jax.jit, static_argnames=("n_energies", "area_normalize", "scaled"))
def _wks_jit(evals, evecs, mass, energies, sigma, landmarks, variance, *, n_energies,
             area_normalize, scaled):
    evals, evecs = _prepare(evals, evecs, mass, area_normalize)
    keep, _ = _nonzero(evals)
    if energies is None:
        energies, auto_sigma = _auto_energies(evals, n_energies, variance)
        sigma = auto_sigma if sigma is None else sigma
    energies = jnp.asarray(energies, evals.dtype)
    sigma = jnp.asarray(sigma, evals.dtype)
    log_ev = jnp.log(jnp.where(keep, evals, 1.0))
    gap = energies[..., :, None] - log_ev[..., None, :]  # (..., E, k)
    weights = jnp.exp(-gap * gap / (2 * sigma[..., None, None] ** 2))
    weights = jnp.where(keep[..., None, :], weights, 0.0)  # constants carry no energy
    return _signature(weights, evecs, landmarks, scaled)


# --------------------------------------------------------------------------- public API


def hks(spectrum: Spectrum, n_times: int = 100, *, times=None, landmarks=None, k: int | None = None,
        area_normalize: bool = True, scaled: bool = True) -> jax.Array:
    """Heat kernel signature ``Σ_l e^{−t λ_l} φ_l(x)²``, or heat kernels at ``landmarks``.

    **Arguments:**

    - `spectrum`: a ``Spectrum``, possibly stacked (``(..., n, k)`` evecs).
    - `n_times`: number of automatic times (log-spaced in [4 ln10/λ_k, 4 ln10/λ₂]); ignored when
      ``times`` is given.
    - `times`: ``(T,)`` or ``(..., T)`` diffusion times (on the unit-area shape when
      ``area_normalize``).
    - `landmarks`: ``(p,)`` or ``(..., p)`` vertex indices: return the heat kernels
      ``Σ_l e^{−t λ_l} φ_l(y) φ_l(x)`` centred at each landmark ``y`` instead.
    - `k`: use only the first ``k`` eigenpairs (default: all).
    - `area_normalize`: evaluate on the shape rescaled to unit area (see module doc).
    - `scaled`: divide each column by ``Σ_l e^{−t λ_l}``.

    **Returns:**

    ``(..., n, T)``, or ``(..., n, p·T)`` landmark-major with ``landmarks``.
    """
    n, k_avail, batch = _check(spectrum)
    k = _check_k(k, k_avail)
    lm = _check_landmarks(landmarks, n, batch)
    if times is None:
        _check_nonzero(spectrum, k, "hks with automatic times")
        n_times = _check_count(n_times, "n_times")
    else:
        times = _scales(times, "times", batch)
        if np.any(times <= 0):
            raise BSFError(f"times must be positive, got min {times.min()}")
        n_times = times.shape[-1]
    return _hks_jit(spectrum.evals[..., :k], spectrum.evecs[..., :k], spectrum.mass, times, lm,
                    n_times=n_times, area_normalize=bool(area_normalize), scaled=bool(scaled))


def wks(spectrum: Spectrum, n_energies: int = 100, *, energies=None, sigma=None,
        variance: float = 7.0, landmarks=None, k: int | None = None, area_normalize: bool = True,
        scaled: bool = True) -> jax.Array:
    """Wave kernel signature ``Σ_l exp(−(e − log λ_l)²/2σ²) φ_l(x)²`` (Aubry et al. 2011).

    **Arguments:**

    - `spectrum`: a ``Spectrum``, possibly stacked.
    - `n_energies`: number of automatic log-energies (see module doc); ignored when
      ``energies`` is given.
    - `energies`: ``(E,)`` or ``(..., E)`` log-energies ``e`` (of the unit-area shape when
      ``area_normalize``).
    - `sigma`: width σ of the log-energy filters; default ``variance · (e_max − e_min) / E``
      (required to be given with ``energies`` unless automatic).
    - `variance`: σ in units of the energy range divided by ``n_energies`` (pyFM: 7).
    - `landmarks`: ``(p,)`` or ``(..., p)`` vertex indices: return
      ``Σ_l w_l(e) φ_l(y) φ_l(x)`` centred at each landmark ``y``.
    - `k`: use only the first ``k`` eigenpairs (default: all).
    - `area_normalize`, `scaled`: as in [`hks`][bsfjax.hks].

    **Returns:**

    ``(..., n, E)``, or ``(..., n, p·E)`` landmark-major with ``landmarks``.
    """
    n, k_avail, batch = _check(spectrum)
    k = _check_k(k, k_avail)
    lm = _check_landmarks(landmarks, n, batch)
    variance = check_real(variance, "variance", positive=True)
    _check_nonzero(spectrum, k, "wks")
    if energies is None:
        n_energies = _check_count(n_energies, "n_energies")
    else:
        energies = _scales(energies, "energies", batch)
        n_energies = energies.shape[-1]
        if sigma is None:
            raise BSFError("sigma must be given together with explicit energies")
    if sigma is not None:
        sig = _as_floats(sigma, "sigma")
        if not np.all(np.isfinite(sig)) or np.any(sig <= 0):
            raise BSFError(f"sigma must be positive and finite, got {sigma!r}")
        if sig.ndim > 0 and sig.shape != batch:
            raise BSFError(f"sigma must be a scalar or have the batch shape {batch}, got "
                           f"{sig.shape}")
        sigma = sig
    return _wks_jit(spectrum.evals[..., :k], spectrum.evecs[..., :k], spectrum.mass, energies,
                    sigma, lm, float(variance), n_energies=n_energies,
                    area_normalize=bool(area_normalize), scaled=bool(scaled))


def hks_times(spectrum: Spectrum, n_times: int = 100, *, area_normalize: bool = True):
    """The automatic HKS times [`hks`][bsfjax.hks] uses, ``(..., n_times)``."""
    _check(spectrum)
    evals, _ = _prepare(spectrum.evals, spectrum.evecs[..., :1, :], spectrum.mass, area_normalize)
    return _auto_times(evals, _check_count(n_times, "n_times"))


def wks_energies(spectrum: Spectrum, n_energies: int = 100, *, variance: float = 7.0,
                 area_normalize: bool = True):
    """The automatic WKS log-energies ``(..., E)`` and σ ``(...)`` [`wks`][bsfjax.wks] uses."""
    _check(spectrum)
    evals, _ = _prepare(spectrum.evals, spectrum.evecs[..., :1, :], spectrum.mass, area_normalize)
    return _auto_energies(evals, _check_count(n_energies, "n_energies"), float(variance))
