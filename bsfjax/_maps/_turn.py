"""The pieces [`MapEstimator`][bsfjax.MapEstimator] shares between its phases and its turn check: a
shape's intrinsic mirror symmetry, landmark pairs read off a point map, where candidate maps
are compared on a large target, and the descriptors of one start; and the turn check itself
(`check_turn`, phase 4).

Each function takes the estimator (its fields) as its first argument; the estimator's own
methods ([`MapEstimator.mirror_symmetry`][bsfjax.MapEstimator.mirror_symmetry]) check the inputs first.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from scipy.spatial import cKDTree

from ._descriptors import wks
from ._distortion import _agreements, _distortions, choose_map
from ._estimate import turn_step
from ._estimation import FmapWeights, estimate_fmap
from ._fmap import fmap_to_p2p, zoomout
from ._guide import turn_mirror_size
from ._orientation import orientation_bases
from .._sampling import farthest_point_sampling, geodesic_distances
from .._spectral import Spectrum
from .._util import BSFError


def self_map(est, spectrum: Spectrum, mesh, refine_to: int, samples, rows) -> np.ndarray:
    """The mirror symmetry ``S: M → M`` (docstring of
    [`MapEstimator.mirror_symmetry`][bsfjax.MapEstimator.mirror_symmetry]), the inputs checked:
    ``refine_to`` resolved, ``samples`` a [`Subsample`][bsfjax.Subsample] or ``None``."""
    # the orientation is checked on every face, or on a large mesh on the selection of
    # faces (and the distortions' samples), where the self-map is searched
    checked, faces = selection_rows(est, mesh)
    single = (est.k, est.wks_variance)
    C = _self_fmap(est, spectrum, mesh, refine_to, samples, single)
    p2p = _self_p2p(C, spectrum, checked)
    extra = [s for s in est.landmark_free_starts if s[0] <= refine_to and s != single]
    if extra and _agreements(mesh, mesh, p2p[None], faces)[0] > est.orientation_slack:
        # not a mirror image: every start, one scan over the faces for them all
        bases = orientation_bases(spectrum, spectrum, mesh, mesh, max(s[0] for s in extra))
        fmaps = [C] + [_self_fmap(est, spectrum, mesh, refine_to, samples, s, bases)
                       for s in extra]
        del bases
        maps = np.stack([p2p] + [_self_p2p(F, spectrum, checked) for F in fmaps[1:]])
        reversal = 1.0 - _agreements(mesh, mesh, maps, faces)
        best = choose_map(_distortions(mesh, mesh, maps, est.distortion_samples, None),
                          reversal, slack=est.orientation_slack)
        C, p2p = fmaps[best], maps[best]
    if checked is None and rows is None:  # (searched over every vertex already)
        return p2p
    return np.asarray(fmap_to_p2p(C, spectrum, spectrum, rows=rows)).astype(np.int64)


def _self_fmap(est, spectrum: Spectrum, mesh, refine_to: int, samples, start, bases=None):
    """One start of the self-map: WKS at ``start = (k₀, variance)``, the estimate with the
    orientation-reversing term at ``k₀ × k₀``, ZoomOut to ``refine_to``."""
    k0, variance = start
    d = wks(spectrum, est.n_energies, k=k0, variance=variance)
    geometry = dict(source_mesh=mesh, target_mesh=mesh) if bases is None else \
        dict(orientation_bases=bases)
    C0 = estimate_fmap(spectrum, spectrum, d, d, k=k0,
                       weights=FmapWeights(orient=est.orient_weight), orientation="reversing",
                       **geometry)
    if refine_to <= k0:
        return C0
    return zoomout(C0, spectrum, spectrum, refine_to, step=turn_step(est),
                   samples=None if samples is None else (samples, samples))


def _self_p2p(C, spectrum: Spectrum, checked) -> np.ndarray:
    """The self point map of ``C`` at the ``checked`` vertices (every vertex for ``None``),
    ``-1`` elsewhere."""
    p2p = np.full(spectrum.n_vertices, -1, np.int64)
    p2p[slice(None) if checked is None else checked] = np.asarray(
        fmap_to_p2p(C, spectrum, spectrum, rows=checked))
    return p2p


def selection_rows(est, target_mesh) -> tuple:
    """``(rows, faces)``: where the estimator compares candidate maps on a target of more
    than ``est.selection_vertices`` vertices: the corners of ``est.selection_faces`` random
    faces (seed 0; the orientation agreement is their area-weighted share) and the samples of
    the distortions.  ``(None, None)`` (every vertex and face) on a smaller target."""
    if target_mesh.n_vertices <= est.selection_vertices:
        return None, None
    faces = np.sort(np.random.default_rng(0).choice(
        target_mesh.n_faces, min(est.selection_faces, target_mesh.n_faces), replace=False))
    samples = [farthest_point_sampling(target_mesh, n)
               for n in (est.distortion_samples, est.turn_samples)]
    rows = np.unique(np.concatenate([target_mesh.faces[faces].ravel(), *samples]))
    return rows.astype(np.int64), faces


def measures_disagree(est, score, orient, pick: int | None = None, turn=(1,)) -> bool:
    """Whether the turn check's score and the orientation agreement prefer different maps of
    two, both within the orientation slack (where [`choose_map`][bsfjax.choose_map] goes by
    the score alone): the kept map ``pick`` (default: the one ``choose_map`` keeps) and its
    other side, the map checked (``0``) for a map of the whole turn (indices ``turn``), else
    the whole turn's map of least score."""
    if pick is None:
        pick = choose_map(score, orient, slack=est.orientation_slack)
    turn = [int(t) for t in turn]
    other = 0 if pick in turn else min(turn, key=lambda t: score[t])
    if abs(orient[pick] - orient[other]) > est.orientation_slack:
        return False
    return bool((score[pick] <= score[other]) != (orient[pick] >= orient[other]))


