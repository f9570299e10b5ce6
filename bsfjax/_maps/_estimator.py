"""Estimate a point map between two meshes from their spectra: the
[`MapEstimator`][bsfjax.MapEstimator] (with landmarks, or from several starts told apart by their
distortion and orientation, then its turn check), and the source's intrinsic
[`mirror_symmetry`][bsfjax.MapEstimator.mirror_symmetry] its turn check uses.  What ``bsfjax
transfer`` runs before it carries anything across; `bsfjax._maps._functions` has the function
forms.
"""

from __future__ import annotations

import equinox as eqx
import numpy as np

from ._distortion import DISTORTION_SAMPLES, ORIENTATION_SLACK, _agreements, _distortions
from ._estimate import MapEstimate, Problem, Run, check_landmark_pairs, check_pair_samples, \
    check_starts, check_symmetry, choice_key, choose_derived, choose_start, resumed_choice, \
    to_given
from ._estimation import FmapWeights, check_fmap_memory, estimate_fmap
from ._fmap import fmap_from_p2p, fmap_to_p2p, zoomout
from ._guide import DERIVED_GUIDANCE, GUIDE_WEIGHT, estimate_zoomout, follows_landmarks, \
    guidable
from ._proxy import needs_proxy, proxy_estimate
from ._turn import LIMB_APART, check_sizes, check_turn, descriptors, landmarks_from_map, \
    selection_rows, self_map, with_read_pairs
from .._sampling import Subsample, subsample
from .._spectral import Spectrum, unit_area_pair
from .._util import (BSFError, check_int, check_real, check_source_mesh, on_one_blas_thread,
                     require_triangles)

__all__ = ["MapEstimate", "MapEstimator"]


