"""The Binary Sparse Frame (paper Sec. 4, Algorithm 1) and its transfer by a functional map.

Owner of: ``Frame``, ``build_frame``, ``transfer_frame``, ``adaptive_taus``, ``unique_atoms``,
``prune_frame``.  With ``sparse=True`` (or automatically when the dense ``(n, q)`` atoms would
exceed :data:`DENSE_BUDGET_BYTES`) ``build_frame`` and ``transfer_frame`` return a
:class:`bsfjax.SparseFrame` (per-vertex atom lists, ``sparse_frame.py``) built without ever
forming the dense matrix; its atoms are the same.

Build (Algorithm 1).  For every scale τ and centre x, the band-limited heat kernel

    g_{τ,x} = Φ (ĝ_τ ⊙ Φ[x, :]ᵀ),      ĝ_τ,l = exp(−τ (λ_l − λ_1)),

is normalized to ``ĝ = |g| / max_v |g|`` and thresholded: the atom is ``1`` where ``ĝ ≥ γ``.
Subtracting λ_1 only rescales g (undone by the normalization) and keeps ĝ_τ,1 = 1.

Adaptive scales (:func:`adaptive_taus`, ``build_frame(..., taus="adaptive")``).  The paper's
fixed τ ∈ {0.001, 0.005, 0.01} give atoms whose size is set by the band limit once k is large
(at k = 50 on FAUST all three cover 1.4–4 % of the area), so sparse codes lack large atoms.
The adaptive choice measures the mean area share of the atoms as a function of τ on the
spectrum itself and picks a geometric series of shares from 1 % to 20 % of the surface.

Hygiene (:func:`unique_atoms`, :func:`prune_frame`).  Binarization can make two columns
identical (two scales at one centre, or neighbouring centres) or empty (a kernel that vanished
after transfer); such columns are masked or dropped, and ``Frame.columns`` records which of the
built columns remain.

Transfer (Eq. 11–12).  A functional map ``C`` ``(k_N, k_M)`` carries the spectral coefficients
``a = ĝ ⊙ Φ_M[x, :]`` of each atom's kernel to ``N``: ``g_N = Φ_N C a``, which is normalized and
thresholded with the same γ, giving binary atoms on ``N``.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._errors import BSFError
from ._sparse_frame import SparseFrame, effective_taus, kernel_mask, sparse_atoms
from ._spectrum import Spectrum

__all__ = ["Frame", "build_frame", "transfer_frame", "adaptive_taus", "prune_frame",
           "unique_atoms", "TAU_CONVENTIONS", "ADAPTIVE_AREA_RANGE", "ADAPTIVE_N_SCALES",
           "DENSE_BUDGET_BYTES"]

#: ``sparse=None`` builds a :class:`~bsfjax.SparseFrame` when the dense atoms (``n · q`` entries
#: of the float dtype) would take more than this many bytes.
DENSE_BUDGET_BYTES = 2**31

#: ``"unit_area"``: τ acts on the eigenvalues of the shape rescaled to unit area (λ · area);
#: ``"raw"``: τ acts on the eigenvalues as they are (the paper's formula).
TAU_CONVENTIONS = ("unit_area", "raw")


class Frame(eqx.Module):
    """A Binary Sparse Frame on one shape: ``q`` binary atoms and where they came from.

    Column order: scale-major — column ``s * n_centers + c`` is the atom of scale ``taus[s]``
    centred at ``centers[c]``; ``Frame.taus`` and ``Frame.centers`` give both per column.

    Attributes:
        atoms: ``(n, q)`` binary matrix B (0/1 in the float dtype), one atom per column.
        coeffs: ``(k, q)`` spectral coefficients ĝ ⊙ Φ[x, :] of the Gaussian behind each atom
            (the quantity a functional map transports, paper Eq. 11), with ĝ in the frame's
            ``tau_convention``.
        taus: ``(q,)`` diffusion scale τ of each column (as given by the caller).
        centers: ``(q,)`` int vertex index of each column's centre.  After
            :func:`transfer_frame` these still index the *source* shape's vertices.
        mass: ``(n,)`` vertex areas of the shape (for area-weighted coding and metrics).
        gammas: ``(q,)`` threshold γ of each column (reused by :func:`transfer_frame`), or
            ``None`` for a hand-made frame.
        tau_convention: how ``taus`` enter ĝ (static): ``"unit_area"`` means
            ĝ_l = exp(−τ · area · (λ_l − λ_1)) with area = Σ mass; ``"raw"`` means
            ĝ_l = exp(−τ (λ_l − λ_1)).  :attr:`effective_taus` gives the τ applied to the raw
            eigenvalues in either case.
        columns: ``(q,)`` int index of each column in the frame as :func:`build_frame` made
            it, after :func:`prune_frame` dropped duplicate or empty atoms; ``None`` for a
            frame that was never pruned (column ``j`` is built column ``j``).
    """

    atoms: jax.Array
    coeffs: jax.Array
    taus: jax.Array
    centers: jax.Array
    mass: jax.Array
    gammas: jax.Array | None = None
    tau_convention: str = eqx.field(static=True, default="unit_area")
    columns: jax.Array | None = None

    def __check_init__(self):
        if self.tau_convention not in TAU_CONVENTIONS:
            raise BSFError(f"tau_convention must be one of {TAU_CONVENTIONS}, "
                           f"got {self.tau_convention!r}")

    @property
    def n_vertices(self) -> int:
        return int(self.atoms.shape[-2])

    @property
    def n_atoms(self) -> int:
        return int(self.atoms.shape[-1])

    @property
    def effective_taus(self) -> jax.Array:
        """``(q,)`` the τ multiplying the raw eigenvalues: ``taus · Σ mass`` for
        ``"unit_area"``, ``taus`` for ``"raw"``.  (After a transfer, Σ mass is the target's.)"""
        return effective_taus(self.taus, self.mass, self.tau_convention)


# --------------------------------------------------------------------------- jitted kernels


#: Kernel values per column block of :func:`_binarize` (4 MiB in float32): the product, the
#: column maxima and the threshold of a block then stay in cache.
_BINARIZE_BLOCK_ELEMS = 2**20


def _binarize(evecs: jax.Array, coeffs: jax.Array, gammas: jax.Array) -> jax.Array:
    """``(n, q)`` atoms ``[|g| / max_v |g| ≥ γ]`` of ``g = evecs @ coeffs``, per column
    (γ ``(q,)``), in the float dtype: the rule of :func:`~bsfjax._sparse_frame.kernel_mask`.

    Computed in blocks of ``w`` whole columns written into the result, so the ``(n, q)`` kernel
    matrix ``g`` never exists: one ``(n, w)`` block is multiplied, reduced and thresholded
    while in cache, and the only ``(n, q)`` traffic is writing the atoms (on FAUST, 6890 × 1032,
    ~1.5× faster inside the pipeline than the product → max → compare passes over a fresh
    ``g``).  The last block is shifted left to end at column ``q`` (recomputing a few columns
    with the same values) instead of padding, so no copy is needed to cut the result.
    """
    n, q = evecs.shape[0], coeffs.shape[1]
    w = int(max(1, min(q, _BINARIZE_BLOCK_ELEMS // max(n, 1))))
    n_blocks = -(-q // w)

    dtype = jnp.result_type(evecs, coeffs)
    if n_blocks == 1:
        return kernel_mask(evecs, coeffs, gammas).astype(dtype)

    def body(i, out):
        start = jnp.minimum(i * w, q - w)
        cb = jax.lax.dynamic_slice_in_dim(coeffs, start, w, axis=1)
        gb = jax.lax.dynamic_slice_in_dim(gammas, start, w, axis=0)
        atoms = kernel_mask(evecs, cb, gb).astype(dtype)
        return jax.lax.dynamic_update_slice_in_dim(out, atoms, start, axis=1)

    return jax.lax.fori_loop(0, n_blocks, body, jnp.zeros((n, q), dtype))


def _coeffs(evals, evecs, mass, centers, taus, unit_area: bool):
    """``(k, S·C)`` coefficients ĝ_s ⊙ Φ[x_c, :], scale-major."""
    k = evals.shape[0]
    taus_eff = taus * jnp.sum(mass) if unit_area else taus
    ghat = jnp.exp(-taus_eff[:, None] * (evals - evals[0])[None, :])  # (S, k)
    rows = evecs[centers]  # (C, k): Φ[x, :] of every centre
    return (ghat[:, None, :] * rows[None, :, :]).reshape(-1, k).T  # (k, S·C)


_coeffs_jit = jax.jit(_coeffs, static_argnames="unit_area")


@functools.partial(jax.jit, static_argnames="unit_area")
def _build_core(evals: jax.Array, evecs: jax.Array, mass: jax.Array, centers: jax.Array,
                taus: jax.Array, gammas: jax.Array, unit_area: bool):
    """Algorithm 1 for ``S`` scales × ``C`` centres at once.

    Shapes: evals ``(k,)``, evecs ``(n, k)``, mass ``(n,)``, centers ``(C,)``, taus ``(S,)``,
    gammas ``(S,)``.  Returns atoms ``(n, S·C)`` and coeffs ``(k, S·C)``, scale-major.
    """
    coeffs = _coeffs(evals, evecs, mass, centers, taus, unit_area)
    gcols = jnp.repeat(gammas, centers.shape[0])  # (S·C,)
    return _binarize(evecs, coeffs, gcols), coeffs


@jax.jit
def _transfer_coeffs(C: jax.Array, coeffs: jax.Array) -> jax.Array:
    return jnp.matmul(C, coeffs[:C.shape[1]], precision=jax.lax.Precision.HIGHEST)


@jax.jit
def _transfer_core(C: jax.Array, coeffs: jax.Array, evecs: jax.Array, gammas: jax.Array):
    """C ``(k_N, k_M)``, coeffs ``(≥k_M, q)``, evecs ``(n_N, ≥k_N)``, gammas ``(q,)``."""
    k_n, k_m = C.shape
    coeffs_n = jnp.matmul(C, coeffs[:k_m], precision=jax.lax.Precision.HIGHEST)  # (k_N, q)
    return _binarize(evecs[:, :k_n], coeffs_n, gammas), coeffs_n


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
    atoms, _ = _build_core(evals, evecs, mass, probes, grid,
                           jnp.full((_TAU_GRID,), gamma, dt), unit_area)
    share = jnp.mean((mass @ atoms).reshape(_TAU_GRID, -1), axis=1) / area
    share = jax.lax.cummax(share)  # larger τ never shrinks the mean atom
    lo_eff = jnp.maximum(lo, _FLOOR_MARGIN * share[0])  # the band limit's smallest atoms
    hi_eff = jnp.maximum(hi, lo_eff)
    targets = jnp.exp(jnp.linspace(jnp.log(lo_eff), jnp.log(hi_eff), n_scales, dtype=dt))
    # strictly increasing abscissae for the interpolation (ties from saturation)
    xs = jnp.log(share) + 1e-9 * jnp.arange(_TAU_GRID, dtype=dt)
    return jnp.exp(jnp.interp(jnp.log(targets), xs, jnp.log(grid)))


def _support_hashes(present: jax.Array):
    """Two 32-bit hashes ``Σ_i [b_i ≠ 0] r_i mod 2³²`` of every column's support (fixed
    random ``r``); equal supports hash equally, distinct ones collide with probability 2⁻⁶⁴."""
    n = present.shape[0]
    r = np.random.default_rng(0x5EED).integers(0, 2**32, size=(2, n), dtype=np.uint32)
    zero = jnp.zeros((), jnp.uint32)
    return tuple(jnp.sum(jnp.where(present, jnp.asarray(ri)[:, None], zero), axis=0,
                         dtype=jnp.uint32) for ri in r)


@jax.jit
def _unique_core(atoms: jax.Array):
    q = atoms.shape[1]
    present = atoms != 0
    h1, h2 = _support_hashes(present)
    idx = jnp.arange(q)
    order = jnp.lexsort((idx, h2, h1))  # by hash, ties by column index
    s1, s2 = h1[order], h2[order]
    new_run = jnp.concatenate([jnp.ones(1, bool), (s1[1:] != s1[:-1]) | (s2[1:] != s2[:-1])])
    start = jax.lax.cummax(jnp.where(new_run, jnp.arange(q), 0))
    rep = jnp.zeros(q, order.dtype).at[order].set(order[start])  # first column of its run
    nonempty = jnp.any(present, axis=0)
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


def _want_sparse(sparse, n: int, q: int, dtype) -> bool:
    if sparse is None:
        return n * q * np.dtype(dtype).itemsize > DENSE_BUDGET_BYTES
    if not isinstance(sparse, (bool, np.bool_)):
        raise BSFError(f"sparse must be None (automatic), True or False, got {sparse!r}")
    return bool(sparse)


def _check_sparse_concrete(*arrays) -> None:
    if not all(_concrete(a) for a in arrays):
        raise BSFError("sparse=True needs concrete inputs (the atom-list width is data "
                       "dependent): call build_frame/transfer_frame outside jit/vmap, or pass "
                       "sparse=False there")


# --------------------------------------------------------------------------- public API


def build_frame(spectrum: Spectrum, centers, taus=(1e-3, 5e-3, 1e-2), gamma=0.75,
                tau_convention: str = "unit_area", *, prune: bool = False,
                sparse: bool | None = None):
    """The Binary Sparse Frame of paper Algorithm 1, every centre and scale in one jitted call.

    For each scale ``τ_s`` and centre ``x_c`` (column ``j = s · n_centers + c``)::

        ĝ_l   = exp(−τ'_s (λ_l − λ_1))                l = 1 … k
        a_j   = ĝ ⊙ Φ[x_c, :]                         (k,)   -> Frame.coeffs[:, j]
        g_j   = Φ a_j                                  (n,)   band-limited heat kernel at x_c
        B_j   = [ |g_j| / max_v |g_j|  ≥  γ_s ]        (n,)   -> Frame.atoms[:, j]

    with ``τ' = τ · area`` (``area = Σ mass``) for ``tau_convention="unit_area"`` and ``τ' = τ``
    for ``"raw"``.  Rescaling a shape by ``s`` divides λ by ``s²`` and multiplies the area by
    ``s²``, so unit-area atoms do not depend on the shape's units; on FAUST (area ≈ 1.8 m²) they
    are close to the paper's raw setting.

    Args:
        spectrum: eigenpairs of the shape (:func:`bsfjax.spectrum`, or
            :func:`bsfjax.interval_spectrum` in 1D); all ``k`` of them are used.
        centers: ``(n_centers,)`` int vertex indices (e.g. :func:`farthest_point_sampling`).
        taus: one τ > 0, a sequence of ``S`` of them (any ``S ≥ 1``), or ``"adaptive"``:
            the :data:`ADAPTIVE_N_SCALES` scales of :func:`adaptive_taus` (mean atom area
            shares from 1 % to 20 % of the surface at this spectrum's ``k``).
        gamma: threshold in ``(0, 1)``, one for all scales or one per τ (one value for
            ``"adaptive"``).
        tau_convention: ``"unit_area"`` (default) or ``"raw"``; see above.
        prune: drop empty and duplicate atoms (:func:`prune_frame`; ``Frame.columns`` then
            says which built columns remain).  Needs concrete (non-traced) inputs.  Default
            ``False``: the paper's frame, every column kept.
        sparse: ``True``: return a :class:`~bsfjax.SparseFrame` (per-vertex atom lists, built
            in vertex blocks, O(nnz) memory; needs concrete inputs); ``False``: a dense
            :class:`Frame`; ``None`` (default): sparse when the dense atoms would exceed
            :data:`DENSE_BUDGET_BYTES` (2 GiB), e.g. ~48K vertices at 5 % × 3 scales.

    Returns:
        A :class:`Frame` (or :class:`~bsfjax.SparseFrame`, same atoms) with
        ``q = S · n_centers`` columns: atoms ``(n, q)`` and coeffs
        ``(k, q)`` in JAX's default float dtype, ``taus``/``gammas``/``centers`` per column as
        given, ``mass = spectrum.mass`` and the ``tau_convention``.

    Raises:
        BSFError: non-positive or non-finite τ, γ outside (0, 1) or the wrong number of γ,
            empty / non-integer / out-of-range centres, an unknown convention, or a malformed
            spectrum — always before anything is traced.
    """
    _check_spectrum(spectrum, "spectrum")
    if tau_convention not in TAU_CONVENTIONS:
        raise BSFError(f"tau_convention must be one of {TAU_CONVENTIONS}, got {tau_convention!r}")
    n = int(np.shape(spectrum.evecs)[0])
    c = _check_centers(centers, n)
    if not isinstance(prune, bool):
        raise BSFError(f"prune must be a bool, got {prune!r}")
    if isinstance(taus, str):
        if taus != "adaptive":
            raise BSFError(f"taus must be numbers or 'adaptive', got {taus!r}")
        if np.size(gamma) != 1:
            raise BSFError(f"taus='adaptive' takes one gamma for all its scales, got {gamma!r}")
        g1 = _check_gammas(gamma, 1)
        t = adaptive_taus(spectrum, c, gamma=float(g1[0]), tau_convention=tau_convention)
        g = np.repeat(g1, ADAPTIVE_N_SCALES)
    else:
        t = _check_taus(taus)
        g = _check_gammas(gamma, t.size)
    n_c = c.shape[0]
    n_s = int(np.shape(t)[0])
    dtype = jax.dtypes.canonicalize_dtype(jnp.float64)
    if _want_sparse(sparse, n, n_s * n_c, dtype):
        if prune:
            raise BSFError("prune=True works on dense frames only; pass sparse=False (or prune "
                           "the codes' frame after building it dense)")
        _check_sparse_concrete(spectrum.evals, spectrum.evecs, spectrum.mass, c, t)
        evecs = jnp.asarray(spectrum.evecs, dtype)
        coeffs = _coeffs_jit(jnp.asarray(spectrum.evals, dtype), evecs,
                             jnp.asarray(spectrum.mass, dtype), jnp.asarray(c), jnp.asarray(t, dtype),
                             tau_convention == "unit_area")
        gcols = jnp.repeat(jnp.asarray(g, dtype), n_c)
        return SparseFrame(atom_lists=sparse_atoms(evecs, coeffs, gcols), coeffs=coeffs,
                           taus=jnp.repeat(jnp.asarray(t), n_c), centers=jnp.tile(jnp.asarray(c), n_s),
                           mass=jnp.asarray(spectrum.mass), gammas=gcols,
                           tau_convention=tau_convention)
    atoms, coeffs = _build_core(jnp.asarray(spectrum.evals), jnp.asarray(spectrum.evecs),
                                jnp.asarray(spectrum.mass), jnp.asarray(c), jnp.asarray(t),
                                jnp.asarray(g), tau_convention == "unit_area")
    frame = Frame(atoms=atoms, coeffs=coeffs, taus=jnp.repeat(jnp.asarray(t), n_c),
                  centers=jnp.tile(jnp.asarray(c), n_s), mass=jnp.asarray(spectrum.mass),
                  gammas=jnp.repeat(jnp.asarray(g), n_c), tau_convention=tau_convention)
    return prune_frame(frame) if prune else frame


def adaptive_taus(spectrum: Spectrum, centers, *, n_scales: int = ADAPTIVE_N_SCALES,
                  area_range=ADAPTIVE_AREA_RANGE, gamma: float = 0.75,
                  tau_convention: str = "unit_area") -> jax.Array:
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

    Args:
        spectrum: eigenpairs of the shape (all ``k`` are used, as :func:`build_frame` does).
        centers: ``(n_centers,)`` vertex indices (the frame's centres).
        n_scales: number of scales, ``≥ 1`` (a single scale gets the share ``lo'``).
        area_range: ``(lo, hi)`` target shares, ``0 < lo ≤ hi < 1``.
        gamma: the threshold the frame will use.
        tau_convention: the convention of the returned τ (see :func:`build_frame`).

    Returns:
        ``(n_scales,)`` non-decreasing τ (equal τ where the shares saturate; the duplicate
        atoms they give are what :func:`prune_frame` removes).
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


def unique_atoms(frame) -> tuple[jax.Array, jax.Array]:
    """Which columns of a frame are distinct and non-empty (traceable).

    Two columns are duplicates when their supports ``{v : B_v ≠ 0}`` are equal (for binary
    atoms: equal columns); a column is empty when its support is.  Found from two 32-bit hashes
    of each support, one sort and a comparison of neighbours — ``O(n q + q log q)``, no
    ``q × q`` Gram matrix.  (Distinct supports collide with probability about ``q² / 2⁶⁴``;
    :func:`prune_frame` verifies every match exactly.)

    Args:
        frame: a :class:`Frame` or an ``(n, q)`` atom array.

    Returns:
        ``(keep, representative)``: ``keep`` ``(q,)`` bool, true for the first column of every
        distinct non-empty support; ``representative`` ``(q,)`` int32, the kept column equal to
        each column (itself when kept), ``-1`` for empty columns.  Masking, ``B * keep``, gives
        a frame with the same span in which no two non-zero columns are equal.
    """
    atoms = frame.atoms if isinstance(frame, Frame) else frame
    if not hasattr(atoms, "ndim"):
        atoms = np.asarray(atoms)
    if atoms.ndim != 2:
        raise BSFError(f"frame atoms must have shape (n, q), got {tuple(np.shape(atoms))}")
    return _unique_core(jnp.asarray(atoms))


def prune_frame(frame: Frame, alpha=None):
    """Drop empty and duplicate atoms, keeping the first of each set of equal columns.

    ``Frame.columns`` of the result gives, for every remaining column, its index in the frame
    as built (composed with an earlier pruning).  Pruning changes nothing that the frame can
    represent: the span of the atoms is the same.

    With ``alpha`` (``(..., q)`` codes in ``frame``, e.g. found on a source frame and decoded on
    its transfer), also return the merged codes ``α'`` ``(..., q')``: the coefficients of equal
    columns are summed onto the kept one and those of empty columns dropped, so
    ``decode(pruned, α') == decode(frame, α)`` (up to rounding).

    Concrete inputs only (the column count of the result depends on the values); under
    ``jit`` mask with :func:`unique_atoms` instead.

    Returns:
        The pruned :class:`Frame`, or ``(frame, alpha_merged)`` when ``alpha`` is given.
    """
    if not isinstance(frame, Frame):
        raise BSFError(f"frame must be a bsfjax.Frame, got {type(frame).__name__}")
    if not _concrete(frame.atoms):
        raise BSFError("prune_frame needs concrete atoms (the number of columns it keeps "
                       "depends on their values); under jit, mask with unique_atoms")
    keep, rep = (np.asarray(x) for x in unique_atoms(frame))
    B = np.asarray(frame.atoms) != 0
    dup = np.flatnonzero((rep >= 0) & ~keep)
    if dup.size and not np.array_equal(B[:, dup], B[:, rep[dup]]):  # hash collision (≈ never)
        _, first, inv = np.unique(np.packbits(B, axis=0).T, axis=0, return_index=True,
                                  return_inverse=True)
        rep = np.where(B.any(axis=0), first[inv.reshape(-1)], -1).astype(np.int32)
        keep = rep == np.arange(rep.size)
    kept = np.flatnonzero(keep)
    if kept.size == 0:
        raise BSFError("every atom of the frame is empty: nothing to keep")
    cols = kept if frame.columns is None else np.asarray(frame.columns)[kept]
    out = Frame(atoms=frame.atoms[:, kept], coeffs=frame.coeffs[:, kept],
                taus=frame.taus[kept], centers=frame.centers[kept], mass=frame.mass,
                gammas=None if frame.gammas is None else frame.gammas[kept],
                tau_convention=frame.tau_convention, columns=jnp.asarray(cols, jnp.int32))
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


def transfer_frame(frame, C, target_spectrum: Spectrum, *, p2p=None, sparse: bool | None = None):
    """Carry a frame from shape ``M`` to shape ``N`` through a functional map (Eq. 11–12).

    With ``C`` ``(k_N, k_M)`` mapping coefficient vectors on ``M`` to ``N``::

        a_N = C · frame.coeffs[:k_M]              (k_N, q)
        g_N = Φ_N[:, :k_N] · a_N                   (n_N, q)
        B_N = [ |g_N| / max_v |g_N| ≥ γ ]          per column, γ = frame.gammas

    ``k_N ≠ k_M`` is fine.  A column whose transported kernel vanishes (``max |g_N| = 0``)
    becomes an all-zero atom, never NaN.

    Every column is kept, in the source's order (also ``Frame.columns``), so a code ``α``
    found on the source frame decodes on the result as it is: empty or equal atoms on ``N``
    are harmless to :func:`bsfjax.decode`.  To remove them, ``prune_frame(result, alpha)``
    merges the code along with the columns.

    With ``p2p`` (``(n_N,)`` source vertex of every target vertex, e.g. from
    :func:`bsfjax.fmap_to_p2p` of a refined map) the binary atoms are pulled back exactly,
    ``B_N = B_M[p2p]``, instead of being re-binarized from ``Φ_N C a`` (the coefficients are
    still ``C a``): with an estimated map this avoids the blur of a truncated ``C``.

    Args:
        frame: a frame on ``M`` with ``gammas`` (as :func:`build_frame` returns) and at least
            ``k_M`` coefficient rows (extra rows are ignored).
        C: ``(k_N, k_M)`` functional map, ``M → N`` on coefficients.
        target_spectrum: eigenpairs of ``N`` with at least ``k_N`` of them (the first ``k_N``
            are used).
        sparse: ``None`` (default): the kind of ``frame`` (a :class:`~bsfjax.SparseFrame` gives
            a sparse result, built in vertex blocks); ``True``/``False`` to choose.

    Returns:
        A :class:`Frame` on ``N``: atoms ``(n_N, q)``, coeffs ``a_N`` ``(k_N, q)``,
        ``mass = target_spectrum.mass``; ``taus``, ``gammas``, ``tau_convention`` and
        ``centers`` are the source's — ``centers`` still index vertices of ``M``.
    """
    if not isinstance(frame, (Frame, SparseFrame)):
        raise BSFError(f"frame must be a bsfjax.Frame or SparseFrame, got {type(frame).__name__}")
    if frame.gammas is None:
        raise BSFError("frame has no gammas (hand-made Frame?): transfer_frame thresholds with "
                       "frame.gammas, so build the frame with build_frame")
    _check_spectrum(target_spectrum, "target_spectrum")
    if not hasattr(C, "shape") or not hasattr(C, "dtype"):
        C = np.asarray(C)
    if C.ndim != 2:
        raise BSFError(f"C must be a 2-D (k_N, k_M) matrix, got shape {tuple(C.shape)}")
    k_n, k_m = (int(s) for s in C.shape)
    k_src, k_tgt = int(frame.coeffs.shape[-2]), int(np.shape(target_spectrum.evals)[0])
    if k_m == 0 or k_n == 0:
        raise BSFError(f"C must be non-empty, got shape {(k_n, k_m)}")
    if k_m > k_src:
        raise BSFError(f"C has k_M = {k_m} columns but frame has only {k_src} coefficient rows")
    if k_n > k_tgt:
        raise BSFError(f"C has k_N = {k_n} rows but target_spectrum has only {k_tgt} "
                       "eigenpairs")
    if _concrete(C) and not np.isfinite(np.asarray(C)).all():
        raise BSFError("C contains NaN or inf")
    if sparse is None:
        sparse = isinstance(frame, SparseFrame)
    sparse = _want_sparse(sparse, 0, 0, np.float32)
    if p2p is not None:
        if sparse or isinstance(frame, SparseFrame):
            raise BSFError("transfer_frame(p2p=...) pulls back dense atoms: use a dense Frame "
                           "and sparse=False")
        n_n, n_m = int(np.shape(target_spectrum.evecs)[0]), frame.n_vertices
        if not hasattr(p2p, "shape"):
            p2p = np.asarray(p2p)
        if tuple(p2p.shape) != (n_n,) or not jnp.issubdtype(p2p.dtype, jnp.integer):
            raise BSFError(f"p2p must be an ({n_n},) integer array (source vertex of every "
                           f"target vertex), got {p2p.dtype}{tuple(p2p.shape)}")
        if _concrete(p2p) and (np.min(p2p) < 0 or np.max(p2p) >= n_m):
            raise BSFError(f"p2p must hold source vertex indices in [0, {n_m})")
    if sparse:
        _check_sparse_concrete(C, frame.coeffs, frame.gammas, target_spectrum.evecs)
        dtype = jax.dtypes.canonicalize_dtype(jnp.float64)
        coeffs = _transfer_coeffs(jnp.asarray(C, dtype), jnp.asarray(frame.coeffs, dtype))
        evecs = jnp.asarray(target_spectrum.evecs[:, :k_n], dtype)  # one (n, k_N) copy, not two
        return SparseFrame(atom_lists=sparse_atoms(evecs, coeffs, frame.gammas), coeffs=coeffs,
                           taus=frame.taus, centers=frame.centers,
                           mass=jnp.asarray(target_spectrum.mass), gammas=frame.gammas,
                           tau_convention=frame.tau_convention)
    atoms, coeffs = _transfer_core(jnp.asarray(C), frame.coeffs, jnp.asarray(target_spectrum.evecs),
                                   frame.gammas)
    if p2p is not None:
        atoms = jnp.asarray(frame.atoms)[p2p]
    return Frame(atoms=atoms, coeffs=coeffs, taus=frame.taus, centers=frame.centers,
                 mass=jnp.asarray(target_spectrum.mass), gammas=frame.gammas,
                 tau_convention=frame.tau_convention, columns=getattr(frame, "columns", None))
