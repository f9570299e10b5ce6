"""TEMPORARY: coder objects until the frame/coding branch lands (then this file goes)."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp

from ._coding import encode as _encode


class AbstractCoder(eqx.Module):
    weights: object = eqx.field(static=True, default="area", kw_only=True)


class OMP(AbstractCoder):
    sparsity: int = eqx.field(static=True, default=10)


class ErrorOMP(AbstractCoder):
    eps_fraction: float = eqx.field(static=True, default=0.1)


class LeastSquares(AbstractCoder):
    rcond: float | None = eqx.field(static=True, default=None)


class Lasso(AbstractCoder):
    lam: float = eqx.field(static=True, default=0.01)
    maxiter: int = eqx.field(static=True, default=2000)
    target_atoms: int | None = eqx.field(static=True, default=None)


CODERS = {"lstsq": LeastSquares, "omp": OMP, "omp_error": ErrorOMP, "lasso": Lasso}
_NAMES = {v: k for k, v in CODERS.items()}


def as_coder(coder, **options):
    if isinstance(coder, AbstractCoder):
        return coder
    return CODERS[coder](**options)


def encode(frame, F, coder):
    name = _NAMES[type(coder)]
    w = frame.mass if coder.weights == "area" else coder.weights
    opts = {f.name: getattr(coder, f.name) for f in dataclasses.fields(coder) if f.name != "weights"}
    if name == "omp_error":
        fn2 = jnp.sum((F * F) * (w if w is not None else 1.0), axis=-1)
        opts = {"eps": opts["eps_fraction"] ** 2 * fn2}
    if name == "lasso" and opts["target_atoms"] is None:
        del opts["target_atoms"]
    elif name == "lasso":
        del opts["lam"]
    q = frame.atoms.shape[-1]
    for k in ("sparsity", "target_atoms"):
        if opts.get(k) is not None and opts[k] > q:
            opts[k] = q
    return _encode(frame.atoms, F, name, weights=w, **opts)
