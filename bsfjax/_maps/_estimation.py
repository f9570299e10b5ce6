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
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from .._util import check_finite
from .._util import BSFError
from ._orientation import _cast, _check_bases, _Geometry, _geometries, _orient_ops
from .._spectral import Spectrum, map_to_unit_area, unit_area_pair

__all__ = ["estimate_fmap", "FmapWeights", "fmap_energy", "LAPLACIAN_MASKS", "ORIENTATIONS"]

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


# --------------------------------------------------------------------------- building blocks


def _column_norms(d, mass):
    """Each descriptor column's area-weighted L2 norm √(dᵀ A d) (1 for a zero column, which
    stays zero)."""
    norms = jnp.sqrt(jnp.einsum("np,n,np->p", d, mass, d))
    return jnp.where(norms > 0, norms, 1.0)


def _mult_ops(evecs, mass, d):
    """``(p, k, k)`` multiplication operators Φᵀ A diag(d_q) Φ in one GEMM over pair products.

    Only the k(k+1)/2 products φ_i φ_j with i ≤ j are formed (the operators are symmetric):
    memory ``n k(k+1)/2``, work ``n k(k+1)/2 p``.
    """
    k = evecs.shape[1]
    iu, ju = np.triu_indices(k)
    pairs = mass[:, None] * evecs[:, iu] * evecs[:, ju]  # (n, k(k+1)/2), A-weighted
    upper = pairs.T @ d  # (k(k+1)/2, p)
    ops = jnp.zeros((d.shape[1], k, k), upper.dtype).at[:, iu, ju].set(upper.T)
    return ops + jnp.swapaxes(ops, 1, 2) * (1.0 - jnp.eye(k, dtype=ops.dtype))


def _lap_mask(evals_m, evals_n, kind: str, gamma: float):
    """``(k_N, k_M)`` Laplacian-commutativity mask."""
    if kind == "plain":
        return jnp.square(evals_m[None, :] - evals_n[:, None])
    # Ren et al. 2019 resolvent mask, both spectra divided by one common scale (pyFM).
    scale = jnp.maximum(jnp.max(jnp.abs(evals_m)), jnp.max(jnp.abs(evals_n)))
    lam = (jnp.abs(evals_m) / scale) ** gamma
    mu = (jnp.abs(evals_n) / scale) ** gamma
    re_m, re_n = lam / (lam**2 + 1), mu / (mu**2 + 1)
    im_m, im_n = 1 / (lam**2 + 1), 1 / (mu**2 + 1)
    return jnp.square(re_m[None, :] - re_n[:, None]) + jnp.square(im_m[None, :] - im_n[:, None])


def _effective_p(F):
    gram = F[1:].T @ F[1:]
    denom = jnp.sum(gram * gram)
    return jnp.where(denom > 0, jnp.trace(gram) ** 2 / jnp.where(denom > 0, denom, 1.0), 1.0)


# --------------------------------------------------------------------------- energy and solve


class _Problem(NamedTuple):
    F_m: jax.Array  # (k_M, p)
    F_n: jax.Array  # (k_N, p)
    D_m: jax.Array  # (p, k_M, k_M)
    D_n: jax.Array  # (p, k_N, k_N)
    O_m: jax.Array | None  # (p, k_M, k_M) orientation operators, or None
    O_n: jax.Array | None  # (p, k_N, k_N), sign σ included
    mask: jax.Array  # (k_N, k_M)
    mu: jax.Array  # (4,) μ_descr, μ_lap, μ_comm, μ_orient
    c00: jax.Array  # fixed C[0, 0]


class _Shape(NamedTuple):
    evals: jax.Array
    evecs: jax.Array
    mass: jax.Array
    descr: jax.Array
    geom: _Geometry | None


