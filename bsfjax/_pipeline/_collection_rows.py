"""The arguments and results of [`bsfjax.transfer_collection`][bsfjax.transfer_collection] around its stages: its estimator, its landmarks, its result per target, and the rows of the files.

With ``file_rows=True`` the collection reads the source's values and the landmarks as rows of
the mesh files and numbers every result by the rows of its target's file
([`Mesh.to_file_rows`][bsfjax.Mesh.to_file_rows]): the readers drop unreferenced vertices and
zero-area triangles, and a user's files must not shift by them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .._maps import MapEstimator, check_landmark_pairs, turn_mirror_size
from .._mesh import MainBody, Mesh, vertex_areas
from .._metrics import missing_labels
from .._util import BSFError

_DEFAULT = MapEstimator()


class TargetTransfer(NamedTuple):
    """The result for one target of [`transfer_collection`][bsfjax.transfer_collection]."""

    labels: np.ndarray | None  #: ``(n_N,)`` int labels (−1 unassigned), or ``None`` for values
    values: np.ndarray  #: ``(m, n_N)`` transferred functions (for labels: the label scores)
    p2p: np.ndarray  #: ``(n_N,)`` the estimated point map (target vertex → source vertex)
    C: np.ndarray  #: ``(k, k)`` the estimated functional map
    map_energy: float  #: the estimation energy E(C) of [`bsfjax.estimate_fmap`][bsfjax.estimate_fmap] at ``C``
    unassigned_share: float  #: area share of the target left unassigned (labels)
    agreement: float | None  #: area share equal to the pull-back through ``p2p`` (labels)
    #: area-weighted mean winning score (labels; ``None`` for labels of triangles)
    confidence: float | None
    regime: str | None  #: ``"refined"`` only: see [`bsfjax.REGIMES`][bsfjax.REGIMES]
    n_vertices: int
    mass: np.ndarray  #: ``(n_N,)`` vertex areas of the target (relative: for area shares)
    #: this target's host work (reading, eigensolve) plus its share of the time its group's
    #: stages were dispatched and awaited (they run while the next target's eigensolve does)
    seconds: float
    #: without landmarks, from several starts: ``MapEstimate.turn_doubtful`` of its map (the
    #: map may be turned front to back); ``None`` otherwise
    turn_doubtful: bool | None = None
    #: the target [`Mesh`][bsfjax.Mesh] as read: ``mesh.to_file_rows(labels)`` numbers a result
    #: by the rows of its file (what ``file_rows=True`` returns)
    mesh: Mesh | None = None
    #: the target's split ([`bsfjax.split_main_body`][bsfjax.split_main_body]): its main body
    #: was matched, its other components labelled from the nearest surface
    main_body: MainBody | None = None
    #: the Taubin iterations of [`bsfjax.denoise`][bsfjax.denoise] on this target (0: none)
    denoise_iterations: int = 0
    #: labels: the source labels with no counterpart on this target (a partial target; see
    #: [`bsfjax.missing_labels`][bsfjax.missing_labels]), in increasing order
    missing: tuple = ()
    #: the vertices its hole patches added for the spectrum (dropped from every result)
    filled_vertices: int = 0
    #: labels: the first map's labels missed source parts (``missing`` non-empty), so this
    #: map was estimated again with ``derived_guidance`` (a partial target;
    #: ``transfer_collection``'s ``estimate_again``); ``missing`` is then the second's
    estimated_again: bool = False


def collection_estimator(estimator, k: int, k_map: int, n_energies, zoomout_samples,
                         starts) -> MapEstimator:
    """The collection's [`MapEstimator`][bsfjax.MapEstimator] at ``k`` and ZoomOut to ``k_map``
    (`transfer_collection`'s ``estimator`` argument)."""
    if estimator is None:
        return MapEstimator(k=k, refine_to=k_map, n_energies=n_energies,
                            zoomout_samples=zoomout_samples, starts=starts)
    if not isinstance(estimator, MapEstimator):
        raise BSFError(f"estimator must be a bsfjax.MapEstimator, got "
                       f"{type(estimator).__name__}")
    if (n_energies, zoomout_samples, starts) != (_DEFAULT.n_energies,
                                                 _DEFAULT.zoomout_samples, _DEFAULT.starts):
        raise BSFError("with an estimator, give n_energies, zoomout_samples and starts as its "
                       "fields")
    return dataclasses.replace(estimator, k=k, refine_to=k_map)


class SourceSymmetry:
    """The source's mirror symmetry for the estimators' turn check, computed once per size:
    that of the estimator's own check (`bsfjax._maps._guide.turn_mirror_size`)."""

    def __init__(self, spectrum, mesh, samples):
        self.spectrum, self.mesh, self.samples, self.by_size = spectrum, mesh, samples, {}

    def __call__(self, est: MapEstimator):
        size = turn_mirror_size(est, est.refine_to, est.guided_to)
        if size not in self.by_size:
            self.by_size[size] = dataclasses.replace(est, refine_to=size).mirror_symmetry(
                self.spectrum, self.mesh, samples=self.samples)
        return self.by_size[size]


def landmark_lookup(landmarks, source: Mesh,
                    file_rows: bool) -> Callable[[int, Mesh], tuple | None]:
    """``(index, target mesh) →`` the checked landmark pair of target ``index`` (vertex
    indices of ``source`` and of the target), or ``None``; with ``file_rows`` the given
    indices are rows of the two files, mapped onto the vertices their readers kept."""
    if landmarks is None:
        given = lambda i: None  # noqa: E731
    elif callable(landmarks):
        given = landmarks
    else:
        seq = list(landmarks)
        given = lambda i: seq[i] if i < len(seq) else None  # noqa: E731

    def lookup(i: int, mesh: Mesh):
        if not file_rows:
            return check_landmark_pairs(given(i), source.n_vertices, mesh.n_vertices)
        lm = check_landmark_pairs(given(i), source.n_file_rows, mesh.n_file_rows)
        if lm is None:
            return None
        return (source.file_row_index(lm[0], "source landmarks"),
                mesh.file_row_index(lm[1], f"target landmarks of {mesh.name or f'target {i}'}"))

    return lookup


def source_values(source: Mesh, values, faces: bool, labels: bool, file_rows: bool):
    """The collection's ``values`` on the source's vertices (triangles): with ``file_rows``
    given per row of its file (labels ``(n,)``, functions ``(m, n)``)."""
    vals = np.asarray(values)
    if not file_rows:
        return vals
    if vals.ndim == 0 or vals.shape[-1] != (source.n_file_faces if faces else source.n_file_rows):
        what = "triangle" if faces else "row"
        raise BSFError(f"values must have one entry per {what} of the source's file "
                       f"({source.n_file_faces if faces else source.n_file_rows}), got shape "
                       f"{vals.shape}")
    return np.moveaxis(source.from_file_rows(np.moveaxis(vals, -1, 0), faces=faces), 0, -1)


def file_row_results(res, source: Mesh, faces: bool):
    """A [`TargetTransfer`][bsfjax.TargetTransfer] numbered by the rows of its target's file:
    ``-1`` labels and point-map entries, NaN values and zero mass on the rows without a vertex
    (triangle), the point map's entries as rows of the source's file."""
    mesh = res.mesh
    rows_m = source.vertex_ids if source.vertex_ids is not None else np.arange(source.n_vertices)
    labels = None if res.labels is None else mesh.to_file_rows(res.labels, faces=faces)
    p2p = np.where(res.p2p >= 0, rows_m[res.p2p], -1)  # (-1: a fragment far from the body)
    return res._replace(labels=labels, values=mesh.to_file_rows(res.values.T).T,
                        p2p=mesh.to_file_rows(p2p),
                        mass=mesh.to_file_rows(res.mass, 0.0))


def on_body(parts: MainBody, vals: np.ndarray, faces: bool) -> np.ndarray:
    """The source's values (last axis: its vertices or triangles) on its main body."""
    if not parts.n_other_components:
        return vals
    return vals[..., parts.faces if faces else parts.vertices]


def whole_result(res, parts: MainBody, src_parts: MainBody, faces: bool):
    """A [`TargetTransfer`][bsfjax.TargetTransfer] of a target's main body on the whole target
    and numbered by the whole source's vertices: the other components' vertices (triangles)
    take the labels, values and point map of the nearest main-body vertex (triangle) within
    ``parts.reach``, else ``-1`` / NaN; their mass is their barycentric area (at the scale of
    the main body's)."""
    p2p = res.p2p if not src_parts.n_other_components else src_parts.vertices[res.p2p]
    if not parts.n_other_components:
        return res._replace(p2p=p2p)
    whole = parts.whole
    mass = parts.to_whole(res.mass)
    scale = float(np.sum(res.mass)) / parts.mesh.area
    mass[parts.other] = vertex_areas(whole)[parts.other] * scale
    labels = None if res.labels is None else parts.to_whole(res.labels, faces=faces)
    return res._replace(labels=labels, values=parts.to_whole(res.values.T).T,
                        p2p=parts.to_whole(p2p), mass=mass, n_vertices=whole.n_vertices,
                        mesh=whole, main_body=parts)


def body_result(res, fill, src_prep, faces: bool):
    """A [`TargetTransfer`][bsfjax.TargetTransfer] on a target's filled mesh on its body (the
    main body as read): the hole patches' vertices (triangles) dropped, its point map's
    entries on the source's patches replaced by their nearest original source vertex, and its
    mass the body's vertex areas (at the scale of the spectrum's)."""
    p2p = np.asarray(res.p2p)
    if src_prep.n_added:  # (a source vertex of a patch: its nearest original one)
        n0 = src_prep.body.n_vertices
        p2p = np.where(p2p >= n0, src_prep.fill.nearest[np.maximum(p2p - n0, 0)], p2p)
    if fill is None:
        return res._replace(p2p=p2p)
    body = fill.original
    mass = vertex_areas(body) * (float(np.sum(res.mass)) / fill.mesh.area)
    labels = None if res.labels is None else fill.restrict(res.labels, faces=faces)
    return res._replace(labels=labels, values=fill.restrict(res.values.T).T,
                        p2p=fill.restrict(p2p), mass=mass, n_vertices=body.n_vertices,
                        filled_vertices=fill.n_added)


def missing_parts(res, source_labels, source_body: Mesh, faces: bool) -> tuple:
    """The source labels with no counterpart on a target ([`missing_labels`][bsfjax.missing_labels]):
    the source's on its body (its own areas), the target's on the target as read."""
    area_m = source_body.face_areas() if faces else vertex_areas(source_body)
    area_n = res.mesh.face_areas() if faces else res.mass
    return tuple(int(i) for i in missing_labels(source_labels, area_m, res.labels, area_n))


__all__ = ["body_result", "collection_estimator", "missing_parts", "file_row_results", "landmark_lookup", "on_body",
           "source_values", "whole_result"]
