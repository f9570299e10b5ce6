r"""Frame hygiene and scale selection: adaptive τ, distinct atoms, pruning.

Owner of: [`adaptive_taus`][bsfjax.adaptive_taus], `unique_atoms`, [`prune_frame`][bsfjax.prune_frame], and the input
checks shared with [`bsfjax.build_frame`][bsfjax.build_frame] / [`bsfjax.transfer_frame`][bsfjax.transfer_frame].  Everything
here works on any [`AbstractFrame`][bsfjax.AbstractFrame] (dense or sparse) through its interface.

Adaptive scales ([`adaptive_taus`][bsfjax.adaptive_taus], ``build_frame(..., taus="adaptive")``).  The paper's
fixed τ ∈ {0.001, 0.005, 0.01} give atoms whose size is set by the band limit once k is large
(at k = 50 on FAUST all three cover 1.4–4 % of the area), so sparse codes lack large atoms.
The adaptive choice measures the mean area share of the atoms as a function of τ on the
spectrum itself and picks a geometric series of shares from 1 % to 20 % of the surface.

Hygiene (`unique_atoms`, [`prune_frame`][bsfjax.prune_frame]).  Binarization can make two columns
identical (two scales at one centre, or neighbouring centres) or empty (a kernel that vanished
after transfer); such columns are masked or dropped, and ``frame.columns`` records which of the
built columns remain.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._binarize import build_core
from ._dense_frame import Frame
from .._util import BSFError
from ._operator import TAU_CONVENTIONS, AbstractFrame
from .._spectral import Spectrum

__all__ = ["adaptive_taus", "unique_atoms", "prune_frame", "ADAPTIVE_AREA_RANGE",
           "ADAPTIVE_N_SCALES"]

#: Default area-share range ``(lo, hi)`` of the atoms chosen by ``taus="adaptive"``.
ADAPTIVE_AREA_RANGE = (0.01, 0.20)
#: Default number of scales of ``taus="adaptive"``.
ADAPTIVE_N_SCALES = 6
_TAU_GRID = 32  # τ values probed by adaptive_taus
_N_PROBES = 64  # centres probed by adaptive_taus
_FLOOR_MARGIN = 1.25  # smallest chosen share ≥ this × the band-limit floor


@functools.partial(jax.jit, static_argnames=("n_scales", "unit_area"))
def _adaptive_core(evals, evecs, mass, probes, gamma, lo, hi, n_scales: int, unit_area: bool):
    """τ (in the frame's convention) whose mean atom area share follows a geometric series."""
    dt = evecs.dtype
    area = jnp.sum(mass)
    # flat-surface heat kernel exp(−d²/4t) (t = τ · area): [ĝ ≥ γ] is a disc of area
    # 4π t ln(1/γ), i.e. share 4π τ ln(1/γ) — only used to place the probe grid
    tau_of_share = 1.0 / (4.0 * jnp.pi * jnp.log(1.0 / gamma))
    grid = tau_of_share * jnp.exp(jnp.linspace(jnp.log(lo / 30.0), jnp.log(hi * 3.0),
                                               _TAU_GRID, dtype=dt))
    grid = grid if unit_area else grid * area
    atoms, _ = build_core(evals, evecs, mass, probes, grid,
                           jnp.full((_TAU_GRID,), gamma, dt), unit_area)
    share = jnp.mean((mass @ atoms).reshape(_TAU_GRID, -1), axis=1) / area
    share = jax.lax.cummax(share)  # larger τ never shrinks the mean atom
    lo_eff = jnp.maximum(lo, _FLOOR_MARGIN * share[0])  # the band limit's smallest atoms
    hi_eff = jnp.maximum(hi, lo_eff)
    targets = jnp.exp(jnp.linspace(jnp.log(lo_eff), jnp.log(hi_eff), n_scales, dtype=dt))
    # strictly increasing abscissae for the interpolation (ties from saturation)
    xs = jnp.log(share) + 1e-9 * jnp.arange(_TAU_GRID, dtype=dt)
    return jnp.exp(jnp.interp(jnp.log(targets), xs, jnp.log(grid)))


#: Fixed random rows of the support hashes of `unique_atoms` (two 32-bit hashes).
_HASH_SEED = 0x5EED


def _hash_rows(n: int) -> np.ndarray:
    return np.random.default_rng(_HASH_SEED).integers(0, 2**32, size=(2, n), dtype=np.uint32)


@jax.jit
def _unique_core(frame: AbstractFrame, r):
    """``(keep, representative)`` from two 32-bit hashes ``Σ_v [B_vj ≠ 0] r_v mod 2³²`` of
    every column's support: equal supports hash equally, distinct ones collide with
    probability 2⁻⁶⁴."""
    q = frame.n_atoms
    h1, h2 = frame.support_hashes(r)
    idx = jnp.arange(q)
    order = jnp.lexsort((idx, h2, h1))  # by hash, ties by column index
    s1, s2 = h1[order], h2[order]
    new_run = jnp.concatenate([jnp.ones(1, bool), (s1[1:] != s1[:-1]) | (s2[1:] != s2[:-1])])
    start = jax.lax.cummax(jnp.where(new_run, jnp.arange(q), 0))
    rep = jnp.zeros(q, order.dtype).at[order].set(order[start])  # first column of its run
    nonempty = frame.nonempty()
    return (rep == idx) & nonempty, jnp.where(nonempty, rep, -1).astype(jnp.int32)


# --------------------------------------------------------------------------- validation


def _concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def _check_spectrum(spectrum, name: str) -> None:
    if not isinstance(spectrum, Spectrum):
        raise BSFError(f"{name} must be a bsfjax.Spectrum, got {type(spectrum).__name__}")
    ev, phi, m = (tuple(np.shape(a)) for a in (spectrum.evals, spectrum.evecs, spectrum.mass))
    if len(ev) != 1 or len(m) != 1 or phi != (m[0], ev[0]):
        raise BSFError(f"{name} must have evals (k,), evecs (n, k), mass (n,) (one shape, not a "
                       f"stacked batch), got shapes {ev}, {phi}, {m}")


def _check_centers(centers, n: int) -> jax.Array | np.ndarray:
    if not _concrete(centers):
        if centers.ndim != 1 or centers.shape[0] == 0 or not jnp.issubdtype(centers.dtype,
                                                                             jnp.integer):
            raise BSFError(f"centers must be a non-empty 1-D integer array, got "
                           f"{centers.dtype}{tuple(centers.shape)}")
        return centers  # values cannot be range-checked while traced
    c = np.asarray(centers)
    if c.ndim == 0:
        c = c[None]
    if c.ndim != 1:
        raise BSFError(f"centers must be a 1-D array of vertex indices, got shape {c.shape}")
    if c.size == 0:
        raise BSFError("centers is empty: a frame needs at least one centre")
    if not np.issubdtype(c.dtype, np.integer) or c.dtype == np.bool_:
        raise BSFError(f"centers must be integer vertex indices, got dtype {c.dtype}")
    lo, hi = int(c.min()), int(c.max())
    if lo < 0 or hi >= n:
        raise BSFError(f"centers must index the {n} vertices (0..{n - 1}), found values in "
                       f"[{lo}, {hi}]")
    return c


def _as_float_vector(x, name: str) -> np.ndarray:
    if isinstance(x, (bool, np.bool_)) or not _concrete(x):
        raise BSFError(f"{name} must be a concrete number or sequence of numbers, got {x!r}")
    try:
        v = np.atleast_1d(np.asarray(x, dtype=np.float64))
    except (TypeError, ValueError) as exc:
        raise BSFError(f"{name} must be a number or a sequence of numbers, got {x!r}") from exc
    if v.ndim != 1 or v.size == 0:
        raise BSFError(f"{name} must be a number or a non-empty 1-D sequence, got shape "
                       f"{np.shape(x)}")
    return v


def _check_taus(taus) -> np.ndarray:
    t = _as_float_vector(taus, "taus")
    if not (np.isfinite(t).all() and (t > 0).all()):
        raise BSFError(f"taus must be positive and finite, got {t.tolist()}")
    return t


def _check_gammas(gamma, n_scales: int) -> np.ndarray:
    g = _as_float_vector(gamma, "gamma")
    if g.size == 1:
        g = np.repeat(g, n_scales)
    if g.size != n_scales:
        raise BSFError(f"gamma must be one float or one per tau ({n_scales}), got {g.size} "
                       f"values {g.tolist()}")
    if not (np.isfinite(g).all() and (g > 0).all() and (g < 1).all()):
        raise BSFError(f"gamma must be in the open interval (0, 1), got {g.tolist()}")
    return g


def adaptive_taus(spectrum: Spectrum, centers: Int[ArrayLike, " c"], *,
                  n_scales: int = ADAPTIVE_N_SCALES, area_range=ADAPTIVE_AREA_RANGE,
                  gamma: float = 0.75, tau_convention: str = "unit_area") -> Float[Array, " s"]:
    """Scales chosen from the spectrum: atoms whose mean area share spans ``area_range``.

    With ``s(τ)`` the mean area share ``Σ_v A_v B_v / Σ A`` of the atoms of scale τ (at up to
    64 of ``centers``, evenly spaced in their order; Algorithm 1 at this spectrum's ``k`` and
    ``gamma``), the ``n_scales`` scales are

        τ_i = s⁻¹(σ_i),   σ_i = lo' (hi'/lo')^{i/(n_scales−1)},   i = 0 … n_scales − 1,

    a geometric series of shares from ``lo' = max(lo, 1.25 · s(τ_min))`` to
    ``hi' = max(hi, lo')``.  ``s`` is tabulated on 32 geometrically spaced τ (around the
    flat-surface value ``s ≈ 4π τ ln(1/γ)`` of the unit-area heat kernel), made monotone
    (running maximum) and inverted by interpolation in ``log τ``.  ``s(τ_min)`` is the floor
    the band limit sets (a k-term kernel cannot be narrower than about the reproducing kernel
    ``Φ Φ[x]ᵀ``), so at small ``k`` the series starts higher than ``lo``.

    Deterministic (no random numbers); **scale invariant**: rescaling the shape leaves the
    shares unchanged, so the ``"unit_area"`` τ are unchanged and the ``"raw"`` τ scale with
    the area, exactly as the atoms require.  Traceable (works under ``jit``/``vmap``).

    **Arguments:**

        spectrum: eigenpairs of the shape (all ``k`` are used, as [`build_frame`][bsfjax.build_frame] does).
        centers: ``(n_centers,)`` vertex indices (the frame's centres).
        n_scales: number of scales, ``≥ 1`` (a single scale gets the share ``lo'``).
        area_range: ``(lo, hi)`` target shares, ``0 < lo ≤ hi < 1``.
        gamma: the threshold the frame will use.
        tau_convention: the convention of the returned τ (see [`build_frame`][bsfjax.build_frame]).

    **Returns:**

    ``(n_scales,)`` non-decreasing τ (equal τ where the shares saturate; the duplicate
    atoms they give are what [`prune_frame`][bsfjax.prune_frame] removes).
    """
    _check_spectrum(spectrum, "spectrum")
    if tau_convention not in TAU_CONVENTIONS:
        raise BSFError(f"tau_convention must be one of {TAU_CONVENTIONS}, got {tau_convention!r}")
    c = _check_centers(centers, int(np.shape(spectrum.evecs)[0]))
    if isinstance(n_scales, bool) or not isinstance(n_scales, (int, np.integer)) \
            or n_scales < 1:
        raise BSFError(f"n_scales must be a positive int, got {n_scales!r}")
    rng = _as_float_vector(area_range, "area_range")
    if rng.size != 2 or not (0 < rng[0] <= rng[1] < 1):
        raise BSFError(f"area_range must be (lo, hi) with 0 < lo <= hi < 1, got "
                       f"{rng.tolist()}")
    g = float(_check_gammas(gamma, 1)[0])
    n_c = int(np.shape(c)[0])
    probes = jnp.asarray(c)[np.unique(np.linspace(0, n_c - 1, min(n_c, _N_PROBES))
                                      .round().astype(int))]
    evecs = jnp.asarray(spectrum.evecs)
    dt = evecs.dtype
    return _adaptive_core(jnp.asarray(spectrum.evals, dt), evecs, jnp.asarray(spectrum.mass, dt),
                          probes, jnp.asarray(g, dt), jnp.asarray(rng[0], dt),
                          jnp.asarray(rng[1], dt), int(n_scales), tau_convention == "unit_area")


def unique_atoms(frame: AbstractFrame | Float[ArrayLike, "n q"]
                 ) -> tuple[Bool[Array, " q"], Int[Array, " q"]]:
    """Which columns of a frame are distinct and non-empty (traceable).

    Two columns are duplicates when their supports ``{v : B_v ≠ 0}`` are equal (for binary
    atoms: equal columns); a column is empty when its support is.  Found from two 32-bit hashes
    of each support, one sort and a comparison of neighbours — ``O(n q + q log q)``, no
    ``q × q`` Gram matrix.  (Distinct supports collide with probability about ``q² / 2⁶⁴``;
    [`prune_frame`][bsfjax.prune_frame] verifies every match exactly.)

    **Arguments:**

        frame: a [`Frame`][bsfjax.Frame], a [`SparseFrame`][bsfjax.SparseFrame] or an ``(n, q)``
            atom array.

    **Returns:**

    ``(keep, representative)``: ``keep`` ``(q,)`` bool, true for the first column of every
    distinct non-empty support; ``representative`` ``(q,)`` int32, the kept column equal to
    each column (itself when kept), ``-1`` for empty columns.  Masking, ``B * keep``, gives
    a frame with the same span in which no two non-zero columns are equal.
    """
    if not isinstance(frame, AbstractFrame):
        atoms = frame if hasattr(frame, "ndim") else np.asarray(frame)
        if atoms.ndim != 2:
            raise BSFError(f"frame atoms must have shape (n, q), got {tuple(np.shape(atoms))}")
        n, q = atoms.shape
        frame = Frame(atoms=jnp.asarray(atoms), coeffs=jnp.zeros((0, q)), taus=jnp.zeros(q),
                      centers=jnp.zeros(q, jnp.int32), mass=None)
    return _unique_core(frame, jnp.asarray(_hash_rows(frame.n_vertices)))


def prune_frame(frame: AbstractFrame, alpha: Float[ArrayLike, "*batch q"] | None = None):
    """Drop empty and duplicate atoms, keeping the first of each set of equal columns.

    ``Frame.columns`` of the result gives, for every remaining column, its index in the frame
    as built (composed with an earlier pruning).  Pruning changes nothing that the frame can
    represent: the span of the atoms is the same.

    With ``alpha`` (``(..., q)`` codes in ``frame``, e.g. found on a source frame and decoded on
    its transfer), also return the merged codes ``α'`` ``(..., q')``: the coefficients of equal
    columns are summed onto the kept one and those of empty columns dropped, so
    ``decode(pruned, α') == decode(frame, α)`` (up to rounding).

    Concrete inputs only (the column count of the result depends on the values); under
    ``jit`` mask with `unique_atoms` instead.

    **Returns:**

    The pruned [`Frame`][bsfjax.Frame], or ``(frame, alpha_merged)`` when ``alpha`` is given.
    """
    if not isinstance(frame, AbstractFrame):
        raise BSFError(f"frame must be a bsfjax.Frame or SparseFrame, got "
                       f"{type(frame).__name__}")
    if not all(_concrete(x) for x in jax.tree.leaves(frame)):
        raise BSFError("prune_frame needs concrete atoms (the number of columns it keeps "
                       "depends on their values); under jit, mask with unique_atoms")
    keep, rep = (np.array(x) for x in unique_atoms(frame))
    dup = np.flatnonzero((rep >= 0) & ~keep)
    if dup.size:  # verify every match exactly (a hash collision is ≈ never)
        same = frame.supports_equal(dup, rep[dup])
        keep[dup[~same]] = True  # a collision: keep the column as its own atom
        rep[dup[~same]] = dup[~same]
    kept = np.flatnonzero(keep)
    if kept.size == 0:
        raise BSFError("every atom of the frame is empty: nothing to keep")
    cols = kept if frame.columns is None else np.asarray(frame.columns)[kept]
    out = frame.select_columns(kept, jnp.asarray(cols, jnp.int32))
    if alpha is None:
        return out
    if not hasattr(alpha, "shape"):
        alpha = np.asarray(alpha)
    q = frame.n_atoms
    if alpha.ndim < 1 or alpha.shape[-1] != q:
        raise BSFError(f"alpha must have shape (..., q) with q = {q}, got {tuple(alpha.shape)}")
    pos = np.full(q, kept.size, np.int32)  # empty columns go to a dropped extra slot
    pos[kept] = np.arange(kept.size)
    seg = np.where(rep >= 0, pos[np.maximum(rep, 0)], kept.size)
    a = jnp.moveaxis(jnp.asarray(alpha), -1, 0)
    merged = jax.ops.segment_sum(a, jnp.asarray(seg), num_segments=kept.size + 1)[:-1]
    return out, jnp.moveaxis(merged, 0, -1)
