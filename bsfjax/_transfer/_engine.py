"""The transfer engine: one function that runs every method on one pair or a stack of pairs.

[`transfer`][bsfjax.transfer] validates the inputs once (concrete values, before tracing), then runs the
method's ``prepare`` and ``carry`` (`bsfjax._transfer._methods`) in one jitted function; a stacked
[`Pair`][bsfjax.Pair] (leading pair axis on every array) runs all pairs under one ``vmap``,
with the pair axis sharded over all JAX devices.  Everything else that transfers — the
mesh-level [`bsfjax.transfer_values`][bsfjax.transfer_values] / [`bsfjax.transfer_labels`][bsfjax.transfer_labels], ``bsfjax
transfer``, ``bsfjax demo``, the experiments and [`transfer_pairs`][bsfjax.transfer_pairs] — calls this.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._util import pad_leading, shard_leading
from .._util import BSFError
from .._frame import DENSE_BUDGET_BYTES
from .._util import check_finite, homogeneous, is_traced, restore_scale, unit_scale
from ._methods import AbstractMethod, Pair, as_method, method_name
from .._spectral import Spectrum, map_to_unit_area, unit_area, unit_area_pair
from .._util import on_one_blas_thread

__all__ = ["TransferResult", "transfer", "transfer_pairs", "stack_pairs"]


class TransferResult(NamedTuple):
    """Output of [`transfer`][bsfjax.transfer] (leading pair axis when the pair was stacked)."""

    approximation: Float[Array, "*pairs m n_M"] | None  #: ``f̃`` on the source, or ``None``
    transferred: Float[Array, "*pairs m n_N"] | tuple | None  #: on the target (tuple per k_N)
    codes: Float[Array, "*pairs m q"] | None  #: the BSF codes ``α`` (``None`` without a frame)


def _kernel(method: AbstractMethod, pair: Pair, F, k: int, k_targets, batched: bool):
    """``k_targets``: ``None`` (no transfer), ``()`` (transfer with all of ``pair.C``) or a
    tuple of row counts ``k_N`` (one transfer per ``C[:k_N]``)."""

    def one(p, f):
        approx, carry, codes = method.prepare(p, f, k)
        if k_targets is None:
            out = None
        elif not k_targets:
            out = carry(p.C)
        else:
            out = tuple(carry(p.C[:kn]) for kn in k_targets)
        return approx, out, codes

    if not batched:
        return one(pair, F)
    return jax.vmap(one)(pair, F)


_run = eqx.filter_jit(_kernel)


def _check_k_targets(k_targets, method, pair, transfer: bool):
    if k_targets is None:
        return None
    if not transfer or method.own_map:
        raise BSFError("k_targets needs transfer=True and a method other than 'std2' and "
                       "'p2p' (their transfer does not use C)")
    try:
        k_targets = tuple(int(v) for v in k_targets)
    except (TypeError, ValueError):
        raise BSFError(f"k_targets must be a sequence of ints, got {k_targets!r}") from None
    rows = np.shape(pair.C)[-2]
    if not k_targets or not all(1 <= v <= rows for v in k_targets):
        raise BSFError(f"k_targets must be non-empty ints in [1, C rows = {rows}], got "
                       f"{k_targets}")
    return k_targets


def _check_pair(method: AbstractMethod, pair: Pair, k: int, transfer: bool, b: int) -> None:
    name = method_name(method)
    src = pair.source
    if not isinstance(src, Spectrum):
        raise BSFError(f"pair.source must be a bsfjax.Spectrum, got {type(src).__name__}")
    k_m = np.shape(src.evecs)[-1]
    need = method.source_k(k)
    if not method.transfer_only and need > k_m:
        raise BSFError(f"method {name!r} with k={k} needs {need} source eigenpairs, the source "
                       f"spectrum has {k_m}")
    if transfer and not isinstance(pair.target, Spectrum):
        raise BSFError(f"transfer with {name!r} needs pair.target (a bsfjax.Spectrum)")
    method.check(pair, k, transfer, b)
    if transfer and not method.own_map:
        C = pair.C
        if C is None:
            raise BSFError(f"transfer with {name!r} needs pair.C ({k} columns)")
        kn, km = np.shape(C)[b:]
        if km != k:
            raise BSFError(f"pair.C must have k_M = {k} columns for k={k}, got shape "
                           f"{tuple(np.shape(C))}")
        k_avail = np.shape(pair.target.evecs)[-1]
        if kn > k_avail:
            raise BSFError(f"pair.C has {kn} rows but the target spectrum only {k_avail} "
                           "eigenpairs")
        check_finite(C, "pair.C")


@on_one_blas_thread
def transfer(method: AbstractMethod | str, pair: Pair, f: Float[ArrayLike, "*pairs m n_M"], *,
             k: int | None = None, transfer: bool = True, k_targets=None,
             **options) -> TransferResult:
    r"""Approximate ``f`` on the source and carry it to the target with one method.

    The one transfer function of bsfjax: the manual route
    ``decode(transfer_frame(frame, C, N), encode(frame, f, coder))`` and this give the same
    numbers for the same frame, coder and map.

    **Arguments:**

    - `method`: a name of [`bsfjax.METHODS`][bsfjax.METHODS] (``"omp"``, ``"lstsq"``, ``"std"``,
      ``"p2p"``, …) or a method object (``bsfjax.BSF(coder=bsfjax.OMP(sparsity=20))``).
    - `pair`: a [`Pair`][bsfjax.Pair], or a stack of ``P`` of them
      ([`stack_pairs`][bsfjax.stack_pairs]: leading axis ``P``) to run all pairs under one ``vmap``.
    - `f`: ``(m, n_M)`` functions on the source (``(P, m, n_M)`` for a stack).
    - `k`: source basis size (``"std2"`` uses ``2k``).  Default: the columns of ``pair.C``.
    - `transfer`: also transfer (needs ``target`` and ``C`` / ``C2`` / ``p2p``).
    - `k_targets`: optional target sizes ``k_N ≤ C.shape[0]``: one transfer per
      ``C[:k_N]``, reusing one code; ``transferred`` is then a tuple.
    - ``**options``: with a method name, its options (`as_method`).

    Returns a [`TransferResult`][bsfjax.TransferResult] ``(approximation, transferred, codes)``: ``(m, n_M)``,
    ``(m, n_N)`` and ``(m, q)`` arrays (``(P, …)`` for a stack); ``approximation`` is
    ``None`` for ``"p2p"``, ``transferred`` when ``transfer=False``, ``codes`` for methods
    without a frame.
    """
    method = as_method(method, **options)
    if not isinstance(pair, Pair):
        raise BSFError(f"pair must be a bsfjax.Pair, got {type(pair).__name__}")
    if method.transfer_only and not transfer:
        raise BSFError(f"method {method_name(method)!r} only transfers (its approximation "
                       "would be f itself)")
    batched = np.ndim(pair.source.evals) == 2
    if k is None:
        if pair.C is not None:
            k = int(np.shape(pair.C)[-1])
        elif method.transfer_only:  # "p2p", "refined": no basis size of their own
            k = 1
        else:
            raise BSFError("k must be given when pair.C is None")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise BSFError(f"k must be a positive int, got {k!r}")
    k = int(k)
    b = 1 if batched else 0
    _check_pair(method, pair, k, transfer, b)
    k_targets = _check_k_targets(k_targets, method, pair, transfer)
    n_m = np.shape(pair.source.evecs)[-2]
    f_shape = tuple(np.shape(f))
    P = np.shape(pair.source.evals)[0] if batched else None
    if len(f_shape) != 2 + b or f_shape[-1] != n_m or (batched and f_shape[0] != P):
        raise BSFError(f"f must have shape {'(P, m, n_M)' if batched else '(m, n_M)'} with "
                       f"n_M = {n_m}, got {f_shape}")
    check_finite(f, "f")
    dtype = jax.dtypes.canonicalize_dtype(jnp.float64)
    # per function, in float64 before the cast; not for an absolute coder eps
    F, scale = unit_scale(f, dtype) if homogeneous(method) else (jnp.asarray(f, dtype), None)
    pair = _unit_area_pair(method, pair)
    pair = jax.tree.map(lambda x: jnp.asarray(x, dtype)
                        if np.issubdtype(np.asarray(x).dtype, np.floating) else jnp.asarray(x),
                        pair)
    kt = None if not transfer else (() if k_targets is None else k_targets)
    itemsize = jax.dtypes.canonicalize_dtype(jnp.float64).itemsize
    if not batched and method.frame_entries(pair) * itemsize > DENSE_BUDGET_BYTES:
        # a dense frame would not fit: run eagerly, so that build_frame / transfer_frame make
        # per-vertex-list frames (SparseFrame) and encode / decode use them
        return _rescaled(TransferResult(*_kernel(method, pair, F, k, kt, batched)), scale, f)
    if batched and jax.device_count() > 1:
        # pairs are independent: GSPMD splits the vmapped kernel without communication, each
        # device computing whole pairs (identical results); padding repeats the last pair
        d = jax.device_count()
        pair, F = jax.tree.map(lambda x: shard_leading(pad_leading(x, d, "edge"), "pairs"),
                               (pair, F))
        out = _run(method, pair, F, k, kt, batched)
        return _rescaled(TransferResult(*jax.tree.map(lambda x: x[:P], out)), scale, f)
    return _rescaled(TransferResult(*_run(method, pair, F, k, kt, batched)), scale, f)


def _unit_area_pair(method: AbstractMethod, pair: Pair) -> Pair:
    """The pair on the shapes rescaled to unit area (`bsfjax._spectral.unit_area`), in
    float64 on the host before any cast: maps ``C``, ``C2`` become ``C·√(S_M/S_N)`` and geodesic
    distances ``d/√S_M``; every method's output is invariant to this (its scales follow the
    areas: the ``"unit_area"`` τ convention, ball radii from atom areas).  Not with the
    ``"raw"`` τ convention, whose τ is in the mesh's own units."""
    if getattr(method, "tau_convention", "unit_area") != "unit_area":
        return pair
    if pair.target is None:
        source, am = unit_area(pair.source)
        target = an = None
    else:  # both at one area: ZoomOut-type steps compare the shapes at one scale
        source, am, target, an = unit_area_pair(pair.source, pair.target)
    if am is None:
        return pair
    dist = pair.distances
    if dist is not None and not isinstance(dist, jax.core.Tracer):
        dist = np.asarray(dist, np.float64) / np.sqrt(am)[..., None, None]
    return Pair(source=source, target=target if target is not None else pair.target,
                C=map_to_unit_area(pair.C, am, an), C2=map_to_unit_area(pair.C2, am, an),
                p2p=pair.p2p, centers=pair.centers, distances=dist, samples=pair.samples)


