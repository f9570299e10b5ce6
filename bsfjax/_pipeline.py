"""Pipeline helpers: approximate a function in a frame, transfer it through a transferred frame,
and run the whole frame → code → transfer pipeline for a stack of shape pairs under one ``vmap``.

Stage order: frame.py (atoms on M, atoms on N) → coding.py (α on M) → here (decode on M or N).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._devices import pad_leading, shard_leading
from ._validate import check_finite
from ._encode import decode, encode
from ._errors import BSFError
from ._frame import Frame, build_frame, transfer_frame
from ._sparse_frame import SparseFrame
from ._spectrum import Spectrum

__all__ = ["approximate", "transfer", "PairResult", "transfer_pairs", "stack_spectra"]


def approximate(frame: Frame, f, method: str = "omp", **options) -> jax.Array:
    """Approximation ``B α`` of ``f`` (``(..., n)``) in its own frame (paper Eq. 14's ``f̃``).

    ``α = encode(frame, f, method, **options)``; see :func:`bsfjax.encode` for methods/options.
    """
    return decode(frame, encode(frame, f, method, **options))


def transfer(frame: Frame, target_frame: Frame, f, method: str = "omp", **options) -> jax.Array:
    """Transfer ``f`` (``(..., n_M)``) from M to N: encode on M, decode on N (paper Eq. 13).

    ``target_frame`` is ``transfer_frame(frame, C, target_spectrum)``: its column ``j`` is the
    image of the source column ``j``, so the source code ``α`` applies to it unchanged:
    ``f_N = B_N α`` with ``α = encode(frame, f)``.  Returns ``(..., n_N)``.
    """
    for name, fr in (("frame", frame), ("target_frame", target_frame)):
        if not isinstance(fr, (Frame, SparseFrame)):
            raise BSFError(f"{name} must be a bsfjax.Frame or SparseFrame, got "
                           f"{type(fr).__name__}")
    q_m, q_n = frame.n_atoms, target_frame.n_atoms
    if q_m != q_n:
        raise BSFError(f"target_frame has {q_n} atoms but frame has {q_m}: target_frame must be "
                       "transfer_frame(frame, C, target_spectrum)")
    return decode(target_frame, encode(frame, f, method, **options))


class PairResult(NamedTuple):
    """Output of :func:`transfer_pairs` (leading axis: pairs)."""

    alpha: jax.Array  #: ``(P, m, q)`` codes on the sources
    approximation: jax.Array  #: ``(P, m, n_M)`` ``B_M α``, the approximation on each source
    transferred: jax.Array  #: ``(P, m, n_N)`` ``B_N α``, the transfer to each target


def stack_spectra(spectra: Sequence[Spectrum]) -> Spectrum:
    """Stack spectra of equal ``(n, k)`` along a new leading axis, for ``vmap`` over shapes."""
    spectra = list(spectra)
    if not spectra or not all(isinstance(s, Spectrum) for s in spectra):
        raise BSFError("spectra must be a non-empty sequence of bsfjax.Spectrum, got "
                       f"{[type(s).__name__ for s in spectra]}")
    shapes = {(s.n_vertices, s.k) for s in spectra}
    if len(shapes) != 1:
        raise BSFError(f"spectra to stack must share (n_vertices, k); got {sorted(shapes)}")
    return jax.tree.map(lambda *x: np.stack(x), *spectra)


@partial(jax.jit, static_argnames=("taus", "gammas", "method", "options", "tau_convention"))
def _pairs_kernel(source, target, C, centers, F, *, taus, gammas, method, options, tau_convention):
    def one(src, tgt, c, ctr, f):
        frame = build_frame(src, ctr, taus, gammas, tau_convention=tau_convention, sparse=False)
        tframe = transfer_frame(frame, c, tgt)
        alpha = encode(frame, f, method, **dict(options))
        return PairResult(alpha, decode(frame, alpha), decode(tframe, alpha))

    return jax.vmap(one)(source, target, C, centers, F)


def transfer_pairs(sources: Spectrum | Sequence[Spectrum], targets: Spectrum | Sequence[Spectrum],
                   C, centers, f, *, taus=(1e-3, 5e-3, 1e-2), gamma=0.75,
                   tau_convention: str = "unit_area", method: str = "omp",
                   **options) -> PairResult:
    """The whole pipeline for ``P`` shape pairs in one jitted ``vmap``.

    For each pair p: ``B_M = build_frame(sources[p], centers[p])``, ``B_N = transfer_frame(B_M,
    C[p], targets[p])``, ``α = encode(B_M, f[p])``, then ``B_M α`` and ``B_N α``.

    Args:
        sources, targets: ``P`` spectra each (lists, or already stacked with
            :func:`stack_spectra`); all sources share ``(n_M, k_M)``, all targets ``(n_N, k_N)``.
        C: ``(P, k_N, k_M)`` functional maps.
        centers: ``(P, n_centers)`` frame centres on each source.
        f: ``(P, m, n_M)`` functions on each source (``m`` per pair).
        taus, gamma, tau_convention: as :func:`bsfjax.build_frame`.
        method, **options: as :func:`bsfjax.encode`.

    Shapes are static, so a new ``(P, n_M, n_N, k, m)`` compiles once and is then cached by
    ``jax.jit``; pairs of different vertex counts go into separate calls (one compiled function
    per shape).

    With several JAX devices (GPUs, or CPU devices from
    ``XLA_FLAGS=--xla_force_host_platform_device_count=N``) the pair axis is sharded across them
    automatically (``jax.sharding``, a 1-D device mesh named ``"pairs"``): no code change, same
    results.  (:func:`bsfjax.encode`, and so :func:`approximate` and :func:`transfer`, split
    the function axis of a batch over the devices the same way.)
    """
    src = stack_spectra(sources) if not isinstance(sources, Spectrum) else sources
    tgt = stack_spectra(targets) if not isinstance(targets, Spectrum) else targets
    if np.ndim(src.evals) != 2 or np.ndim(tgt.evals) != 2:
        raise BSFError("sources and targets must be lists of spectra or stacked spectra (P, ...)")
    P = src.evals.shape[0]
    C = np.asarray(C) if not isinstance(C, jax.Array) else C
    centers = np.asarray(centers) if not isinstance(centers, jax.Array) else centers
    f = np.asarray(f) if not isinstance(f, jax.Array) else f
    k_m, k_n = src.evals.shape[1], tgt.evals.shape[1]
    if tgt.evals.shape[0] != P:
        raise BSFError(f"got {P} sources but {tgt.evals.shape[0]} targets")
    if C.shape != (P, k_n, k_m):
        raise BSFError(f"C must have shape (P, k_N, k_M) = {(P, k_n, k_m)}, got {C.shape}")
    if centers.ndim != 2 or centers.shape[0] != P or centers.shape[1] == 0:
        raise BSFError(f"centers must have shape (P={P}, n_centers >= 1), got {centers.shape}")
    n_m = src.evecs.shape[1]
    if f.ndim != 3 or f.shape[0] != P or f.shape[2] != n_m:
        raise BSFError(f"f must have shape (P={P}, m, n_M={n_m}), got {f.shape}")
    check_finite(f, "f")
    check_finite(C, "C")
    if not isinstance(centers, jax.Array) and (centers.min() < 0 or centers.max() >= n_m):
        raise BSFError(f"centers must index source vertices in [0, {n_m}), got "
                       f"[{centers.min()}, {centers.max()}]")
    # run the Python-side validation of the stages once on the first pair (concrete values)
    first = jax.tree.map(lambda x: x[0], src)
    frame0 = build_frame(first, centers[0], taus, gamma, tau_convention=tau_convention,
                         sparse=False)
    encode(frame0.atoms, f[0, :1], method, **options)
    n_c = centers.shape[1]
    # per-scale τ and γ as static tuples (build_frame validates concrete values)
    per_scale_taus = tuple(float(t) for t in np.asarray(frame0.taus).reshape(-1, n_c)[:, 0])
    per_scale_gammas = tuple(float(g) for g in np.asarray(frame0.gammas).reshape(-1, n_c)[:, 0])
    args = (src, tgt, C, centers, f)
    devices = jax.devices()
    if len(devices) > 1:
        args = _shard_pairs(args, devices)
    out = _pairs_kernel(*args, taus=per_scale_taus, gammas=per_scale_gammas,
                        method=method, options=tuple(sorted(options.items())),
                        tau_convention=tau_convention)
    return jax.tree.map(lambda x: x[:P], out)


def _shard_pairs(args, devices):
    """Pad the pair axis to a multiple of the device count and shard it across ``devices``.

    Pairs are independent, so GSPMD partitions the vmapped kernel without communication; each
    device computes whole pairs, which keeps results identical to a single-device run.  Padding
    repeats the last pair and is sliced off by the caller.
    """
    d = len(devices)
    return jax.tree.map(lambda x: shard_leading(pad_leading(x, d, "edge"), "pairs"), args)
