"""Functional map estimation from descriptors (Ovsjanikov et al. 2012; Nogneng & Ovsjanikov 2017).

Given descriptors ``d_M`` ``(n_M, p)`` on the source and ``d_N`` ``(n_N, p)`` on the target (column
``q`` of both describes "the same" function), the functional map ``C`` ``(k_N, k_M)`` minimizes

    E(C) = μ_descr · ½ ‖C F_M − F_N‖²                         descriptor preservation
         + μ_lap   · ½ Σ_ij M_ij C_ij²                          Laplacian commutativity
         + μ_comm  · ½ Σ_q ‖C D_M^q − D_N^q C‖²                  descriptor commutativity

with ``F = Φᵀ A d`` the spectral coefficients of the descriptors and
``D^q = Φᵀ A diag(d_q) Φ`` the multiplication operator of descriptor ``q`` in the reduced basis
(Nogneng & Ovsjanikov 2017).  ``M`` is the Laplacian mask: ``"plain"`` gives
``M_ij = (λ_M,j − λ_N,i)²``, i.e. ‖C Λ_M − Λ_N C‖²; ``"resolvent"`` (default, as pyFM) uses the
bounded resolvent mask of Ren et al. 2019 with exponent ``gamma``, with the same null space.

The first column of C (the image of the constant function) is fixed analytically, as in pyFM:
``C[:, 0] = (s √(S_N / S_M), 0, …, 0)`` with ``S`` the areas and ``s`` the sign product of the
two constant eigenvectors; only ``C[:, 1:]`` is optimized.

Weights, as pyFM's ``FunctionalMapping.fit`` (v1.3, ``normalize_weights=True``): the user
weights ``w = (descr, lap, comm)`` (pyFM defaults ``(1e-1, 1e-3, 1)``) are divided by their sum
and by the canonical scale τ of each term, ``μ_t = w_t / τ_t``, where with ``m = min(k_M, k_N)``
and the effective descriptor count ``p_eff = mean over shapes of (tr G)² / ‖G‖_F²``,
``G = F[1:]ᵀ F[1:]``:

    τ_descr = m ‖F_M[1:]‖² / (k_M p_eff)
    τ_lap   = m Σ_ij M_ij / (k_M k_N)
    τ_comm  = m Σ_q (k_N ‖D_M^q‖² + k_M ‖D_N^q‖² − 2 tr D_M^q tr D_N^q) / (k_M k_N p_eff)

(a non-positive τ is replaced by 1).  Descriptors are first L2-normalized per column in the
area-weighted inner product (``normalize_descriptors=True``, pyFM's default).

Solve.  E is quadratic in C, so its minimizer solves the normal equations ``H c = g`` of the
stacked least-squares residual.  ``H`` is assembled exactly from Kronecker structure (row-major
``vec``): ``H = μ_descr I ⊗ F_M F_Mᵀ + μ_lap diag(vec M) + μ_comm (I ⊗ S_M + S_N ⊗ I − 2 Σ_q D_N^q ⊗
D_M^q)`` with ``S = Σ_q (D^q)²`` — the last sum is one GEMM ``(k_N², p) @ (p, k_M²)`` — and
never the ``p k² × k²`` Jacobian.  The linear residual ``r(c) = H c − g`` is then solved by
``optimistix.least_squares`` with Gauss–Newton and a lineax Cholesky solve (``H`` is symmetric
positive definite): the first step is the exact solution, the next is an iterative-refinement
step that certifies convergence.  Everything runs in one jitted call; a stack of pairs (stacked
spectra and descriptors of equal shapes) is ``vmap``-ed.
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

from .errors import BSFError
from .spectrum import Spectrum

__all__ = ["estimate_fmap", "FmapWeights", "fmap_energy", "LAPLACIAN_MASKS"]

LAPLACIAN_MASKS = ("resolvent", "plain")


class FmapWeights(NamedTuple):
    """Relative weights of the three energy terms (pyFM's ``w_descr``, ``w_lap``, ``w_dcomm``).

    Only their ratios matter: they are divided by their sum and, with ``normalize_weights``, by
    each term's canonical scale (module doc).
    """

    descr: float = 1e-1
    lap: float = 1e-3
    comm: float = 1.0


# --------------------------------------------------------------------------- building blocks


def _normalize_columns(d, mass):
    """Each column divided by its area-weighted L2 norm √(dᵀ A d)."""
    norms = jnp.sqrt(jnp.einsum("np,n,np->p", d, mass, d))
    return d / jnp.where(norms > 0, norms, 1.0)


def _mult_ops(evecs, mass, d):
    """``(p, k, k)`` multiplication operators Φᵀ A diag(d_q) Φ in one GEMM over pair products.

    Only the k(k+1)/2 products φ_i φ_j with i ≤ j are formed (the operators are symmetric):
    memory ``n k(k+1)/2``, work ``n k(k+1)/2 p``.
    """
    k = evecs.shape[1]
    iu, ju = np.triu_indices(k)
    pairs = evecs[:, iu] * evecs[:, ju]  # (n, k(k+1)/2)
    upper = pairs.T @ (mass[:, None] * d)  # (k(k+1)/2, p)
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


def _canonical_taus(F_m, F_n, D_m, D_n, mask):
    """pyFM's canonical scales (τ_descr, τ_lap, τ_comm) of the three terms (module doc)."""
    km, kn = F_m.shape[0], F_n.shape[0]
    m = min(km, kn)
    p_eff = jnp.maximum(0.5 * (_effective_p(F_m) + _effective_p(F_n)), 1e-12)

    def guard(v):
        return jnp.where(v > 0, v, 1.0)

    tau_descr = guard(m * jnp.sum(F_m[1:] ** 2) / km / p_eff)
    tau_lap = guard(m * jnp.sum(mask) / (km * kn))
    sq_m = jnp.sum(D_m**2, axis=(1, 2))
    sq_n = jnp.sum(D_n**2, axis=(1, 2))
    tr_m = jnp.trace(D_m, axis1=1, axis2=2)
    tr_n = jnp.trace(D_n, axis1=1, axis2=2)
    positive = jnp.sum(kn * sq_m + km * sq_n)
    total = jnp.maximum(positive - 2 * jnp.sum(tr_m * tr_n), 0.0)
    tau_comm = jnp.where(total <= 1e-12 * positive, 1.0, total * m / (km * kn) / p_eff)
    return tau_descr, tau_lap, tau_comm


class _Problem(NamedTuple):
    F_m: jax.Array  # (k_M, p)
    F_n: jax.Array  # (k_N, p)
    D_m: jax.Array  # (p, k_M, k_M)
    D_n: jax.Array  # (p, k_N, k_N)
    mask: jax.Array  # (k_N, k_M)
    mu: jax.Array  # (3,) μ_descr, μ_lap, μ_comm
    c00: jax.Array  # fixed C[0, 0]


def _setup(evals_m, evecs_m, mass_m, evals_n, evecs_n, mass_n, d_m, d_n, w, *, lap_kind, gamma,
           normalize_descriptors, normalize_weights) -> _Problem:
    if normalize_descriptors:
        d_m = _normalize_columns(d_m, mass_m)
        d_n = _normalize_columns(d_n, mass_n)
    F_m = evecs_m.T @ (mass_m[:, None] * d_m)
    F_n = evecs_n.T @ (mass_n[:, None] * d_n)
    D_m = _mult_ops(evecs_m, mass_m, d_m)
    D_n = _mult_ops(evecs_n, mass_n, d_n)
    mask = _lap_mask(evals_m, evals_n, lap_kind, gamma)
    w = w / jnp.sum(w)
    if normalize_weights:
        w = w / jnp.stack(_canonical_taus(F_m, F_n, D_m, D_n, mask))
    sign = jnp.sign(evecs_m[0, 0] * evecs_n[0, 0])
    c00 = jnp.where(sign == 0, 1.0, sign) * jnp.sqrt(jnp.sum(mass_n) / jnp.sum(mass_m))
    return _Problem(F_m, F_n, D_m, D_n, mask, w, c00)


def _normal_equations(pb: _Problem):
    """Gram ``H`` ``(k_N, k_M, k_N, k_M)`` and right-hand side ``g`` ``(k_N, k_M)`` of E."""
    mu_d, mu_l, mu_c = pb.mu
    kn, km = pb.mask.shape
    eye_n = jnp.eye(kn, dtype=pb.mask.dtype)
    eye_m = jnp.eye(km, dtype=pb.mask.dtype)
    G_m = pb.F_m @ pb.F_m.T
    S_m = jnp.einsum("qij,qjk->ik", pb.D_m, pb.D_m)
    S_n = jnp.einsum("qij,qjk->ik", pb.D_n, pb.D_n)
    p = pb.D_m.shape[0]
    # Σ_q D_N^q[i, a] D_M^q[j, b] as one GEMM, then (i, a, j, b) → (i, j, a, b).
    cross = (pb.D_n.reshape(p, kn * kn).T @ pb.D_m.reshape(p, km * km))
    cross = cross.reshape(kn, kn, km, km).transpose(0, 2, 1, 3)
    H = (jnp.einsum("ia,jb->ijab", eye_n, mu_d * G_m + mu_c * S_m)
         + jnp.einsum("ia,jb->ijab", mu_c * S_n, eye_m)
         - 2 * mu_c * cross
         + mu_l * jnp.einsum("ij,ia,jb->ijab", pb.mask, eye_n, eye_m))
    g = mu_d * pb.F_n @ pb.F_m.T
    return H, g


def _energy(C, pb: _Problem):
    mu_d, mu_l, mu_c = pb.mu
    e_descr = 0.5 * jnp.sum((C @ pb.F_m - pb.F_n) ** 2)
    e_lap = 0.5 * jnp.sum(pb.mask * C * C)
    comm = jnp.einsum("ij,qjk->qik", C, pb.D_m) - jnp.einsum("qij,jk->qik", pb.D_n, C)
    e_comm = 0.5 * jnp.sum(comm * comm)
    return mu_d * e_descr + mu_l * e_lap + mu_c * e_comm


def _residual(y, args):
    H, rhs = args
    return H @ y - rhs


def _solve(pb: _Problem, *, rtol, atol, max_steps):
    H, g = _normal_equations(pb)
    kn, km = pb.mask.shape
    # Only C[:, 1:] is free; the fixed column contributes −H[free, (0, 0)] C[0, 0] to the rhs.
    H_ff = H[:, 1:, :, 1:].reshape(kn * (km - 1), kn * (km - 1))
    rhs = (g[:, 1:] - H[:, 1:, 0, 0] * pb.c00).reshape(-1)
    # Unit mean diagonal: tolerances mean the same whatever the descriptors' scale.
    scale = jnp.trace(H_ff) / H_ff.shape[0]
    scale = jnp.where(scale > 0, scale, 1.0)
    H_ff, rhs = H_ff / scale, rhs / scale
    H_ff = 0.5 * (H_ff + H_ff.T)  # exact symmetry for the Cholesky solve
    solver = optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=lx.Cholesky())
    sol = optx.least_squares(_residual, solver, jnp.zeros_like(rhs), args=(H_ff, rhs),
                             max_steps=max_steps, throw=False,
                             tags=frozenset({lx.symmetric_tag, lx.positive_semidefinite_tag}))
    free = sol.value.reshape(kn, km - 1)
    first = jnp.zeros((kn, 1), free.dtype).at[0, 0].set(pb.c00)
    return jnp.concatenate([first, free], axis=1)


