"""The functional-map estimation problem of one pair: descriptor operators, mask and term scales.
Owner of each shape's descriptor coefficients ``F`` and multiplication and orientation
operators ``D``, ``O`` (`_Shape`, `_ShapeOps`, `_shape_ops`), the Laplacian mask, pyFM's
canonical term scales (`_taus`), and `_setup`, which assembles them into a `_Problem` for the
solve of `bsfjax._maps._fmap_solve` (`bsfjax._maps._estimation` states the energy and its
weights).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._util import BSFError
from ._orientation import _Geometry, _orient_ops

__all__: list[str] = []


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
    """pyFM's canonical scales (τ_descr, τ_lap, τ_comm, τ_orient) of the terms (module doc of
    `bsfjax._maps._estimation`)."""
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