#: A landmark farther than this many turn radii from its mirror image along the surface is a
#: limb even where the pose brings it within a radius of that image in space (hands held
#: together, feet side by side): 5 (1.0 at unit area, about 1.3 m on a FAUST body) takes
#: FAUST 001's hands and feet (1.6–1.7) and not its upper thigh (0.57), whose set mostly
#: repeats the kept map and only adds a near-tie to the choice (counted as a limb, 001→011
#: without its left forearm and right foot fell from 93.5 to 90.9 % without landmarks).
LIMB_APART = 5.0


def turn_landmark_sets(source_mesh, x, sx, y, radius: float, apart: float | None = LIMB_APART):
    """The landmark pairs of the turn check's alternatives to a map that gave the pairs
    ``(x, y)`` (``S x``: their mirror images): the whole turn ``(S x, y)``, then one set per
    limb: each landmark ``xᵢ`` farther than ``radius`` (at unit area) from its mirror image
    in space, or farther than ``apart`` radii along the surface (a limb, not the head), is
    mirrored, ``xᵢ → S xᵢ``, together with the landmarks near ``S xᵢ`` (within ``radius``,
    along the surface; in space where ``apart`` is ``None``: the other hand's, when both are
    landmarks: the two swap sides), the others kept: the map with one pair of limbs on the
    other side.  Sets equal to the whole turn's are left out.

    Along the surface: in FAUST 001's pose the hands are within a radius of their mirror
    images in space, and the set that puts one arm right was missing (the mirror cut of
    FAUST 011 without landmarks kept its left arm labelled as the right one,
    docs/results/scans.md).  ``apart=None`` (``MapEstimator.turn_limbs_apart`` on clouds):
    in space only."""
    x, sx, y = (np.asarray(a, np.int64) for a in (x, sx, y))
    r = radius * np.sqrt(source_mesh.area)
    v = np.asarray(source_mesh.vertices, np.float64)
    n = len(x)
    if apart is None:
        off = np.linalg.norm(v[sx] - v[x], axis=1) > r
        near = np.linalg.norm(v[sx][:, None] - v[x][None], axis=2) < r  # (S xᵢ, xⱼ)
    else:
        # Dijkstra from the 2n ends to each other only (rows: x then S x); a landmark on
        # another component than its mirror image is infinitely far from it: a limb
        ends = np.concatenate([x, sx])
        d = geodesic_distances(source_mesh, ends, targets=ends)
        off = ((np.linalg.norm(v[sx] - v[x], axis=1) > r)
               | (d[np.arange(n), n + np.arange(n)] > apart * r))
        near = d[n:, :n] < r
    groups = []
    for i in np.flatnonzero(off):
        g = frozenset([int(i)]) | frozenset(np.flatnonzero(near[i]).tolist())
        if g not in groups and g != frozenset(np.flatnonzero(off).tolist()):
            groups.append(g)
    sets = [(sx, y)]
    for g in groups:
        xi = x.copy()
        xi[list(g)] = sx[list(g)]
        sets.append((xi, y))
    return sets


