"""Mesh-to-mesh entry points: estimate a map between two shapes and carry values or a
segmentation across it.  What ``bsfjax transfer`` and ``bsfjax demo`` run.

They compose the stages (spectrum → frame → coding → transfer); each step is also available
on its own (:func:`bsfjax.build_frame`, :func:`bsfjax.estimate_fmap`, …).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float, Int
from scipy.spatial import cKDTree

from ._methods import (AbstractMethod, BSF, GeodesicBalls, PullBack, RefinedPullBack, SaturatedHeat,
                       SpectralProjection, as_method, method_name)
from ._transfer import Pair, transfer
from ._descriptors import wks
from ._distortion import (DISTORTION_SAMPLES, ORIENTATION_SLACK, _distortions, _Geodesics,
                          choose_map, orientation_agreement)
from ._errors import BSFError
from ._estimation import FmapWeights, estimate_fmap
from ._orientation import orientation_bases
from ._geodesics import geodesic_distances
from ._fmap import fmap_from_p2p, fmap_to_p2p, zoomout
from ._indicators import labels_to_indicators
from ._sampling import Subsample, farthest_point_sampling, subsample
from ._spectrum import Spectrum, map_to_unit_area, unit_area_pair
from ._threads import on_one_blas_thread
from ._validate import check_indices, check_int, check_real, check_source_mesh, compact_labels

__all__ = ["MapEstimate", "estimate_map", "mirror_symmetry", "transfer_values",
           "transfer_labels", "LabelTransfer", "REGIMES"]

class MapEstimate(NamedTuple):
    C: np.ndarray  #: ``(k, k)`` functional map source → target
    p2p: np.ndarray  #: ``(n_N,)`` point map, target vertex → source vertex
    C_initial: np.ndarray  #: the descriptor-based map before ZoomOut (``k₀ × k₀``: its start's)
    #: ``(source, target)`` :class:`~bsfjax.Subsample` s ZoomOut ran on (``None``: every
    #: vertex); ``"refined"`` continues on them (``transfer_labels(..., samples=)``)
    samples: tuple | None = None
    #: with several starts (no landmarks): the kept map's geodesic distortion
    #: (:func:`bsfjax.map_distortion`) and orientation agreement
    #: (:func:`bsfjax.orientation_agreement`), the start ``(k₀, WKS variance)`` chosen among
    #: them, and the landmark pairs read off its map when the estimate made with them was kept;
    #: ``None`` with landmarks or a single start
    distortion: float | None = None
    orientation: float | None = None
    start: tuple | None = None
    landmarks: tuple | None = None
    #: with several starts and the turn check: whether the kept map is the alternative with
    #: left and right swapped (the chosen map was turned front to back); ``None`` otherwise
    swapped: bool | None = None


def _check_landmarks(landmarks, n_m: int, n_n: int):
    if landmarks is None:
        return None
    src, tgt = (np.asarray(x) for x in landmarks)
    if src.ndim != 1 or tgt.ndim != 1 or src.shape != tgt.shape or src.size == 0:
        raise BSFError(f"landmarks must be two lists of equal length, got {src.size} source and "
                       f"{tgt.size} target indices")
    return (check_indices(src, "source landmarks", n_m),
            check_indices(tgt, "target landmarks", n_n))


#: Weight of the orientation-preserving term when :func:`estimate_map` has no landmarks but
#: the meshes (the flips it avoids: docs/results.md, "Real segmentations").
ORIENT_WEIGHT = 1.0


#: Farthest-point samples per shape on which :func:`estimate_map`'s ZoomOut runs when it has
#: the meshes (:func:`bsfjax.subsample`): on FAUST (6890 vertices) 12× fewer search
#: operations, the same accuracy on 9 pairs (docs/results.md, "ZoomOut on samples").
ZOOMOUT_SAMPLES = 2000

#: Eigenpairs :func:`estimate_map`'s ZoomOut adds per iteration (15 iterations from 30 to 60
#: instead of 30 at step 1: half the searches).  Measured (stop 29) on the 9 FAUST / FAUST_5k
#: pairs of ``bench_segmentation.py``: mean geodesic error 0.0184 at steps 1, 2 and 3 (0.0185
#: / 0.0183 on every vertex), SMPL-part accuracy of the pull-back 94.30 / 94.38 / 94.46 %
#: and of ``refined`` 94.95 / 94.98 / 95.10 % (docs/results.md, "ZoomOut's step").
ZOOMOUT_STEP = 2

#: Initial estimates :func:`estimate_map` tries without landmarks, ``(k₀, WKS variance)``: each
#: is estimated at ``k₀ × k₀`` with WKS of that ``variance`` (σ in units of the energy range over
#: the 100 energies), refined by ZoomOut, and the map of least geodesic distortion among those
#: of the best orientation is kept (:func:`bsfjax.choose_map`).  Without landmarks a single
#: start lands in a partly mirrored or slid map on 5 of the 9 pairs of docs/results.md ("Without
#: landmarks"), and which start does differs from pair to pair.
LANDMARK_FREE_STARTS = tuple((k0, v) for k0 in (16, 20, 24, 30, 40) for v in (3.5, 7.0, 14.0))

#: The WKS variance of a single start (with landmarks): pyFM's.
WKS_VARIANCE = 7.0

#: The turn check of :func:`estimate_map` without landmarks (docs/results.md, "The turn
#: check"): landmark pairs read off the kept map at the source's farthest points (the tips of
#: the limbs, where a turn swaps left and right), then moved to their mirror images by the
#: source's intrinsic symmetry; and the local distortion (:func:`bsfjax.map_distortion` with
#: ``radius``, on that many target samples) that tells the kept map from the alternative.
TURN_LANDMARKS = 5
TURN_SAMPLES = 200
TURN_RADIUS = 0.15

#: Landmark pairs :func:`estimate_map` reads off its chosen map without landmarks, for a second
#: estimate.  On the 9 pairs of docs/results.md: SMPL-part accuracy of the pull-back 92.57 %
#: with none, 94.40 % with 10, 94.47 % with 20 (5 put FAUST 000→010 at 54.6 %: a flip);
#: with 5 true landmarks 94.46 %.
DERIVED_LANDMARKS = 20


@on_one_blas_thread
def estimate_map(source: Spectrum, target: Spectrum, *, k: int = 30, landmarks=None,
                 refine_to: int | None = None, n_energies: int = 100, source_mesh=None,
                 target_mesh=None, zoomout_samples: int | None = ZOOMOUT_SAMPLES,
                 zoomout_step: int = ZOOMOUT_STEP, starts=None,
                 derived_landmarks: int = DERIVED_LANDMARKS,
                 turn_check: bool = True, source_symmetry=None) -> MapEstimate:
    """Estimate a ``k × k`` functional map from descriptors (and optional landmarks).

    WKS descriptors (plus WKS functions centred at the landmarks) with descriptor preservation,
    descriptor commutativity and Laplacian commutativity (:func:`bsfjax.estimate_fmap`), then
    ZoomOut to ``refine_to`` eigenpairs (default: as many as both spectra have), and back to a
    ``k × k`` map from the refined point map.

    Without landmarks but with the meshes this runs from several starts (``starts``) and keeps
    the map of least geodesic distortion among those of the best orientation
    (:func:`bsfjax.choose_map`): one start often lands in a partly mirrored map (both arms
    swapped) or a slid one (a leg on a foot), and which start does depends on the pair.  Then
    it reads ``derived_landmarks`` landmark pairs off that map (the source's farthest points,
    each with the target vertex whose image lies nearest), estimates again with them as if they
    were given, and keeps the second map if :func:`bsfjax.choose_map` prefers it.  On the 9
    FAUST / FAUST_5k pairs of docs/results.md ("Without landmarks") this is as accurate as 5
    true landmarks.

    Two human shapes can also be matched turned front to back (left and right limbs swapped, the
    limbs twisted, the torso turned), a map that keeps orientation and long distances.  The turn
    check (``turn_check``) builds the alternative: it estimates the source's intrinsic mirror
    symmetry ``S`` (a self-map that reverses orientation), reads :data:`TURN_LANDMARKS`
    landmark pairs ``(x, y)`` off the kept map, estimates with ``(S x, y)`` and the orientation
    term, then once more with landmarks read off that map, and keeps whichever of the two maps
    :func:`bsfjax.choose_map` prefers by local distortion (:data:`TURN_RADIUS`), which a
    twisted limb raises.

    Args:
        source, target: spectra with at least ``max(k, refine_to)`` eigenpairs.
        landmarks: ``(source_indices, target_indices)`` of equal length, or ``None``.  Without
            landmarks an intrinsically symmetric shape may be matched to its mirror image,
            unless the meshes are given (below).
        source_mesh, target_mesh: the :class:`~bsfjax.Mesh` of each spectrum.  Without
            landmarks they switch on the orientation-preserving term of
            :func:`bsfjax.estimate_fmap` (weight :data:`ORIENT_WEIGHT`), which tells a shape
            from its mirror image, and the choice among ``starts``.  They also give ZoomOut its
            samples (below).
        zoomout_samples: with the meshes, ZoomOut runs on this many farthest-point samples of
            each shape (:func:`bsfjax.subsample`; :data:`ZOOMOUT_SAMPLES`), or on the given
            ``(source, target)`` :class:`~bsfjax.Subsample` s; ``None``, or no meshes: on every
            vertex.  The final point map is always over every vertex.
        zoomout_step: eigenpairs added per ZoomOut iteration (:data:`ZOOMOUT_STEP`; 1 is
            ZoomOut's original schedule).
        starts: ``(k₀, variance)`` pairs, each an initial ``k₀ × k₀`` estimate with WKS of that
            variance (``wks(…, variance=)``); those with ``k₀ > refine_to`` are skipped.
            Default: :data:`LANDMARK_FREE_STARTS` without landmarks when the meshes are given,
            else the single start ``((k, WKS_VARIANCE),)``.  Several starts need the meshes.
        derived_landmarks: landmark pairs read off the kept start's map for the second
            estimate (:data:`DERIVED_LANDMARKS`; 0: none).  Used only with several starts.
        turn_check: run the turn check above (only with several starts).
        source_symmetry: the source's :func:`bsfjax.mirror_symmetry` for the turn check, when
            it is at hand (``transfer_collection`` computes it once for all its targets);
            default: computed here with this call's ``k``, ``refine_to`` and samples.
    """
    refine_to = _check_sizes(k, refine_to, min(source.k, target.k))
    check_int(zoomout_step, "zoomout_step", 1)
    lm = _check_landmarks(landmarks, source.n_vertices, target.n_vertices)
    meshes = source_mesh is not None and target_mesh is not None
    starts = _check_starts(starts, refine_to, ((k, WKS_VARIANCE),),
                           LANDMARK_FREE_STARTS if lm is None and meshes else None)
    if len(starts) > 1 and not meshes:
        raise BSFError("several starts are told apart by the meshes: give source_mesh and "
                       "target_mesh, or a single start")
    check_int(derived_landmarks, "derived_landmarks", 0)
    if not isinstance(turn_check, (bool, np.bool_)):
        raise BSFError(f"turn_check must be True or False, got {turn_check!r}")
    if source_symmetry is not None:
        source_symmetry = np.asarray(source_symmetry)
        if source_symmetry.shape != (source.n_vertices,):
            raise BSFError(f"source_symmetry must have one source vertex per source vertex "
                           f"({source.n_vertices}), got shape {source_symmetry.shape}")
        source_symmetry = check_indices(source_symmetry, "source_symmetry", source.n_vertices,
                                        what="source vertex indices")
    # the estimation runs on the unit-area shapes (float64 rescaling before any float32 cast);
    # the maps are converted back to the given bases at the end
    source_given = source  # (mirror_symmetry checks its mesh against the given spectrum)
    source, am, target, an = unit_area_pair(source, target)
    samples = None
    if isinstance(zoomout_samples, tuple):  # (the collection's, computed once)
        samples = _check_samples(zoomout_samples, source.n_vertices, target.n_vertices)
    elif zoomout_samples is not None and meshes:
        samples = (subsample(source_mesh, zoomout_samples), subsample(target_mesh, zoomout_samples))

    def run(start, pairs, orient=None):
        """One start with landmark ``pairs`` (or ``None``): the estimate at ``k₀``, ZoomOut to
        ``refine_to``, the point map.  The orientation term is on without landmarks (with
        the meshes), or where ``orient`` says so."""
        k0, variance = start
        dm = [wks(source, n_energies, k=k0, variance=variance)]
        dn = [wks(target, n_energies, k=k0, variance=variance)]
        if pairs is not None:
            dm.append(wks(source, n_energies, landmarks=pairs[0], k=k0, variance=variance))
            dn.append(wks(target, n_energies, landmarks=pairs[1], k=k0, variance=variance))
        extra = {}
        if meshes and (pairs is None if orient is None else orient):
            extra = dict(weights=FmapWeights(orient=ORIENT_WEIGHT), orientation_bases=bases())
        C0 = estimate_fmap(source, target, jnp.concatenate(dm, axis=1),
                           jnp.concatenate(dn, axis=1), k=k0, **extra)
        C_ref = zoomout(C0, source, target, refine_to, step=zoomout_step, samples=samples) \
            if refine_to > k0 else C0
        return C0, np.asarray(fmap_to_p2p(C_ref, source, target))

    @functools.cache
    def bases():
        """The pair's orientation bases, one face scan for every start that uses them."""
        k_max = max(k0 for k0, _ in starts + ((k, WKS_VARIANCE),))
        return orientation_bases(source, target, source_mesh, target_mesh, k_max)

    def refined(p2p):
        """A second estimate, with ``derived_landmarks`` landmarks read off ``p2p``."""
        pairs = _landmarks_from_map(source_mesh, p2p, derived_landmarks)
        return pairs, run((k, WKS_VARIANCE), pairs)

    runs = [run(s, lm) for s in starts]
    quality = {}
    if len(runs) > 1:
        maps = np.stack([p for _, p in runs])
        # the distortions below share their Dijkstra runs (each vertex of a shape run once)
        geodesics = (_Geodesics(source_mesh), _Geodesics(target_mesh))

        def distortion(candidates, n_samples=DISTORTION_SAMPLES, radius=None):
            return _distortions(source_mesh, target_mesh,
                                np.atleast_2d(candidates).astype(np.int64), n_samples, radius,
                                geodesics)

        orient = orientation_agreement(source_mesh, target_mesh, maps)
        # choose_map picks among the maps within its slack of the best orientation: only
        # their distortions are needed (fewer Dijkstra sources, the same choice)
        near = np.flatnonzero(orient >= orient.max() - ORIENTATION_SLACK)
        dist = distortion(maps[near])
        pick = choose_map(dist, orient[near])
        best = int(near[pick])
        quality = dict(start=starts[best], distortion=float(dist[pick]),
                       orientation=float(orient[best]))
        runs = [runs[best]]
        if derived_landmarks:  # a second estimate, with landmarks read off the kept map
            derived, second = refined(runs[0][1])
            d2 = float(distortion(second[1])[0])
            o2 = orientation_agreement(source_mesh, target_mesh, second[1])
            if choose_map([quality["distortion"], d2], [quality["orientation"], o2]) == 1:
                runs = [second]
                quality.update(landmarks=derived, distortion=d2, orientation=o2)
        if turn_check:  # the alternative with left and right swapped (docstring)
            sym = source_symmetry if source_symmetry is not None else mirror_symmetry(
                source_given, source_mesh, k=k, refine_to=refine_to, n_energies=n_energies,
                samples=None if samples is None else samples[0], zoomout_step=zoomout_step)
            x, y = _landmarks_from_map(source_mesh, runs[0][1], TURN_LANDMARKS)
            alt, alt_landmarks = run((k, WKS_VARIANCE), (sym[x], y), orient=True), (sym[x], y)
            if derived_landmarks:
                alt_landmarks, alt = refined(alt[1])
            both = np.stack([runs[0][1], alt[1]]).astype(np.int64)
            local = distortion(both, TURN_SAMPLES, TURN_RADIUS)
            orient = orientation_agreement(source_mesh, target_mesh, both)
            # (a target too coarse for the local distortion keeps the map)
            quality["swapped"] = local is not None and choose_map(local, orient) == 1
            if quality["swapped"]:
                runs = [alt]
                quality.update(landmarks=alt_landmarks, orientation=float(orient[1]),
                               distortion=float(distortion(alt[1])[0]))
    C0, p2p = runs[0]
    C = np.asarray(fmap_from_p2p(source.truncate(k), target.truncate(k), p2p))
    back = lambda X: np.asarray(map_to_unit_area(np.asarray(X), am, an, inverse=True),  # noqa: E731
                                np.asarray(X).dtype)
    return MapEstimate(C=back(C), p2p=p2p, C_initial=back(C0), samples=samples, **quality)


@on_one_blas_thread
def mirror_symmetry(spectrum: Spectrum, mesh, *, k: int = 30, refine_to: int | None = None,
                    n_energies: int = 100, samples: int | Subsample | None = ZOOMOUT_SAMPLES,
                    zoomout_step: int = ZOOMOUT_STEP) -> np.ndarray:
    """The shape's intrinsic mirror symmetry ``S: M → M``, a self point map that reverses
    orientation (left ↔ right on a body).

    The functional map of ``M`` to itself from WKS descriptors with the orientation-*reversing*
    term (:func:`bsfjax.estimate_fmap`, ``orientation="reversing"``, weight
    :data:`ORIENT_WEIGHT`) at ``k × k``, ZoomOut to ``refine_to``, then the point map: the
    self-map :func:`bsfjax.estimate_map` would give with the orientation term turned around.
    On FAUST registrations it maps each SMPL part to its mirror part on 93–99 % of the area.
    :func:`bsfjax.estimate_map` uses it for its turn check.

    **Arguments:**

    - ``spectrum``, ``mesh``: the shape (``refine_to`` eigenpairs at least).
    - ``k``, ``refine_to``, ``n_energies``, ``zoomout_step``: as in
      :func:`bsfjax.estimate_map` (``refine_to`` default: the spectrum's size).
    - ``samples``: ZoomOut on this many farthest-point samples (:func:`bsfjax.subsample`), on
      a given :class:`~bsfjax.Subsample`, or on every vertex (``None``).

    **Returns:** ``(n,)`` int array, ``S[i]`` the mirror image of vertex ``i``.
    """
    if not isinstance(spectrum, Spectrum):
        raise BSFError(f"spectrum must be a bsfjax.Spectrum, got {type(spectrum).__name__}")
    check_source_mesh(mesh, spectrum.n_vertices, spectrum.mass)
    refine_to = _check_sizes(k, refine_to, spectrum.k)
    if samples is not None and not isinstance(samples, Subsample):
        samples = subsample(mesh, check_int(samples, "samples", 1))
    d = wks(spectrum, n_energies, k=k, variance=WKS_VARIANCE)
    C0 = estimate_fmap(spectrum, spectrum, d, d, k=k, weights=FmapWeights(orient=ORIENT_WEIGHT),
                       source_mesh=mesh, target_mesh=mesh, orientation="reversing")
    C = zoomout(C0, spectrum, spectrum, refine_to, step=zoomout_step,
                samples=None if samples is None else (samples, samples)) \
        if refine_to > k else C0
    return np.asarray(fmap_to_p2p(C, spectrum, spectrum)).astype(np.int64)


def _check_sizes(k, refine_to, km: int) -> int:
    """``k`` and ``refine_to`` (default ``km``) checked against the ``km`` eigenpairs there
    are; returns ``refine_to``."""
    if not isinstance(k, (int, np.integer)) or not 1 <= k <= km:
        raise BSFError(f"k must be an integer in [1, {km}] (the spectra's size), got {k!r}")
    refine_to = km if refine_to is None else refine_to
    if not isinstance(refine_to, (int, np.integer)) or not k <= refine_to <= km:
        raise BSFError(f"refine_to must be an integer in [{k}, {km}], got {refine_to!r}")
    return refine_to


def _landmarks_from_map(source_mesh, p2p, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` landmark pairs read off a point map ``T: N → M``: the source's ``n`` farthest
    points (Euclidean, seed 0), each with the target vertex whose image ``T(j)`` lies nearest
    to it in the source's space (of several with that image, the first)."""
    src = np.asarray(farthest_point_sampling(source_mesh, n), np.int64)
    v = np.asarray(source_mesh.vertices, np.float64)
    images, first = np.unique(np.asarray(p2p), return_index=True)  # (ties: the first target)
    return src, first[cKDTree(v[images]).query(v[src])[1]].astype(np.int64)


def _check_samples(samples, n_m: int, n_n: int) -> tuple:
    """Given ``(source, target)`` subsamples, each with one cell per vertex of its shape."""
    ok = len(samples) == 2 and all(isinstance(s, Subsample) for s in samples)
    if not ok or samples[0].cells.shape != (n_m,) or samples[1].cells.shape != (n_n,):
        raise BSFError(f"zoomout_samples must be an int, None, or (source, target) Subsamples "
                       f"of {n_m} and {n_n} vertices")
    return samples


def _check_starts(starts, refine_to: int, single: tuple, default) -> tuple:
    """The ``(k₀, variance)`` starts with ``k₀ ≤ refine_to``, checked; ``None`` gives
    ``default`` (or ``single`` where ``default`` is ``None`` or has no such start)."""
    given = starts is not None
    try:
        pairs = [tuple(p) for p in (starts if given else default or single)]
    except TypeError:
        raise BSFError(f"starts must be a sequence of (k0, variance) pairs, got {starts!r}") \
            from None
    out = []
    for p in pairs:
        if len(p) != 2:
            raise BSFError(f"starts must be (k0, variance) pairs, got {p!r}")
        k0 = check_int(p[0], "a start's k0", 1)
        out.append((k0, check_real(p[1], "a start's WKS variance", positive=True)))
    kept = tuple(p for p in dict.fromkeys(out) if p[0] <= refine_to)
    if not kept:
        if given:
            raise BSFError(f"no start has k0 <= refine_to = {refine_to}: {starts!r}")
        kept = single
    return kept


@on_one_blas_thread
def transfer_values(source: Spectrum, target: Spectrum,
                    values: Float[ArrayLike, "m n_M"] | Float[ArrayLike, " n_M"], *,
                    method: AbstractMethod | str = "omp",
                    C: Float[ArrayLike, "k_N k"] | None = None,
                    p2p: Int[ArrayLike, " n_N"] | None = None, k: int | None = None,
                    centers: Int[ArrayLike, " n_c"] | None = None, n_bsf: float | int = 0.05,
                    seed: int = 0, mesh=None, samples=None, **options) -> np.ndarray:
    """Transfer functions ``values`` ``(m, n_M)`` (or ``(n_M,)``) from source to target.

    The mesh-level entry point of :func:`bsfjax.transfer`: it samples the frame centres and
    builds the :class:`~bsfjax.Pair`, then runs the one engine.

    **Arguments:**

    - ``method``: a name of :data:`bsfjax.METHODS` or a method object (see
      :func:`bsfjax.as_method`); ``**options`` are its options with a name (e.g.
      ``sparsity=20``, ``taus="adaptive"``, ``frame_transfer="p2p"``).
    - ``C``: ``(k_N, k)`` functional map (every method but ``"p2p"``); ``k`` defaults to its
      column count.
    - ``p2p``: ``(n_N,)`` point map target vertex → source vertex (``"p2p"``, and
      ``frame_transfer="p2p"``).
    - ``centers``: the frame centres; default ``n_bsf`` of them (a share or a count) by
      farthest point sampling (``seed``) on ``mesh`` — the source :class:`~bsfjax.Mesh` — or
      on the spectral embedding when no mesh is given.  With the same centres this equals
      ``decode(transfer_frame(build_frame(source, centers), C, target), encode(...))``.
    - ``samples``: ``(source, target)`` :class:`~bsfjax.Subsample` s for ``"refined"`` (e.g.
      ``estimate_map(...).samples``); ignored by the other methods.
    """
    method = as_method(method, **options)
    f = np.asarray(values, dtype=float)
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
    res = transfer(method, pair, f, k=k)
    out = np.asarray(res.transferred)
    return out[0] if single else out


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
    #: :data:`REGIMES`; ``None`` for the other methods
    regime: str | None = None


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
    indicator is transferred with :func:`transfer_values` (``**kwargs``: ``C``, ``p2p``, …); a
    target vertex takes the label with the largest transferred value, or −1 ("unassigned") when
    that value is below ``threshold``.

    **Arguments:**

    - ``method``: default ``"refined"`` (:class:`~bsfjax.RefinedPullBack`: the most accurate
      from an estimated map; needs ``p2p`` or ``C`` and spectra of ~100 eigenpairs); ``"p2p"``
      for a map that is already right (a registration); the paper's BSF is ``"omp"``.
    - ``threshold``: default 0.5 (the midpoint of an indicator's two values) and 0 for
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
    return _decide_labels(ids, scores, np.asarray(target.mass, dtype=float), threshold, refined,
                          None if p2p is None else lab[np.asarray(p2p)])


#: What ``transfer_labels`` passes on to :func:`transfer_values` as inputs; its other keyword
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
    """The :class:`LabelTransfer` of label ``scores`` ``(L, m)`` (row ``i``: label ``ids[i]``)
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
