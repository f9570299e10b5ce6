"""Mesh-to-mesh entry points: carry values or a segmentation across a map between two shapes
(the map from [`bsfjax.estimate_map`][bsfjax.estimate_map] or the user's).  What
``bsfjax transfer`` and ``bsfjax demo`` run after the map.

They compose the stages (spectrum → frame → coding → transfer); each step is also available
on its own ([`bsfjax.build_frame`][bsfjax.build_frame], [`bsfjax.estimate_fmap`][bsfjax.estimate_fmap], …).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from jaxtyping import ArrayLike, Float, Int

from .._transfer import AbstractMethod, BSF, GeodesicBalls, PullBack, RefinedPullBack, SaturatedHeat, SpectralProjection, as_method, method_name
from .._transfer import Pair, transfer
from .._util import BSFError
from .._sampling import geodesic_distances
from .._metrics import labels_to_indicators, missing_labels
from .._sampling import farthest_point_sampling
from .._spectral import Spectrum
from .._util import on_one_blas_thread
from .._util import check_finite, check_indices, check_source_mesh, compact_labels
from .._util import homogeneous, pow2_scale
from .._mesh import as_mesh

__all__ = ["transfer_values", "transfer_labels", "LabelTransfer", "REGIMES"]


@on_one_blas_thread
def transfer_values(source: Spectrum, target: Spectrum,
                    values: Float[ArrayLike, "m n_M"] | Float[ArrayLike, " n_M"], *,
                    method: AbstractMethod | str = "omp",
                    C: Float[ArrayLike, "k_N k"] | None = None,
                    p2p: Int[ArrayLike, " n_N"] | None = None, k: int | None = None,
                    centers: Int[ArrayLike, " n_c"] | None = None, n_bsf: float | int = 0.05,
                    seed: int = 0, mesh=None, samples=None, **options) -> np.ndarray:
    """Transfer functions ``values`` ``(m, n_M)`` (or ``(n_M,)``) from source to target.

    The mesh-level entry point of [`bsfjax.transfer`][bsfjax.transfer]: it samples the frame centres and
    builds the [`Pair`][bsfjax.Pair], then runs the one engine.

    **Arguments:**

    - `method`: a name of [`bsfjax.METHODS`][bsfjax.METHODS] or a method object (see
      `as_method`); ``**options`` are its options with a name (e.g.
      ``sparsity=20``, ``taus="adaptive"``, ``frame_transfer="p2p"``).
    - `C`: ``(k_N, k)`` functional map (every method but ``"p2p"``); ``k`` defaults to its
      column count.
    - `p2p`: ``(n_N,)`` point map target vertex → source vertex (``"p2p"``, and
      ``frame_transfer="p2p"``).
    - `centers`: the frame centres; default ``n_bsf`` of them (a share or a count) by
      farthest point sampling (``seed``) on ``mesh`` — the source [`Mesh`][bsfjax.Mesh] — or
      on the spectral embedding when no mesh is given.  With the same centres this equals
      ``decode(transfer_frame(build_frame(source, centers), C, target), encode(...))``.
    - `samples`: ``(source, target)`` [`Subsample`][bsfjax.Subsample] s for ``"refined"`` (e.g.
      ``estimate_map(...).samples``); ignored by the other methods.

    **Returns:**

    The transferred values ``(m, n_N)`` (or ``(n_N,)``), in the engine's dtype (float32
    unless ``jax_enable_x64``) where it holds them exactly, else in float64: values of any
    float64 magnitude (1e300) are computed at unit scale on the host and scaled back in
    float64, never returned as inf or NaN.  Complex values are refused.
    """
    mesh = None if mesh is None else as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F)
    method = as_method(method, **options)
    f = _real_array(values, "values")
    single = f.ndim == 1
    f = f[None] if single else f
    if f.ndim != 2 or f.shape[1] != source.n_vertices:
        raise BSFError(f"values must have shape (n_source,) or (m, n_source) with n_source = "
                       f"{source.n_vertices}, got {np.shape(values)}")
    if p2p is not None:
        p2p = np.asarray(p2p)
        if p2p.shape != (target.n_vertices,):
            raise BSFError(f"p2p must have one source index per target vertex "
                           f"({target.n_vertices}), got shape {p2p.shape}")
        p2p = check_indices(p2p, "p2p", source.n_vertices, what="source vertex indices")
    if mesh is not None:
        check_source_mesh(mesh, source.n_vertices, source.mass)
    if p2p is None and (isinstance(method, PullBack) or getattr(method, "frame_transfer", "")
                        == "p2p"):
        raise BSFError(f"method {method_name(method)!r} needs a point map (p2p)")
    if C is None and not isinstance(method, PullBack) and not (
            isinstance(method, RefinedPullBack) and p2p is not None):
        raise BSFError(f"method {method_name(method)!r} needs a functional map C"
                       + (" or a point map p2p" if isinstance(method, RefinedPullBack) else ""))
    if C is not None:
        C = np.asarray(C)
        if C.ndim != 2:
            raise BSFError(f"C must be a (k_N, k) matrix, got shape {C.shape}")
    k = (int(C.shape[1]) if C is not None else 1) if k is None else k
    needs_centers = isinstance(method, (BSF, GeodesicBalls, SaturatedHeat))
    if needs_centers and centers is None:
        pts = mesh if mesh is not None else np.asarray(source.evecs[:, 1:4])
        centers = farthest_point_sampling(pts, n_bsf, seed=seed)
    distances = None
    if isinstance(method, GeodesicBalls):
        if mesh is None:
            raise BSFError("method 'geod' needs the source mesh (mesh=) for geodesic distances")
        distances = geodesic_distances(mesh, centers)
    kn = C.shape[0] if C is not None else target.k
    full = getattr(method, "full_spectra", False)  # "refined" grows the map past k
    pair = Pair(source=source if full or (isinstance(method, SpectralProjection)
                                          and method.factor == 2) else source.truncate(k),
                target=target if full else target.truncate(kn), C=C,
                centers=None if centers is None
                else np.asarray(centers), p2p=p2p,
                distances=distances,
                samples=samples if isinstance(method, RefinedPullBack) else None)
    check_finite(f, "values")
    # per function, on the host in float64: the engine's own float32 restore would overflow
    # for float64 values beyond float32 (1e39, 1e300); not for a method with a fixed scale
    scale = pow2_scale(np.max(np.abs(f), axis=-1)) if homogeneous(method) else None
    res = transfer(method, pair, f if scale is None else f / scale[:, None], k=k)
    out = _host_restore(np.asarray(res.transferred), scale, values)
    return out[0] if single else out


def _real_array(values, name: str) -> np.ndarray:
    """``values`` as a float64 array; complex values are refused (not cut to the real part)."""
    arr = np.asarray(values)
    if np.iscomplexobj(arr):
        raise BSFError(f"{name} must be real numbers, got dtype {arr.dtype}")
    try:
        return np.asarray(arr, dtype=float)
    except (TypeError, ValueError) as exc:
        raise BSFError(f"{name} must be an array of real numbers, got dtype {arr.dtype} "
                       f"({exc})") from None


def _host_restore(out: np.ndarray, scale, values) -> np.ndarray:
    """``out · scale`` per function in float64: in ``out``'s dtype where that holds the result
    exactly (every ordinary case: the scale is a power of two), else in float64; a result
    beyond float64 is a `BSFError`."""
    if scale is None:
        return out
    full = out.astype(np.float64) * scale[:, None]
    if not np.isfinite(full).all():
        top = float(np.max(np.abs(np.asarray(values, np.float64))))
        raise BSFError(f"values up to {top:.3g} transfer to values beyond the float64 range "
                       f"(max {np.finfo(np.float64).max:.3g}): rescale the values")
    with np.errstate(over="ignore", under="ignore"):
        cast = full.astype(out.dtype)
    return cast if np.array_equal(cast.astype(np.float64), full) else full


class LabelTransfer(NamedTuple):
    labels: np.ndarray  #: ``(n_N,)`` int, −1 where unassigned
    scores: np.ndarray  #: ``(L, n_N)`` transferred indicator of each label present, in increasing order
    unassigned_share: float  #: area share of the target left unassigned
    #: area share of the target where the labels equal the pull-back through the input point
    #: map (``None`` without ``p2p``)
    agreement: float | None = None
    #: area-weighted mean of the winning score (for ``"refined"``: the share of its maps that
    #: vote for the label it gives); ``None`` for labels of triangles, whose scores are area
    #: shares of a neighbourhood, below 1 at every border, not votes
    confidence: float | None = None
    #: ``"refined"`` only: how much the refinement changed the input map's labels — see
    #: [`REGIMES`][bsfjax.REGIMES]; ``None`` for the other methods
    regime: str | None = None
    #: the source labels with (almost) no counterpart on the target, in increasing order: a
    #: part under ``MISSING_RATIO`` of its source share of the area (see
    #: [`missing_labels`][bsfjax.missing_labels]; a partial target)
    missing: tuple = ()


#: Regimes of the ``"refined"`` transfer (from the map alone, never from ground truth):
#: ``"kept"``: the labels agree with the input map's pull-back on ≥ 99 % of the area (the
#: input was already at the refinement's fixed point); ``"refined"``: 90–99 %; ``"corrected"``:
#: the input map was rewritten on more than 10 % of the area (a crude or partly wrong map: check
#: the result); ``"unreliable"``: the refined maps disagree (confidence < 0.8), so the map is
#: not converging and the labels should not be trusted.
REGIMES = ("kept", "refined", "corrected", "unreliable")


def _regime(agreement: float | None, confidence: float | None) -> str:
    if confidence is not None and confidence < 0.8:
        return "unreliable"
    if agreement is None:  # no input point map to compare with
        return "refined"
    return "kept" if agreement >= 0.99 else "refined" if agreement >= 0.9 else "corrected"


@on_one_blas_thread
def transfer_labels(source: Spectrum, target: Spectrum, labels: Int[ArrayLike, " n_M"], *,
                    method: AbstractMethod | str = "refined", threshold: float | None = None,
                    **kwargs) -> LabelTransfer:
    """Transfer a segmentation: one step function per label, then arg-max on the target.

    ``labels`` ``(n_M,)`` non-negative ints of any size: they are compacted to the ``L`` labels
    present first, so ``scores`` row ``i`` is the ``i``-th smallest label.  Each label's
    indicator is transferred with [`transfer_values`][bsfjax.transfer_values] (``**kwargs``: ``C``, ``p2p``, …); a
    target vertex takes the label with the largest transferred value, or −1 ("unassigned") when
    that value is below ``threshold``.

    **Arguments:**

    - `method`: default ``"refined"`` ([`RefinedPullBack`][bsfjax.RefinedPullBack]: the most accurate
      from an estimated map; needs ``p2p`` or ``C`` and spectra of ~100 eigenpairs); ``"p2p"``
      for a map that is already right (a registration); the paper's BSF is ``"omp"``.
    - `threshold`: default 0.5 (the midpoint of an indicator's two values) and 0 for
      ``"p2p"`` and ``"refined"``, whose scores are shares (every vertex takes its plurality
      label).
    """
    lab = np.asarray(labels)
    if lab.shape != (source.n_vertices,):
        raise BSFError(f"labels must have one entry per source vertex ({source.n_vertices}), got "
                       f"shape {lab.shape}")
    method, inputs, threshold, refined = _split_label_kwargs(method, threshold, kwargs)
    # one indicator per label *present*, whatever the ids (an id of 1e12 allocates nothing)
    ids, codes = compact_labels(lab)
    scores = transfer_values(source, target,
                             np.asarray(labels_to_indicators(codes, len(ids))), method=method,
                             **inputs)
    p2p = inputs.get("p2p")
    mass = np.asarray(target.mass, dtype=float)
    res = _decide_labels(ids, scores, mass, threshold, refined,
                         None if p2p is None else lab[np.asarray(p2p)])
    gone = missing_labels(lab, np.asarray(source.mass, dtype=float), res.labels, mass)
    return res._replace(missing=tuple(int(i) for i in gone))


#: What ``transfer_labels`` passes on to [`transfer_values`][bsfjax.transfer_values] as inputs; its other keyword
#: arguments are options of the method.
_LABEL_INPUTS = frozenset({"C", "p2p", "k", "centers", "n_bsf", "seed", "mesh", "samples"})


def _split_label_kwargs(method, threshold, kwargs):
    """``(method, inputs, threshold, refined)`` of a label transfer: the method built with its
    options from ``kwargs``, the rest of ``kwargs`` (the pair's inputs), the threshold with
    its default, and whether the method is ``"refined"``."""
    method = as_method(method, **{k: v for k, v in kwargs.items() if k not in _LABEL_INPUTS})
    inputs = {k: v for k, v in kwargs.items() if k in _LABEL_INPUTS}
    refined = isinstance(method, RefinedPullBack)
    if threshold is None:
        threshold = default_threshold(method)
    if not 0 <= threshold < 1:
        raise BSFError(f"threshold must be in [0, 1), got {threshold!r}")
    return method, inputs, threshold, refined


def default_threshold(method: AbstractMethod) -> float:
    """The score below which a label transfer leaves an element unassigned, by default: 0 for
    the pull-backs (``"p2p"``, ``"refined"``), whose scores are shares (of the maps' votes, of
    a triangle's neighbourhood), so every element takes its plurality label; 0.5, the midpoint
    of an indicator's two values, for the methods that reconstruct indicators."""
    return 0.0 if isinstance(method, (PullBack, RefinedPullBack)) else 0.5


def _decide_labels(ids, scores, weights, threshold: float, refined: bool, reference,
                   votes: bool = True) -> LabelTransfer:
    """The [`LabelTransfer`][bsfjax.LabelTransfer] of label ``scores`` ``(L, m)`` (row ``i``: label ``ids[i]``)
    on ``m`` elements of areas ``weights``: the arg-max, −1 below ``threshold``; ``reference``:
    the labels of the input map's pull-back (``None``: no input point map); ``votes``: the
    scores are indicators' transfers, whose winning value is a confidence (else ``None``)."""
    scores = np.asarray(scores)
    best = scores.max(axis=0)
    out = np.where(best < threshold, -1, ids[scores.argmax(axis=0)].astype(np.int64))
    total = np.sum(weights)
    share = float(np.sum(weights * (out < 0)) / total)
    agreement = (None if reference is None else
                 float(np.sum(weights * (np.asarray(reference) == out)) / total))
    confidence = float(np.sum(weights * best) / total) if votes else None
    return LabelTransfer(labels=out, scores=scores, unassigned_share=share, agreement=agreement,
                         confidence=confidence,
                         regime=_regime(agreement, confidence) if refined else None)
