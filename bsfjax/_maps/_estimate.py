"""What one call of [`MapEstimator`][bsfjax.MapEstimator] works on and returns: the
[`MapEstimate`][bsfjax.MapEstimate], the call's problem shared by its phases, and the checks of its
inputs.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from ._coverage import coverage_errors
from ._distortion import _Geodesics, _agreements, choose_map
from ._orientation import orientation_bases
from .._sampling import Subsample
from .._spectral import Spectrum, map_to_unit_area
from .._util import BSFError, check_indices, check_int, check_real

__all__ = ["MapEstimate", "check_landmark_pairs", "check_starts"]


class MapEstimate(NamedTuple):
    """The result of a [`MapEstimator`][bsfjax.MapEstimator] (and of
    [`estimate_map`][bsfjax.estimate_map])."""

    C: np.ndarray  #: ``(k, k)`` functional map source → target
    p2p: np.ndarray  #: ``(n_N,)`` point map, target vertex → source vertex
    C_initial: np.ndarray  #: the descriptor-based map before ZoomOut (``k₀ × k₀``: its start's)
    #: ``(source, target)`` [`Subsample`][bsfjax.Subsample] s ZoomOut ran on (``None``: every
    #: vertex); ``"refined"`` continues on them (``transfer_labels(..., samples=)``)
    samples: tuple | None = None
    #: with several starts (no landmarks), or landmarks and ``derived_guidance`` (phases 3
    #: and 4 after phase 1): the kept map's geodesic distortion
    #: ([`bsfjax.map_distortion`][bsfjax.map_distortion]) and orientation agreement
    #: ([`bsfjax.orientation_agreement`][bsfjax.orientation_agreement]), the start ``(k₀, WKS variance)`` chosen among
    #: them, and the landmark pairs read off its map when the estimate made with them was kept
    #: (with given landmarks and ``added_landmarks``: the pairs read off the first map, beside
    #: the given ones); ``None`` otherwise, with landmarks or a single start
    distortion: float | None = None
    orientation: float | None = None
    start: tuple | None = None
    landmarks: tuple | None = None
    #: with phase 4, the turn check (several starts, or landmarks and ``derived_guidance``):
    #: whether the kept map is the alternative with
    #: left and right swapped (the chosen map was turned front to back); ``None`` otherwise
    swapped: bool | None = None
    #: with the turn check: whether its two measures disagree about which of its two maps is
    #: turned (the local distortion prefers one, the orientation agreement the other, within
    #: the estimator's ``orientation_slack`` of each other).  The kept map is then a guess and
    #: may be turned front to back: give two landmark pairs.  On 120 FAUST / FAUST_5k pairs
    #: without landmarks it was ``True`` on 8, and the kept map was turned on 3 of them (of
    #: the 5 turned maps kept in all) and partly wrong on 2 (docs/results/segmentation.md,
    #: "Without landmarks").  ``None`` without the check, or on a target too coarse for it
    turn_doubtful: bool | None = None
    #: without landmarks on a mesh above the estimator's ``proxy_above`` vertices: the vertex
    #: counts ``(source, target)`` of the proxies the choice among starts ran on (a mesh
    #: below the threshold is its own proxy); ``None`` otherwise
    proxy: tuple | None = None
    #: with several starts (not through proxies): the run the choice among starts kept (phase
    #: 2), from which ``MapEstimator(...)(..., resume=this)`` goes on; internal
    choice: tuple | None = None


class Run(NamedTuple):
    """One estimate: its initial map ``C0``, its point map (``-1`` where not searched), the
    map after ZoomOut it came from, and ZoomOut's ``(landmarks, guide)`` (to grow ``C0``
    again at another step)."""

    C0: object
    p2p: np.ndarray
    C_ref: object
    grown: tuple = (None, 0.0)


@dataclasses.dataclass
class Problem:
    """One call's problem: the unit-area spectra and their meshes, ZoomOut's samples, where
    the candidates are compared (``rows``, ``faces``: `selection_rows`), and what the
    phases share, computed once on first use (the orientation bases, the Dijkstra runs)."""

    source: Spectrum
    target: Spectrum
    source_mesh: object
    target_mesh: object
    refine_to: int
    samples: tuple | None
    rows: np.ndarray | None
    faces: np.ndarray | None
    k_bases: int  # the largest k₀ of the estimates that use the orientation bases
    masses: tuple = ()  # the given spectra's vertex areas (the landmark guidance's units)
    guided_to: int = 0  # the size of the guided ZoomOut (`bsfjax._maps._guide`)
    _bases: object = None
    _geodesics: tuple | None = None

    @property
    def meshes(self) -> bool:
        return self.source_mesh is not None and self.target_mesh is not None

    def bases(self):
        """The pair's orientation bases, one face scan for every estimate that uses them."""
        if self._bases is None:
            self._bases = orientation_bases(self.source, self.target, self.source_mesh,
                                            self.target_mesh, self.k_bases)
        return self._bases

    def geodesics(self) -> tuple:
        """The distortions' shared Dijkstra runs (each vertex of a shape run once)."""
        if self._geodesics is None:
            self._geodesics = (_Geodesics(self.source_mesh), _Geodesics(self.target_mesh))
        return self._geodesics