class MapEstimator(eqx.Module):
    r"""Estimate a point map ``T: N → M`` and a ``k × k`` functional map between two shapes
    from their spectra (and optional landmarks).

    Called as ``MapEstimator(...)(source, target, landmarks, source_mesh=, target_mesh=)``
    it returns a [`MapEstimate`][bsfjax.MapEstimate]; [`estimate_map`][bsfjax.estimate_map] is one
    call with the options as keywords, [`transfer_collection`][bsfjax.transfer_collection]
    and ``bsfjax transfer`` take one.  Its phases:

    1. **One start** ``(k₀, σ)``: WKS descriptors of ``n_energies`` energies and variance
       ``σ`` (plus WKS centred at the landmarks) on ``k₀`` eigenpairs, and the ``k₀ × k₀`` map
       ``C₀`` of least descriptor-preservation, descriptor-commutativity and
       Laplacian-commutativity energy ([`bsfjax.estimate_fmap`][bsfjax.estimate_fmap]); without
       landmarks but with the meshes, plus ``orient_weight`` times the orientation-preserving
       term, which tells a shape from its mirror image.  ZoomOut then grows ``C₀`` to
       ``refine_to × refine_to``, ``zoomout_step`` eigenpairs per iteration, on
       ``zoomout_samples`` farthest-point samples of each shape; the point map is the nearest
       neighbour of each target row of ``Φ_N C`` among the rows of ``Φ_M``, and ``C`` the
       ``k × k`` map of that point map.  With landmarks (or without the meshes) this is all
       (``added_landmarks``: once more, with pairs read off the map beside the given ones;
       ``derived_guidance`` between triangle meshes: phases 3 and 4 follow from its map).
    2. **The choice among starts** (no landmarks, with the meshes): every start of ``starts``
       (default ``landmark_free_starts``) runs phase 1; among the point maps whose
       orientation agreement ([`bsfjax.orientation_agreement`][bsfjax.orientation_agreement]) is
       within ``orientation_slack`` of the best, the one of least geodesic distortion
       ([`bsfjax.map_distortion`][bsfjax.map_distortion] on ``distortion_samples`` target samples) is
       kept ([`bsfjax.choose_map`][bsfjax.choose_map]).  One start often lands in a partly mirrored
       map (both arms swapped) or a slid one (a leg on a foot), and which start does depends on
       the pair.
    3. **Derived landmarks**: ``derived_landmarks`` landmark pairs read off the kept map (the
       source's farthest points, each with the target vertex whose image lies nearest), and
       phase 1 again with them at ``(k, wks_variance)``, as if they were given (with
       ``derived_guidance`` also with ZoomOut guided by them); the second map is kept if
       [`bsfjax.choose_map`][bsfjax.choose_map] prefers it (``keep_derived``: whenever its
       orientation agreement is within ``orientation_slack``).  On the 9 FAUST / FAUST_5k
       pairs of docs/results/segmentation.md ("Without landmarks") this is as accurate as 5 true
       landmarks.
    4. **The turn check** (``turn_check``): two human shapes can also be matched turned front
       to back (left and right limbs swapped, the limbs twisted, the torso turned), a map that
       keeps orientation and long distances.  The check estimates the source's intrinsic
       mirror symmetry ``S`` ([`mirror_symmetry`][bsfjax.MapEstimator.mirror_symmetry], a
       self-map that reverses orientation), reads ``turn_landmarks`` pairs ``(x, y)`` off the
       kept map, estimates with ``(S x, y)`` and the orientation term, then once more with
       ``derived_landmarks`` pairs read off that map (the whole turn).  With
       ``turn_candidates="limbs"`` a single swapped pair of limbs (noisy shins) is checked
       too: each landmark farther than ``turn_radius`` from its mirror image (or than
       ``turn_limbs_apart`` radii along the surface) gives the alternative ``(x, y)`` with
       that ``xᵢ`` replaced by ``S xᵢ``.  Among the maps
       within ``orientation_slack`` of the best orientation agreement, the one of least local
       distortion (pairs of ``turn_samples`` target samples closer than ``turn_radius``: a
       twisted limb raises it) times global distortion (a limb torn off its side) is kept
       (``"mirror"``: the whole turn alone, by local distortion).  Where the orientation
       agreement prefers the other side the choice is a guess: ``MapEstimate.turn_doubtful``.

    On a target of more than ``selection_vertices`` vertices, phases 2–4 search each
    candidate's point map only where it is compared: the corners of ``selection_faces``
    random faces and the distortions' samples; the kept map is searched over every vertex at
    the end.

    **Arguments:**

    - `k`: size of the returned functional map, and ``k₀`` of the single start (30).
    - `refine_to`: ZoomOut's final size (``None``, the default: as many eigenpairs as both
      spectra have).
    - `n_energies`: WKS energies (100).
    - `wks_variance`: the WKS variance ``σ`` of the single start, of the derived and of the
      turned estimates (7.0, pyFM's; in units of the energy range over the energies).
    - `zoomout_samples`: with the meshes, ZoomOut runs on this many farthest-point samples of
      each shape ([`bsfjax.subsample`][bsfjax.subsample]; 2000: on FAUST 12× fewer searches and the
      same accuracy on 9 FAUST / FAUST_5k pairs); ``None``, or no meshes: on every vertex.
      The final point map is always over every vertex.
    - `zoomout_step`: eigenpairs added per ZoomOut iteration (2: half the searches of
      ZoomOut's original step 1, the same accuracy on the 9 FAUST / FAUST_5k pairs;
      ``bsfjax transfer`` and `transfer_collection` use at least 6 where a shape is a point
      cloud, `for_point_clouds`).
    - `turn_step`: ZoomOut's step in phase 4's maps (the kept one, the turned ones, the
      source's mirror symmetry); a turned map it keeps grows again at ``zoomout_step``
      (``None``: that step throughout).  Clouds: 2, the rest at 6 (`for_point_clouds`);
      phase 4 at 6 turned 2 of 12 noisy FAUST clouds (31.4, 31.6 % against 92.7–93.9 %).
    - `orient_weight`: weight of the orientation term of [`bsfjax.estimate_fmap`][bsfjax.estimate_fmap]
      without landmarks but with the meshes (1.0; docs/results/segmentation.md, "Real
      segmentations").
    - `starts`: ``(k₀, σ)`` pairs, each an initial ``k₀ × k₀`` estimate with WKS of variance
      ``σ``; those with ``k₀ > refine_to`` are skipped.  ``None`` (the default):
      ``landmark_free_starts`` without landmarks when the meshes are given, else the single
      start ``((k, wks_variance),)``.  Several starts need the meshes.
    - `landmark_free_starts`: the default starts without landmarks, and those
      [`mirror_symmetry`][bsfjax.MapEstimator.mirror_symmetry] falls back on: ``k₀`` in 16, 20, 24,
      30, 40 by ``σ`` in 3.5, 7.0, 14.0.  Without landmarks a single start lands in a partly
      mirrored or slid map on 5 of the 9 pairs of docs/results/segmentation.md ("Without
      landmarks").
    - `orientation_slack`: the candidates within this much of the best orientation agreement
      are compared by distortion (``ORIENTATION_SLACK`` of
      [`bsfjax.choose_map`][bsfjax.choose_map], 0.1: right maps 0.90–0.97 on the FAUST pairs, partly
      mirrored or slid ones down to 0.34).
    - `choice_coverage`: phase 2 weighs the [`map_coverage`][bsfjax.map_coverage] errors beside
      the distortions (``False``; on where a shape is a point cloud, `for_point_clouds`: the
      12 noisy FAUST clouds without landmarks 10 → 11 within 4 points of the clean pairs).
    - `distortion_samples`: target samples of the geodesic distortion (that of
      [`bsfjax.map_distortion`][bsfjax.map_distortion], 100).
    - `fit_scale`: phases 2–4 take the global distortion up to a bounded scale (``True``;
      [`map_distortion`][bsfjax.map_distortion]'s ``fit_scale``: bodies of other builds).
    - `landmark_guidance`: with landmarks and two triangle meshes, ZoomOut also compares
      geodesic distances to them, at this weight falling to 0 at ``guided_to`` (1.5; 0:
      plain ZoomOut; `bsfjax._maps._guide`: a cut foot no longer draws the leg into it).
    - `guided_to`: the size a guided ZoomOut runs to (``None``: every eigenpair of the
      spectra; at least ``refine_to``; ``bsfjax transfer``: 100); unguided ZoomOut stops at
      ``refine_to``.
    - `derived_guidance`: phases 3 and 4 also estimate with ZoomOut guided by the landmark
      pairs read off a map (at ``DERIVED_GUIDANCE``, half, of ``landmark_guidance``, to
      ``guided_to``; the turn check's mirror symmetry at ``guided_to`` too), beside the
      unguided estimate, and the choice keeps one (``False``; ``bsfjax transfer
      --partial``).  For a target that misses parts (a cut limb) and has no landmarks: on
      the partial FAUST targets of docs/results/scans.md the labels came within 0.5–2.9
      points of the clean pairs on 9 of 9 (before: 84.2 % on average, 7–62 points lost on
      the first cut).  With landmarks, phases 3 and 4 follow phase 1 (the command's second
      estimate of a target that misses parts): 9 FAUST targets cut three ways, with their
      3–4 kept landmarks, 93.93 → 94.66 % on average.  Off by default: on clean pairs the
      choice sometimes keeps the guided estimate where it is less accurate (its distortion
      and orientation both better): the 9 pairs of docs/results/segmentation.md without
      landmarks 95.04 → 94.66 %, FAUST_5k 000→010 93.92 → 90.11 %.
    - `derived_landmarks`: landmark pairs of phase 3 (20; 0: no phase 3).  SMPL-part accuracy
      of the pull-back on the 9 pairs: 92.57 % with none, 94.40 % with 10, 94.47 % with 20
      (94.46 % with 5 true landmarks).
    - `keep_derived`: phase 3 keeps the estimate with the derived landmarks whenever its
      orientation agreement is within ``orientation_slack`` of the best, not by distortion;
      where that changed phase 3's pick and phase 4 is then doubtful (``turn_doubtful``),
      phases 3 and 4 run again without it (``False``; on where a shape is a point cloud,
      `for_point_clouds`: the distortion on a noisy cloud's stand-in surface kept the start's
      map on 4 of 12 noisy FAUST clouds where the derived one labelled 0.4–11 points better;
      11 → 12 of 12 within 4 points of the clean pairs, docs/results/scans.md).
    - `added_landmarks`: with given landmarks and the meshes, this many pairs read off phase
      1's map (as phase 3 reads them) join them for a second estimate, kept
      (``MapEstimate.landmarks``: the pairs read; 0, the default; 40 on clouds,
      `for_point_clouds`: docs/results/scans.md).
    - `turn_check`: run phase 4 (``True``).
    - `turn_landmarks`: landmark pairs moved by the mirror symmetry in phase 4 (5: the
      source's farthest points, the tips of the limbs, where a turn swaps left and right).
    - `turn_candidates`: the alternatives of phase 4 and how they are compared, ``"limbs"``
      (the whole turn and one limb at a time, by local times global distortion) or
      ``"mirror"`` (the whole turn, by local distortion: the earlier check) (``"limbs"``).
    - `turn_samples`, `turn_radius`: the local distortion of phase 4, on this many target
      samples (200), over their pairs closer than this (0.15, at unit area).
    - `turn_limbs_apart`: a landmark this many ``turn_radius`` from its mirror image along the
      surface is a limb even near it in space (``LIMB_APART``; ``None`` on clouds: in space).
    - `selection_vertices`, `selection_faces`: above this many target vertices (20000) the
      candidates are compared at the corners of this many random faces (4096: the
      orientation agreement's standard error below 0.01) and the distortions' samples
      (TOSCA cat subdivided once, 111.5K vertices: 146 s instead of 357 s, the same map).
    - `proxy_above`, `proxy_vertices`: without landmarks, when the source or the target has
      more than ``proxy_above`` vertices (20000; ``None``: never), phases 2–4 run on proxies
      of about ``proxy_vertices`` vertices (10000; [`bsfjax.decimate`][bsfjax.decimate]), and
      the kept proxy map is carried back (`bsfjax._maps._proxy`: the nearest proxy vertex,
      its ``k × k`` map on the given spectra, ZoomOut to ``refine_to``).
      ``MapEstimate.proxy`` gives the proxies' sizes.  TOSCA cat subdivided once: 1.58 GB
      peak instead of 5.30, the same geodesic error (docs/benchmarks.md).
    """

    k: int = eqx.field(static=True, default=30)
    refine_to: int | None = eqx.field(static=True, default=None)
    n_energies: int = eqx.field(static=True, default=100)
    wks_variance: float = eqx.field(static=True, default=7.0)
    zoomout_samples: int | None = eqx.field(static=True, default=2000)
    zoomout_step: int = eqx.field(static=True, default=2)
    turn_step: int | None = eqx.field(static=True, default=None)
    orient_weight: float = eqx.field(static=True, default=1.0)
    starts: tuple | None = eqx.field(static=True, default=None)
    landmark_free_starts: tuple = eqx.field(static=True, default=tuple(
        (k0, v) for k0 in (16, 20, 24, 30, 40) for v in (3.5, 7.0, 14.0)))
    orientation_slack: float = eqx.field(static=True, default=ORIENTATION_SLACK)
    choice_coverage: bool = eqx.field(static=True, default=False)
    distortion_samples: int = eqx.field(static=True, default=DISTORTION_SAMPLES)
    derived_landmarks: int = eqx.field(static=True, default=20)
    keep_derived: bool = eqx.field(static=True, default=False)
    added_landmarks: int = eqx.field(static=True, default=0)
    turn_check: bool = eqx.field(static=True, default=True)
    turn_landmarks: int = eqx.field(static=True, default=5)
    turn_candidates: str = eqx.field(static=True, default="limbs")
    fit_scale: bool = eqx.field(static=True, default=True)
    landmark_guidance: float = eqx.field(static=True, default=GUIDE_WEIGHT)
    guided_to: int | None = eqx.field(static=True, default=None)
    derived_guidance: bool = eqx.field(static=True, default=False)
    turn_samples: int = eqx.field(static=True, default=200)
    turn_radius: float = eqx.field(static=True, default=0.15)
    turn_limbs_apart: float | None = eqx.field(static=True, default=LIMB_APART)
    selection_vertices: int = eqx.field(static=True, default=20000)
    selection_faces: int = eqx.field(static=True, default=4096)
    proxy_above: int | None = eqx.field(static=True, default=20000)
    proxy_vertices: int = eqx.field(static=True, default=10000)

    def __check_init__(self):
        # (k, refine_to, n_energies, starts, zoomout_samples: checked against the shapes)
        check_int(self.zoomout_step, "zoomout_step", 1)
        if self.turn_step is not None:
            check_int(self.turn_step, "turn_step", 1)
        check_int(self.derived_landmarks, "derived_landmarks", 0)
        check_int(self.added_landmarks, "added_landmarks", 0)
        for flag in ("derived_guidance", "keep_derived", "turn_check"):
            if not isinstance(getattr(self, flag), (bool, np.bool_)):
                raise BSFError(f"{flag} must be True or False, got {getattr(self, flag)!r}")
        check_real(self.wks_variance, "wks_variance", positive=True)
        check_real(self.orient_weight, "orient_weight", positive=True)
        if not 0 <= check_real(self.orientation_slack, "orientation_slack") <= 1:
            raise BSFError(f"orientation_slack must be in [0, 1], got {self.orientation_slack}")
        check_int(self.distortion_samples, "distortion_samples", 2)
        check_int(self.turn_landmarks, "turn_landmarks", 1)
        if self.turn_candidates not in ("limbs", "mirror"):
            raise BSFError(f"turn_candidates must be 'limbs' or 'mirror', got {self.turn_candidates!r}")
        check_int(self.turn_samples, "turn_samples", 2)
        check_real(self.turn_radius, "turn_radius", positive=True)
        if self.turn_limbs_apart is not None:
            check_real(self.turn_limbs_apart, "turn_limbs_apart", positive=True)
        check_int(self.selection_vertices, "selection_vertices", 0)
        check_int(self.selection_faces, "selection_faces", 1)
        check_int(0 if self.proxy_above is None else self.proxy_above, "proxy_above", 0)
        check_int(self.proxy_vertices, "proxy_vertices", 4)
        if check_real(self.landmark_guidance, "landmark_guidance") < 0:
            raise BSFError(f"landmark_guidance must be >= 0, got {self.landmark_guidance!r}")

    @on_one_blas_thread
    def __call__(self, source: Spectrum, target: Spectrum, landmarks=None, *, source_mesh=None,
                 target_mesh=None, samples=None, source_symmetry=None,
                 resume: MapEstimate | None = None) -> MapEstimate:
        """Estimate the map (the phases of the class docstring).

        **Arguments:**

        - `source`, `target`: spectra with at least ``max(k, refine_to)`` eigenpairs.
        - `landmarks`: ``(source_indices, target_indices)`` of equal length, or ``None``.
          Without landmarks an intrinsically symmetric shape may be matched to its mirror
          image, unless the meshes are given.
        - `source_mesh`, `target_mesh`: the [`Mesh`][bsfjax.Mesh] of each spectrum: without
          landmarks they switch on the orientation term and the choice among starts, and they
          give ZoomOut its samples.
        - `samples`: ``(source, target)`` [`Subsample`][bsfjax.Subsample] s for ZoomOut, when at
          hand (instead of ``zoomout_samples`` new ones).
        - `source_symmetry`: the source's [`mirror_symmetry`][bsfjax.mirror_symmetry] for the
          turn check, when at hand (``transfer_collection``'s, once for all its targets).
        - `resume`: an estimate of the same shapes from several starts by an estimator that
          differs from this one at most in ``derived_guidance``, ``derived_landmarks``,
          ``keep_derived`` and the turn check: its kept start (phases 1 and 2) is taken as
          is, the call goes on from phase 3.  Ignored with landmarks, a single start, or
          proxies (a large mesh).

        **Returns:**

        a [`MapEstimate`][bsfjax.MapEstimate].
        """
        if landmarks is None:
            for mesh, role in ((source_mesh, "source"), (target_mesh, "target")):
                require_triangles(mesh, f"a point cloud {role} needs landmarks: the "
                                  "landmark-free map's orientation term needs triangles "
                                  "(give two or more landmark pairs)")
        refine_to = check_sizes(self.k, self.refine_to, min(source.k, target.k))
        guided_to = max(refine_to, check_sizes(self.k, self.guided_to, min(source.k, target.k),
                                               "guided_to"))
        guided_to = guided_to if self.landmark_guidance else refine_to  # (nothing guided)
        lm = check_landmark_pairs(landmarks, source.n_vertices, target.n_vertices)
        meshes = source_mesh is not None and target_mesh is not None
        single = self._single_start()
        starts = check_starts(self.starts, refine_to, (single,),
                              self.landmark_free_starts if lm is None and meshes else None)
        if len(starts) > 1 and not meshes:
            raise BSFError("several starts are told apart by the meshes: give source_mesh and "
                           "target_mesh, or a single start")
        check_fmap_memory(max(k0 for k0, _ in starts + (single,)))  # before any allocation
        source_symmetry = check_symmetry(source_symmetry, source.n_vertices)
        if len(starts) > 1 and needs_proxy(self, source_mesh, target_mesh):  # a large mesh
            return proxy_estimate(self, source, target, source_mesh, target_mesh, refine_to,
                                  samples, source_symmetry)
        # on the unit-area shapes (float64 before any float32 cast), back in the given bases
        source_given = source  # (mirror_symmetry checks its mesh against the given spectrum)
        masses = (source.mass, target.mass)  # (the landmark guidance's units)
        source, am, target, an = unit_area_pair(source, target)
        if samples is not None:  # (the collection's, computed once)
            samples = check_pair_samples(samples, source.n_vertices, target.n_vertices)
        elif self.zoomout_samples is not None and meshes:
            samples = (subsample(source_mesh, self.zoomout_samples),
                       subsample(target_mesh, self.zoomout_samples))
        # several starts on a large target: the candidates' point maps are searched only where
        # they are compared, and the kept one over every vertex at the end
        later = follows_landmarks(self, lm, source_mesh, target_mesh)
        rows, faces = selection_rows(self, target_mesh) if len(starts) > 1 or later else \
            (None, None)
        pb = Problem(source, target, source_mesh, target_mesh, refine_to, samples, rows, faces,
                     max(k0 for k0, _ in starts + (single,)), masses, guided_to)
        choice = None
        if len(starts) > 1:  # (phases 1 and 2, or the kept start of an earlier call)
            key = choice_key(self, starts, refine_to, source, target,
                             (pb.source_mesh, pb.target_mesh))
            run, quality = (resumed_choice(resume, key) if resume is not None else
                            self._choose_start(pb, starts, [
                                self._estimate(pb, s, lm, guide=self.landmark_guidance)
                                for s in starts]))
            choice = (key, run, dict(quality))
            run, quality = self._later_phases(pb, run, quality, source_given, source_symmetry)
        else:
            run, quality = self._estimate(pb, starts[0], lm, guide=self.landmark_guidance), {}
            if later:  # (a target that misses parts: phases 3 and 4 from the landmarks' map)
                run, quality = self._later_phases(pb, *self._rated(pb, run, {}), source_given,
                                                  source_symmetry, given=True)
            elif lm is not None and self.added_landmarks and pb.meshes:  # (again, with more)
                both, read = with_read_pairs(lm, pb.source_mesh, run.p2p, self.added_landmarks)
                run = self._estimate(pb, starts[0], both, guide=self.landmark_guidance)
                quality = dict(landmarks=read)
        return self._result(pb, run, am, an, quality)._replace(choice=choice)

    @on_one_blas_thread
    def mirror_symmetry(self, spectrum: Spectrum, mesh, *, samples: Subsample | None = None,
                        rows=None) -> np.ndarray:
        """The shape's intrinsic mirror symmetry ``S: M → M``, a self point map that reverses
        orientation (left ↔ right on a body).

        The functional map of ``M`` to itself from WKS descriptors with the
        orientation-*reversing* term ([`bsfjax.estimate_fmap`][bsfjax.estimate_fmap],
        ``orientation="reversing"``, weight ``orient_weight``) at ``k × k``, ZoomOut to
        ``refine_to`` (at ``turn_step``), then the point map: the self-map of phase 1 with
        the orientation term turned around.

        Where it keeps the orientation on more than ``orientation_slack`` of the area (fallen
        part of the way to the identity: FAUST ``tr_reg_002``), every start of
        ``landmark_free_starts`` runs and [`bsfjax.choose_map`][bsfjax.choose_map] keeps the
        least distorted of those that reverse it best.  On FAUST it maps each SMPL part to its
        mirror part on 97–99 % of the area (FAUST_5k: 93–95 %).  The turn check uses it.

        **Arguments:**

        - `spectrum`, `mesh`: the shape (``refine_to`` eigenpairs at least; ``refine_to``
          ``None``: the spectrum's size).
        - `samples`: ZoomOut on this [`Subsample`][bsfjax.Subsample] (default: on
          ``zoomout_samples`` farthest-point samples, or on every vertex when that is
          ``None``).
        - `rows`: the vertices whose mirror images to return (default: every vertex); each
          is its image in the whole map, only the search is smaller.

        **Returns:**

        ``(n,)`` int array, ``S[i]`` the mirror image of vertex ``i`` (with
        ``rows``, ``(len(rows),)``: the image of ``rows[i]``).
        """
        if not isinstance(spectrum, Spectrum):
            raise BSFError(f"spectrum must be a bsfjax.Spectrum, got {type(spectrum).__name__}")
        check_source_mesh(mesh, spectrum.n_vertices, spectrum.mass)
        require_triangles(mesh, "a point cloud has no mirror symmetry here: its orientation "
                          "term needs triangles")
        refine_to = check_sizes(self.k, self.refine_to, spectrum.k)
        if samples is None and self.zoomout_samples is not None:
            samples = subsample(mesh, check_int(self.zoomout_samples, "samples", 1))
        elif samples is not None and not isinstance(samples, Subsample):
            raise BSFError(f"samples must be a bsfjax.Subsample or None, got "
                           f"{type(samples).__name__}")
        return self_map(self, spectrum, mesh, refine_to, samples, rows)

    # ----------------------------------------------------------------------- the phases

    def _single_start(self) -> tuple:
        return (self.k, self.wks_variance)

    def _estimate(self, pb: Problem, start, landmarks, orient=None, guide=0.0) -> Run:
        """Phase 1 from ``start`` with ``landmarks`` (or ``None``): the estimate at ``k₀``,
        ZoomOut to ``refine_to`` (``guide > 0``: guided by ``landmarks`` at this weight, to
        ``guided_to``), the point map (at ``pb.rows`` only, ``-1`` elsewhere).  The
        orientation term is on without landmarks (with the meshes), or where ``orient`` says
        so."""
        k0, variance = start
        extra = {}
        if pb.meshes and (landmarks is None if orient is None else orient):
            extra = dict(weights=FmapWeights(orient=self.orient_weight),
                         orientation_bases=pb.bases())
        C0 = estimate_fmap(pb.source, pb.target, *(
            descriptors(s, self.n_energies, k0, variance,
                        None if landmarks is None else landmarks[i])
            for i, s in enumerate((pb.source, pb.target))), k=k0, **extra)
        return self._grow(pb, C0, landmarks, guide)

    def _grow(self, pb: Problem, C0, landmarks, guide: float) -> Run:
        """ZoomOut from ``C0`` at ``zoomout_step`` (as `_estimate` says), the point map."""
        C_ref, k0 = C0, C0.shape[0]
        if (pb.guided_to > k0 and guide and landmarks is not None
                and guidable(pb.source_mesh, pb.target_mesh, self)):
            C_ref = estimate_zoomout(pb, C0, landmarks, self.zoomout_step, guide)
        elif pb.refine_to > k0:
            C_ref = zoomout(C0, pb.source, pb.target, pb.refine_to, step=self.zoomout_step,
                            samples=pb.samples)
        p2p = found = np.asarray(fmap_to_p2p(C_ref, pb.source, pb.target, rows=pb.rows))
        if pb.rows is not None:  # (-1 where not searched)
            p2p = np.full(pb.target.n_vertices, -1, np.int64)
            p2p[pb.rows] = found
        return Run(C0, p2p, C_ref, (landmarks, guide))

    def _grow_again(self, pb: Problem, run: Run, quality: dict) -> tuple:
        """The kept run grown again from its ``C0`` at ``zoomout_step``, its quality anew."""
        return self._rated(pb, self._grow(pb, run.C0, *run.grown), quality)

    def _rated(self, pb: Problem, run: Run, quality: dict) -> tuple:
        """``run`` and ``quality`` with its distortion and orientation agreement."""
        orient = _agreements(pb.source_mesh, pb.target_mesh, run.p2p[None], pb.faces)
        return run, dict(quality, distortion=float(self._distortion(pb, run.p2p)[0]),
                         orientation=float(orient[0]))

    def _distortion(self, pb: Problem, candidates, n_samples=None, radius=None):
        """The geodesic distortions of candidate point maps (local ones with ``radius``)."""
        return _distortions(pb.source_mesh, pb.target_mesh,
                            np.atleast_2d(candidates).astype(np.int64),
                            self.distortion_samples if n_samples is None else n_samples,
                            radius, pb.geodesics(),
                            fit_scale=self.fit_scale and radius is None)

    def _choose_start(self, pb: Problem, starts: tuple, runs: list) -> tuple:
        """Phase 2: the run [`choose_map`][bsfjax.choose_map] keeps, and its quality."""
        return choose_start(self, pb, starts, runs, self._distortion)

    def _derived(self, pb: Problem, p2p) -> list:
        """``derived_landmarks`` landmark pairs read off ``p2p``, and phase 1 with them: as if
        given, and (where the guidance can run) with ZoomOut guided by them at
        ``DERIVED_GUIDANCE`` of ``landmark_guidance`` (``derived_guidance``);
        ``[(pairs, run), ...]``."""
        pairs = landmarks_from_map(pb.source_mesh, p2p, self.derived_landmarks)
        guides = [0.0]
        if (self.derived_guidance and pb.guided_to > self.k
                and guidable(pb.source_mesh, pb.target_mesh, self)):
            guides.append(DERIVED_GUIDANCE * self.landmark_guidance)
        return [(pairs, self._estimate(pb, self._single_start(), pairs, guide=g))
                for g in guides]

    def _later_phases(self, pb: Problem, run: Run, quality: dict, source_given: Spectrum,
                      source_symmetry, given: bool = False) -> tuple:
        """Phases 3 and 4 from the kept start's run (``given``: the given landmarks'; phase 3
        then prefers its guided estimate, `GUIDED_SLACK`); with ``keep_derived``, phase 3's
        choice once more without it where it changed the pick and phase 4 was doubtful."""
        prefer = None
        if self.derived_landmarks:
            found = self._derived(pb, run.p2p)
            guided = [i for i, (_, r) in enumerate(found, 1) if r.grown[1]]
            prefer = guided[0] if given and guided else None
            maps = np.stack([r.p2p for _, r in found])
            dist = [quality["distortion"], *map(float, self._distortion(pb, maps))]
            orient = [quality["orientation"], *map(float, _agreements(
                pb.source_mesh, pb.target_mesh, maps, pb.faces))]
        for trust in dict.fromkeys((self.keep_derived, False)):
            kept, q, trusted = (choose_derived(self, run, quality, found, dist, orient, trust,
                                               prefer)
                                if self.derived_landmarks else (run, quality, False))
            if self.turn_check:
                kept, q = check_turn(self, pb, kept, q, source_given, source_symmetry)
                if trusted and q.get("turn_doubtful"):  # (the distortion's pick instead)
                    continue
            return kept, q

    def _result(self, pb: Problem, run: Run, am, an, quality: dict) -> MapEstimate:
        """The kept run as a [`MapEstimate`][bsfjax.MapEstimate] in the given bases (its point
        map searched over every vertex)."""
        p2p = run.p2p
        if pb.rows is not None:
            p2p = np.asarray(fmap_to_p2p(run.C_ref, pb.source, pb.target))
        C = np.asarray(fmap_from_p2p(pb.source.truncate(self.k), pb.target.truncate(self.k),
                                     p2p))
        return MapEstimate(C=to_given(C, am, an), p2p=p2p, C_initial=to_given(run.C0, am, an),
                           samples=pb.samples, **quality)
