r"""One segmentation (or function) to a whole collection of targets, in batches.

For one source ``M`` and targets ``N₁ … N_T`` this does what [`bsfjax.estimate_map`][bsfjax.estimate_map]
followed by [`bsfjax.transfer_labels`][bsfjax.transfer_labels] does for each pair — WKS descriptors (and landmark
WKS), the functional map of [`bsfjax.estimate_fmap`][bsfjax.estimate_fmap] (orientation term without
landmarks), ZoomOut, its point map, and the method's transfer through the one engine
(``method.prepare`` / ``carry``) — but with the source prepared once and the targets run
through **three jitted stages** per group of equal shapes (the estimation problem, the map,
the transfer; `bsfjax._pipeline._stages`).  A target **without landmarks** gets
[`bsfjax.estimate_map`][bsfjax.estimate_map]'s own point map, computed on the host with the target's other host
work: its choice among several starts by geodesic distortion and orientation is Dijkstra and
numpy, not a jitted stage; the problem stage (for the map's energy) and the transfer stage then
run on it as for any other target; so does one with landmarks estimated again (phases 3
and 4 after the landmarks' map).  With the single start ``starts=((k, wks_variance),)``
(``bsfjax transfer --one-start``) such a target runs through the three stages like the others.

- **size buckets**: a target of ``n`` vertices (``m`` faces) is padded to the bucket size
  ``size_bucket(n)`` (``size_bucket(m)``): extra vertices have zero mass and zero eigenvector
  rows, extra faces zero area.  Every stage weighs vertices by mass or uses the target's
  vertices only as queries, so the padded target gives the unpadded results (tested); the
  stages that touch every vertex compile once per bucket, not once per vertex count, and the
  map stage (the ``k × k`` solve and ZoomOut on the subsamples) once for all buckets.  In a
  small collection a bucket with few targets joins a larger one when that costs less padding
  than a compilation (`merge_buckets`): six 3.4K–6.9K-vertex targets
  compile once, not three times.
- **devices and batches**: a group of targets is split over this process's JAX devices, each
  running its slice at the same time, ``batch`` targets per device under ``vmap`` (one
  target per device by default: a CPU gains nothing from batching);
- **processes**: under ``jax.distributed`` target ``i`` belongs to the process owning global
  device ``i mod D``, so the processes share the targets without any communication, and a
  target's result does not depend on which process or batch computed it.

The eigensolve of each target stays on the host (scipy), as in the single-pair path, and runs
while the group dispatched before it computes.  On a CPU the two share the cores: the stages'
BLAS calls run on one thread (`bsfjax._util._threads`), as does the eigensolve of a target below
``ONE_THREAD_BELOW`` vertices (a larger one waits for the group).  Eight 5K targets:
0.47–0.52 s per target against 0.62–0.67 s one after the other (docs/benchmarks.md).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable, Iterator, Sequence
from typing import NamedTuple

import jax
import numpy as np

from .._util import BUCKET_FACTORS, BSFError, merge_buckets, size_bucket
from ._arrays import cast_tree, item_arrays
from ._stages import StageConfig, capped_batch, dispatch_stages, stages_for
from ._mesh_level import _decide_labels, _split_label_kwargs
from .._maps import (REFINE_EIGENPAIRS, MapEstimate, MapEstimator, check_starts, default_chunk,
                     estimate_size, estimates_again, face_geometry, follows_landmarks,
                     for_point_clouds, guidable, landmark_geodesics, with_read_pairs)
from ._face_labels import decide_face_labels, face_label_shares
from ._collection_rows import (SourceSymmetry, TargetTransfer, body_result, collection_estimator,
                               file_row_results, landmark_lookup, missing_parts, on_body,
                               source_values, whole_result)
from .._metrics import labels_to_indicators
from .._mesh import (HoleFill, MainBody, Mesh, as_mesh, as_strength, is_mesh_like, load_mesh,
                     prepare_scan, surface_for_map)
from .._transfer import (BSF, GeodesicBalls, SaturatedHeat, as_method, method_for_shapes,
                         method_name)
from .._sampling import Subsample, subsample
from .._spectral import Spectrum, map_to_unit_area, spectrum, unit_area, unit_area_pair
from .._util import eigensolve_on_one_thread, one_blas_thread
from .._util import check_int, compact_labels

__all__ = ["transfer_collection", "TargetTransfer", "size_bucket", "BUCKET_FACTORS"]

_DEFAULT = MapEstimator()
#: Collections of at most this many targets are read once ahead for their sizes,
#: so that buckets with few targets merge into larger ones (`merge_buckets`).
_SCAN_LIMIT = 64
#: Meshes the scan keeps for the run (bytes of vertex and face arrays): one read of each
#: target instead of two (a FAUST-sized OFF file takes 10–50 ms to read and check).
_KEEP_BYTES = 256 * 2 ** 20


# --------------------------------------------------------------------------- host side


class _Target(NamedTuple):
    index: int
    mesh: Mesh
    spectrum: Spectrum  # unit-area-pair scaled, float64
    factors: tuple  # (a_M, a_N) of bsfjax.unit_area_pair: C back to the given bases
    landmarks: tuple | None
    samples: Subsample | None  # ZoomOut's
    seconds: float
    p2p: np.ndarray | None = None  # without landmarks: the estimator's, chosen among starts
    turn_doubtful: bool | None = None  # and its MapEstimate.turn_doubtful
    parts: MainBody | None = None  # the whole target: `mesh` is its (denoised) main body
    denoised: int = 0  # the Taubin iterations run on the main body
    fill: HoleFill | None = None  # the holes closed for its spectrum (`mesh` has them)
    guide: tuple | None = None  # with landmarks: ZoomOut's guidance (landmark_geodesics)
    again: bool = False  # this is a second estimate (estimates_again)
    may: bool = False  # it may get a second estimate (estimates_again)
    first: MapEstimate | None = None  # its first estimate from several starts, to resume
    step: int = 2  # ZoomOut's eigenpairs per iteration (for_point_clouds: more on a cloud)
    method: object = None  # its transfer's (method_for_shapes: a cloud's options)


def _as_mesh(target) -> Mesh:
    if isinstance(target, Mesh):
        return target
    return as_mesh(target) if is_mesh_like(target) else load_mesh(target)


def _merged_sizes(targets: list, lm_of, keep: dict[int, Mesh] | None = None,
                  mine: Iterable[int] = ()) -> dict[int, tuple[int, int]]:
    """The padded (vertex, face) counts of each target of a small collection after
    `merge_buckets` (within each landmark count): its targets are read once ahead for
    their sizes.  Empty for more than `_SCAN_LIMIT` targets (each bucket then holds
    enough of them to be worth its compilation).  A target that cannot be read, or whose
    landmarks are invalid, is skipped here; the run reports it.  Every process scans the
    whole collection: a target's padding (and so its result, to the last bit of a float
    reduction) must not depend on how the processes share it.  ``keep``: filled with the meshes
    of this process's targets (``mine``) read here from files, up to `_KEEP_BYTES` of
    them, so that the run does not read them again."""
    if len(targets) > _SCAN_LIMIT:
        return {}
    seen = {}
    kept = 0
    mine = set(mine)
    for i, target in enumerate(targets):
        try:
            mesh = _as_mesh(target)
            lm = lm_of(i, mesh)
        except (BSFError, ValueError, OSError):
            continue
        size = mesh.vertices.nbytes + mesh.faces.nbytes
        if keep is not None and i in mine and mesh is not target and kept + size <= _KEEP_BYTES:
            keep[i] = mesh
            kept += size
        seen[i] = (0 if lm is None else len(lm[0]), size_bucket(mesh.n_vertices),
                   size_bucket(mesh.n_faces))
    out = {}
    for p in {v[0] for v in seen.values()}:
        group = {i: v for i, v in seen.items() if v[0] == p}
        into = merge_buckets([v[1] for v in group.values()])
        faces: dict[int, int] = {}
        for _, n_b, m_b in group.values():
            faces[into[n_b]] = max(faces.get(into[n_b], 0), m_b)
        out.update({i: (into[n_b], faces[into[n_b]]) for i, (_, n_b, _) in group.items()})
    return out


def _bucket_key(t: _Target, pad: bool, orient: bool, n_samples: int | None,
                merged: dict[int, tuple[int, int]]):
    n, m = t.mesh.n_vertices, t.mesh.n_faces
    n_b, m_b = merged.get(t.index, (size_bucket(n), size_bucket(m))) if pad else (n, m)
    if pad and m > m_b:  # a cloud's stand-in surface: its triangles are made after the scan
        m_b = size_bucket(m)
    m_b = m_b if orient else 0
    s_b = 0 if n_samples is None else min(n_samples, n_b)
    return n_b, m_b, 0 if t.landmarks is None else len(t.landmarks[0]), s_b


def process_share(indices: Sequence[int]) -> list[int]:
    """The targets of this process: target ``i`` goes to global device ``i mod D``."""
    devices = jax.devices()
    me = jax.process_index()
    return [i for j, i in enumerate(indices) if devices[j % len(devices)].process_index == me]


def transfer_collection(source: Mesh | str, values, targets: Iterable, *, labels: bool = True,
                        method="refined", k: int = 30, landmarks=None,
                        threshold: float | None = None, pad: bool = True,
                        n_energies: int = _DEFAULT.n_energies, n_bsf: float | int = 0.05,
                        seed: int = 0, zoomout_samples: int | None = _DEFAULT.zoomout_samples,
                        spectrum_cache: str | None = None,
                        errors: str = "raise", batch: int = 1, starts=None,
                        faces: bool = False, file_rows: bool = False,
                        estimator: MapEstimator | None = None,
                        denoise: bool | int | str = True,
                        estimate_again: bool = True) -> Iterator[tuple[int, TargetTransfer | Exception]]:
    """Transfer one segmentation (or functions) from ``source`` to every mesh of ``targets``.

    Yields ``(index, result)`` as batches finish (grouped by size bucket, so not in order);
    ``dict(transfer_collection(...))`` collects them.  Each result equals, up to float
    round-off, [`bsfjax.estimate_map`][bsfjax.estimate_map] (``k``, ZoomOut to ``2k``; with landmarks, guided by
    them to the spectra's size) followed by [`bsfjax.transfer_labels`][bsfjax.transfer_labels] with ``method``, as
    ``bsfjax transfer`` runs them.

    **Arguments:**

    - `source`: the source [`Mesh`][bsfjax.Mesh] or its file.
    - `values`: ``(n_M,)`` int labels (``labels=True``) or ``(m, n_M)`` functions.
    - `faces`: ``values`` are ``(m_M,)`` labels of the source's triangles, carried as
      [`bsfjax.transfer_face_labels`][bsfjax.transfer_face_labels] does (each label's share of the vertices' stars);
      each result's ``labels`` are then per target triangle, its ``unassigned_share`` and
      ``agreement`` weighted by triangle area (``confidence`` ``None``), its ``values`` the
      transferred shares at the vertices.
    - `targets`: meshes or mesh files (loaded one at a time; a collection may be larger than
      memory).
    - `method`: as [`bsfjax.transfer_labels`][bsfjax.transfer_labels] (default ``"refined"``; the spectra then
      have 100 eigenpairs, else ``2k``); ``"std2"`` is not supported here.
    - `landmarks`: ``None``, or a callable ``index → (source indices, target indices) or
      None``, or a sequence with one such entry per target.
    - `file_rows`: ``values``, ``landmarks`` and the results are numbered by the rows of the
      source's and targets' files (as ``bsfjax transfer --out-dir`` reads and writes them), not
      by the vertices their readers kept ([`Mesh.to_file_rows`][bsfjax.Mesh.to_file_rows]): a
      result's ``labels``, ``values``, ``p2p`` (source file rows) and ``mass`` have one entry
      per row of the target's file, ``-1`` / NaN / ``-1`` / ``0`` on its rows without a vertex;
      a landmark on such a row is an error naming the row.
    - `threshold`: as [`bsfjax.transfer_labels`][bsfjax.transfer_labels].
    - `zoomout_samples`: as [`bsfjax.estimate_map`][bsfjax.estimate_map] (ZoomOut on this many
      farthest-point samples per shape; ``None``: every vertex).
    - `starts`: as [`bsfjax.estimate_map`][bsfjax.estimate_map], for the targets without landmarks: by
      default its several starts, each target's map then estimated by
      [`bsfjax.estimate_map`][bsfjax.estimate_map] on the host with its turn check (accurate, about 7 s for a
      FAUST-sized target on two cores, compiled per vertex count; the source's
      [`bsfjax.mirror_symmetry`][bsfjax.mirror_symmetry] once for all); ``((k, wks_variance),)``, a single start,
      runs them through the batched stages with the others (about 17× faster, and less
      accurate: docs/results/segmentation.md, "Without landmarks").
    - `estimator`: the [`MapEstimator`][bsfjax.MapEstimator] of the maps (default: one with
      ``n_energies``, ``zoomout_samples`` and ``starts`` above, its other fields at their
      defaults); its ``k`` and ``refine_to`` are replaced by ``k`` and ``2k``.  Given, it
      holds ``n_energies``, ``zoomout_samples`` and ``starts``: leave those arguments out.
      The batched stages follow its ``wks_variance``, ``orient_weight`` and
      ``zoomout_step`` (at least 6 on a point cloud: `bsfjax._maps.for_point_clouds`), the
      targets without landmarks (several starts) all of it.
    - `denoise`: ``True`` (default) computes the source's and every target's spectrum, map
      and transfer on [`bsfjax.denoise`][bsfjax.denoise]'s geometry with the strength chosen
      from each mesh (none on a clean mesh); the labels are on the original vertices, and
      each result's ``denoise_iterations`` and ``mesh`` (as read) say what was done.
      ``False``: the meshes as given; an integer: that many Taubin iterations on every mesh.
    - `estimate_again`: labels, two triangle meshes (without landmarks: several starts;
      with them, phases 3 and 4 after their map): a target whose labels miss source parts
      (``missing``: a partial target, whose first map may have slid a limb into the missing
      part) has its map estimated again with the estimator's ``derived_guidance`` on, as
      ``bsfjax transfer`` does, and yields that result (``estimated_again``; ``True``,
      default).  ``False``: one estimate each (an estimator with ``derived_guidance`` runs
      it on every target from the start).
    - `pad`: pad vertex and face counts to `size_bucket` sizes, merged for a
      collection of at most 64 targets (module doc; ``False``: one compilation per distinct
      count).
    - `spectrum_cache`: folder for the spectra (see [`bsfjax.spectrum`][bsfjax.spectrum]).
    - `errors`: ``"raise"``, or ``"report"``: a target that cannot be read or solved yields
      its exception and the others go on.
    - `batch`: targets per device and dispatch, run as one program batched under
      `jax.vmap` (a group of the same size bucket; a short group is filled with copies of
      its last target, so results do not depend on the grouping: equal to ``batch=1`` up to
      float round-off, the same point maps and labels on the tested targets).  On a CPU this
      changes nothing (two 5K targets: 0.76 s batched against 0.77 s one after the other, as
      XLA CPU already uses every core for one target); it is for accelerators, where one
      target does not fill the device.  Memory grows with ``batch`` (up to the targets per device).

    Under ``jax.distributed`` each process yields only its own share of the targets (target
    ``i`` belongs to the process that owns global device ``i mod D``).
    """

    if errors not in ("raise", "report"):
        raise BSFError(f"errors must be 'raise' or 'report', got {errors!r}")
    check_int(batch, "batch", 1)
    named, method = method, as_method(method)  # (named: method_for_shapes adapts "refined")
    if method_name(method) == "std2":
        raise BSFError("method 'std2' needs a 2k x 2k map: not supported by transfer_collection")
    capped_batch(batch, check_int(k, "k", 2))  # (the dense systems: before any work)
    strength = as_strength(denoise)
    src_prep = prepare_scan(_as_mesh(source), strength)  # a scan in pieces: its main body,
    src_parts, source = src_prep.parts, src_prep.mesh    # smoothed when noisy, is matched
    vals = on_body(src_parts, source_values(src_parts.whole, values, faces, labels, file_rows),
                   faces)
    body_vals = vals  # (on the source's body; `vals`: also on its hole patches, if any)
    vals = np.moveaxis(src_prep.extend(np.moveaxis(np.asarray(vals), -1, 0), faces=faces), 0, -1)
    n_m = source.n_vertices
    if faces:
        if not labels:
            raise BSFError("faces=True carries labels of triangles: labels must be True")
        shares = face_label_shares(source, vals)
        ids, F = shares.ids, shares.shares
    elif labels:
        if vals.shape != (n_m,):
            raise BSFError(f"labels must have one entry per source vertex ({n_m}), got shape "
                           f"{vals.shape}")
        ids, codes = compact_labels(vals)
        F = np.asarray(labels_to_indicators(codes, len(ids)), np.float64)
    else:
        F = np.asarray(vals, np.float64)
        F = F[None] if F.ndim == 1 else F
        if F.ndim != 2 or F.shape[1] != n_m or not np.all(np.isfinite(F)):
            raise BSFError(f"values must be finite, of shape (n_source,) or (m, n_source) with "
                           f"n_source = {n_m}, got {vals.shape}")
    _, _, threshold, refined = _split_label_kwargs(method, threshold, {})
    k_map = 2 * k
    estimator = collection_estimator(estimator, k, k_map, n_energies, zoomout_samples, starts)
    n_energies, zoomout_samples = estimator.n_energies, estimator.zoomout_samples
    k_spec = max(k_map, REFINE_EIGENPAIRS) if getattr(method, "full_spectra", False) else k_map
    if k_spec >= n_m:
        raise BSFError(f"the source has {n_m} vertices: too few for {k_spec} eigenpairs")
    src_spec = spectrum(source, k_spec, cache_dir=spectrum_cache)
    src_unit, a0 = unit_area(src_spec)
    rep = {"evals": np.asarray(src_unit.evals), "evecs": np.asarray(src_unit.evecs),
           "mass": np.asarray(src_unit.mass), "F": F}
    # a point cloud's stand-in surface for the orientation term and the choice among starts
    src_geometry = surface_for_map(source)
    geom_src = face_geometry(src_geometry)
    rep_orient = {"faces": geom_src.faces, "K": geom_src.K, "third_area": geom_src.third_area}
    if isinstance(method, (BSF, GeodesicBalls, SaturatedHeat)):
        from .._sampling import farthest_point_sampling

        rep["centers"] = np.asarray(farthest_point_sampling(source, n_bsf, seed=seed))
        if isinstance(method, GeodesicBalls):
            from .._sampling import geodesic_distances

            rep["distances"] = np.asarray(geodesic_distances(source, rep["centers"]),
                                          np.float64) / np.sqrt(a0)
    chunk = default_chunk(n_m)
    zo_chunk = sub_m = None
    if zoomout_samples is not None:
        check_int(zoomout_samples, "zoomout_samples", 1)
        sub_m = subsample(source, zoomout_samples)
        rep["zo_indices"] = sub_m.indices
        rep["zo_cells"] = sub_m.cells
        zo_chunk = default_chunk(sub_m.indices.size)
    lm_of = landmark_lookup(landmarks, src_parts.whole, file_rows)  # (of the whole meshes)
    # one start, the batched stages' own: (k, wks_variance) with the orientation term
    single = (k, estimator.wks_variance)
    one_start = check_starts(estimator.starts, k_map, (single,),
                             estimator.landmark_free_starts) == (single,)
    pending: dict[tuple, list[_Target]] = {}
    source_symmetry = SourceSymmetry(src_spec, src_geometry, sub_m)  # (once per size)

    def prepare(i, mesh: Mesh, t: float, estimator: MapEstimator, again: bool) -> _Target:
        """Target ``i``'s host work (``t``: when its reading began; ``again``: its second
        estimate)."""
        lm, prep = lm_of(i, mesh), prepare_scan(mesh, strength)  # matched: the main body alone
        parts, mesh, n_it = prep.parts, prep.mesh, prep.denoise_iterations
        lm = None if lm is None else (src_parts.index(lm[0], "source landmarks"),
                                      parts.index(lm[1], "target landmarks"))
        if mesh.n_vertices <= k_spec:
            raise BSFError(f"{mesh.name or f'target {i}'}: {mesh.n_vertices} vertices, too few "
                           f"for {k_spec} eigenpairs")
        if faces and mesh.is_point_cloud:
            raise BSFError(f"{mesh.name or f'target {i}'}: per-triangle labels need a triangle "
                           "target; a point cloud has none")
        spec = spectrum(mesh, k_spec, cache_dir=spectrum_cache)
        this = for_point_clouds(estimator, source, mesh)  # (a point cloud: unguided, step 6)
        may = estimates_again(estimator, lm, source, mesh, k_map)  # (before the stand-in)
        if lm is None:  # (the orientation term's triangles: a point cloud's stand-in surface)
            mesh = surface_for_map(mesh)
        _, am, scaled, an = unit_area_pair(src_spec, spec)  # at the source's unit area
        sub = None if zoomout_samples is None else subsample(mesh, zoomout_samples)
        if lm is not None and this.added_landmarks:  # (a cloud: more pairs, read off a map)
            first = dataclasses.replace(this, added_landmarks=0)(
                src_spec, spec, lm, source_mesh=src_geometry, target_mesh=mesh,
                samples=None if sub is None else (sub_m, sub))
            lm = with_read_pairs(lm, src_geometry, first.p2p, this.added_landmarks)[0]
        est = None  # the estimator's own map: its choice among starts, or its phases 3 and 4
        if (lm is None and not one_start) or follows_landmarks(this, lm, src_geometry, mesh):
            est = this(src_spec, spec, lm, source_mesh=src_geometry, target_mesh=mesh,
                       samples=None if sub is None else (sub_m, sub),
                       source_symmetry=source_symmetry(this),
                       resume=firsts.pop(i, None) if again else None)
        guide = None if lm is None or not guidable(source, mesh, estimator) else \
            landmark_geodesics(source, mesh, lm, (src_spec.mass, spec.mass))
        # (a point cloud is never guided: for_point_clouds)
        return _Target(i, mesh, scaled, (am, an), lm, sub, time.perf_counter() - t,
                       None if est is None else est.p2p,
                       None if est is None else est.turn_doubtful, parts, n_it, prep.fill,
                       guide, bool(again), may, est if may else None,  # (again: not may)
                       this.zoomout_step, as_method(method_for_shapes(named, source, prep.mesh)))

    devices = jax.local_devices()
    on_device: dict[int, list] = {}  # the source arrays, placed once per device and bucket kind
    ops_cache: dict[tuple, object] = {}  # the source's share of the problem (_source_ops_stage)

    def source_ops(cfg: StageConfig, tg: _Target, i: int):
        """The source's operators for target ``tg`` on device ``i``: one computation per set
        of source landmarks (kept for the last few of them)."""
        lm = None if tg.landmarks is None else np.asarray(tg.landmarks[0], np.int32)
        key = (cfg, None if lm is None else lm.tobytes(), i)
        if key not in ops_cache:
            if len(ops_cache) >= 4 * len(devices) * batch:  # per-target source landmarks
                ops_cache.pop(next(iter(ops_cache)))
            lm = jax.device_put(lm, devices[i])
            ops_stage = stages_for(cfg, batch > 1)[0]  # (never batched: once per key)
            ops_cache[key] = ops_stage(on_device[cfg.n_landmarks][i], lm)
        return ops_cache[key]

    def launch(key, group: list[_Target]):
        """Dispatch a group (not awaited: the next target's eigensolve runs meanwhile)."""
        (n_b, m_b, p, s_b), guided, step, this_method = key
        cfg = StageConfig(this_method, k, estimate_size(k, k_spec, guided), k_spec,
                          n_energies, p, chunk, zo_chunk, estimator.wks_variance,
                          estimator.orient_weight, step,
                          estimator.landmark_guidance)
        if p not in on_device:
            src_arrays = cast_tree(dict(rep, **(rep_orient if p == 0 else {})))
            on_device[p] = [jax.device_put(src_arrays, dev) for dev in devices]
        t = time.perf_counter()
        with one_blas_thread(cpu):
            out = dispatch_stages(cfg, on_device[p], [cast_tree(item_arrays(tg, n_b, m_b, s_b))
                                                for tg in group],
                            [source_ops(cfg, tg, j // batch) for j, tg in enumerate(group)],
                            batch)
        return group, out, time.perf_counter() - t

    def finish(launched, retry: dict | None):
        """The results of a launched group; a target to estimate again goes to ``retry``
        (its index → its seconds so far) instead."""
        group, out, seconds = launched
        t = time.perf_counter()
        per_target = []
        with one_blas_thread(cpu):  # (the group's stages may still be running)
            for o, n_real in out:
                o = jax.tree.map(np.asarray, o)
                per_target += [o] if batch == 1 else \
                    [jax.tree.map(lambda x, j=j: x[j], o) for j in range(n_real)]
        share = (seconds + time.perf_counter() - t) / len(group)
        for j, tg in enumerate(group):
            o = per_target[j]
            n = tg.mesh.n_vertices
            vals_j = o["values"][:, :n].astype(np.float64)
            p2p = o["p2p"][:n].astype(np.int64)
            mass = np.asarray(tg.spectrum.mass, np.float64)
            lab = agree = conf = regime = None
            share_un = 0.0
            if faces:
                lab, _, share_un, agree, conf, regime = decide_face_labels(
                    tg.mesh, shares, vals_j, p2p, threshold, refined)[:6]
            elif labels:
                lab, _, share_un, agree, conf, regime = _decide_labels(
                    ids, vals_j, mass, threshold, refined, vals[p2p])[:6]
            res = TargetTransfer(
                labels=lab, values=vals_j, p2p=p2p,
                C=map_to_unit_area(o["C"].astype(np.float64), *tg.factors, inverse=True),
                map_energy=float(o["energy"]), unassigned_share=share_un,
                agreement=agree, confidence=conf, regime=regime, n_vertices=n, mass=mass,
                seconds=tg.seconds + share, turn_doubtful=tg.turn_doubtful,
                mesh=tg.parts.mesh, denoise_iterations=tg.denoised)  # (the geometry as read)
            res = body_result(res, tg.fill, src_prep, faces)  # (hole patches dropped)
            res = whole_result(res, tg.parts, src_parts, faces)  # (other components: nearest)
            if labels:
                res = res._replace(missing=missing_parts(res, body_vals, src_prep.body, faces),
                                   estimated_again=tg.again)
                if res.missing and tg.may and retry is not None:
                    retry[tg.index] = res.seconds  # (a partial target: its map again)
                    firsts[tg.index] = tg.first
                    continue
            yield tg.index, file_row_results(res, src_parts.whole, faces) if file_rows else res

    targets = list(targets)
    share = process_share(range(len(targets)))
    batch = capped_batch(batch, k, len(share))  # no padding beyond this process's targets
    read: dict[int, Mesh] = {}  # targets of this process the scan has read, handed to prepare
    merged = _merged_sizes(targets, lm_of, read, share) if pad else {}
    cpu = jax.default_backend() == "cpu"

    def run(indices, estimator: MapEstimator, retry: dict | None, before: dict):
        """The targets ``indices`` through the stages (``before``: seconds each spent
        already); the group in flight is collected after the next target's host work
        (module doc)."""
        in_flight = None
        for i in indices:
            t = time.perf_counter() - before.get(i, 0.0)
            try:
                mesh = read.pop(i) if i in read else _as_mesh(targets[i])
            except (BSFError, ValueError, OSError) as exc:
                mesh = exc  # (reported below)
            if in_flight is not None and cpu and isinstance(mesh, Mesh) \
                    and not eigensolve_on_one_thread(mesh.n_vertices):  # multithreaded: wait
                yield from finish(in_flight, retry)
                in_flight = None
            try:
                if isinstance(mesh, Exception):
                    raise mesh
                with one_blas_thread(cpu and in_flight is not None):
                    tg = prepare(i, mesh, t, estimator, i in before)
            except (BSFError, ValueError, OSError) as exc:
                if errors == "raise":
                    raise
                yield i, exc
                continue
            key = (_bucket_key(tg, pad, tg.landmarks is None, zoomout_samples, merged),
                   tg.guide is not None, tg.step, tg.method)  # (guided: to k_spec)
            pending.setdefault(key, []).append(tg)
            if len(pending[key]) == len(devices) * batch:  # `batch` targets per device
                launched = launch(key, pending.pop(key))
                if in_flight is not None:
                    yield from finish(in_flight, retry)
                in_flight = launched
        for key in list(pending):
            launched = launch(key, pending.pop(key))
            if in_flight is not None:
                yield from finish(in_flight, retry)
            in_flight = launched
        if in_flight is not None:
            yield from finish(in_flight, retry)

    retry: dict[int, float] = {}
    firsts: dict = {}  # (their first estimates: the second goes on from its kept start)
    yield from run(share, estimator, retry if estimate_again else None, {})
    if retry:  # partial targets: their maps again, guided by landmarks read off the first
        yield from run(list(retry), dataclasses.replace(estimator, derived_guidance=True),
                       None, retry)