def to_given(X, am, an) -> np.ndarray:
    """A map of the unit-area bases back in the given bases."""
    X = np.asarray(X)
    return np.asarray(map_to_unit_area(X, am, an, inverse=True), X.dtype)


def check_symmetry(source_symmetry, n_m: int):
    if source_symmetry is None:
        return None
    source_symmetry = np.asarray(source_symmetry)
    if source_symmetry.shape != (n_m,):
        raise BSFError(f"source_symmetry must have one source vertex per source vertex "
                       f"({n_m}), got shape {source_symmetry.shape}")
    return check_indices(source_symmetry, "source_symmetry", n_m, what="source vertex indices")


def check_landmark_pairs(landmarks, n_m: int, n_n: int):
    if landmarks is None:
        return None
    src, tgt = (np.asarray(x) for x in landmarks)
    if src.ndim != 1 or tgt.ndim != 1 or src.shape != tgt.shape or src.size == 0:
        raise BSFError(f"landmarks must be two lists of equal length, got {src.size} source and "
                       f"{tgt.size} target indices")
    return (check_indices(src, "source landmarks", n_m),
            check_indices(tgt, "target landmarks", n_n))


def check_pair_samples(samples, n_m: int, n_n: int) -> tuple:
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


def turn_step(estimator) -> int:
    """ZoomOut's step in the maps of ``estimator``'s turn check (the kept map, the turned
    ones, the source's mirror symmetry): ``turn_step``, by default ``zoomout_step``."""
    return estimator.zoomout_step if estimator.turn_step is None else estimator.turn_step


def choose_start(estimator, pb: Problem, starts: tuple, runs: list, distortion) -> tuple:
    """Phase 2 of ``estimator``: the run of ``runs`` (one per start of ``starts``)
    [`choose_map`][bsfjax.choose_map] keeps, with the coverage errors where
    ``choice_coverage`` says so, and its quality; ``distortion(pb, maps)`` the distortions."""
    maps = np.stack([r.p2p for r in runs])
    orient = _agreements(pb.source_mesh, pb.target_mesh, maps, pb.faces)
    # choose_map picks among the maps within its slack of the best orientation: only their
    # distortions (coverages) are needed (fewer Dijkstra sources, the same choice)
    near = np.flatnonzero(orient >= orient.max() - estimator.orientation_slack)
    dist = distortion(pb, maps[near])
    cover = None
    if estimator.choice_coverage:  # (the spectra's masses: a cloud's from its Laplacian)
        cover = coverage_errors(pb.source_mesh, maps[near], pb.target.mass, pb.source.mass)
    pick = choose_map(dist, orient[near], slack=estimator.orientation_slack, coverage=cover)
    best = int(near[pick])
    return runs[best], dict(start=starts[best], distortion=float(dist[pick]),
                            orientation=float(orient[best]))


