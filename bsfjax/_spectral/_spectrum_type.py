"""The [`Spectrum`][bsfjax.Spectrum] pytree and its rescaling. Owner of the type itself (checks,
truncation), `stack_spectra` (for ``vmap``) and the rescaling of one shape or a pair to unit
area (`unit_area`, `unit_area_pair`, `map_to_unit_area`) that keeps later float32 stages at
unit scale; the eigensolves that produce spectra live in `bsfjax._spectral._spectrum`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._util import BSFError

__all__ = ["Spectrum", "stack_spectra", "unit_area", "unit_area_pair", "map_to_unit_area"]


class Spectrum(eqx.Module):
    """The first ``k`` Laplace–Beltrami eigenpairs of a shape.

    **Attributes:**

    - `evals`: ``(k,)`` eigenvalues λ₁ ≤ … ≤ λ_k (λ₁ = 0 on a connected shape; clipped at 0).
    - `evecs`: ``(n, k)`` eigenvectors Φ, A-orthonormal: Φᵀ A Φ = I.
    - `mass`: ``(n,)`` diagonal of the lumped mass matrix A (vertex areas).

    Sign convention: every eigenvector has its entry of largest magnitude positive, so the same
    input always gives the same basis.  ``Spectrum`` is a pytree: pass it to jitted functions, or
    stack several of equal shapes with ``jax.tree.map(lambda *x: jnp.stack(x), *spectra)`` to
    ``vmap`` over shapes.

    Constructing a ``Spectrum`` from concrete arrays checks them ([`bsfjax.BSFError`][bsfjax.BSFError]):
    matching shapes, real finite values, ``mass >= 0`` with a positive finite total;
    traced values are not checked.
    """

    evals: np.ndarray
    evecs: np.ndarray
    mass: np.ndarray

    def __check_init__(self):
        # Shapes and values are checked whenever a Spectrum is built from concrete arrays, so
        # a NaN eigenvector or a negative area stops here instead of inside a jitted stage.
        # (Pytree operations — vmap, jax.tree.map, stacking — do not run this check.)
        arrays = (self.evals, self.evecs, self.mass)
        if not all(isinstance(a, (np.ndarray, jax.Array)) for a in arrays) \
                or any(isinstance(a, jax.core.Tracer) for a in arrays):
            return  # traced or abstract values: nothing concrete to check
        ev, phi, m = (tuple(a.shape) for a in arrays)
        if len(ev) < 1 or len(phi) < 2 or len(m) < 1 or phi[-1] != ev[-1] or phi[-2] != m[-1] \
                or not (phi[:-2] == ev[:-1] == m[:-1]):
            raise BSFError(f"Spectrum needs evals (..., k), evecs (..., n, k) and mass (..., n) "
                           f"with equal batch axes, got shapes {ev}, {phi}, {m}")
        for name, a in zip(("evals", "evecs", "mass"), arrays):
            if not (jnp.issubdtype(a.dtype, jnp.floating) or jnp.issubdtype(a.dtype, jnp.integer)):
                raise BSFError(f"Spectrum.{name} must be real numbers, got dtype {a.dtype}")
            bad = int(jnp.sum(~jnp.isfinite(a))) if isinstance(a, jax.Array) \
                else int(np.sum(~np.isfinite(a)))
            if bad:
                raise BSFError(f"Spectrum.{name} contains {bad} NaN or infinite values")
        neg = int(jnp.sum(self.mass < 0)) if isinstance(self.mass, jax.Array) \
            else int(np.sum(self.mass < 0))
        if neg:
            raise BSFError(f"Spectrum.mass (vertex areas) must be >= 0, found {neg} negative "
                           "entries")
        # every later stage divides by the total area (unit-area rescaling, norms)
        with np.errstate(over="ignore"):
            total = np.sum(np.asarray(self.mass, np.float64), axis=-1)
        bad = ~(np.isfinite(total) & (total > 0))
        if np.any(bad):
            i = int(np.flatnonzero(np.reshape(bad, -1))[0])
            where = "" if np.ndim(total) == 0 else f" (spectrum {i} of the stack)"
            raise BSFError(f"Spectrum.mass (vertex areas) must have a positive, finite total, "
                           f"got {np.reshape(total, -1)[i]:.3g}{where}: every stage divides by "
                           "the area")

    @property
    def k(self) -> int:
        return int(self.evals.shape[-1])

    @property
    def n_vertices(self) -> int:
        return int(self.evecs.shape[-2])

    @property
    def area(self):
        """Total area Σ A_ii (a scalar, or an array for a stacked Spectrum)."""
        return self.mass.sum(axis=-1)

    def truncate(self, k: int) -> "Spectrum":
        """The first ``k`` eigenpairs."""
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)) \
                or not 1 <= k <= self.k:
            raise BSFError(f"k must be an integer in [1, {self.k}], got {k!r}")
        return Spectrum(self.evals[..., :k], self.evecs[..., :k], self.mass)


def stack_spectra(spectra) -> Spectrum:
    """Stack spectra of equal ``(n, k)`` along a new leading axis, for ``vmap`` over shapes."""
    spectra = list(spectra)
    if not spectra or not all(isinstance(s, Spectrum) for s in spectra):
        raise BSFError("spectra must be a non-empty sequence of bsfjax.Spectrum, got "
                       f"{[type(s).__name__ for s in spectra]}")
    shapes = {(s.n_vertices, s.k) for s in spectra}
    if len(shapes) != 1:
        raise BSFError(f"spectra to stack must share (n_vertices, k); got {sorted(shapes)}")
    return jax.tree.map(lambda *x: np.stack(x), *spectra)


def unit_area_pair(source: Spectrum, target: Spectrum):
    """``(source', a_M, target', a_N)``: the two spectra rescaled to one area near 1, the
    source as `unit_area` does (``a_M`` the power of 4 nearest ``S_M``), the target by
    ``a_N = a_M·S_N/S_M`` (per pair of a stack).

    What a pair-level computation needs: descriptor and Laplacian-commutativity terms compare
    the two shapes' eigenvalues and descriptors, and ZoomOut's nearest neighbours (``Φ_M Cᵀ``
    against ``Φ_N``) presume an orthogonal ``C``, which an isometry has only between shapes of
    one area.  So a target in millimetres and a source in metres are matched as two shapes in
    metres (one common factor for both, keeping their relative scale, gets such a pair
    2 % of the SMPL parts right).  Two shapes of equal area keep exact power-of-4 factors: the
    results of the unscaled shapes bit for bit.  Returns ``(source, None, target, None)`` for
    traced arrays or areas that are not finite and positive.
    """
    import jax

    specs = (source, target)
    if any(isinstance(x, jax.core.Tracer) for s_ in specs for x in (s_.evals, s_.evecs, s_.mass)):
        return source, None, target, None
    areas = [np.asarray(s_.mass, np.float64).sum(axis=-1) for s_ in specs]
    if not all(np.all(np.isfinite(a)) and np.all(a > 0) for a in areas):
        return source, None, target, None
    from .._util import pow2_scale

    a_m = np.asarray(pow2_scale(areas[0], even=True))
    a_n = a_m * (areas[1] / areas[0])  # = a_m, exactly, for equal areas
    return _rescaled(source, a_m), a_m, _rescaled(target, a_n), a_n


def _rescaled(spec: Spectrum, a) -> Spectrum:
    if np.all(a == 1) and all(isinstance(x, np.ndarray) and x.dtype == np.float64
                              for x in (spec.evals, spec.evecs, spec.mass)):
        return spec  # already what the rescaling would give: no n × k copy (the steps after
        # estimate_map's own rescaling see the source at factor 1)
    return Spectrum(np.asarray(spec.evals, np.float64) * a[..., None],
                    np.asarray(spec.evecs, np.float64) * np.sqrt(a)[..., None, None],
                    np.asarray(spec.mass, np.float64) / a[..., None])


def unit_area(spec: Spectrum):
    """``(spectrum of the shape rescaled to unit area, area)``, computed on the host in float64.

    ``λ ↦ λ·S``, ``Φ ↦ Φ·√S``, ``A ↦ A/S`` with ``S ≈ Σ A`` (the nearest power of 4; per
    shape of a stack), so the
    stages after the spectrum, which cast to float32 by default, see unit-scale numbers: a mesh
    in units of 1e-20 or 1e20 (areas 1e±40, beyond float32) works like one in metres.  A map
    ``C`` between the original bases is ``C' = C·√(S_M/S_N)`` between the unit-area ones; a
    function's values do not change.  Returns ``(spec, None)`` for traced arrays (no change).
    """
    import jax

    if any(isinstance(x, jax.core.Tracer) for x in (spec.evals, spec.evecs, spec.mass)):
        return spec, None
    from .._util import pow2_scale

    mass = np.asarray(spec.mass, np.float64)
    area = mass.sum(axis=-1)
    if not np.all(np.isfinite(area)) or not np.all(area > 0):
        return spec, None  # nothing to normalize by (the Spectrum check reports bad areas)
    # S rounded to a power of 4: the rescaling (and √S) is exact, so a mesh of ordinary size
    # gives bit-identical results, and the areas end up in [0.5, 2]
    a = np.asarray(pow2_scale(area, even=True))
    out = Spectrum(np.asarray(spec.evals, np.float64) * a[..., None],
                   np.asarray(spec.evecs, np.float64) * np.sqrt(a)[..., None, None],
                   mass / a[..., None])
    return out, a


def map_to_unit_area(C, area_source, area_target, inverse: bool = False):
    """``C·√(S_M/S_N)`` (a map between original bases → between unit-area bases), or the
    inverse; ``C`` unchanged when an area is ``None`` (traced).  A host array (or list) comes
    back as a float64 numpy array, a JAX array in its dtype."""
    if C is None or area_source is None or area_target is None:
        return C
    r = np.sqrt(np.asarray(area_source, np.float64) / np.asarray(area_target, np.float64))
    r = 1.0 / r if inverse else r
    if np.ndim(r):
        r = r[..., None, None]
    if not isinstance(C, jax.Array):
        return np.asarray(C, np.float64) * r
    return C * jnp.asarray(r, jnp.result_type(C))
