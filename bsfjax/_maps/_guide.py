r"""Landmark-guided ZoomOut: geodesic distances to the landmarks beside the spectral embedding.

Plain ZoomOut's nearest-neighbour step matches the aligned spectral embeddings alone.  On a
partial target (a foot cut off, its stump closed for the spectrum) the low-frequency
eigenfunctions of the shortened leg end at the stump as the source's end at the toes, and
ZoomOut from a rough ``C₀`` slides the leg into the missing foot: the shin's lower third
labelled foot, the thigh's lower part shin.  Geodesic distances from the landmark pairs tell
the two apart: a point of the shin is as far from the head on the scan as on the template,
whatever was cut below it.  So while the basis is small, each search also compares them:

.. math::

    T_t(y) = \arg\min_x \big\| Φ_M(x) C_t^⊤ − Φ_N(y) \big\|^2
             + w_t^2 s_t^2 \big\| g_M(x) − σ\, g_N(y) \big\|^2,
    \qquad w_t = w \, \frac{k_{\max} − k_t}{k_{\max} − k_0}

with ``g(x)`` the Dijkstra distances from ``x`` to the shape's ``L`` landmarks (in units of
``√area`` of its shape), ``σ`` the target's scale (bodies of other builds keep geodesics only
up to a few per cent; a target that lost a limb has a smaller area): the smaller of the
least-squares fit of the landmarks' mutual distances and the median over the landmarks of
the ratio of the distances' area-weighted 0.3-quantiles, clipped to ``[1/1.2, 1.2]`` as the
landmark-free choice's ``fit_scale``; ``s_t`` the mean row norm of the target's truncated
basis times ``√area`` (so ``w`` does not depend on the units or on ``k_t``).  The weight falls
to 0 at the last size: the distances set the basin, the spectral detail places the borders
(a constant weight of 1–2 cost 0.1–2.4 points on clean FAUST pairs, whose Dijkstra distances
disagree by a few per cent).  Why the smaller ``σ``: an overestimate stretches the target's
distances and slides a limb towards its end, the failure guided against, where an
underestimate of 4 % cost little; on FAUST targets without a hand and a foot (3 landmarks)
the landmark fit alone was 3–4 % too large (labels 2–3 points lower), the quantiles 1–3 %
too large where a foot was cut and 1–3 % too small elsewhere.

Measured (``bsfjax transfer`` with the landmarks the cut kept; SMPL parts, share of the
target's area; FAUST 000→010, 001→011, 002→012; docs/results/scans.md): left forearm, hand and
right foot cut, 91.1 / 90.0 / 89.2 % → 94.1 / 93.4 / 93.6 %; the mirror cut 90.2 / 89.4 / 87.9
→ 94.5 / 92.4 / 93.4 %; the left shin and foot cut 93.7 / 92.4 / 94.2 → 95.3 / 95.0 / 93.7 %;
the clean pairs 96.8 / 95.4 / 95.7 → 97.0 / 95.6 / 96.5 %, the 9 pairs of
docs/results/segmentation.md 95.01 → 95.13 %.

Owner of `landmark_geodesics` (the features, on the host) and `guided_zoomout` (the jitted
continuation: one ``lax.fori_loop`` with the bases masked to the current size, as
[`bsfjax.zoomout`][bsfjax.zoomout]).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ._distortion import SCALE_RANGE, _capped
from ._estimate import turn_step
from ._fmap import _from_p2p, _nearest

__all__ = ["DERIVED_GUIDANCE", "GUIDE_WEIGHT", "estimate_size", "estimates_again", "guidable",
           "estimate_zoomout", "guided_zoomout", "landmark_geodesics", "turn_mirror_size",
           "for_point_clouds", "CLOUD_ZOOMOUT_STEP", "CLOUD_ADDED_LANDMARKS"]

#: The quantile of the distances to a landmark whose ratio between the shapes estimates ``σ``.
SCALE_QUANTILE = 0.3
#: ``w`` of the module doc: the weight of the landmark distances at ZoomOut's first size (on
#: the partial FAUST targets, ZoomOut to 60: 1.0 gave 0.4–1.9 points less, 2.0 as much and
#: the clean pairs 0.05–0.3 less).
GUIDE_WEIGHT = 1.5
#: The share of ``w`` at which landmark pairs read off a map guide ZoomOut
#: (``MapEstimator.derived_guidance``): they are right to a few per cent of the height, given
#: ones exactly.  On the 9 FAUST targets without a forearm and a foot (three cuts, ZoomOut
#: to 100, no landmarks) a share of 1 gave 93.0 % on average, 0.5 93.9 % (before: 84.2 %),
#: and 0.5 kept holed and noisy targets within 0.6 points of the unguided labels on average
#: where 1 lost 0.7–0.9 on some.
DERIVED_GUIDANCE = 0.5
#: ZoomOut's eigenpairs per iteration where a shape is a point cloud (`for_point_clouds`;
#: 2 on meshes).  Each ZoomOut iteration refits ``C`` to a nearest-neighbour map, and on a
#: noisy cloud's Laplacian every refit at a small step moves the map a little further from
#: the truth: from the exact ``C`` at 30 eigenpairs, step 2 drifted from 93.4 % to 93.0 % at
#: 60 and 92.1 % at 100 (the exact map reads 95.7 / 95.6 % in those bases; 002→012), and the
#: exact ``30 × 30`` map grown to 60 then ``refined`` labelled 1.3–2.0 points more at step 6
#: than at 2 on three pairs.  On the noisy 15K clouds of FAUST 000→010, 001→011, 002→012,
#: ``bsfjax transfer`` with 5 landmarks labelled 92.63 % on average with step 2, 93.37 with
#: 4, 93.36 with 6, 93.34 with 8, 92.98 with 10, 91.72 with 30: a plateau from 4 to 8; 6,
#: the fewer searches.  Without landmarks the starts and the derived landmarks' maps grow at
#: it too, the turn check's maps at the given step (``turn_step``): at 6 it turned 2 of 12
#: clouds; the starts compared at 2 kept a wrong one on 4 (docs/results/scans.md).
CLOUD_ZOOMOUT_STEP = 6
#: ``MapEstimator.added_landmarks`` where a shape is a point cloud: with given landmarks a
#: cloud's descriptor-based ``C₀`` is far from the true map (relative error 0.26 against
#: 0.07 on a mesh pair) and ZoomOut's growth does not close the gap; 40 pairs read off the
#: first map beside the given ones bring it nearer (12 noisy FAUST clouds with 5 landmarks:
#: mean 93.76 → 93.98 %, 8 → 11 of 12 within 3 points of the clean pairs; 20 or 80 pairs,
#: or a second round, no better: docs/results/scans.md).
CLOUD_ADDED_LANDMARKS = 40


def _quantile(x: np.ndarray, w: np.ndarray, q: float) -> float:
    """The ``w``-weighted ``q``-quantile of ``x``."""
    order = np.argsort(x)
    cum = np.cumsum(w[order])
    return float(x[order][min(np.searchsorted(cum, q * cum[-1]), len(x) - 1)])


def for_point_clouds(estimator, *shapes):
    """``estimator`` for a map between ``shapes`` (as read): where one is a point cloud,
    with ``landmark_guidance`` 0, ``zoomout_step`` at least `CLOUD_ZOOMOUT_STEP` (the
    turn check at the given step: ``turn_step``), ``added_landmarks`` at least
    `CLOUD_ADDED_LANDMARKS`, ``choice_coverage`` and ``keep_derived`` on
    (the distortion on a noisy cloud's stand-in surface does not tell the starts apart,
    `bsfjax._maps._coverage`, nor the start's map from the one with landmarks read off it),
    and the turn check's limbs told in space alone (``turn_limbs_apart=None``: each set more
    is one more chance for those noisy measures to err; with the limbs told along the
    surface a noisy 15K cloud of FAUST 001→011 turned, 93.5 → 87.5 % without landmarks).

    Unguided: its landmark-free estimates run on stand-in surfaces (`surface_for_map`) whose
    Dijkstra distances the noise lengthens unevenly; guided by the landmarks read off a map
    (``derived_guidance``), noisy 15K clouds of FAUST 000→010 labelled 89.8 / 89.7 % instead
    of 92.7 / 93.5 %.  The larger step: see `CLOUD_ZOOMOUT_STEP`."""
    if any(getattr(m, "is_point_cloud", False) for m in shapes):
        return dataclasses.replace(
            estimator, landmark_guidance=0.0,
            zoomout_step=max(estimator.zoomout_step, CLOUD_ZOOMOUT_STEP),
            turn_step=turn_step(estimator), choice_coverage=True, keep_derived=True,
            added_landmarks=max(estimator.added_landmarks, CLOUD_ADDED_LANDMARKS),
            turn_limbs_apart=None)
    return estimator


def turn_mirror_size(estimator, refine_to, guided_to):
    """The size of the turn check's mirror symmetry: ``guided_to`` where the landmarks read
    off a map guide (``derived_guidance`` with ``landmark_guidance`` on), else ``refine_to``.
    Measured with the derived pairs guiding at the full weight, on FAUST 001→011 without a
    forearm and a foot: 92.3 % at 100 against 87.8 % at 60."""
    return guided_to if estimator.derived_guidance and estimator.landmark_guidance else refine_to


def guidable(source_mesh, target_mesh, estimator) -> bool:
    """Whether landmarks guide ZoomOut between these meshes: the estimator's
    ``landmark_guidance`` is on and both are triangle meshes.  A point cloud's distances run
    along its k-nearest-neighbour graph, which noise lengthens unevenly: guided, noisy 15K
    clouds of FAUST targets labelled 0.5–1.1 points less (docs/results/scans.md)."""
    return bool(estimator.landmark_guidance) and all(
        m is not None and not getattr(m, "is_point_cloud", False)
        for m in (source_mesh, target_mesh))


def follows_landmarks(estimator, landmarks, source_mesh, target_mesh) -> bool:
    """Whether [`MapEstimator`][bsfjax.MapEstimator] runs phases 3 and 4 after the map of
    these ``landmarks`` (a second estimate of a target that misses parts): with
    ``derived_guidance``, between two triangle meshes that the guidance runs on
    (`guidable`)."""
    return (landmarks is not None and bool(estimator.derived_guidance)
            and guidable(source_mesh, target_mesh, estimator))


def estimates_again(estimator, landmarks, source_mesh, target_mesh, refine_to: int) -> bool:
    """Whether a target whose labels miss source parts gets its map estimated again with
    ``derived_guidance`` (``bsfjax transfer``, [`transfer_collection`][bsfjax.transfer_collection]):
    only where that second estimate can differ from the first, that is with phases 3 or 4
    (the derived pairs, the turn check) on, ``derived_guidance`` still off, the guidance on
    and both shapes triangle meshes (`guidable`; a point cloud's estimate is never guided);
    and without ``landmarks``, from several starts (phases 3 and 4 run only after a choice
    among starts; ``refine_to``: the size that keeps a start).  With landmarks they run
    after phase 1.  Anything else would pay a second estimate that returns the first map."""
    from ._estimate import check_starts

    if estimator.derived_guidance or not (estimator.derived_landmarks or estimator.turn_check):
        return False
    if not guidable(source_mesh, target_mesh, estimator):
        return False
    if landmarks is not None:
        return True
    single = (estimator.k, estimator.wks_variance)
    starts = check_starts(estimator.starts, refine_to, (single,), estimator.landmark_free_starts)
    return len(starts) > 1


def landmark_geodesics(source_mesh, target_mesh, landmarks, masses,
                       scale_range: float = SCALE_RANGE) -> tuple[np.ndarray, np.ndarray]:
    """The guidance features ``(g_M (n_M, L), σ g_N (n_N, L))``: Dijkstra distances from each
    shape's landmarks (``landmarks = (source rows, target rows)``), each over the square root
    of its shape's area (``masses = (A_M, A_N)``, the vertex areas of the two spectra: a
    target in millimetres is the same shape), the target's times the scale ``σ`` of the
    module doc.  Distances to another component are capped at the largest finite one."""
    from .._sampling import geodesic_distances

    lm_m, lm_n = (np.asarray(x, np.int64) for x in landmarks)
    w_m, w_n = (np.asarray(m, np.float64) for m in masses)
    g_m = _capped(np.asarray(geodesic_distances(source_mesh, lm_m), np.float64)).T
    g_n = _capped(np.asarray(geodesic_distances(target_mesh, lm_n), np.float64)).T
    g_m, g_n = g_m / np.sqrt(w_m.sum()), g_n / np.sqrt(w_n.sum())
    # two estimates of σ, each fooled in its own way: the landmarks' mutual distances (few
    # pairs, three on a scan without a hand and a foot: limbs of another build weigh on each)
    # and the ratio of the distance distributions' lower quantiles (a part cut off removes
    # mass from the far tail); the smaller is kept: an overestimate stretches the target's
    # distances and slides a limb towards its end, the failure guided for
    a, b = g_m[lm_m], g_n[lm_n]  # (L, L) distances among the landmarks
    den = float(np.sum(b * b))
    sigma = float(np.sum(a * b)) / den if len(lm_m) > 1 and den > 0 else np.inf
    ratios = [_quantile(g_m[:, i], w_m, SCALE_QUANTILE) / _quantile(g_n[:, i], w_n, SCALE_QUANTILE)
              for i in range(len(lm_m))]
    sigma = min(sigma, float(np.median(ratios)))
    return g_m, g_n * float(np.clip(sigma, 1.0 / scale_range, scale_range))


def guided_search(C, evecs_m, evecs_n, w_n, g_m, g_n, weight, chunk: int, n_valid=None):
    """One step's point map: the nearest row of ``[Φ_M Cᵀ, w s g_M]`` for each row of
    ``[Φ_N, w s g_N]`` (``s`` of the module doc over the rows of positive ``w_n``)."""
    ref, qry = evecs_m @ C.T, evecs_n
    real = w_n > 0
    rows = jnp.sum(jnp.where(real, jnp.linalg.norm(qry, axis=1), 0.0)) / jnp.maximum(
        jnp.sum(real), 1)
    s = weight * rows * jnp.sqrt(jnp.sum(w_n))
    return _nearest(jnp.concatenate([ref, s * g_m], axis=1),
                    jnp.concatenate([qry, s * g_n], axis=1), chunk, n_valid)


@functools.partial(jax.jit, static_argnames=("sizes", "chunk", "weight"))
def guided_zoomout(C0, evecs_m, evecs_n, mass_n, g_m, g_n, *, sizes, chunk, weight):
    """ZoomOut from ``C0`` through the square sizes ``sizes`` (``k₀, …, k_max``) with the
    guidance of the module doc; rows as [`bsfjax.zoomout`][bsfjax.zoomout] (the samples' rows
    and cell areas ``mass_n`` with samples).  Returns the ``(k_max, k_max)`` map."""
    dt = jnp.result_type(float)
    evecs_m, evecs_n, mass_n, g_m, g_n = (jnp.asarray(x, dt) for x in
                                          (evecs_m, evecs_n, mass_n, g_m, g_n))
    k0, k = sizes[0], sizes[-1]
    C = jnp.zeros((k, k), dt).at[:C0.shape[0], :C0.shape[1]].set(jnp.asarray(C0, dt))
    sizes_arr = jnp.asarray(sizes, jnp.int32)
    cols = jnp.arange(k)

    def body(it, C):
        cur = (cols < sizes_arr[it]).astype(dt)
        w = weight * (k - sizes_arr[it]).astype(dt) / max(k - k0, 1)
        p2p = guided_search(C, evecs_m * cur, evecs_n * cur, mass_n, g_m, g_n, w, chunk)
        nxt = (cols < sizes_arr[it + 1]).astype(dt)
        return _from_p2p(p2p, evecs_m * nxt, evecs_n * nxt, mass_n)

    return lax.fori_loop(0, len(sizes) - 1, body, C)


def estimate_zoomout(pb, C0, landmarks, step: int, weight: float):
    """[`MapEstimator`][bsfjax.MapEstimator]'s ZoomOut with landmarks: ``C0`` (``k₀ × k₀``,
    unit-area bases of the problem ``pb``) grown to ``pb.guided_to`` in steps of ``step``,
    guided by the landmark distances (on ``pb.samples`` when it has them)."""
    from ._fmap import _size_schedule, chunk_for

    g_m, g_n = landmark_geodesics(pb.source_mesh, pb.target_mesh, landmarks, pb.masses)
    k0, k = C0.shape[0], pb.guided_to
    phi_m, phi_n = pb.source.evecs[:, :k], pb.target.evecs[:, :k]
    mass_n = jnp.asarray(pb.target.mass)
    if pb.samples is not None:
        sub_m, sub_n = pb.samples
        mass_n = sub_n.weights(mass_n)
        phi_m, g_m = jnp.asarray(phi_m)[sub_m.indices], g_m[sub_m.indices]
        phi_n, g_n = jnp.asarray(phi_n)[sub_n.indices], g_n[sub_n.indices]
    sizes = _size_schedule(int(k0), int(k), int(step), -(-(k - k0) // step))
    return guided_zoomout(C0, phi_m, phi_n, mass_n, g_m, g_n, sizes=sizes,
                          chunk=chunk_for(phi_m.shape[0], phi_n.shape[0], None),
                          weight=float(weight))


def estimate_size(k: int, k_spectra: int, guided: bool) -> int:
    """The size the mesh-level commands' estimate grows to by ZoomOut (``bsfjax transfer``,
    [`transfer_collection`][bsfjax.transfer_collection], ``reproduce segmentation``): guided
    by landmarks (`guidable`), every eigenpair of the spectra (``k_spectra``): the guidance
    falls to 0 only there, and stopped at ``2k`` the refined continuation that follows lets a
    cut leg slide again (the partial FAUST targets: 92.9 / 92.0 / 91.8 % instead of 94.1 /
    93.4 / 93.6 %); else ``2k`` (the landmark-free choice compares its candidates there; noisy
    15K clouds with landmarks lost 0.3–1.0 points at 100).  ``guided`` is ``False`` without
    landmarks."""
    return int(k_spectra) if guided else min(2 * int(k), int(k_spectra))
