"""The Binary Sparse Frame (paper Sec. 4, Algorithm 1) and its transfer by a functional map.

Owner of: ``build_frame`` and ``transfer_frame``, for both kinds of frame (the dense
[`bsfjax.Frame`][bsfjax.Frame] of ``_dense_frame.py`` and the list-based [`bsfjax.SparseFrame`][bsfjax.SparseFrame] of
``_sparse_frame.py``, two implementations of [`bsfjax.AbstractFrame`][bsfjax.AbstractFrame]).  With ``sparse=True`` (or automatically when the dense ``(n, q)`` atoms would
exceed `DENSE_BUDGET_BYTES`) ``build_frame`` and ``transfer_frame`` return a
[`bsfjax.SparseFrame`][bsfjax.SparseFrame] (per-vertex atom lists, ``sparse_frame.py``) built without ever
forming the dense matrix; its atoms are the same.

Build (Algorithm 1).  For every scale τ and centre x, the band-limited heat kernel

    g_{τ,x} = Φ (ĝ_τ ⊙ Φ[x, :]ᵀ),      ĝ_τ,l = exp(−τ (λ_l − λ_1)),

is normalized to ``ĝ = |g| / max_v |g|`` and thresholded: the atom is ``1`` where ``ĝ ≥ γ``.
Subtracting λ_1 only rescales g (undone by the normalization) and keeps ĝ_τ,1 = 1.

Adaptive scales, pruning: ``_frame_tools.py``.

Transfer (Eq. 11–12).  A functional map ``C`` ``(k_N, k_M)`` carries the spectral coefficients
``a = ĝ ⊙ Φ_M[x, :]`` of each atom's kernel to ``N``: ``g_N = Φ_N C a``, which is normalized and
thresholded with the same γ, giving binary atoms on ``N``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float, Int

from ._binarize import build_core_jit, carry_dense, kernel_coeffs_jit, transfer_coeffs_jit
from ._dense_frame import Frame
from .._util import BSFError
from ._frame_tools import ADAPTIVE_AREA_RANGE, ADAPTIVE_N_SCALES, _check_centers, _check_gammas, _check_spectrum, _check_taus, _concrete, adaptive_taus, prune_frame, unique_atoms
from ._operator import DENSE_BUDGET_BYTES, TAU_CONVENTIONS, AbstractFrame
from ._packed_lists import pack_lists
from ._sparse_frame import SparseFrame, sparse_atom_lists
from .._spectral import Spectrum

__all__ = ["Frame", "AbstractFrame", "build_frame", "transfer_frame", "adaptive_taus",
           "prune_frame", "unique_atoms", "TAU_CONVENTIONS", "ADAPTIVE_AREA_RANGE",
           "ADAPTIVE_N_SCALES", "DENSE_BUDGET_BYTES"]

#: The jitted Algorithm 1 (a module attribute, so tests can check it is never reached with
#: bad input).
_build_core = build_core_jit


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


def build_frame(spectrum: Spectrum, centers: Int[ArrayLike, " c"],
                taus: Float[ArrayLike, " s"] | float | str = (1e-3, 5e-3, 1e-2),
                gamma: Float[ArrayLike, " s"] | float = 0.75, tau_convention: str = "unit_area",
                *, prune: bool = False, sparse: bool | None = None) -> AbstractFrame:
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

    **Arguments:**

        spectrum: eigenpairs of the shape ([`bsfjax.spectrum`][bsfjax.spectrum], or
            [`bsfjax.interval_spectrum`][bsfjax.interval_spectrum] in 1D); all ``k`` of them are used.
        centers: ``(n_centers,)`` int vertex indices (e.g. [`farthest_point_sampling`][bsfjax.farthest_point_sampling]).
        taus: one τ > 0, a sequence of ``S`` of them (any ``S ≥ 1``), or ``"adaptive"``:
            the `ADAPTIVE_N_SCALES` scales of [`adaptive_taus`][bsfjax.adaptive_taus] (mean atom area
            shares from 1 % to 20 % of the surface at this spectrum's ``k``).
        gamma: threshold in ``(0, 1)``, one for all scales or one per τ (one value for
            ``"adaptive"``).
        tau_convention: ``"unit_area"`` (default) or ``"raw"``; see above.
        prune: drop empty and duplicate atoms ([`prune_frame`][bsfjax.prune_frame]; ``Frame.columns`` then
            says which built columns remain).  Needs concrete (non-traced) inputs.  Default
            ``False``: the paper's frame, every column kept.
        sparse: ``True``: return a [`SparseFrame`][bsfjax.SparseFrame] (per-vertex atom lists, built
            in vertex blocks, O(nnz) memory; needs concrete inputs); ``False``: a dense
            [`Frame`][bsfjax.Frame]; ``None`` (default): sparse when the dense atoms would exceed
            `DENSE_BUDGET_BYTES` (2 GiB), e.g. ~48K vertices at 5 % × 3 scales.

    **Returns:**

    A [`Frame`][bsfjax.Frame] (or [`SparseFrame`][bsfjax.SparseFrame], same atoms) with
    ``q = S · n_centers`` columns: atoms ``(n, q)`` and coeffs
    ``(k, q)`` in JAX's default float dtype, ``taus``/``gammas``/``centers`` per column as
    given, ``mass = spectrum.mass`` and the ``tau_convention``.

    **Raises:**

    - `BSFError`: non-positive or non-finite τ, γ outside (0, 1) or the wrong number of γ,
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
        _check_sparse_concrete(spectrum.evals, spectrum.evecs, spectrum.mass, c, t)
        evecs = jnp.asarray(spectrum.evecs, dtype)
        coeffs = kernel_coeffs_jit(jnp.asarray(spectrum.evals, dtype), evecs,
                             jnp.asarray(spectrum.mass, dtype), jnp.asarray(c), jnp.asarray(t, dtype),
                             tau_convention == "unit_area")
        gcols = jnp.repeat(jnp.asarray(g, dtype), n_c)
        lists, seg = sparse_atom_lists(evecs, coeffs, gcols)
        frame = SparseFrame(atom_lists=lists, atom_segments=seg, coeffs=coeffs,
                            taus=jnp.repeat(jnp.asarray(t), n_c),
                            centers=jnp.tile(jnp.asarray(c), n_s),
                            mass=jnp.asarray(spectrum.mass), gammas=gcols,
                            tau_convention=tau_convention)
        return prune_frame(frame) if prune else frame
    atoms, coeffs = _build_core(jnp.asarray(spectrum.evals), jnp.asarray(spectrum.evecs),
                                jnp.asarray(spectrum.mass), jnp.asarray(c), jnp.asarray(t),
                                jnp.asarray(g), tau_convention == "unit_area")
    frame = Frame(atoms=atoms, coeffs=coeffs, taus=jnp.repeat(jnp.asarray(t), n_c),
                  centers=jnp.tile(jnp.asarray(c), n_s), mass=jnp.asarray(spectrum.mass),
                  gammas=jnp.repeat(jnp.asarray(g), n_c), tau_convention=tau_convention)
    return prune_frame(frame) if prune else frame


def transfer_frame(frame: AbstractFrame, C: Float[ArrayLike, "kN kM"],
                   target_spectrum: Spectrum, *, p2p: Int[ArrayLike, " nN"] | None = None,
                   sparse: bool | None = None) -> AbstractFrame:
    """Carry a frame from shape ``M`` to shape ``N`` through a functional map (Eq. 11–12).

    With ``C`` ``(k_N, k_M)`` mapping coefficient vectors on ``M`` to ``N``::

        a_N = C · frame.coeffs[:k_M]              (k_N, q)
        g_N = Φ_N[:, :k_N] · a_N                   (n_N, q)
        B_N = [ |g_N| / max_v |g_N| ≥ γ ]          per column, γ = frame.gammas

    ``k_N ≠ k_M`` is fine.  A column whose transported kernel vanishes (``max |g_N| = 0``)
    becomes an all-zero atom, never NaN.

    Every column is kept, in the source's order (also ``Frame.columns``), so a code ``α``
    found on the source frame decodes on the result as it is: empty or equal atoms on ``N``
    are harmless to [`bsfjax.decode`][bsfjax.decode].  To remove them, ``prune_frame(result, alpha)``
    merges the code along with the columns.

    With ``p2p`` (``(n_N,)`` source vertex of every target vertex, e.g. from
    [`bsfjax.fmap_to_p2p`][bsfjax.fmap_to_p2p] of a refined map) the binary atoms are pulled back exactly,
    ``B_N = B_M[p2p]``, instead of being re-binarized from ``Φ_N C a`` (the coefficients are
    still ``C a``): with an estimated map this avoids the blur of a truncated ``C``.

    **Arguments:**

        frame: a frame on ``M`` with ``gammas`` (as [`build_frame`][bsfjax.build_frame] returns) and at least
            ``k_M`` coefficient rows (extra rows are ignored).
        C: ``(k_N, k_M)`` functional map, ``M → N`` on coefficients.
        target_spectrum: eigenpairs of ``N`` with at least ``k_N`` of them (the first ``k_N``
            are used).
        p2p: optional ``(n_N,)`` int source vertex of every target vertex (pull-back of the
            binary atoms, dense or sparse alike).
        sparse: ``None`` (default): the kind of ``frame`` (a [`SparseFrame`][bsfjax.SparseFrame] gives
            a sparse result, built in vertex blocks); ``True``/``False`` to choose.

    **Returns:**

    A frame of the same kind (or as ``sparse`` says) on ``N``: atoms ``(n_N, q)``, coeffs ``a_N`` ``(k_N, q)``,
    ``mass = target_spectrum.mass``; ``taus``, ``gammas``, ``tau_convention`` and
    ``centers`` are the source's — ``centers`` still index vertices of ``M``.
    """
    if not isinstance(frame, AbstractFrame):
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
        n_n, n_m = int(np.shape(target_spectrum.evecs)[0]), frame.n_vertices
        if not hasattr(p2p, "shape"):
            p2p = np.asarray(p2p)
        if tuple(p2p.shape) != (n_n,) or not jnp.issubdtype(p2p.dtype, jnp.integer):
            raise BSFError(f"p2p must be an ({n_n},) integer array (source vertex of every "
                           f"target vertex), got {p2p.dtype}{tuple(p2p.shape)}")
        if _concrete(p2p) and (np.min(p2p) < 0 or np.max(p2p) >= n_m):
            raise BSFError(f"p2p must hold source vertex indices in [0, {n_m})")
    if sparse != isinstance(frame, SparseFrame):  # the other kind: its atoms only for p2p
        frame = (_to_sparse if sparse else _to_dense)(frame, with_atoms=p2p is not None)
    mass = jnp.asarray(target_spectrum.mass)
    if sparse:
        _check_sparse_concrete(C, frame.coeffs, frame.gammas, target_spectrum.evecs)
        dtype = jax.dtypes.canonicalize_dtype(jnp.float64)
        coeffs = transfer_coeffs_jit(jnp.asarray(C, dtype), jnp.asarray(frame.coeffs, dtype))
    elif p2p is None:  # the common case, one fused call (product, maxima, threshold)
        coeffs, atoms = carry_dense(jnp.asarray(C), frame.coeffs,
                                    jnp.asarray(target_spectrum.evecs), frame.gammas)
        return Frame(atoms=atoms, coeffs=coeffs, taus=frame.taus, centers=frame.centers,
                     mass=mass, gammas=frame.gammas, tau_convention=frame.tau_convention,
                     columns=frame.columns)
    else:
        coeffs = transfer_coeffs_jit(jnp.asarray(C), frame.coeffs)
    if p2p is not None:
        return frame.pull_back(p2p, coeffs, mass)
    return frame.rebinarized(jnp.asarray(target_spectrum.evecs), coeffs, mass)


def _to_sparse(frame: Frame, with_atoms: bool) -> SparseFrame:
    """The same frame as lists (host; concrete frames), or only its column data."""
    q = frame.n_atoms
    lists, seg = np.full((0, 1), q, np.int32), None
    if with_atoms:
        B = np.asarray(frame.atoms) != 0
        width = max(1, int(B.sum(axis=1).max(initial=0)))
        lists = np.full((B.shape[0], width), q, np.int32)
        r, c = np.nonzero(B)
        lists[r, np.arange(r.size) - np.searchsorted(r, r)] = c
        lists, seg = pack_lists(lists, q)
        seg = None if seg is None else jnp.asarray(seg)
    return SparseFrame(atom_lists=jnp.asarray(lists), atom_segments=seg, coeffs=frame.coeffs,
                       taus=frame.taus,
                       centers=frame.centers, mass=frame.mass, gammas=frame.gammas,
                       tau_convention=frame.tau_convention, columns=frame.columns)


def _to_dense(frame: SparseFrame, with_atoms: bool) -> Frame:
    """The same frame as a matrix, or only its column data."""
    atoms = (frame.todense(frame.coeffs.dtype) if with_atoms
             else jnp.zeros((0, frame.n_atoms), frame.coeffs.dtype))
    return Frame(atoms=atoms, coeffs=frame.coeffs, taus=frame.taus,
                 centers=frame.centers, mass=frame.mass, gammas=frame.gammas,
                 tau_convention=frame.tau_convention, columns=frame.columns)