@functools.partial(jax.jit, static_argnames=("lap_kind", "normalize_descriptors",
                                             "normalize_weights", "max_steps", "batched"))
def _estimate_jit(evals_m, evecs_m, mass_m, evals_n, evecs_n, mass_n, d_m, d_n, w, gamma, *,
                  lap_kind, normalize_descriptors, normalize_weights, max_steps, batched):
    dt = jnp.result_type(float)
    rtol, atol = (1e-10, 1e-12) if dt == jnp.float64 else (1e-4, 1e-6)

    def one(em, vm, am, en, vn, an, dm, dn):
        args = [jnp.asarray(x, dt) for x in (em, vm, am, en, vn, an, dm, dn)]
        pb = _setup(*args, jnp.asarray(w, dt), lap_kind=lap_kind, gamma=jnp.asarray(gamma, dt),
                    normalize_descriptors=normalize_descriptors,
                    normalize_weights=normalize_weights)
        return _solve(pb, rtol=rtol, atol=atol, max_steps=max_steps)

    f = jax.vmap(one) if batched else one
    return f(evals_m, evecs_m, mass_m, evals_n, evecs_n, mass_n, d_m, d_n)


@functools.partial(jax.jit, static_argnames=("lap_kind", "normalize_descriptors",
                                             "normalize_weights"))
