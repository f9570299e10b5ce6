"""Mesh-to-mesh entry points: estimate a map between two shapes and carry values or a
segmentation across it.  What ``bsfjax transfer`` and ``bsfjax demo`` run.

They compose the stages (spectrum → frame → coding → transfer); each step is also available
on its own (:func:`bsfjax.build_frame`, :func:`bsfjax.estimate_fmap`, …).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ._baselines import PairInput, run_baseline
from ._descriptors import wks
from ._errors import BSFError
from ._estimation import estimate_fmap
from ._fmap import fmap_from_p2p, fmap_to_p2p, zoomout
from ._indicators import labels_to_indicators
from ._sampling import farthest_point_sampling
from ._spectrum import Spectrum

__all__ = ["MapEstimate", "estimate_map", "transfer_values", "transfer_labels", "LabelTransfer",
           "TRANSFER_METHODS"]

#: Methods usable between two meshes (``prod``/``geod``/``heat`` need extra inputs; see
#: :mod:`bsfjax.baselines`).
TRANSFER_METHODS = ("omp", "omp_error", "lstsq", "lasso", "std", "p2p")


class MapEstimate(NamedTuple):
    C: np.ndarray  #: ``(k, k)`` functional map source → target
    p2p: np.ndarray  #: ``(n_N,)`` point map, target vertex → source vertex
    C_initial: np.ndarray  #: the descriptor-based map before ZoomOut


def _check_landmarks(landmarks, n_m: int, n_n: int):
    if landmarks is None:
        return None
    src, tgt = (np.asarray(x) for x in landmarks)
    if src.ndim != 1 or tgt.ndim != 1 or src.shape != tgt.shape or src.size == 0:
        raise BSFError(f"landmarks must be two lists of equal length, got {src.size} source and "
                       f"{tgt.size} target indices")
    for name, idx, n in (("source", src, n_m), ("target", tgt, n_n)):
        if not np.issubdtype(idx.dtype, np.integer) or idx.min() < 0 or idx.max() >= n:
            raise BSFError(f"{name} landmarks must be vertex indices in [0, {n}), got "
                           f"{idx.tolist()}")
    return src, tgt


def estimate_map(source: Spectrum, target: Spectrum, *, k: int = 30, landmarks=None,
                 refine_to: int | None = None, n_energies: int = 100) -> MapEstimate:
    """Estimate a ``k × k`` functional map from descriptors (and optional landmarks).

    WKS descriptors (plus WKS functions centred at the landmarks) with descriptor preservation,
    descriptor commutativity and Laplacian commutativity (:func:`bsfjax.estimate_fmap`), then
    ZoomOut to ``refine_to`` eigenpairs (default: as many as both spectra have), and back to a
    ``k × k`` map from the refined point map.

    Args:
        source, target: spectra with at least ``max(k, refine_to)`` eigenpairs.
        landmarks: ``(source_indices, target_indices)`` of equal length, or ``None``.  Without
            landmarks an intrinsically symmetric shape may be matched to its mirror image.
    """
    km = min(source.k, target.k)
    if not isinstance(k, (int, np.integer)) or not 1 <= k <= km:
        raise BSFError(f"k must be an integer in [1, {km}] (the spectra's size), got {k!r}")
    refine_to = km if refine_to is None else refine_to
    if not isinstance(refine_to, (int, np.integer)) or not k <= refine_to <= km:
        raise BSFError(f"refine_to must be an integer in [{k}, {km}], got {refine_to!r}")
    lm = _check_landmarks(landmarks, source.n_vertices, target.n_vertices)
    dm = [wks(source, n_energies, k=k)]
    dn = [wks(target, n_energies, k=k)]
    if lm is not None:
        dm.append(wks(source, n_energies, landmarks=lm[0], k=k))
        dn.append(wks(target, n_energies, landmarks=lm[1], k=k))
    C0 = estimate_fmap(source, target, jnp.concatenate(dm, axis=1), jnp.concatenate(dn, axis=1), k=k)
    C_ref = zoomout(C0, source, target, refine_to) if refine_to > k else C0
    p2p = np.asarray(fmap_to_p2p(C_ref, source, target))
    C = np.asarray(fmap_from_p2p(source.truncate(k), target.truncate(k), p2p))
    return MapEstimate(C=C, p2p=p2p, C_initial=np.asarray(C0))


def transfer_values(source: Spectrum, target: Spectrum, values, *, C=None, p2p=None,
                    method: str = "omp", k: int | None = None, n_bsf: float | int = 0.05,
                    seed: int = 0, mesh=None, **params) -> np.ndarray:
    """Transfer functions ``values`` ``(m, n_M)`` (or ``(n_M,)``) from source to target.

    ``method`` is one of :data:`TRANSFER_METHODS`: a BSF coder (``"omp"``, ``"omp_error"``,
    ``"lstsq"``, ``"lasso"``; frame with ``n_bsf`` centres by farthest point sampling on
    ``mesh`` — the source :class:`~bsfjax.Mesh` — or on the spectral embedding when no mesh is
    given), the spectral projection ``"std"``, or the pull-back ``"p2p"`` (needs ``p2p``).
    ``C`` is ``(k, k)``; ``k`` defaults to its size.  Extra ``params`` go to
    :class:`bsfjax.baselines.Params` (e.g. ``sparsity=20``, ``taus="adaptive"``, or
    ``frame_transfer="p2p"`` with ``p2p`` to pull the atoms back through the point map — the
    robust choice with an estimated map, see ``docs/results.md``).
    """
    from ._baselines import Params

    if method not in TRANSFER_METHODS:
        raise BSFError(f"method must be one of {TRANSFER_METHODS}, got {method!r}")
    f = np.asarray(values, dtype=float)
    single = f.ndim == 1
    f = f[None] if single else f
    if f.ndim != 2 or f.shape[1] != source.n_vertices:
        raise BSFError(f"values must have shape (n_source,) or (m, n_source) with n_source = "
                       f"{source.n_vertices}, got {np.shape(values)}")
    if method == "p2p":
        if p2p is None:
            raise BSFError("method 'p2p' needs a point map (p2p)")
        idx = np.asarray(p2p)
        if idx.shape != (target.n_vertices,):
            raise BSFError(f"p2p must have one source index per target vertex ({target.n_vertices}),"
                           f" got shape {idx.shape}")
        out = f[:, idx]
        return out[0] if single else out
    if C is None:
        raise BSFError(f"method {method!r} needs a functional map C")
    C = np.asarray(C)
    k = int(C.shape[1]) if k is None else k
    centers = None
    if method not in ("std",):
        pts = mesh if mesh is not None else np.asarray(source.evecs[:, 1:4])
        centers = farthest_point_sampling(pts, n_bsf, seed=seed)
    pair = PairInput(source=source.truncate(k), target=target.truncate(C.shape[0]), C=C,
                     centers=centers, p2p=None if p2p is None else np.asarray(p2p))
    res = run_baseline(method, pair, f, k=k, params=Params(**params))
    out = np.asarray(res.transferred)
    return out[0] if single else out


class LabelTransfer(NamedTuple):
    labels: np.ndarray  #: ``(n_N,)`` int, −1 where unassigned
    scores: np.ndarray  #: ``(L, n_N)`` transferred indicator of each label
    unassigned_share: float  #: area share of the target left unassigned


def transfer_labels(source: Spectrum, target: Spectrum, labels, *, threshold: float = 0.5,
                    **kwargs) -> LabelTransfer:
    """Transfer a segmentation: one step function per label, then arg-max on the target.

    ``labels`` ``(n_M,)`` non-negative ints.  Each label's indicator is transferred with
    :func:`transfer_values` (``**kwargs``: ``C``, ``p2p``, ``method``, …); a target vertex takes
    the label with the largest transferred value, or −1 ("unassigned") when that value is below
    ``threshold`` (the midpoint of an indicator's two values by default).
    """
    lab = np.asarray(labels)
    if lab.shape != (source.n_vertices,):
        raise BSFError(f"labels must have one entry per source vertex ({source.n_vertices}), got "
                       f"shape {lab.shape}")
    if not 0 <= threshold < 1:
        raise BSFError(f"threshold must be in [0, 1), got {threshold!r}")
    scores = transfer_values(source, target, np.asarray(labels_to_indicators(lab)), **kwargs)
    best = scores.max(axis=0)
    out = np.where(best < threshold, -1, scores.argmax(axis=0))
    share = float(np.sum(np.asarray(target.mass) * (out < 0)) / np.sum(target.mass))
    return LabelTransfer(labels=out, scores=scores, unassigned_share=share)