def _taus(pb: _Problem):
    """pyFM's canonical scales (τ_descr, τ_lap, τ_comm, τ_orient) of the terms (module doc)."""
    km, kn = pb.F_m.shape[0], pb.F_n.shape[0]
    m = min(km, kn)
    p_eff = jnp.maximum(0.5 * (_effective_p(pb.F_m) + _effective_p(pb.F_n)), 1e-12)

    def guard(v):
        return jnp.where(v > 0, v, 1.0)

    def op_tau(A, B, skew):
        positive = jnp.sum(kn * jnp.sum(A**2, axis=(1, 2)) + km * jnp.sum(B**2, axis=(1, 2)))
        total = positive
        if not skew:
            total = total - 2 * jnp.sum(jnp.trace(A, axis1=1, axis2=2)
                                        * jnp.trace(B, axis1=1, axis2=2))
        total = jnp.maximum(total, 0.0)
        return jnp.where(total <= 1e-12 * positive, 1.0, total * m / (km * kn) / p_eff)

    tau_descr = guard(m * jnp.sum(pb.F_m[1:] ** 2) / km / p_eff)
    tau_lap = guard(m * jnp.sum(pb.mask) / (km * kn))
    tau_comm = op_tau(pb.D_m, pb.D_n, skew=False)
    tau_orient = jnp.ones(()) if pb.O_m is None else op_tau(pb.O_m, pb.O_n, skew=True)
    return jnp.stack([tau_descr, tau_lap, tau_comm, tau_orient.astype(tau_descr.dtype)])


class _ShapeOps(NamedTuple):
    """What the energy needs of one shape's descriptors: their coefficients and operators."""

    F: jax.Array  # (k, p) Φᵀ A d
    D: jax.Array  # (p, k, k) multiplication operators
    O: jax.Array | None  # (p, k, k) orientation operators, or None without the geometry


def _shape_ops(s: _Shape, normalize_descriptors: bool) -> _ShapeOps:
    """One shape's share of `_setup`: it depends on that shape alone, so a source matched
    to many targets ([`bsfjax.transfer_collection`][bsfjax.transfer_collection]) computes it once.

    F, D and O are linear in each descriptor column: the normalization divides them after
    the reductions over the vertices, and the mass weights the eigenvectors, so the only
    ``(n, p)`` array is the descriptors themselves (a copy is 0.9 GB for the 2100 descriptors
    of 20 landmarks on a 111K-vertex shape)."""
    d = s.descr
    F = (s.mass[:, None] * s.evecs).T @ d
    D = _mult_ops(s.evecs, s.mass, d)
    O = None if s.geom is None else _orient_ops(s.evecs, s.geom, d)
    if normalize_descriptors:
        inv = 1.0 / _column_norms(d, s.mass)
        F, D = F * inv, D * inv[:, None, None]
        O = None if O is None else O * inv[:, None, None]
    return _ShapeOps(F, D, O)


def _setup(sm: _Shape, sn: _Shape, w, *, lap_kind, gamma, normalize_descriptors,
           normalize_weights, orient_sign, ops_m: _ShapeOps | None = None) -> _Problem:
    """The estimation problem of a pair.  ``ops_m``: the source's `_shape_ops`, when the
    caller has it already (``sm.descr`` is then not read)."""
    om = _shape_ops(sm, normalize_descriptors) if ops_m is None else ops_m
    on = _shape_ops(sn, normalize_descriptors)
    if (om.O is None) != (on.O is None):
        raise BSFError("the orientation term needs the geometry of both shapes")
    O_n = None if on.O is None else orient_sign * on.O
    mask = _lap_mask(sm.evals, sn.evals, lap_kind, gamma)
    sign = jnp.sign(sm.evecs[0, 0] * sn.evecs[0, 0])
    c00 = jnp.where(sign == 0, 1.0, sign) * jnp.sqrt(jnp.sum(sn.mass) / jnp.sum(sm.mass))
    w = w / jnp.sum(w)
    pb = _Problem(om.F, on.F, om.D, on.D, om.O, O_n, mask, w, c00)
    if normalize_weights:
        pb = pb._replace(mu=w / _taus(pb))
    return pb


def _kron4(A, B):
    """(A ⊗ B) as a 4-index array [i, j, a, b] = A[i, a] B[j, b] (row-major vec layout)."""
    return jnp.einsum("ia,jb->ijab", A, B)