def _energy_jit(C, evals_m, evecs_m, mass_m, evals_n, evecs_n, mass_n, d_m, d_n, w, gamma, *,
                lap_kind, normalize_descriptors, normalize_weights):
    dt = jnp.result_type(float)
    args = [jnp.asarray(x, dt) for x in (evals_m, evecs_m, mass_m, evals_n, evecs_n, mass_n,
                                         d_m, d_n)]
    pb = _setup(*args, jnp.asarray(w, dt), lap_kind=lap_kind, gamma=jnp.asarray(gamma, dt),
                normalize_descriptors=normalize_descriptors, normalize_weights=normalize_weights)
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
            raise BSFError(f"weights must be FmapWeights, a mapping or a 3-sequence "
                           f"(descr, lap, comm), got {weights!r}") from exc
    w = np.asarray(weights, dtype=np.float64)
    if not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise BSFError(f"weights must be finite, non-negative and not all 0, got {weights}")
    return w


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
    dm, dn = np.asarray(source_descr), np.asarray(target_descr)
    want = 3 if batched else 2
    for d, s, name in ((dm, sm, "source_descr"), (dn, sn, "target_descr")):
        if d.ndim == want - 1:
            d = d[..., None]
        if d.ndim != want or d.shape[:-1] != s[:-1]:
            raise BSFError(f"{name} must have shape {(*s[:-1], 'p')} (one row per vertex of its "
                           f"spectrum), got {np.shape(d)}")
        if not np.issubdtype(d.dtype, np.number) or not np.all(np.isfinite(d)):
            raise BSFError(f"{name} must be finite numbers (found NaN/inf or a non-numeric dtype)")
    if dm.ndim == want - 1:
        dm = dm[..., None]
    if dn.ndim == want - 1:
        dn = dn[..., None]
    if dm.shape[-1] != dn.shape[-1]:
        raise BSFError(f"source_descr and target_descr must have the same number of descriptors "
                       f"(columns), got {dm.shape[-1]} and {dn.shape[-1]}")
    return batched, km, kn, dm, dn


