"""Estimate a point map between two meshes from their spectra: [`estimate_map`][bsfjax.estimate_map] (with
landmarks, or from several starts told apart by their distortion and orientation) and the
source's intrinsic [`mirror_symmetry`][bsfjax.mirror_symmetry] its turn check uses.  What ``bsfjax transfer``
runs before it carries anything across.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from scipy.spatial import cKDTree

from ._descriptors import wks
from ._distortion import DISTORTION_SAMPLES, ORIENTATION_SLACK, _agreements, _distortions, _Geodesics, choose_map
from .._util import BSFError
from ._estimation import FmapWeights, estimate_fmap
from ._orientation import orientation_bases
from ._fmap import fmap_from_p2p, fmap_to_p2p, zoomout
from .._sampling import Subsample, farthest_point_sampling, subsample
from .._spectral import Spectrum, map_to_unit_area, unit_area_pair
from .._util import on_one_blas_thread
from .._util import check_indices, check_int, check_real, check_source_mesh

__all__ = ["MapEstimate", "estimate_map", "mirror_symmetry"]

class MapEstimate(NamedTuple):
    C: np.ndarray  #: ``(k, k)`` functional map source → target
    p2p: np.ndarray  #: ``(n_N,)`` point map, target vertex → source vertex
    C_initial: np.ndarray  #: the descriptor-based map before ZoomOut (``k₀ × k₀``: its start's)
    #: ``(source, target)`` [`Subsample`][bsfjax.Subsample] s ZoomOut ran on (``None``: every
    #: vertex); ``"refined"`` continues on them (``transfer_labels(..., samples=)``)
    samples: tuple | None = None
    #: with several starts (no landmarks): the kept map's geodesic distortion
    #: ([`bsfjax.map_distortion`][bsfjax.map_distortion]) and orientation agreement
    #: ([`bsfjax.orientation_agreement`][bsfjax.orientation_agreement]), the start ``(k₀, WKS variance)`` chosen among
    #: them, and the landmark pairs read off its map when the estimate made with them was kept;
    #: ``None`` with landmarks or a single start
    distortion: float | None = None
    orientation: float | None = None
    start: tuple | None = None
    landmarks: tuple | None = None
    #: with several starts and the turn check: whether the kept map is the alternative with
    #: left and right swapped (the chosen map was turned front to back); ``None`` otherwise
    swapped: bool | None = None
    #: with the turn check: whether its two measures disagree about which of its two maps is
    #: turned (the local distortion prefers one, the orientation agreement the other, within
    #: `bsfjax.ORIENTATION_SLACK` of each other).  The kept map is then a guess and may
    #: be turned front to back: give two landmark pairs.  On 120 FAUST / FAUST_5k pairs
    #: without landmarks it was ``True`` on 8, and the kept map was turned on 3 of them (of
    #: the 5 turned maps kept in all) and partly wrong on 2 (docs/results.md, "The turn
    #: check").  ``None`` without the check, or on a target too coarse for it
    turn_doubtful: bool | None = None


def check_landmark_pairs(landmarks, n_m: int, n_n: int):
    if landmarks is None:
        return None
    src, tgt = (np.asarray(x) for x in landmarks)
    if src.ndim != 1 or tgt.ndim != 1 or src.shape != tgt.shape or src.size == 0:
        raise BSFError(f"landmarks must be two lists of equal length, got {src.size} source and "
                       f"{tgt.size} target indices")
    return (check_indices(src, "source landmarks", n_m),
            check_indices(tgt, "target landmarks", n_n))


#: Weight of the orientation-preserving term when [`estimate_map`][bsfjax.estimate_map] has no landmarks but
#: the meshes (the flips it avoids: docs/results.md, "Real segmentations").
ORIENT_WEIGHT = 1.0


#: Farthest-point samples per shape on which [`estimate_map`][bsfjax.estimate_map]'s ZoomOut runs when it has
#: the meshes ([`bsfjax.subsample`][bsfjax.subsample]): on FAUST (6890 vertices) 12× fewer search
#: operations, the same accuracy on 9 pairs (docs/results.md, "ZoomOut on samples").
ZOOMOUT_SAMPLES = 2000

#: Eigenpairs [`estimate_map`][bsfjax.estimate_map]'s ZoomOut adds per iteration (15 iterations from 30 to 60
#: instead of 30 at step 1: half the searches).  Measured (stop 29) on the 9 FAUST / FAUST_5k
#: pairs of ``bench_segmentation.py``: mean geodesic error 0.0184 at steps 1, 2 and 3 (0.0185
#: / 0.0183 on every vertex), SMPL-part accuracy of the pull-back 94.30 / 94.38 / 94.46 %
#: and of ``refined`` 94.95 / 94.98 / 95.10 % (docs/results.md, "ZoomOut's step").
ZOOMOUT_STEP = 2

#: Initial estimates [`estimate_map`][bsfjax.estimate_map] tries without landmarks, ``(k₀, WKS variance)``: each
#: is estimated at ``k₀ × k₀`` with WKS of that ``variance`` (σ in units of the energy range over
#: the 100 energies), refined by ZoomOut, and the map of least geodesic distortion among those
#: of the best orientation is kept ([`bsfjax.choose_map`][bsfjax.choose_map]).  Without landmarks a single
#: start lands in a partly mirrored or slid map on 5 of the 9 pairs of docs/results.md ("Without
#: landmarks"), and which start does differs from pair to pair.
LANDMARK_FREE_STARTS = tuple((k0, v) for k0 in (16, 20, 24, 30, 40) for v in (3.5, 7.0, 14.0))

#: The WKS variance of a single start (with landmarks): pyFM's.
WKS_VARIANCE = 7.0

#: The turn check of [`estimate_map`][bsfjax.estimate_map] without landmarks (docs/results.md, "The turn
#: check"): landmark pairs read off the kept map at the source's farthest points (the tips of
#: the limbs, where a turn swaps left and right), then moved to their mirror images by the
#: source's intrinsic symmetry; and the local distortion ([`bsfjax.map_distortion`][bsfjax.map_distortion] with
#: ``radius``, on that many target samples) that tells the kept map from the alternative.
TURN_LANDMARKS = 5
TURN_SAMPLES = 200
TURN_RADIUS = 0.15

#: Landmark pairs [`estimate_map`][bsfjax.estimate_map] reads off its chosen map without landmarks, for a second
#: estimate.  On the 9 pairs of docs/results.md: SMPL-part accuracy of the pull-back 92.57 %
#: with none, 94.40 % with 10, 94.47 % with 20 (5 put FAUST 000→010 at 54.6 %: a flip);
#: with 5 true landmarks 94.46 %.
DERIVED_LANDMARKS = 20

#: Without landmarks, on a target of more vertices than this [`estimate_map`][bsfjax.estimate_map] compares its
#: candidate maps (every start, the derived and the turned estimates) at the corners of
#: ``SELECTION_FACES`` random faces and at the distortions' samples only, not at every vertex;
#: the kept map is then searched over every vertex.  Each candidate's search is a
#: ``rows × n_M`` nearest-neighbour search instead of ``n_N × n_M``: on TOSCA cat subdivided
#: once (111.5K vertices) the estimate takes 146 s instead of 357 s, with the same start
#: kept and the same geodesic error (``benchmarks/bench_large_map.py``, docs/benchmarks.md).
#: The orientation agreement's estimate from 4096 faces has a standard error below 0.01, a
#: tenth of `bsfjax.ORIENTATION_SLACK`.
SELECTION_VERTICES = 20000
SELECTION_FACES = 4096


@on_one_blas_thread
def estimate_map(source: Spectrum, target: Spectrum, *, k: int = 30, landmarks=None,
                 refine_to: int | None = None, n_energies: int = 100, source_mesh=None,
                 target_mesh=None, zoomout_samples: int | None = ZOOMOUT_SAMPLES,
                 zoomout_step: int = ZOOMOUT_STEP, starts=None,
                 derived_landmarks: int = DERIVED_LANDMARKS,
                 turn_check: bool = True, source_symmetry=None) -> MapEstimate:
    """Estimate a ``k × k`` functional map from descriptors (and optional landmarks).

    WKS descriptors (plus WKS functions centred at the landmarks) with descriptor preservation,
    descriptor commutativity and Laplacian commutativity ([`bsfjax.estimate_fmap`][bsfjax.estimate_fmap]), then
    ZoomOut to ``refine_to`` eigenpairs (default: as many as both spectra have), and back to a
    ``k × k`` map from the refined point map.

    Without landmarks but with the meshes this runs from several starts (``starts``) and keeps
    the map of least geodesic distortion among those of the best orientation
    ([`bsfjax.choose_map`][bsfjax.choose_map]): one start often lands in a partly mirrored map (both arms
    swapped) or a slid one (a leg on a foot), and which start does depends on the pair.  Then
    it reads ``derived_landmarks`` landmark pairs off that map (the source's farthest points,
    each with the target vertex whose image lies nearest), estimates again with them as if they
    were given, and keeps the second map if [`bsfjax.choose_map`][bsfjax.choose_map] prefers it.  On the 9
    FAUST / FAUST_5k pairs of docs/results.md ("Without landmarks") this is as accurate as 5
    true landmarks.

    Two human shapes can also be matched turned front to back (left and right limbs swapped, the
    limbs twisted, the torso turned), a map that keeps orientation and long distances.  The turn
    check (``turn_check``) builds the alternative: it estimates the source's intrinsic mirror
    symmetry ``S`` (a self-map that reverses orientation), reads `TURN_LANDMARKS`
    landmark pairs ``(x, y)`` off the kept map, estimates with ``(S x, y)`` and the orientation
    term, then once more with landmarks read off that map, and keeps whichever of the two maps
    [`bsfjax.choose_map`][bsfjax.choose_map] prefers by local distortion (`TURN_RADIUS`), which a
    twisted limb raises.  Where the orientation agreement prefers the other map, the choice
    is a guess, and ``MapEstimate.turn_doubtful`` says so.

    Args:
        source, target: spectra with at least ``max(k, refine_to)`` eigenpairs.
        landmarks: ``(source_indices, target_indices)`` of equal length, or ``None``.  Without
            landmarks an intrinsically symmetric shape may be matched to its mirror image,
            unless the meshes are given (below).
        source_mesh, target_mesh: the [`Mesh`][bsfjax.Mesh] of each spectrum.  Without
            landmarks they switch on the orientation-preserving term of
            [`bsfjax.estimate_fmap`][bsfjax.estimate_fmap] (weight `ORIENT_WEIGHT`), which tells a shape
            from its mirror image, and the choice among ``starts``.  They also give ZoomOut its
            samples (below).
        zoomout_samples: with the meshes, ZoomOut runs on this many farthest-point samples of
            each shape ([`bsfjax.subsample`][bsfjax.subsample]; `ZOOMOUT_SAMPLES`), or on the given
            ``(source, target)`` [`Subsample`][bsfjax.Subsample] s; ``None``, or no meshes: on every
            vertex.  The final point map is always over every vertex.
        zoomout_step: eigenpairs added per ZoomOut iteration (`ZOOMOUT_STEP`; 1 is
            ZoomOut's original schedule).
        starts: ``(k₀, variance)`` pairs, each an initial ``k₀ × k₀`` estimate with WKS of that
            variance (``wks(…, variance=)``); those with ``k₀ > refine_to`` are skipped.
            Default: `LANDMARK_FREE_STARTS` without landmarks when the meshes are given,
            else the single start ``((k, WKS_VARIANCE),)``.  Several starts need the meshes.
        derived_landmarks: landmark pairs read off the kept start's map for the second
            estimate (`DERIVED_LANDMARKS`; 0: none).  Used only with several starts.
        turn_check: run the turn check above (only with several starts).
        source_symmetry: the source's [`bsfjax.mirror_symmetry`][bsfjax.mirror_symmetry] for the turn check, when
            it is at hand (``transfer_collection`` computes it once for all its targets);
            default: computed here with this call's ``k``, ``refine_to`` and samples.
    """
    refine_to = _check_sizes(k, refine_to, min(source.k, target.k))
    check_int(zoomout_step, "zoomout_step", 1)
    lm = check_landmark_pairs(landmarks, source.n_vertices, target.n_vertices)
    meshes = source_mesh is not None and target_mesh is not None
    starts = check_starts(starts, refine_to, ((k, WKS_VARIANCE),),
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
        samples = check_samples(zoomout_samples, source.n_vertices, target.n_vertices)
    elif zoomout_samples is not None and meshes:
        samples = (subsample(source_mesh, zoomout_samples), subsample(target_mesh, zoomout_samples))

    # several starts on a large target: the candidates' point maps are searched only where
    # they are compared (module constants), and the kept one over every vertex at the end
    rows, faces = _selection_rows(target_mesh) if len(starts) > 1 else (None, None)

    def run(start, pairs, orient=None):
        """One start with landmark ``pairs`` (or ``None``): the estimate at ``k₀``, ZoomOut to
        ``refine_to``, the point map (at ``rows`` only, ``-1`` elsewhere).  The orientation
        term is on without landmarks (with the meshes), or where ``orient`` says so."""
        k0, variance = start
        extra = {}
        if meshes and (pairs is None if orient is None else orient):
            extra = dict(weights=FmapWeights(orient=ORIENT_WEIGHT), orientation_bases=bases())
        C0 = estimate_fmap(source, target, *(
            _descriptors(s, n_energies, k0, variance, None if pairs is None else pairs[i])
            for i, s in enumerate((source, target))), k=k0, **extra)
        C_ref = zoomout(C0, source, target, refine_to, step=zoomout_step, samples=samples) \
            if refine_to > k0 else C0
        if rows is None:
            return C0, np.asarray(fmap_to_p2p(C_ref, source, target)), C_ref
        p2p = np.full(target.n_vertices, -1, np.int64)
        p2p[rows] = np.asarray(fmap_to_p2p(C_ref, source, target, rows=rows))
        return C0, p2p, C_ref

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
        maps = np.stack([p for _, p, _ in runs])
        # the distortions below share their Dijkstra runs (each vertex of a shape run once)
        geodesics = (_Geodesics(source_mesh), _Geodesics(target_mesh))

        def distortion(candidates, n_samples=DISTORTION_SAMPLES, radius=None):
            return _distortions(source_mesh, target_mesh,
                                np.atleast_2d(candidates).astype(np.int64), n_samples, radius,
                                geodesics)

        orient = _agreements(source_mesh, target_mesh, maps, faces)
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
            o2 = float(_agreements(source_mesh, target_mesh, second[1][None], faces)[0])
            if choose_map([quality["distortion"], d2], [quality["orientation"], o2]) == 1:
                runs = [second]
                quality.update(landmarks=derived, distortion=d2, orientation=o2)
        if turn_check:  # the alternative with left and right swapped (docstring)
            x, y = _landmarks_from_map(source_mesh, runs[0][1], TURN_LANDMARKS)
            # the mirror images of x only (a search of TURN_LANDMARKS rows, not of every
            # vertex), unless the caller has the whole symmetry at hand
            sx = source_symmetry[x] if source_symmetry is not None else mirror_symmetry(
                source_given, source_mesh, k=k, refine_to=refine_to, n_energies=n_energies,
                samples=None if samples is None else samples[0], zoomout_step=zoomout_step,
                rows=x)
            alt, alt_landmarks = run((k, WKS_VARIANCE), (sx, y), orient=True), (sx, y)
            if derived_landmarks:
                alt_landmarks, alt = refined(alt[1])
            both = np.stack([runs[0][1], alt[1]]).astype(np.int64)
            local = distortion(both, TURN_SAMPLES, TURN_RADIUS)
            orient = _agreements(source_mesh, target_mesh, both, faces)
            # (a target too coarse for the local distortion keeps the map)
            quality["swapped"] = local is not None and choose_map(local, orient) == 1
            if local is not None:
                quality["turn_doubtful"] = _measures_disagree(local, orient)
            if quality["swapped"]:
                runs = [alt]
                quality.update(landmarks=alt_landmarks, orientation=float(orient[1]),
                               distortion=float(distortion(alt[1])[0]))
    C0, p2p, C_ref = runs[0]
    if rows is not None:  # the kept candidate over every vertex
        p2p = np.asarray(fmap_to_p2p(C_ref, source, target))
    C = np.asarray(fmap_from_p2p(source.truncate(k), target.truncate(k), p2p))
    back = lambda X: np.asarray(map_to_unit_area(np.asarray(X), am, an, inverse=True),  # noqa: E731
                                np.asarray(X).dtype)
    return MapEstimate(C=back(C), p2p=p2p, C_initial=back(C0), samples=samples, **quality)


@on_one_blas_thread
def mirror_symmetry(spectrum: Spectrum, mesh, *, k: int = 30, refine_to: int | None = None,
                    n_energies: int = 100, samples: int | Subsample | None = ZOOMOUT_SAMPLES,
                    zoomout_step: int = ZOOMOUT_STEP, rows=None) -> np.ndarray:
    """The shape's intrinsic mirror symmetry ``S: M → M``, a self point map that reverses
    orientation (left ↔ right on a body).

    The functional map of ``M`` to itself from WKS descriptors with the orientation-*reversing*
    term ([`bsfjax.estimate_fmap`][bsfjax.estimate_fmap], ``orientation="reversing"``, weight
    `ORIENT_WEIGHT`) at ``k × k``, ZoomOut to ``refine_to``, then the point map: the
    self-map [`bsfjax.estimate_map`][bsfjax.estimate_map] would give with the orientation term turned around.

    A mirror image reverses the orientation of every triangle.  Where this self-map keeps it
    on more than `bsfjax.ORIENTATION_SLACK` of the area, the estimate has fallen part of
    the way to the identity, which the descriptors favour (FAUST ``tr_reg_002``: 33 % kept,
    57 % of the area on its own part).  It is then estimated from every start of
    `LANDMARK_FREE_STARTS` as well, and [`bsfjax.choose_map`][bsfjax.choose_map] keeps the one of least
    geodesic distortion among those that reverse the orientation best.  On the FAUST
    registrations the result maps each SMPL part to its mirror part on 97–99 % of the area,
    on the FAUST_5k remeshes on 93–95 %.  [`bsfjax.estimate_map`][bsfjax.estimate_map] uses it for its turn
    check.

    **Arguments:**

    - ``spectrum``, ``mesh``: the shape (``refine_to`` eigenpairs at least).
    - ``k``, ``refine_to``, ``n_energies``, ``zoomout_step``: as in
      [`bsfjax.estimate_map`][bsfjax.estimate_map] (``refine_to`` default: the spectrum's size).
    - ``samples``: ZoomOut on this many farthest-point samples ([`bsfjax.subsample`][bsfjax.subsample]), on
      a given [`Subsample`][bsfjax.Subsample], or on every vertex (``None``).

    - ``rows``: the vertices whose mirror images to return (default: every vertex); each
      is its image in the whole map, only the search is smaller.

    **Returns:** ``(n,)`` int array, ``S[i]`` the mirror image of vertex ``i`` (with ``rows``,
    ``(len(rows),)``: the image of ``rows[i]``).
    """
    if not isinstance(spectrum, Spectrum):
        raise BSFError(f"spectrum must be a bsfjax.Spectrum, got {type(spectrum).__name__}")
    check_source_mesh(mesh, spectrum.n_vertices, spectrum.mass)
    refine_to = _check_sizes(k, refine_to, spectrum.k)
    if samples is not None and not isinstance(samples, Subsample):
        samples = subsample(mesh, check_int(samples, "samples", 1))

    def estimate(start, bases=None):
        k0, variance = start
        d = wks(spectrum, n_energies, k=k0, variance=variance)
        geometry = dict(source_mesh=mesh, target_mesh=mesh) if bases is None else \
            dict(orientation_bases=bases)
        C0 = estimate_fmap(spectrum, spectrum, d, d, k=k0,
                           weights=FmapWeights(orient=ORIENT_WEIGHT), orientation="reversing",
                           **geometry)
        return zoomout(C0, spectrum, spectrum, refine_to, step=zoomout_step,
                       samples=None if samples is None else (samples, samples)) \
            if refine_to > k0 else C0

    # the orientation is checked on every face, or on a large mesh on estimate_map's
    # selection of faces (and the distortions' samples), where the self-map is searched
    checked, faces = _selection_rows(mesh)

    def at_checked(C):
        p2p = np.full(mesh.n_vertices, -1, np.int64)
        p2p[slice(None) if checked is None else checked] = np.asarray(
            fmap_to_p2p(C, spectrum, spectrum, rows=checked))
        return p2p

    C = estimate((k, WKS_VARIANCE))
    p2p = at_checked(C)
    extra = [s for s in LANDMARK_FREE_STARTS if s[0] <= refine_to and s != (k, WKS_VARIANCE)]
    if extra and _agreements(mesh, mesh, p2p[None], faces)[0] > ORIENTATION_SLACK:
        # not a mirror image: every start (docstring), one scan over the faces for them all
        bases = orientation_bases(spectrum, spectrum, mesh, mesh, max(s[0] for s in extra))
        fmaps = [C] + [estimate(s, bases) for s in extra]
        del bases
        maps = np.stack([p2p] + [at_checked(F) for F in fmaps[1:]])
        reversal = 1.0 - _agreements(mesh, mesh, maps, faces)
        best = choose_map(_distortions(mesh, mesh, maps, DISTORTION_SAMPLES, None), reversal)
        C, p2p = fmaps[best], maps[best]
    if checked is None and rows is None:  # (searched over every vertex already)
        return p2p
    return np.asarray(fmap_to_p2p(C, spectrum, spectrum, rows=rows)).astype(np.int64)


def _descriptors(spectrum: Spectrum, n_energies: int, k0: int, variance: float, landmarks):
    """A shape's descriptors for [`estimate_fmap`][bsfjax.estimate_fmap]: WKS, and WKS centred at ``landmarks``
    (if any) beside them.  The parts are freed once joined: on a large shape with many
    landmarks they are most of the estimate's memory."""
    plain = wks(spectrum, n_energies, k=k0, variance=variance)
    if landmarks is None:
        return plain
    return jnp.concatenate([plain, wks(spectrum, n_energies, landmarks=landmarks, k=k0,
                                       variance=variance)], axis=1)


def _measures_disagree(local, orient) -> bool:
    """Whether the local distortion and the orientation agreement of the turn check's two maps
    prefer different maps, both maps within the orientation slack (where [`choose_map`][bsfjax.choose_map]
    goes by the local distortion alone)."""
    if abs(orient[0] - orient[1]) > ORIENTATION_SLACK:
        return False
    return bool((local[0] <= local[1]) != (orient[0] >= orient[1]))


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
    to it in the source's space (of several with that image, the first).  Target vertices
    where ``p2p`` is ``-1`` (not searched, `_selection_rows`) do not count."""
    src = np.asarray(farthest_point_sampling(source_mesh, n), np.int64)
    v = np.asarray(source_mesh.vertices, np.float64)
    p2p = np.asarray(p2p)
    known = np.flatnonzero(p2p >= 0)
    images, first = np.unique(p2p[known], return_index=True)  # (ties: the first target)
    return src, known[first[cKDTree(v[images]).query(v[src])[1]]].astype(np.int64)


def _selection_rows(target_mesh) -> tuple:
    """``(rows, faces)``: where [`estimate_map`][bsfjax.estimate_map] compares its candidate maps on a target
    of more than `SELECTION_VERTICES` vertices: the corners of
    `SELECTION_FACES` random faces (seed 0; the orientation agreement is their
    area-weighted share) and the samples of the distortions.  ``(None, None)`` (every
    vertex and face) on a smaller target."""
    if target_mesh.n_vertices <= SELECTION_VERTICES:
        return None, None
    faces = np.sort(np.random.default_rng(0).choice(
        target_mesh.n_faces, min(SELECTION_FACES, target_mesh.n_faces), replace=False))
    samples = [farthest_point_sampling(target_mesh, n) for n in (DISTORTION_SAMPLES,
                                                                 TURN_SAMPLES)]
    rows = np.unique(np.concatenate([target_mesh.faces[faces].ravel(), *samples]))
    return rows.astype(np.int64), faces


def check_samples(samples, n_m: int, n_n: int) -> tuple:
    """Given ``(source, target)`` subsamples, each with one cell per vertex of its shape."""
    ok = len(samples) == 2 and all(isinstance(s, Subsample) for s in samples)
    if not ok or samples[0].cells.shape != (n_m,) or samples[1].cells.shape != (n_n,):
        raise BSFError(f"zoomout_samples must be an int, None, or (source, target) Subsamples "
                       f"of {n_m} and {n_n} vertices")
    return samples


def check_starts(starts, refine_to: int, single: tuple, default) -> tuple:
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