def _rescaled(res: TransferResult, scale, f) -> TransferResult:
    """Every output of a method is linear in ``f``: undo `unit_scale` per function.  With
    concrete ``f`` (finite: checked), a result that does not fit the dtype (float64 values
    beyond float32's range) is a `BSFError` naming the range, never an inf or NaN returned."""
    with np.errstate(over="ignore"):  # a scale beyond the dtype: refused below, not warned
        res = TransferResult(*(restore_scale(x, scale) for x in res))
    if is_traced(f):
        return res
    leaves = [x for x in jax.tree.leaves(res) if jnp.issubdtype(jnp.result_type(x), jnp.floating)]
    if all(bool(jnp.isfinite(x).all()) for x in leaves):
        return res
    dtype = jnp.result_type(leaves[0])
    top = float(np.max(np.abs(np.asarray(f, np.float64))))
    raise BSFError(f"f has values up to {top:.3g}: the results do not fit in {dtype} (max "
                   f"{float(jnp.finfo(dtype).max):.3g}); rescale f, enable jax_enable_x64, or use "
                   "transfer_values, which rescales on the host and returns float64 beyond the "
                   "float32 range")


def stack_pairs(pairs: Sequence[Pair]) -> Pair:
    """Stack pairs of equal shapes along a new leading axis (for one vmapped [`transfer`][bsfjax.transfer])."""
    pairs = list(pairs)
    if not pairs or not all(isinstance(p, Pair) for p in pairs):
        raise BSFError("pairs must be a non-empty sequence of bsfjax.Pair, got "
                       f"{[type(p).__name__ for p in pairs]}")
    structure = {jax.tree.structure(p) for p in pairs}
    shapes = {tuple(np.shape(x) for x in jax.tree.leaves(p)) for p in pairs}
    if len(structure) != 1 or len(shapes) != 1:
        raise BSFError("pairs to stack must have the same fields and shapes (equal vertex "
                       "counts and k); run differently sized pairs in separate calls")
    return jax.tree.map(lambda *x: np.stack([np.asarray(v) for v in x]), *pairs)


def transfer_pairs(method: AbstractMethod | str, pairs: Sequence[Pair] | Pair,
                   f: Float[ArrayLike, "P m n_M"], **kwargs) -> TransferResult:
    """[`transfer`][bsfjax.transfer] over ``P`` pairs of equal shapes in one jitted ``vmap``.

    ``pairs``: a sequence of [`Pair`][bsfjax.Pair] (stacked here) or an already stacked one;
    ``f``: ``(P, m, n_M)``.  Shapes are static, so a new ``(P, n_M, n_N, k, m)`` compiles
    once.  With several JAX devices (GPUs, or CPU devices from
    ``XLA_FLAGS=--xla_force_host_platform_device_count=N``) the pair axis is sharded across
    them: no code change, same results.
    """
    pair = pairs if isinstance(pairs, Pair) else stack_pairs(pairs)
    if np.ndim(pair.source.evals) != 2:
        raise BSFError("pairs must be a sequence of bsfjax.Pair or a stacked Pair (P, ...)")
    return transfer(method, pair, f, **kwargs)