def landmarks_from_map(source_mesh, p2p, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` landmark pairs read off a point map ``T: N → M``: the source's ``n`` farthest
    points (Euclidean, seed 0), each with the target vertex whose image ``T(j)`` lies nearest
    to it in the source's space (of several with that image, the first).  Target vertices
    where ``p2p`` is ``-1`` (not searched: `selection_rows`) do not count."""
    src = np.asarray(farthest_point_sampling(source_mesh, n), np.int64)
    v = np.asarray(source_mesh.vertices, np.float64)
    p2p = np.asarray(p2p)
    known = np.flatnonzero(p2p >= 0)
    images, first = np.unique(p2p[known], return_index=True)  # (ties: the first target)
    return src, known[first[cKDTree(v[images]).query(v[src])[1]]].astype(np.int64)


def with_read_pairs(landmarks, source_mesh, p2p, n: int) -> tuple:
    """``(joined, read)``: ``n`` landmark pairs read off ``p2p`` (`landmarks_from_map`) and
    the given ``landmarks`` followed by them, the pairs of the second estimate of
    ``MapEstimator.added_landmarks`` (`transfer_collection` reads them the same way)."""
    read = landmarks_from_map(source_mesh, p2p, n)
    return tuple(np.concatenate([np.asarray(a, np.int64), b])
                 for a, b in zip(landmarks, read)), read


def descriptors(spectrum: Spectrum, n_energies: int, k0: int, variance: float, landmarks):
    """A shape's descriptors for [`estimate_fmap`][bsfjax.estimate_fmap]: WKS, and WKS centred at
    ``landmarks`` (if any) beside them.  The parts are freed once joined: on a large shape with
    many landmarks they are most of the estimate's memory."""
    plain = wks(spectrum, n_energies, k=k0, variance=variance)
    if landmarks is None:
        return plain
    return jnp.concatenate([plain, wks(spectrum, n_energies, landmarks=landmarks, k=k0,
                                       variance=variance)], axis=1)


def check_sizes(k, refine_to, km: int, name: str = "refine_to") -> int:
    """``k`` and ``refine_to`` (default ``km``; ``name`` in messages) checked against the
    ``km`` eigenpairs there are; returns ``refine_to``."""
    if not isinstance(k, (int, np.integer)) or not 1 <= k <= km:
        raise BSFError(f"k must be an integer in [1, {km}] (the spectra's size), got {k!r}")
    refine_to = km if refine_to is None else refine_to
    if not isinstance(refine_to, (int, np.integer)) or not k <= refine_to <= km:
        raise BSFError(f"{name} must be an integer in [{k}, {km}], got {refine_to!r}")
    return refine_to


def turn_candidates(est, pb, run, quality: dict, source_given: Spectrum, source_symmetry,
                    joint: bool) -> tuple:
    """The maps the turn check of ``est`` compares, ``(runs, landmark_sets, turn)``: the kept
    ``run`` first, then the estimates with the mirrored landmark pairs (and with the pairs
    read off them); ``turn`` the indices of the whole turn's.  ``joint``: one set per limb
    too (``turn_candidates="limbs"``), each estimate competing beside its derived one."""
    x, y = landmarks_from_map(pb.source_mesh, run.p2p, est.turn_landmarks)
    if source_symmetry is not None:
        sx = source_symmetry[x]
    else:  # the mirror images of x only (a search of len(x) rows, not of every vertex)
        at_size = dataclasses.replace(
            est, refine_to=turn_mirror_size(est, pb.refine_to, pb.guided_to))
        sx = at_size.mirror_symmetry(
            source_given, pb.source_mesh,
            samples=None if pb.samples is None else pb.samples[0], rows=x)
    sets = (turn_landmark_sets(pb.source_mesh, x, sx, y, est.turn_radius,
                               est.turn_limbs_apart) if joint
            else [(sx, y)])
    runs, kept_sets, turn = [run], [quality.get("landmarks")], []
    for n, lms in enumerate(sets):
        alt = est._estimate(pb, est._single_start(), lms, orient=True)
        if joint or not est.derived_landmarks:  # ("limbs": both estimates compete)
            runs.append(alt)
            kept_sets.append(lms)
            turn += [len(runs) - 1] if n == 0 else []
        if est.derived_landmarks:
            for derived, alt in est._derived(pb, alt.p2p):
                runs.append(alt)
                kept_sets.append(derived)
                turn += [len(runs) - 1] if n == 0 else []
    return runs, kept_sets, turn


def turn_choice(est, pb, runs: list, joint: bool, turn: list):
    """Which of the turn check's ``runs`` to keep, whether that is doubtful, and their
    orientation agreements; ``None`` on a target too coarse for the local distortion.

    **Arguments:**

    - `pb`: the estimator's problem (meshes, selection of faces).
    - `runs`: the kept run first, then the alternatives.
    - `joint`: score by local times global distortion (``turn_candidates="limbs"``), else by
      the local distortion alone.
    - `turn`: the indices of the whole turn's maps in ``runs``.
    """
    maps = np.stack([r.p2p for r in runs]).astype(np.int64)
    local = est._distortion(pb, maps, est.turn_samples, est.turn_radius)
    if local is None:
        return None
    orient = _agreements(pb.source_mesh, pb.target_mesh, maps, pb.faces)
    score = local * est._distortion(pb, maps) if joint else local
    pick = choose_map(score, orient, slack=est.orientation_slack)
    return pick, measures_disagree(est, score, orient, pick, turn), orient


def check_turn(est, pb, run, quality: dict, source_given: Spectrum,
               source_symmetry) -> tuple:
    """Phase 4 of ``est`` (a [`MapEstimator`][bsfjax.MapEstimator]): the alternatives of
    ``run`` with left and right swapped, one kept if preferred; ``(run, quality)``."""
    if turn_step(est) != est.zoomout_step:  # (the maps at turn_step; a swap regrown)
        at = dataclasses.replace(est, zoomout_step=turn_step(est), turn_step=None)
        turned, q = check_turn(at, pb, *at._grow_again(pb, run, quality), source_given,
                               source_symmetry)  # (not swapped: the run as it came)
        return est._grow_again(pb, turned, q) if q.get("swapped") else (run, dict(
            q, distortion=quality["distortion"], orientation=quality["orientation"]))
    joint = est.turn_candidates == "limbs"
    runs, kept_sets, turn = turn_candidates(est, pb, run, quality, source_given,
                                            source_symmetry, joint)
    quality = dict(quality, swapped=False)
    choice = turn_choice(est, pb, runs, joint, turn)
    if choice is None:  # (a target too coarse for the local distortion keeps the map)
        return run, quality
    pick, doubtful, orient = choice
    quality.update(swapped=pick != 0, turn_doubtful=doubtful)
    if pick:
        quality.update(landmarks=kept_sets[pick], orientation=float(orient[pick]),
                       distortion=float(est._distortion(pb, runs[pick].p2p)[0]))
    return runs[pick], quality
