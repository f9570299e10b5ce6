"""``bsfjax transfer``: one target (``--out``) here, many (``--out-dir``) in ``_many``."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from ._io import (TURN_DOUBT, CLIError, _read_array, _write_array, coloured_data, dropped_note,
                  is_json, map_estimator, part_list, read_truth, read_values)
from .._mesh import is_face_file


#: Methods that need inputs the command line does not give (``std2``: a 2k × 2k map).
CLI_EXCLUDED = ("std2",)


def _parse_landmarks(text: str | None):
    if text is None:
        return None
    try:
        left, right = text.split(":")
        src = [int(t) for t in left.split(",") if t.strip()]
        tgt = [int(t) for t in right.split(",") if t.strip()]
    except ValueError:
        raise CLIError(f"--landmarks must look like 'i,j,...:i2,j2,...', got {text!r}") from None
    if len(src) != len(tgt) or not src:
        raise CLIError(f"--landmarks: {len(src)} source and {len(tgt)} target indices; the two "
                       "lists must have the same, non-zero length")
    return src, tgt


#: Said when a target matched without landmarks misses source parts, before its map is
#: estimated again as with ``--partial``.
PARTIAL_AGAIN = ("the target misses source parts and no landmarks were given: estimating its "
                 "map again with the landmarks read off the first one guiding ZoomOut "
                 "(--partial; landmarks on what it kept are better)")
#: The same with landmarks: the turn check and the pairs read off the first map follow it.
PARTIAL_AGAIN_LANDMARKS = ("the target misses source parts: estimating its map again, the "
                           "landmarks read off the first one guiding ZoomOut and the turn "
                           "check comparing left and right (as --partial)")


def missing_line(values, result, src_prep, prep, per_face: bool, names=None) -> tuple:
    """The line naming the source labels (parts) with no counterpart on the target (a partial
    target): [`missing_labels`][bsfjax.missing_labels] over the two bodies' own areas (the
    vertices, triangles, as read: hole patches left out); and how many there are."""
    from .._metrics import MISSING_RATIO, missing_labels
    from .._mesh import vertex_areas

    area = (lambda m: m.face_areas()) if per_face else vertex_areas
    gone = missing_labels(src_prep.restrict(values, faces=per_face), area(src_prep.body),
                          prep.restrict(result, faces=per_face), area(prep.body))
    return (f"source parts with no counterpart on the target (under {MISSING_RATIO:.0%} of "
            f"their source share of the area): {part_list(gone, names)}"), len(gone)


def _cmd_transfer(args) -> int:
    from .._transfer import METHODS

    names = tuple(m for m in METHODS if m not in CLI_EXCLUDED)
    if args.method is None:  # a given point map is trusted as it is; an estimated one is refined
        args.method = "p2p" if args.map[0] == "p2p" else "refined"
    if args.method not in names:
        raise CLIError(f"--method must be one of {', '.join(names)}, got {args.method!r}")
    if args.out_dir is not None:
        from ._many import cmd_transfer_many

        if args.map != ["estimate"]:
            raise CLIError("with --out-dir the map is estimated per target (--map estimate); "
                           "transfer through given maps one target at a time (--out)")
        if args.truth_dir is not None and not args.labels:
            raise CLIError("--truth-dir compares labels: use it with --labels")
        return cmd_transfer_many(args, CLIError)
    from ._distributed import check_backend

    check_backend(CLIError)
    return _transfer_one(args)


def _transfer_one(args) -> int:
    import numpy as np

    from .._mesh import load_mesh, prepare_scan, save_mesh
    from .._spectral import spectrum

    if Path(args.out).suffix not in (".npy", ".txt") and not (
            args.labels and (is_json(args.out) or is_face_file(args.out))):
        raise CLIError(f"--out {args.out}: use a .txt or .npy file name (labels: also .json or "
                       ".seg)")
    if args.truth and not args.labels:
        raise CLIError("--truth compares labels: use it with --labels")
    if args.mesh_out and Path(args.mesh_out).suffix.lower() != ".ply":
        raise CLIError(f"--mesh-out {args.mesh_out}: use a .ply file name")
    kind, *rest = args.map
    if kind not in ("estimate", "p2p", "fmap") or (kind == "estimate") != (len(rest) == 0) or len(rest) > 1:
        raise CLIError("--map must be 'estimate', 'p2p FILE' or 'fmap FILE'")
    landmarks = _parse_landmarks(args.landmarks)
    # a scan in pieces: matched through its main body (one zero eigenvalue), smoothed when it
    # is noisy (the same vertices); its other components are labelled from the nearest
    # main-body vertex at the end
    src_prep = prepare_scan(load_mesh(args.source), not args.no_denoise)
    prep = prepare_scan(load_mesh(args.target), not args.no_denoise)
    src_parts, parts = src_prep.parts, prep.parts
    source, target = src_prep.mesh, prep.mesh
    # (holes closed for the spectrum: file rows are read onto the bodies, whose vertices and
    # triangles come first in source / target)
    src_body, body = src_prep.body, prep.body
    if src_parts.n_other_components:  # their labels are not carried
        print(f"source: {src_parts.other.size} vertices in {src_parts.n_other_components} other "
              "components left out (its main body is matched)", file=sys.stderr)
    if landmarks is not None:
        from .._util import check_indices

        # given as rows of the mesh files: onto the vertices each reader kept
        landmarks = tuple(mesh.file_row_index(check_indices(lm, f"--landmarks ({side})",
                                                            mesh.n_file_rows),
                                              f"--landmarks ({side})").tolist()
                          for lm, side, mesh in zip(landmarks, ("source", "target"),
                                                    (src_body, body)))
    values, names, per_face = read_values(args, src_body)
    values = (src_prep.extend(values.T).T if values.ndim == 2 else
              src_prep.extend(values, faces=per_face))
    if per_face and target.is_point_cloud:
        raise CLIError(f"{target.name}: per-triangle labels need a triangle target; a point "
                       "cloud has none (give one label per source vertex)")
    if args.labels and (is_json(args.out) if per_face else is_face_file(args.out)):
        kinds = "triangle: write .seg," if per_face else "vertex: write .json,"
        raise CLIError(f"--out {args.out}: the labels are per {kinds} .txt or .npy")
    truth = None
    if args.truth:
        truth = read_truth(args.truth, names)
        where, n = (("triangle", body.n_file_faces) if per_face else
                    ("vertex", body.n_file_rows))
        if truth.shape != (n,):
            raise CLIError(f"truth file {args.truth}: expected one label per target {where} "
                           f"({n}), got shape {truth.shape}")
        truth = body.from_file_rows(truth, faces=per_face)
    if not args.no_denoise:  # the spectra, map and transfer ran on smoothed geometry
        print(f"denoise: {src_prep.summary('source')}; {prep.summary('target')}", file=sys.stderr)
    for p_, role in ((src_prep, "source"), (prep, "target")):
        if p_.n_added:
            print(p_.fill_summary(role), file=sys.stderr)
    k = args.k
    kmax = min(source.n_vertices, target.n_vertices) - 1
    if not 1 <= k <= kmax:
        raise CLIError(f"-k must be in [1, {kmax}], got {k}")
    if kind == "estimate":  # the estimate's dense k^2 x k^2 system, before the spectra
        from .._maps import check_fmap_memory

        check_fmap_memory(k)
    C = p2p = est = None
    k_spec = min(2 * k, kmax) if kind == "estimate" else k
    if kind == "fmap":
        C = _read_array(rest[0], "fmap")
        if C.ndim != 2 or C.shape[0] != C.shape[1]:
            raise CLIError(f"fmap file {rest[0]}: expected a square k x k matrix, got shape {C.shape}")
        k = k_spec = C.shape[0]
    k_map = k_spec  # the estimated map's ZoomOut size; 'refined' continues it further
    if args.method == "refined":
        from .._maps import REFINE_EIGENPAIRS

        k_spec = min(max(k_spec, REFINE_EIGENPAIRS), kmax)
    if kind == "p2p":  # read and checked before the spectra, so a bad file costs nothing
        p2p = _read_array(rest[0], "p2p", dtype=int)
        if p2p.shape != (body.n_file_rows,):
            raise CLIError(f"p2p file {rest[0]}: expected {body.n_file_rows} source vertex indices in "
                           f"[0, {src_body.n_file_rows}), got shape {p2p.shape}")
        from .._util import check_indices

        try:  # one source row per target row: the kept rows, onto the kept source vertices
            p2p = check_indices(p2p, "p2p", src_body.n_file_rows, what="source vertex indices")
            p2p = prep.extend(src_body.file_row_index(body.from_file_rows(p2p), "p2p (source)"))
        except ValueError as exc:
            raise CLIError(f"p2p file {rest[0]}: {exc}") from None
    sm = spectrum(source, k_spec, cache_dir=args.spectrum_cache)
    sn = spectrum(target, k_spec, cache_dir=args.spectrum_cache)
    print(f"spectra: {source.n_vertices} and {target.n_vertices} vertices, k = {k_spec}", file=sys.stderr)
    if kind == "p2p":
        from .._maps import fmap_from_p2p

        C = np.asarray(fmap_from_p2p(sm, sn, p2p))
    elif kind == "estimate":
        if landmarks is None:
            warnings.warn("no --landmarks: an intrinsically symmetric shape may be matched to its "
                          "mirror image or turned front to back (an orientation term and a choice "
                          "among several starts make it less likely; two landmark pairs remove "
                          "it)", stacklevel=1)
        est = _estimate_map(args, k, k_map, k_spec, sm, sn, landmarks, source, target,
                            args.partial)
        C, p2p = est.C, est.p2p
    res = _transfer_through(args, k, kind, C, p2p, est, sm, sn, values, source, target,
                            per_face)
    on_whole = False  # the result on the whole target (main body and other components)
    if args.labels:
        result = res.labels.astype(np.int64)
        print(f"transferred {np.unique(values).size} labels "
              f"{'of triangles ' if per_face else ''}with {args.method}; unassigned: "
              f"{res.unassigned_share:.1%} of the target area", file=sys.stderr)
        line, n_gone = missing_line(values, result, src_prep, prep, per_face, names)
        from .._maps import estimates_again

        # (a partial target: its first map may have slid a limb into the missing part)
        if n_gone and kind == "estimate" and estimates_again(
                map_estimator(args, k, k_map), landmarks, source, target, k_map):
            print(f"{line}\n{PARTIAL_AGAIN if landmarks is None else PARTIAL_AGAIN_LANDMARKS}",
                  file=sys.stderr)
            est = _estimate_map(args, k, k_map, k_spec, sm, sn, landmarks, source, target, True,
                                resume=est)  # (from the first estimate's kept start)
            C, p2p = est.C, est.p2p
            res = _transfer_through(args, k, kind, C, p2p, est, sm, sn, values, source, target,
                                    per_face)
            result = res.labels.astype(np.int64)
            line = missing_line(values, result, src_prep, prep, per_face, names)[0]
        print(line, file=sys.stderr)
        if res.regime is not None:
            why = [] if res.agreement is None else [f"{res.agreement:.1%} of the area as the "
                                                    "input map's pull-back"]
            if res.confidence is not None and res.confidence < 1:  # a vote (n_vote > 1)
                why.append(f"vote confidence {res.confidence:.2f}")
            print(f"regime: {res.regime}" + (f" ({', '.join(why)})" if why else ""),
                  file=sys.stderr)
        if truth is not None:
            area = target.face_areas() if per_face else np.asarray(sn.mass)
            if parts.n_other_components or prep.n_added:  # over the whole target as read
                from .._mesh import vertex_areas

                whole, on_whole = parts.whole, True
                result, truth = (prep.to_whole(result, faces=per_face),
                                 whole.from_file_rows(body.to_file_rows(truth, faces=per_face),
                                                      faces=per_face))
                area = whole.face_areas() if per_face else vertex_areas(whole)
            correct = result == truth
            print(f"accuracy against {args.truth}: {np.sum(area * correct) / np.sum(area):.1%} of "
                  f"the target area ({np.mean(correct):.1%} of its "
                  f"{'triangles' if per_face else 'vertices'})", file=sys.stderr)
    else:
        result = res.T if res.ndim == 2 else res
    # every file written has the target file's rows: -1 / NaN where the reader dropped one
    if parts.n_other_components or prep.n_added:
        if not on_whole:  # (already there for the accuracy)
            result = prep.to_whole(result, faces=per_face)
        if parts.n_other_components:
            print(parts.summary(), file=sys.stderr)
    target = parts.whole
    result = target.to_file_rows(result, faces=per_face)
    if args.mesh_out:
        coloured = coloured_data(result, bool(args.labels))
        save_mesh(args.mesh_out, target.file_mesh(),  # (the geometry as read: parts.whole)
                  **({"cell_data": coloured} if per_face else {"point_data": coloured}))
    _write_array(args.out, result, names)
    if args.render:  # PNGs of the source and the result (bsfjax.plot.render)
        from ._view import render_run

        render_run(args, args.target, result, names, per_face, args.truth)
    print(f"wrote {args.out}" + (f" and {args.mesh_out}" if args.mesh_out else "")
          + dropped_note(target, per_face), file=sys.stderr)
    return 0


def _estimate_map(args, k, k_map, k_spec, sm, sn, landmarks, source, target, partial: bool,
                  resume=None):
    """The command's [`MapEstimator`][bsfjax.MapEstimator] run (``partial``:
    ``derived_guidance``; ``resume``: a first estimate to go on from), what it did said on
    stderr."""
    import dataclasses

    from .._maps import for_point_clouds
    from .._mesh import surface_for_map

    # without landmarks a point cloud gives the orientation term its stand-in surface
    shapes = ((source, target) if landmarks is not None else
              (surface_for_map(source), surface_for_map(target)))
    # ZoomOut to k_map; where landmarks (given, or read off a map with --partial) guide it on
    # two triangle meshes, to every eigenpair (MapEstimator.guided_to)
    estimator = dataclasses.replace(map_estimator(args, k, k_map), derived_guidance=partial)
    est = for_point_clouds(estimator, source, target)(
        sm, sn, landmarks, source_mesh=shapes[0], target_mesh=shapes[1], resume=resume)
    print(f"estimated a {k}x{k} map (ZoomOut to {k_map}, to {k_spec} where landmarks guide "
          "it)", file=sys.stderr)
    if est.start is not None:
        second = ("" if est.landmarks is None else
                  f", then {len(est.landmarks[0])} landmarks read off its map")
        turn = ", then swapped left and right (it was turned)" if est.swapped else ""
        print(f"no landmarks: kept start k0 = {est.start[0]}, WKS variance "
              f"{est.start[1]:g}{second}{turn}; geodesic distortion {est.distortion:.4f}, "
              f"orientation agreement {est.orientation:.1%}", file=sys.stderr)
        if est.proxy is not None:  # a large mesh: the start was chosen on proxies
            print(f"large mesh: chosen on proxies of {est.proxy[0]} and {est.proxy[1]} "
                  "vertices, then carried to the meshes", file=sys.stderr)
        if est.turn_doubtful:
            warnings.warn(TURN_DOUBT, stacklevel=1)
    return est


def _transfer_through(args, k, kind, C, p2p, est, sm, sn, values, source, target, per_face):
    """The values' transfer through the map: a label transfer's result, or a function's
    values on the target."""
    from .._pipeline import transfer_labels, transfer_values
    from .._transfer import method_for_shapes

    # a pair with a point cloud: the refined continuation without the WKS descriptors
    common = dict(C=C, p2p=p2p, method=method_for_shapes(args.method, source, target),
                  mesh=source)
    if args.method == "refined":  # its continuation runs on the samples of the map's ZoomOut
        from .._sampling import subsample

        n_samples = map_estimator(args, k).zoomout_samples
        common["samples"] = (est.samples if kind == "estimate" else
                             (subsample(source, n_samples), subsample(target, n_samples)))
    if args.labels and per_face:
        from .._pipeline import transfer_face_labels

        del common["mesh"]
        return transfer_face_labels(sm, sn, values, source_mesh=source, target_mesh=target,
                                    threshold=args.threshold, **common)
    if args.labels:
        return transfer_labels(sm, sn, values, threshold=args.threshold, **common)
    return transfer_values(sm, sn, values, **common)