#: With given landmarks, phase 3 keeps its guided estimate when its distortion is within this
#: share of the least (and its orientation within the slack of the best).  On a target that
#: misses parts the distortion is also measured across the stumps and the closed holes: on the
#: 9 cut FAUST targets of docs/results/scans.md the guided estimate was within 0–3 % of the
#: least distortion on 8, where it labelled best or within 0.33 points of the best, and 24 %
#: above it on the ninth, where it labelled 4 points worse; by the least distortion alone,
#: 002→012's mirror cut kept the landmarks' map (93.42 % against 95.10 %).
GUIDED_SLACK = 0.05


def choose_derived(estimator, run, quality: dict, found: list, dist: list, orient: list,
                   trust: bool, prefer: int | None = None) -> tuple:
    """Phase 3's choice of ``estimator`` between the kept ``run`` (its ``quality``) and the
    estimates ``found`` (``[(pairs, run), ...]``) made with the landmark pairs read off it;
    ``dist``, ``orient``: the kept run's and theirs.  [`choose_map`][bsfjax.choose_map]
    decides; with ``trust`` (``keep_derived``) the first derived estimate whose orientation
    is within the slack of the best is kept instead; ``prefer``: the index in ``dist`` of an
    estimate kept whenever its orientation is within the slack and its distortion within
    `GUIDED_SLACK` of the least.  Returns ``(run, quality, trusted)``, ``trusted`` whether
    ``trust`` changed the pick."""
    pick = choose_map(dist, orient, slack=estimator.orientation_slack)
    if (prefer is not None and orient[prefer] >= max(orient) - estimator.orientation_slack
            and dist[prefer] <= (1 + GUIDED_SLACK) * min(dist)):
        pick = prefer
    trusted = False
    if trust and pick == 0:
        near = [i for i in range(1, len(dist))
                if orient[i] >= max(orient) - estimator.orientation_slack]
        if near:
            pick, trusted = near[0], True
    if pick == 0:
        return run, quality, False
    return found[pick - 1][1], dict(quality, landmarks=found[pick - 1][0],
                                    distortion=dist[pick], orientation=orient[pick]), trusted


def mesh_key(mesh) -> tuple:
    """A mesh's identity for `choice_key`: its sizes and a digest of its vertices and faces
    (a mesh re-read or rebuilt from the same file has the same key)."""
    import hashlib

    digest = hashlib.blake2b(digest_size=16)
    faces = getattr(mesh, "faces", None)
    for a in (np.asarray(mesh.vertices, np.float64),
              np.zeros((0, 3), np.int64) if faces is None else np.asarray(faces, np.int64)):
        digest.update(np.ascontiguousarray(a).tobytes())
    return (mesh.n_vertices, 0 if faces is None else len(faces), digest.hexdigest())


def choice_key(estimator, starts: tuple, refine_to: int, source: Spectrum,
               target: Spectrum, meshes: tuple = ()) -> tuple:
    """What phases 1 and 2 of ``estimator`` depend on: its options for them, the starts, the
    sizes, the spectra's sizes and first eigenvalues, and the ``meshes`` (`mesh_key`)."""
    e = estimator
    return (starts, refine_to, e.n_energies, e.wks_variance, e.zoomout_samples,
            e.zoomout_step, e.orient_weight, e.orientation_slack, e.choice_coverage,
            e.distortion_samples,
            e.fit_scale, e.selection_vertices, e.selection_faces, source.n_vertices,
            target.n_vertices,
            tuple(np.round(np.asarray(source.evals[:4], np.float64), 10)),
            tuple(np.round(np.asarray(target.evals[:4], np.float64), 10)),
            tuple(mesh_key(m) for m in meshes))


def resumed_choice(resume, key: tuple):
    """The ``(run, quality)`` of phase 2 kept in ``resume`` (a `MapEstimate`), checked
    against this call's ``key`` (`choice_key`)."""
    choice = getattr(resume, "choice", None)
    if not isinstance(resume, MapEstimate) or choice is None:
        raise BSFError("resume must be a MapEstimate made from several starts (without "
                       "landmarks, with the meshes; not through proxies)")
    if choice[0] != key:
        raise BSFError("resume: that estimate was made with other spectra, meshes, starts or "
                       "options than this call's (only derived_guidance, derived_landmarks, "
                       "keep_derived and the turn check may differ)")
    return choice[1], dict(choice[2])
