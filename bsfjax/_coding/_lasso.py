r"""ℓ1-regularised coding in a frame: the [`Lasso`][bsfjax.Lasso] coder.

    min_α ½‖f − Bα‖²_W + λ‖α‖₁,      λ = lam · ‖BᵀWf‖∞  per function,

by accelerated proximal gradient (FISTA, ``jaxopt.ProximalGradient``) on ``G = BᵀWB``, or
with ``λ`` chosen per function by bisection for a target number of atoms.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

with warnings.catch_warnings():  # jaxopt warns on import that it is unmaintained; it works
    warnings.filterwarnings("ignore", message="JAXopt is no longer maintained")
    from jaxopt import ProximalGradient
    from jaxopt.prox import prox_lasso

from ._coders import AbstractCoder, check_positive
from .._util import BSFError
from .._util import check_int, is_traced

__all__ = ["Lasso", "LASSO_DEFAULT_LAM", "LASSO_TARGET_STEPS", "LASSO_LAM_MIN"]

#: The relative λ of a [`Lasso`][bsfjax.Lasso] without ``lam`` or ``target_atoms``.
LASSO_DEFAULT_LAM = 0.01


class Lasso(AbstractCoder):
    """The lasso ``min ½‖f − Bα‖²_W + λ‖α‖₁`` (FISTA on the Gram matrix).

    **Arguments:**

    - `lam`: relative ``λ = lam · ‖BᵀWf‖∞`` per function, so the same ``lam`` means the same
      relative sparsity pressure whatever the scale of ``f`` (``λ ≥ ‖BᵀWf‖∞`` is the smallest
      value giving ``α = 0``, so ``lam ≥ 1`` gives 0).  ``None`` (default): 0.01
      (`LASSO_DEFAULT_LAM`) — or chosen by ``target_atoms``.
    - `target_atoms`: instead of ``lam``, choose ``lam`` per function by bisection so that the
      code has at most that many non-zeros (as many as the bisection finds; ``info.n_atoms``
      says how many).  Not with ``lam`` or ``init``.
    - `maxiter` (10000) and `tol` (1e-4): FISTA with step ``1/L`` (``L ≥ λ_max(G)``) stops,
      per function, when one iteration changes the coefficients by ``√L·‖Δα‖ ≤ tol·‖f‖`` — a
      bound on the change of the approximation ``‖BΔα‖`` relative to ``‖f‖``.  On FAUST
      frames the defaults reach the optimum objective to ~1e-5 relative.
    - `init`: ``(..., q)`` warm start (e.g. the solution for a nearby ``lam``), or ``None``.
    - `weights`: the coding norm (see [`AbstractCoder`][bsfjax.AbstractCoder]).
    """

    lam: float | None = eqx.field(static=True, default=None)
    maxiter: int = eqx.field(static=True, default=10000)
    tol: float = eqx.field(static=True, default=1e-4)
    target_atoms: int | None = eqx.field(static=True, default=None)
    init: Any = None
    name = "lasso"

    def __check_init__(self):
        if self.lam is not None:
            check_positive("lam", self.lam)
        check_int(self.maxiter, "maxiter", 1, 10**9)
        check_positive("tol", self.tol)
        if self.target_atoms is not None:
            check_int(self.target_atoms, "target_atoms", 1)
            if self.lam is not None:
                raise BSFError("give lam or target_atoms, not both (target_atoms chooses λ)")
            if self.init is not None:
                raise BSFError("init cannot be combined with target_atoms (the bisection "
                               "starts from α = 0)")

    def _options(self, frame, w, lead, m, dtype, host=False):
        q = frame.n_atoms
        target = self.target_atoms
        if target is not None and target > q:
            raise BSFError(f"target_atoms must be in [1, q={q}], got {target}")
        static = {"target_atoms": target, "maxiter": int(self.maxiter), "tol": float(self.tol),
                  "lam": float(LASSO_DEFAULT_LAM if self.lam is None else self.lam)}
        per = {}
        if self.init is not None:
            init = self.init
            if tuple(np.shape(init)) != tuple(lead) + (q,):
                raise BSFError(f"init must have shape {tuple(lead) + (q,)}, got "
                               f"{tuple(np.shape(init))}")
            if not is_traced(init) and not np.all(np.isfinite(np.asarray(init))):
                raise BSFError("init contains NaN or infinite values")
            per["init"] = jnp.reshape(jnp.asarray(init, dtype), (m, q))
        return static, {}, per

    @classmethod
    def _solve(cls, frame, F, w, C, fnorm2, static, dyn):
        G = frame.gram(w).astype(C.dtype)
        if static["target_atoms"] is None:
            alpha, err = lasso(G, C, fnorm2, static["lam"], dyn.get("init"), static["maxiter"],
                               static["tol"])
        else:
            alpha, err = lasso_target(G, C, fnorm2, static["target_atoms"], static["maxiter"],
                                      static["tol"])
        return alpha, err <= static["tol"]


def _spectral_bound(G, iters: int = 30):
    """An upper bound ``L ≥ λ_max(G)`` for symmetric ``G``.

    Collatz–Wielandt: for the entrywise ``|G|`` (with ``ρ(G) ≤ ρ(|G|)``) and any positive
    ``x``, ``ρ(|G|) ≤ maxᵢ (|G|x)ᵢ / xᵢ``; a few power iterations make ``x`` close to the Perron
    vector, so the bound is nearly tight, and it stays a guaranteed bound (unlike the power
    estimate itself, which is a lower bound).  Binary frames have ``G ≥ 0``.
    """
    M = jnp.abs(G)
    x = jnp.ones(G.shape[0], G.dtype)

    def step(x, _):
        y = M @ x
        return y / jnp.maximum(jnp.max(y), jnp.finfo(G.dtype).tiny), None

    x, _ = jax.lax.scan(step, x, None, length=iters)
    x = x + 1e-3  # keep every entry positive (x is normalised to max 1)
    bound = jnp.max((M @ x) / x)
    return jnp.where(bound > 0, bound, 1.0)


#: Bisection steps of ``target_atoms`` (on log λ in [log LAM_MIN, 0]) and its lower end.
LASSO_TARGET_STEPS = 14
LASSO_LAM_MIN = 1e-4


def lasso_target(G, C, fnorm2, target: int, maxiter: int, tol: float):
    r"""Lasso whose relative λ is chosen per function so that ``‖α‖₀ ≤ target``, as large a
    support as bisection finds.

    ``lam = 1`` gives ``α = 0`` (feasible).  Bisection on ``log lam`` ∈ ``[log 1e-4, 0]``
    (`LASSO_TARGET_STEPS` steps, each a warm-started FISTA solve, G formed once): a step
    whose solution has at most ``target`` non-zeros becomes the new feasible end.  The result
    is the solution at the smallest feasible λ tried (the support size is not monotone in λ in
    general, so ``n_atoms`` may fall short of ``target``; it never exceeds it)."""
    L = _spectral_bound(G)
    m, q = C.shape
    lo = jnp.full((m,), math.log(LASSO_LAM_MIN), C.dtype)
    hi = jnp.zeros((m,), C.dtype)
    best = jnp.zeros_like(C)
    err = jnp.zeros((m,), C.dtype)

    def step(_, state):
        lo, hi, best, err = state
        mid = 0.5 * (lo + hi)
        a, e = lasso_solve(G, L, C, fnorm2, jnp.exp(mid), best, maxiter, tol)
        feas = jnp.sum(a != 0, axis=1) <= target
        return (jnp.where(feas, lo, mid), jnp.where(feas, mid, hi),
                jnp.where(feas[:, None], a, best), jnp.where(feas, e, err))

    _, _, best, err = jax.lax.fori_loop(0, LASSO_TARGET_STEPS, step, (lo, hi, best, err))
    return best, err


def lasso(G, C, fnorm2, lam, init, maxiter: int, tol: float):
    return lasso_solve(G, _spectral_bound(G), C, fnorm2, lam, init, maxiter, tol)


def lasso_solve(G, L, C, fnorm2, lam, init, maxiter: int, tol: float):
    r"""``min_α ½αᵀGα − αᵀc + λ‖α‖₁`` per row ``c`` of ``C``, ``λ = lam·‖c‖∞``.

    Solved in normalised coordinates ``α = s·z`` with ``s = ‖f‖ / √L`` (``L ≥ λ_max(G)``):
    dividing the objective by ``s²L`` gives ``min_z ½ zᵀ(G/L)z − zᵀĉ + λ̂‖z‖₁`` with
    ``ĉ = c / (‖f‖√L)`` (``‖ĉ‖∞ ≤ 1``) and ``λ̂ = λ / (‖f‖√L)``.  Its gradient is 1-Lipschitz, so
    FISTA runs with step 1, and a step ``‖Δz‖`` bounds the change of the approximation,
    ``‖BΔα‖ ≤ √L‖Δα‖ = ‖f‖·‖Δz‖``: ``tol`` is relative to ``‖f‖`` and scale free.
    """
    Gh = G / L
    fnorm = jnp.sqrt(fnorm2)
    has = fnorm > 0
    denom = jnp.where(has, fnorm, 1.0) * jnp.sqrt(L)
    Ch = C / denom[:, None]
    lam_h = lam * jnp.max(jnp.abs(Ch), axis=1)
    scale = jnp.where(has, fnorm / jnp.sqrt(L), 0.0)
    if init is None:
        Z0 = jnp.zeros_like(C)
    else:
        Z0 = jnp.where(has[:, None], init / jnp.where(has, scale, 1.0)[:, None], 0.0)

    def value_and_grad(z, ch):
        h = Gh @ z
        return jnp.dot(z, 0.5 * h - ch), h - ch

    # unroll=False: jaxopt's default here (implicit_diff off) is a scan of maxiter lax.cond
    # steps, which never exits early and, under vmap, broadcasts G to (m, q, q) every step.
    solver = ProximalGradient(fun=value_and_grad, value_and_grad=True, prox=prox_lasso,
                              stepsize=1.0, maxiter=maxiter, tol=tol, acceleration=True,
                              implicit_diff=False, unroll=False)

    def one(z0, l1, ch):
        res = solver.run(z0, l1, ch)
        return res.params, res.state.error

    # vmap (not one joint problem) so every function has its own stopping test.
    Z, err = jax.vmap(one)(Z0, lam_h, Ch)
    return Z * scale[:, None], err