def _check_options(laplacian, gamma):
    if laplacian not in LAPLACIAN_MASKS:
        raise BSFError(f"laplacian must be one of {LAPLACIAN_MASKS}, got {laplacian!r}")
    if not np.isfinite(gamma) or not 0 < gamma <= 1:
        raise BSFError(f"gamma must be in (0, 1], got {gamma!r}")


# --------------------------------------------------------------------------- public API


def estimate_fmap(source_spectrum: Spectrum, target_spectrum: Spectrum, source_descr,
                  target_descr, *, k=30, weights=None, laplacian: str = "resolvent",
                  gamma: float = 0.5, normalize_descriptors: bool = True,
                  normalize_weights: bool = True, max_steps: int = 8) -> jax.Array:
    """Functional map ``C`` ``(k_N, k_M)`` from source to target minimizing the energy above.

    Args:
        source_spectrum, target_spectrum: spectra of ``M`` and ``N`` with at least ``k``
            eigenpairs, or stacks of ``B`` spectra each (evecs ``(B, n, k)``) to estimate ``B``
            maps of equal sizes in one vmapped call.
        source_descr: ``(n_M, p)`` (or ``(B, n_M, p)``) descriptors on the source, e.g.
            ``jnp.concatenate([wks(s), wks(s, landmarks=lm)], axis=1)``.
        target_descr: ``(n_N, p)`` (or ``(B, n_N, p)``), column ``q`` matching column ``q`` of
            ``source_descr``.
        k: map size, an int or ``(k_source, k_target)``.
        weights: ``FmapWeights(descr, lap, comm)``, a mapping with those keys or a 3-sequence;
            default pyFM's ``(1e-1, 1e-3, 1)``.
        laplacian: ``"resolvent"`` (Ren et al. 2019, pyFM's default) or ``"plain"``
            (λ differences squared).
        gamma: resolvent exponent in (0, 1].
        normalize_descriptors: L2-normalize descriptor columns (area-weighted) first.
        normalize_weights: divide each weight by its term's canonical scale (module doc).
        max_steps: Gauss–Newton step limit (2–3 are used; the problem is linear).

    Returns:
        ``(k_N, k_M)`` map (or ``(B, k_N, k_M)``); :func:`bsfjax.fmap_to_p2p` converts it.
    """
    batched, km, kn, dm, dn = _prepare(source_spectrum, target_spectrum, source_descr,
                                       target_descr, k)
    w = _weights_array(weights)
    _check_options(laplacian, gamma)
    if not isinstance(max_steps, (int, np.integer)) or max_steps < 2:
        raise BSFError(f"max_steps must be an integer >= 2, got {max_steps!r}")
    sm, sn = source_spectrum, target_spectrum
    return _estimate_jit(sm.evals[..., :km], sm.evecs[..., :km], sm.mass, sn.evals[..., :kn],
                         sn.evecs[..., :kn], sn.mass, dm, dn, w, float(gamma),
                         lap_kind=laplacian, normalize_descriptors=bool(normalize_descriptors),
                         normalize_weights=bool(normalize_weights), max_steps=int(max_steps),
                         batched=batched)


def fmap_energy(C, source_spectrum: Spectrum, target_spectrum: Spectrum, source_descr,
                target_descr, *, weights=None, laplacian: str = "resolvent", gamma: float = 0.5,
                normalize_descriptors: bool = True, normalize_weights: bool = True) -> jax.Array:
    """The energy E(C) that :func:`estimate_fmap` minimizes (single pair), for diagnostics."""
    shape = np.shape(C)
    if len(shape) != 2:
        raise BSFError(f"C must be a (k_target, k_source) matrix, got shape {shape}")
    batched, km, kn, dm, dn = _prepare(source_spectrum, target_spectrum, source_descr,
                                       target_descr, (shape[1], shape[0]))
    if batched:
        raise BSFError("fmap_energy takes a single pair, not stacked spectra")
    w = _weights_array(weights)
    _check_options(laplacian, gamma)
    sm, sn = source_spectrum, target_spectrum
    return _energy_jit(C, sm.evals[:km], sm.evecs[:, :km], sm.mass, sn.evals[:kn],
                       sn.evecs[:, :kn], sn.mass, dm, dn, w, float(gamma), lap_kind=laplacian,
                       normalize_descriptors=bool(normalize_descriptors),
                       normalize_weights=bool(normalize_weights))