def _normal_equations(pb: _Problem):
    """Gram ``H`` ``(k_N, k_M, k_N, k_M)`` and right-hand side ``g`` ``(k_N, k_M)`` of E."""
    mu_d, mu_l, mu_c, mu_o = pb.mu
    kn, km = pb.mask.shape
    eye_n = jnp.eye(kn, dtype=pb.mask.dtype)
    eye_m = jnp.eye(km, dtype=pb.mask.dtype)
    p = pb.D_m.shape[0]

    def cross(A_n, A_m):  # Σ_q A_N^q[i, a] A_M^q[j, b] as one GEMM, then (i,a,j,b) → (i,j,a,b)
        out = A_n.reshape(p, kn * kn).T @ A_m.reshape(p, km * km)
        return out.reshape(kn, kn, km, km).transpose(0, 2, 1, 3)

    right_m = mu_d * pb.F_m @ pb.F_m.T + mu_c * jnp.einsum("qij,qkj->ik", pb.D_m, pb.D_m)
    left_n = mu_c * jnp.einsum("qji,qjk->ik", pb.D_n, pb.D_n)
    H = -2 * mu_c * cross(pb.D_n, pb.D_m)  # D symmetric: both cross terms coincide
    if pb.O_m is not None:
        right_m = right_m + mu_o * jnp.einsum("qij,qkj->ik", pb.O_m, pb.O_m)
        left_n = left_n + mu_o * jnp.einsum("qji,qjk->ik", pb.O_n, pb.O_n)
        H = H - mu_o * (cross(pb.O_n, pb.O_m)
                        + cross(jnp.swapaxes(pb.O_n, 1, 2), jnp.swapaxes(pb.O_m, 1, 2)))
    H = (H + _kron4(eye_n, right_m) + _kron4(left_n, eye_m)
         + mu_l * jnp.einsum("ij,ia,jb->ijab", pb.mask, eye_n, eye_m))
    g = mu_d * pb.F_n @ pb.F_m.T
    return H, g


def _energy(C, pb: _Problem):
    mu_d, mu_l, mu_c, mu_o = pb.mu

    def comm(A_m, A_n):
        r = jnp.einsum("ij,qjk->qik", C, A_m) - jnp.einsum("qij,jk->qik", A_n, C)
        return 0.5 * jnp.sum(r * r)

    e = (mu_d * 0.5 * jnp.sum((C @ pb.F_m - pb.F_n) ** 2)
         + mu_l * 0.5 * jnp.sum(pb.mask * C * C) + mu_c * comm(pb.D_m, pb.D_n))
    if pb.O_m is not None:
        e = e + mu_o * comm(pb.O_m, pb.O_n)
    return e


def _residual(y, args):
    H, rhs = args
    return H @ y - rhs


def _solve(pb: _Problem, *, rtol, atol, max_steps):
    H, g = _normal_equations(pb)
    kn, km = pb.mask.shape
    # Only C[:, 1:] is free; the fixed column contributes −H[free, (0, 0)] C[0, 0] to the rhs.
    H_ff = H[:, 1:, :, 1:].reshape(kn * (km - 1), kn * (km - 1))
    rhs = (g[:, 1:] - H[:, 1:, 0, 0] * pb.c00).reshape(-1)
    # Jacobi scaling D^{-1/2} H D^{-1/2} (unit diagonal): cuts the condition number several-fold
    # (measured 5500 → 1800 on FAUST), so float32 refinement converges to the tolerances in the
    # minimal 3 Gauss–Newton steps, and the tolerances mean the same whatever the weights.
    dg = jnp.sqrt(jnp.diagonal(H_ff))
    dg = jnp.where(dg > 0, dg, 1.0)
    H_ff = H_ff / dg[:, None] / dg[None, :]
    H_ff = 0.5 * (H_ff + H_ff.T)  # exact symmetry for the Cholesky solve
    solver = optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=lx.Cholesky())
    # throw=False: if float32 round-off keeps the refinement from certifying the tolerances
    # within max_steps, the last iterate (already the solution to working precision) is kept.
    sol = optx.least_squares(_residual, solver, jnp.zeros_like(rhs), args=(H_ff, rhs / dg),
                             max_steps=max_steps, throw=False,
                             tags=frozenset({lx.symmetric_tag, lx.positive_semidefinite_tag}))
    free = (sol.value / dg).reshape(kn, km - 1)
    first = jnp.zeros((kn, 1), free.dtype).at[0, 0].set(pb.c00)
    return jnp.concatenate([first, free], axis=1)


