"""Functional map estimation from descriptors (Ovsjanikov et al. 2012; Nogneng & Ovsjanikov 2017).

Given descriptors ``d_M`` ``(n_M, p)`` on the source and ``d_N`` ``(n_N, p)`` on the target (column
``q`` of both describes "the same" function), the functional map ``C`` ``(k_N, k_M)`` minimizes

    E(C) = μ_descr  · ½ ‖C F_M − F_N‖²                     descriptor preservation
         + μ_lap    · ½ Σ_ij M_ij C_ij²                      Laplacian commutativity
         + μ_comm   · ½ Σ_q ‖C D_M^q − D_N^q C‖²             descriptor commutativity
         + μ_orient · ½ Σ_q ‖C O_M^q − σ O_N^q C‖²           orientation (optional, μ = 0 default)

with ``F = Φᵀ A d`` the spectral coefficients of the descriptors and
``D^q = Φᵀ A diag(d_q) Φ`` the multiplication operator of descriptor ``q`` in the reduced basis
(Nogneng & Ovsjanikov 2017).  ``M`` is the Laplacian mask: ``"plain"`` gives
``M_ij = (λ_M,j − λ_N,i)²``, i.e. ‖C Λ_M − Λ_N C‖²; ``"resolvent"`` (default, as pyFM) uses the
bounded resolvent mask of Ren et al. 2019 with exponent ``gamma``, with the same null space.
The orientation term (Ren et al. 2018, as in pyFM; needs the meshes) uses
``O^q = Φᵀ W_q Φ`` with ``(W_q g)(i) = Σ_{faces t ∋ i} (|t|/3) ⟨n_t × ∇d_q, ∇g⟩_t`` (per-face
gradients of piecewise-linear functions), the reduced form of g ↦ ⟨n × ∇d_q, ∇g⟩
(``_orientation.py``); σ = +1 keeps the orientation, σ = −1 (``orientation="reversing"``)
reverses it.

The first column of C (the image of the constant function) is fixed analytically, as in pyFM:
``C[:, 0] = (s √(S_N / S_M), 0, …, 0)`` with ``S`` the areas and ``s`` the sign product of the
two constant eigenvectors; only ``C[:, 1:]`` is optimized.

Weights, as pyFM's ``FunctionalMapping.fit`` (v1.3, ``normalize_weights=True``): the user
weights ``w = (descr, lap, comm, orient)`` (pyFM defaults ``(1e-1, 1e-3, 1, 0)``) are divided by
their sum and by the canonical scale τ of each term, ``μ_t = w_t / τ_t``, where with
``m = min(k_M, k_N)`` and the effective descriptor count ``p_eff = mean over shapes of
(tr G)² / ‖G‖_F²``, ``G = F[1:]ᵀ F[1:]``:

    τ_descr  = m ‖F_M[1:]‖² / (k_M p_eff)
    τ_lap    = m Σ_ij M_ij / (k_M k_N)
    τ_comm   = m Σ_q (k_N ‖D_M^q‖² + k_M ‖D_N^q‖² − 2 tr D_M^q tr D_N^q) / (k_M k_N p_eff)
    τ_orient = m Σ_q (k_N ‖O_M^q‖² + k_M ‖O_N^q‖²) / (k_M k_N p_eff)

(a non-positive τ is replaced by 1).  Descriptors are first L2-normalized per column in the
area-weighted inner product (``normalize_descriptors=True``, pyFM's default).

Solve.  E is quadratic in C, so its minimizer solves the normal equations ``H c = g`` of the
stacked least-squares residual.  ``H`` is assembled exactly from Kronecker structure (row-major
``vec``, ``(A ⊗ B)[(i,j),(a,b)] = A_ia B_jb``), never through the ``p k² × k²`` Jacobian:

    H = μ_descr I ⊗ F_M F_Mᵀ + μ_lap diag(vec M)
      + μ_comm   (I ⊗ Σ_q D_M^q D_M^q + Σ_q D_N^q D_N^q ⊗ I − 2 Σ_q D_N^q ⊗ D_M^q)
      + μ_orient (I ⊗ Σ_q O_M O_Mᵀ + Σ_q O_NᵀO_N ⊗ I − Σ_q (O_N ⊗ O_M + O_Nᵀ ⊗ O_Mᵀ)),

each ``Σ_q A_N^q ⊗ A_M^q`` being one GEMM ``(k_N², p) @ (p, k_M²)``.  The linear residual
``r(c) = H c − g`` is solved by ``optimistix.least_squares`` with Gauss–Newton and a lineax
Cholesky solve (H is symmetric positive definite, Jacobi-scaled): the first step is the exact
solution, the next ones are iterative-refinement steps that certify convergence.  Everything runs in one jitted
call; a stack of pairs (stacked spectra and descriptors of equal shapes) is ``vmap``-ed.

Cost at k = 30, p = 200, n ≈ 7K: the operators D (one GEMM over the k(k+1)/2 eigenvector
products, ``n k²/2`` memory) dominate with the dense solve of the ``k(k−1)``-unknown system;
the orientation operators add one scatter pass over the faces (shared by several estimates of
one pair with ``orientation_bases``) and one GEMM ``(p, n) @ (n, k²)``.

This module owns the public entry points ([`estimate_fmap`][bsfjax.estimate_fmap],
[`fmap_energy`][bsfjax.fmap_energy]), `FmapWeights` and the checks of their inputs; the
problem's operators are set up in `bsfjax._maps._fmap_problem` and solved in
`bsfjax._maps._fmap_solve`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._util import check_finite
from .._util import BSFError
from ._fmap_problem import _Shape
from ._fmap_solve import _energy_jit, _estimate_jit
from ._orientation import _check_bases, _geometries
from .._spectral import Spectrum, map_to_unit_area, unit_area_pair

__all__ = ["check_fmap_memory", "estimate_fmap", "FmapWeights", "fmap_energy", "LAPLACIAN_MASKS",
           "ORIENTATIONS"]

LAPLACIAN_MASKS = ("resolvent", "plain")
ORIENTATIONS = ("preserving", "reversing")


class FmapWeights(NamedTuple):
    """Relative weights of the energy terms (pyFM's ``w_descr, w_lap, w_dcomm, w_orient``).

    Only their ratios matter: they are divided by their sum and, with ``normalize_weights``, by
    each term's canonical scale (module doc).  ``orient > 0`` needs the meshes.
    """

    descr: float = 1e-1
    lap: float = 1e-3
    comm: float = 1.0
    orient: float = 0.0


# --------------------------------------------------------------------------- validation


def _weights_array(weights) -> np.ndarray:
    if weights is None:
        weights = FmapWeights()
    if isinstance(weights, Mapping):
        unknown = set(weights) - set(FmapWeights._fields)
        if unknown:
            raise BSFError(f"weights has unknown keys {sorted(unknown)}; valid keys are "
                           f"{list(FmapWeights._fields)}")
        weights = FmapWeights(**weights)
    if not isinstance(weights, FmapWeights):
        try:
            weights = FmapWeights(*weights)
        except TypeError as exc:
            raise BSFError(f"weights must be FmapWeights, a mapping or a sequence "
                           f"(descr, lap, comm[, orient]), got {weights!r}") from exc
    w = np.asarray(weights, dtype=np.float64)
    if not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise BSFError(f"weights must be finite, non-negative and not all 0, got {weights}")
    return w


#: Copies of the dense ``(k_N k_M) × (k_N k_M)`` system an estimate holds at its peak (its
#: Gram, the free block, the scaled block and its factor overlap: 778 GB tried at k = 505).
DENSE_COPIES = 3


def check_fmap_memory(k, batch: int = 1, available: int | None = None) -> int:
    """The bytes of the dense ``k² × k²`` system of ``batch`` functional-map estimates at map
    size ``k`` (an int or ``(k_source, k_target)``), checked against the memory available now
    (`bsfjax._util.available_memory`, or ``available``) before anything is allocated: the
    system grows as k⁴ (k = 100: 1.2 GB; k = 505: 778 GB).  Raises
    [`BSFError`][bsfjax.BSFError] naming ``k`` and both byte counts when it does not fit."""
    from .._util import available_memory, format_bytes

    km, kn = (k, k) if isinstance(k, (int, np.integer)) else k
    itemsize = jnp.dtype(jnp.result_type(float)).itemsize
    need = DENSE_COPIES * (int(km) * int(kn)) ** 2 * itemsize * int(batch)
    have = available_memory() if available is None else available
    if have is not None and need > have:
        size = f"k = {km}" if km == kn else f"k = ({km}, {kn})"
        times = f" x {batch} targets in a batch" if batch > 1 else ""
        raise BSFError(f"{size}: the functional-map estimate's dense k^2 x k^2 system{times} "
                       f"needs {format_bytes(need)}, more than the {format_bytes(have)} of "
                       f"memory available; use a smaller k")
    return need


@jax.jit
def _all_finite(d):
    """Whether every entry is finite, in one fused pass (no ``(n, p)`` mask)."""
    return jnp.all(jnp.isfinite(d))


def _prepare(source_spectrum, target_spectrum, source_descr, target_descr, k):
    for s, name in ((source_spectrum, "source_spectrum"), (target_spectrum, "target_spectrum")):
        if not isinstance(s, Spectrum):
            raise BSFError(f"{name} must be a bsfjax.Spectrum, got {type(s).__name__}")
    sm, sn = np.shape(source_spectrum.evecs), np.shape(target_spectrum.evecs)
    if len(sm) not in (2, 3) or len(sn) != len(sm) or sm[:-2] != sn[:-2]:
        raise BSFError(f"source and target spectra must both be single (evecs (n, k)) or stacked "
                       f"alike (evecs (B, n, k)), got evecs {sm} and {sn}")
    batched = len(sm) == 3
    if isinstance(k, (int, np.integer)) and not isinstance(k, bool):
        km = kn = int(k)
    else:
        try:
            km, kn = (int(v) for v in k)
        except (TypeError, ValueError) as exc:
            raise BSFError(f"k must be an int or a pair (k_source, k_target), got {k!r}") from exc
    if not 2 <= km <= sm[-1] or not 2 <= kn <= sn[-1]:
        raise BSFError(f"k=(k_source={km}, k_target={kn}) must be in [2, available]: source has "
                       f"{sm[-1]} eigenpairs, target has {sn[-1]}")
    want = 3 if batched else 2
    out = []
    for d, s, name in ((source_descr, sm, "source_descr"), (target_descr, sn, "target_descr")):
        # a JAX array stays one: numpy's copy would be copied back into JAX by the solve
        # (twice 0.9 GB for 2100 descriptors of a 111K-vertex pair)
        d = d if isinstance(d, jax.Array) else np.asarray(d)
        if d.ndim == want - 1:
            d = d[..., None]
        if d.ndim != want or d.shape[:-1] != s[:-1]:
            raise BSFError(f"{name} must have shape {(*s[:-1], 'p')} (one row per vertex of its "
                           f"spectrum), got {np.shape(d)}")
        # (a NumPy array is checked where it is: _all_finite would copy it into JAX first)
        if not np.issubdtype(d.dtype, np.number) or not (
                _all_finite(d) if isinstance(d, jax.Array) else np.all(np.isfinite(d))):
            raise BSFError(f"{name} must be finite numbers (found NaN/inf or a non-numeric dtype)")
        if d.shape[-1] == 0:  # no descriptor term: the map would be fixed by the regularizers
            raise BSFError(f"{name} has zero columns (shape {d.shape}): give at least one "
                           "descriptor")
        out.append(d)
    dm, dn = out
    if dm.shape[-1] != dn.shape[-1]:
        raise BSFError(f"source_descr and target_descr must have the same number of descriptors "
                       f"(columns), got {dm.shape[-1]} and {dn.shape[-1]}")
    return batched, km, kn, dm, dn


def _options(laplacian, gamma, orientation, w, source_mesh, target_mesh, sm_shape, sn_shape,
             bases=None, ks=None):
    """The checked options; returns each shape's `_Geometry` (from its mesh), its
    `OrientationBasis` (``bases``), or ``None`` without the orientation term."""
    if laplacian not in LAPLACIAN_MASKS:
        raise BSFError(f"laplacian must be one of {LAPLACIAN_MASKS}, got {laplacian!r}")
    if not np.isfinite(gamma) or not 0 < gamma <= 1:
        raise BSFError(f"gamma must be in (0, 1], got {gamma!r}")
    if orientation not in ORIENTATIONS:
        raise BSFError(f"orientation must be one of {ORIENTATIONS}, got {orientation!r}")
    if bases is not None:
        return _check_bases(bases, source_mesh, target_mesh, w, (sm_shape, sn_shape), ks)
    if w[3] == 0:
        return None, None
    if source_mesh is None or target_mesh is None:
        raise BSFError("weights.orient > 0 needs source_mesh and target_mesh (the orientation "
                       "term uses per-face gradients)")
    return (_geometries(source_mesh, sm_shape, "source_mesh"),
            _geometries(target_mesh, sn_shape, "target_mesh"))


def _shapes(source_spectrum, target_spectrum, km, kn, dm, dn, gm, gn):
    sm, sn = source_spectrum, target_spectrum
    return (_Shape(sm.evals[..., :km], sm.evecs[..., :km], sm.mass, dm, gm),
            _Shape(sn.evals[..., :kn], sn.evecs[..., :kn], sn.mass, dn, gn))


# --------------------------------------------------------------------------- public API


def estimate_fmap(source_spectrum: Spectrum, target_spectrum: Spectrum, source_descr,
                  target_descr, *, k=30, weights=None, laplacian: str = "resolvent",
                  gamma: float = 0.5, source_mesh=None, target_mesh=None,
                  orientation: str = "preserving", normalize_descriptors: bool = True,
                  normalize_weights: bool = True, max_steps: int = 8,
                  orientation_bases=None) -> jax.Array:
    """Functional map ``C`` ``(k_N, k_M)`` from source to target minimizing the energy above.

    **Arguments:**

    - `source_spectrum`, `target_spectrum`: spectra of ``M`` and ``N`` with at least ``k``
      eigenpairs, or stacks of ``B`` spectra each (evecs ``(B, n, k)``) to estimate ``B``
      maps of equal sizes in one vmapped call.
    - `source_descr`: ``(n_M, p)`` (or ``(B, n_M, p)``) descriptors on the source, e.g.
      ``jnp.concatenate([wks(s), wks(s, landmarks=lm)], axis=1)``.
    - `target_descr`: ``(n_N, p)`` (or ``(B, n_N, p)``), column ``q`` matching column ``q`` of
      ``source_descr``.
    - `k`: map size, an int or ``(k_source, k_target)`` (pyFM's ``K``).
    - `weights`: ``FmapWeights(descr, lap, comm, orient)``, a mapping with those keys or a
      sequence; default pyFM's ``(1e-1, 1e-3, 1, 0)``.
    - `laplacian`: ``"resolvent"`` (Ren et al. 2019, pyFM's default) or ``"plain"``
      (λ differences squared).
    - `gamma`: resolvent exponent in (0, 1].
    - `source_mesh`, `target_mesh`: the meshes (sequences of meshes for stacked spectra), needed
      only when ``weights.orient > 0``.
    - `orientation`: ``"preserving"`` or ``"reversing"`` (sign σ of the orientation term).
    - `normalize_descriptors`: L2-normalize descriptor columns (area-weighted) first.
    - `normalize_weights`: divide each weight by its term's canonical scale (module doc).
    - `max_steps`: Gauss–Newton step limit (3 are normally used: the problem is linear, the
      first step solves it, the next ones refine and certify convergence).
    - `orientation_bases`: instead of the meshes, the pair's
      `orientation_bases` of at least ``k`` eigenvectors: several
      estimates of one pair (other sizes, descriptors or weights) then share one scan
      over the faces.  The same map as with the meshes, to round-off.

    **Returns:**

    ``(k_N, k_M)`` map (or ``(B, k_N, k_M)``); [`bsfjax.fmap_to_p2p`][bsfjax.fmap_to_p2p] converts it.
    """
    batched, km, kn, dm, dn = _prepare(source_spectrum, target_spectrum, source_descr,
                                       target_descr, k)
    check_fmap_memory((km, kn), np.shape(source_spectrum.evecs)[0] if batched else 1)
    w = _weights_array(weights)
    gm, gn = _options(laplacian, gamma, orientation, w, source_mesh, target_mesh,
                      np.shape(source_spectrum.evecs), np.shape(target_spectrum.evecs),
                      orientation_bases, (km, kn))
    if not isinstance(max_steps, (int, np.integer)) or max_steps < 2:
        raise BSFError(f"max_steps must be an integer >= 2, got {max_steps!r}")
    return _estimate(source_spectrum, target_spectrum, dm, dn, (km, kn), w, (gm, gn),
                     laplacian=laplacian, gamma=gamma, orientation=orientation,
                     normalize_descriptors=normalize_descriptors,
                     normalize_weights=normalize_weights, max_steps=max_steps, batched=batched)


def _estimate(source_spectrum, target_spectrum, dm, dn, ks, w, geoms, *, laplacian, gamma,
              orientation, normalize_descriptors, normalize_weights, max_steps, batched):
    """[`estimate_fmap`][bsfjax.estimate_fmap] after its checks; ``geoms``: each shape's `_Geometry`,
    `OrientationBasis` or ``None``."""
    # the two shapes at one area (bsfjax.unit_area_pair): the Laplacian term compares their
    # eigenvalues, so a target in millimetres is matched as the same shape in metres
    source_spectrum, am, target_spectrum, an = unit_area_pair(source_spectrum, target_spectrum)
    sm, sn = _shapes(source_spectrum, target_spectrum, *ks, dm, dn, *geoms)
    C = _estimate_jit(sm, sn, w, float(gamma), lap_kind=laplacian,
                      normalize_descriptors=bool(normalize_descriptors),
                      normalize_weights=bool(normalize_weights),
                      orient_sign=1.0 if orientation == "preserving" else -1.0,
                      max_steps=int(max_steps), batched=batched)
    return map_to_unit_area(C, am, an, inverse=True)


def fmap_energy(C, source_spectrum: Spectrum, target_spectrum: Spectrum, source_descr,
                target_descr, *, weights=None, laplacian: str = "resolvent", gamma: float = 0.5,
                source_mesh=None, target_mesh=None, orientation: str = "preserving",
                normalize_descriptors: bool = True, normalize_weights: bool = True) -> jax.Array:
    """The energy E(C) that [`estimate_fmap`][bsfjax.estimate_fmap] minimizes (single pair), for diagnostics: of
    ``C`` between the two shapes at one area, as there."""
    shape = np.shape(C)
    if len(shape) != 2:
        raise BSFError(f"C must be a (k_target, k_source) matrix, got shape {shape}")
    check_finite(C, "C")
    batched, km, kn, dm, dn = _prepare(source_spectrum, target_spectrum, source_descr,
                                       target_descr, (shape[1], shape[0]))
    if batched:
        raise BSFError("fmap_energy takes a single pair, not stacked spectra")
    w = _weights_array(weights)
    gm, gn = _options(laplacian, gamma, orientation, w, source_mesh, target_mesh,
                      np.shape(source_spectrum.evecs), np.shape(target_spectrum.evecs))
    source_spectrum, am, target_spectrum, an = unit_area_pair(source_spectrum, target_spectrum)
    C = map_to_unit_area(C, am, an)
    sm, sn = _shapes(source_spectrum, target_spectrum, km, kn, dm, dn, gm, gn)
    return _energy_jit(C, sm, sn, w, float(gamma), lap_kind=laplacian,
                       normalize_descriptors=bool(normalize_descriptors),
                       normalize_weights=bool(normalize_weights),
                       orient_sign=1.0 if orientation == "preserving" else -1.0)