_STATIC = ("lap_kind", "normalize_descriptors", "normalize_weights", "orient_sign")


@functools.partial(jax.jit, static_argnames=_STATIC + ("max_steps", "batched"))
def _estimate_jit(sm: _Shape, sn: _Shape, w, gamma, *, lap_kind, normalize_descriptors,
                  normalize_weights, orient_sign, max_steps, batched):
    dt = jnp.result_type(float)
    rtol, atol = (1e-10, 1e-12) if dt == jnp.float64 else (1e-4, 1e-6)

    def one(a, b):
        pb = _setup(_cast(a, dt), _cast(b, dt), jnp.asarray(w, dt), lap_kind=lap_kind,
                    gamma=jnp.asarray(gamma, dt), normalize_descriptors=normalize_descriptors,
                    normalize_weights=normalize_weights, orient_sign=orient_sign)
        return _solve(pb, rtol=rtol, atol=atol, max_steps=max_steps)

    return (jax.vmap(one) if batched else one)(sm, sn)


@functools.partial(jax.jit, static_argnames=_STATIC)
def _energy_jit(C, sm: _Shape, sn: _Shape, w, gamma, *, lap_kind, normalize_descriptors,
                normalize_weights, orient_sign):
    dt = jnp.result_type(float)
    pb = _setup(_cast(sm, dt), _cast(sn, dt), jnp.asarray(w, dt), lap_kind=lap_kind,
                gamma=jnp.asarray(gamma, dt), normalize_descriptors=normalize_descriptors,
                normalize_weights=normalize_weights, orient_sign=orient_sign)
    return _energy(jnp.asarray(C, dt), pb)


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
    [`OrientationBasis`][bsfjax.OrientationBasis] (``bases``), or ``None`` without the orientation term."""
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

    Args:
        source_spectrum, target_spectrum: spectra of ``M`` and ``N`` with at least ``k``
            eigenpairs, or stacks of ``B`` spectra each (evecs ``(B, n, k)``) to estimate ``B``
            maps of equal sizes in one vmapped call.
        source_descr: ``(n_M, p)`` (or ``(B, n_M, p)``) descriptors on the source, e.g.
            ``jnp.concatenate([wks(s), wks(s, landmarks=lm)], axis=1)``.
        target_descr: ``(n_N, p)`` (or ``(B, n_N, p)``), column ``q`` matching column ``q`` of
            ``source_descr``.
        k: map size, an int or ``(k_source, k_target)`` (pyFM's ``K``).
        weights: ``FmapWeights(descr, lap, comm, orient)``, a mapping with those keys or a
            sequence; default pyFM's ``(1e-1, 1e-3, 1, 0)``.
        laplacian: ``"resolvent"`` (Ren et al. 2019, pyFM's default) or ``"plain"``
            (λ differences squared).
        gamma: resolvent exponent in (0, 1].
        source_mesh, target_mesh: the meshes (sequences of meshes for stacked spectra), needed
            only when ``weights.orient > 0``.
        orientation: ``"preserving"`` or ``"reversing"`` (sign σ of the orientation term).
        normalize_descriptors: L2-normalize descriptor columns (area-weighted) first.
        normalize_weights: divide each weight by its term's canonical scale (module doc).
        max_steps: Gauss–Newton step limit (3 are normally used: the problem is linear, the
            first step solves it, the next ones refine and certify convergence).
        orientation_bases: instead of the meshes, the pair's
            [`bsfjax.orientation_bases`][bsfjax.orientation_bases] of at least ``k`` eigenvectors: several
            estimates of one pair (other sizes, descriptors or weights) then share one scan
            over the faces.  The same map as with the meshes, to round-off.

    Returns:
        ``(k_N, k_M)`` map (or ``(B, k_N, k_M)``); [`bsfjax.fmap_to_p2p`][bsfjax.fmap_to_p2p] converts it.
    """
    batched, km, kn, dm, dn = _prepare(source_spectrum, target_spectrum, source_descr,
                                       target_descr, k)
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
    [`OrientationBasis`][bsfjax.OrientationBasis] or ``None``."""
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
