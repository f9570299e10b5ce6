"""The ``bsfjax`` command line: ``demo``, ``example``, ``transfer``, ``reproduce``, ``spectrum``.

Bad input ends with a one-line message on stderr and exit status 2, never a traceback, and no
partial output file (every output is written atomically, after all the work is done).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from ._cli_io import (CLIError, _read_array, _write_array, coloured_data, is_json,
                      read_truth, read_values)
from ._label_files import is_face_file


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="bsfjax",
        description="Binary Sparse Frames: sparse representation and transfer of step functions "
                    "(segmentations, part labels, region indicators) between shapes.",
    )
    parser.add_argument("--version", action="version", version=f"bsfjax {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("demo", help="run the whole pipeline on the built-in example pair (the main job)")
    p.add_argument("--out", default="bsfjax-demo", help="output folder (default ./bsfjax-demo)")
    p.add_argument("-k", type=int, default=30, help="eigenpairs used by every method (default 30)")
    p.add_argument("--functions", type=int, default=50, help="random indicators (default 50)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("example", help="write the built-in example pair (meshes, segmentation, "
                                       "ground truth, landmarks) to files, to try 'transfer' on")
    p.add_argument("--out", default="bsfjax-example", help="output folder (default ./bsfjax-example)")
    p.add_argument("--levels", type=int, default=3,
                   help="subdivision levels: 126*4^levels+2 vertices (default 3: 8066)")
    p.set_defaults(func=_cmd_example)

    p = sub.add_parser("transfer", help="transfer a segmentation or a function from one mesh to "
                                        "another, or to many (--out-dir)")
    p.add_argument("source", help="source mesh (OFF, PLY, OBJ, STL, ...)")
    p.add_argument("target", nargs="+", help="target mesh; with --out-dir any number of files, "
                                             "folders (their mesh files) or glob patterns")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--labels", help="one integer label per source vertex (.txt or .npy), "
                      "parts as SMPL's .json {part name: [vertex indices]}, or one label per "
                      "triangle (.seg as PSB / COSEG, or .txt / .npy of that length)")
    what.add_argument("--function", help="per-source-vertex values: (n,) or (n, m) (.txt or .npy)")
    p.add_argument("--out", help="per-target-vertex labels/values (.txt or .npy; labels also .json "
                                 "{part name: [vertex indices]}; labels of triangles also .seg), "
                                 "one target")
    p.add_argument("--out-dir", help="many targets: write DIR/<target name>.txt and "
                                     "DIR/summary.json; complete outputs are skipped on a rerun")
    p.add_argument("--map", nargs="+", default=["estimate"], metavar="KIND [FILE]",
                   help="'estimate' (default: WKS + landmarks + ZoomOut), 'p2p FILE' (one source "
                        "vertex index per target vertex) or 'fmap FILE' (k x k matrix, source -> "
                        "target); with --out-dir: 'estimate'")
    p.add_argument("--landmarks", help="landmark vertex indices 'i,j,...:i2,j2,...' (source:target)")
    p.add_argument("--landmarks-file", help="--out-dir: JSON {target file name: [[source "
                                            "indices], [target indices]]}")
    p.add_argument("--one-start", action="store_true",
                   help="without landmarks: estimate the map from one start, not 15 with a "
                        "choice by geodesic distortion (16x faster, less accurate)")
    p.add_argument("-k", type=int, default=30, help="spectral basis size (default 30)")
    p.add_argument("--method", default=None,
                   help="transfer method: refined (default: pull-back through the refined map; "
                        "with '--map p2p FILE' the default is p2p, the given map as it is), p2p "
                        "(pull-back; also for a '--map fmap FILE' that is already accurate), "
                        "omp, omp_error, lstsq, lasso (the paper's BSF coders), std, prod, geod, "
                        "heat")
    p.add_argument("--mesh-out", help="also write the target mesh coloured by the result (.ply)")
    p.add_argument("--mesh-out-dir", help="--out-dir: also write DIR/<target name>.ply coloured")
    p.add_argument("--threshold", type=float, default=None,
                   help="labels: a target vertex whose best score is below this is unassigned (-1) "
                        "(default 0.5; 0 for 'p2p' and 'refined', whose scores are shares)")
    p.add_argument("--truth", help="labels: ground-truth label per target vertex (or triangle) in "
                                   "a file as --labels; report the share of the target's area "
                                   "labelled correctly")
    p.add_argument("--truth-dir", help="--out-dir: folder of <target name>.txt/.npy ground "
                                       "truths; summary.json reports each accuracy")
    p.add_argument("--overwrite", action="store_true", help="--out-dir: recompute complete outputs")
    p.add_argument("--batch", type=int, default=None,
                   help="--out-dir: targets per device run together under vmap (default 1; "
                        "for accelerators, a CPU gains nothing)")
    p.add_argument("--spectrum-cache", help="folder caching the eigenbases between runs")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--coordinator", help="--out-dir on several processes (jax.distributed): "
                   "HOST:PORT of process 0; without these flags a SLURM or Open MPI job is "
                   "detected by itself")
    p.add_argument("--num-processes", type=int, help="number of processes (jax.distributed)")
    p.add_argument("--process-id", type=int, help="this process's rank in [0, N)")
    p.set_defaults(func=_cmd_transfer)

    p = sub.add_parser("spectrum", help="compute the Laplace-Beltrami spectrum of a mesh")
    p.add_argument("mesh", help="mesh file (OFF, PLY, OBJ, STL, ...)")
    p.add_argument("-k", type=int, default=100, help="number of eigenpairs (default 100)")
    p.add_argument("--out", required=True, help="output .npz with evals, evecs, mass")
    p.add_argument("--method", choices=("auto", "block", "lanczos", "dense", "fast"),
                   default="auto", help="eigensolver, as bsfjax.spectrum's method: auto "
                   "(default: dense for small meshes, block Lanczos with CHOLMOD from 20K "
                   "vertices, else ARPACK), block, lanczos (ARPACK), dense (LAPACK, small "
                   "meshes), fast (approximate block solver)")
    p.set_defaults(func=_cmd_spectrum)

    p = sub.add_parser("reproduce", help="run one of the paper's experiments (tables 1-5, "
                       "figures 7 and 10) or the 'sparse' study on a data folder; writes CSV, "
                       "Markdown and PNG")
    from .experiments import EXPERIMENTS  # the registry: one entry per experiment

    p.add_argument("name", choices=tuple(EXPERIMENTS), help="experiment")
    p.add_argument("--data", required=True, help="folder of meshes with ground truth (FAUST-style "
                   "shared vertex order, or corres/<name>.vts files; class subfolders for TOSCA)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--pairs", type=int, default=2, help="shape pairs (table5: per class; "
                   "default 2)")
    p.add_argument("--functions", type=int, default=100, help="random indicator functions per "
                   "shape (default 100)")
    p.add_argument("--seed", type=int, default=0, help="seed of pairs, functions and FPS")
    p.add_argument("--k", default=None, help="comma-separated k list overriding the "
                   "experiment's (fig7: k_M values; fig10, sparse: its k)")
    p.add_argument("--cache", default=None, help="eigenbasis cache folder (default OUT/.spectra)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--segmentation", default=None, help="template part labels for 'segmentation' "
                   "(.json {part: [vertices]} as SMPL's, or one label per template vertex)")
    p.set_defaults(func=lambda a: __import__("bsfjax.experiments", fromlist=["x"]).cli(a))
    return parser


#: Methods that need inputs the command line does not give (``std2``: a 2k × 2k map).
CLI_EXCLUDED = ("std2",)


def one_start(args, k: int):
    """``estimate_map``'s ``starts`` for ``--one-start`` (``None``: its default)."""
    from ._map_estimate import WKS_VARIANCE

    return ((k, WKS_VARIANCE),) if args.one_start else None


#: Said when :func:`bsfjax.estimate_map`'s turn check could not tell which of its two maps is
#: turned front to back (``MapEstimate.turn_doubtful``).
TURN_DOUBT = ("the map may be turned front to back (left and right swapped): without "
              "landmarks the turn check's two measures disagree on this pair; give two landmark "
              "pairs")


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


#: Options of the multi-target form only, and of the one-target form only.
_MANY_ONLY = (("landmarks_file", "--landmarks-file"), ("truth_dir", "--truth-dir"),
              ("mesh_out_dir", "--mesh-out-dir"), ("coordinator", "--coordinator"),
              ("num_processes", "--num-processes"), ("process_id", "--process-id"),
              ("batch", "--batch"))
_ONE_ONLY = (("out", "--out"), ("landmarks", "--landmarks"), ("mesh_out", "--mesh-out"),
             ("truth", "--truth"))


def _cmd_transfer(args) -> int:
    from ._methods import METHODS

    names = tuple(m for m in METHODS if m not in CLI_EXCLUDED)
    if args.method is None:  # a given point map is trusted as it is; an estimated one is refined
        args.method = "p2p" if args.map[0] == "p2p" else "refined"
    if args.method not in names:
        raise CLIError(f"--method must be one of {', '.join(names)}, got {args.method!r}")
    if args.out_dir is not None:
        from ._cli_many import cmd_transfer_many

        if args.map != ["estimate"]:
            raise CLIError("with --out-dir the map is estimated per target (--map estimate); "
                           "transfer through given maps one target at a time (--out)")
        if args.truth_dir is not None and not args.labels:
            raise CLIError("--truth-dir compares labels: use it with --labels")
        return cmd_transfer_many(args, CLIError)
    return _transfer_one(args)


def _transfer_one(args) -> int:
    import numpy as np

    from ._highlevel import transfer_labels, transfer_values
    from ._map_estimate import estimate_map
    from ._mesh import load_mesh
    from ._mesh_write import save_mesh
    from ._spectrum import spectrum

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
    source, target = load_mesh(args.source), load_mesh(args.target)
    if landmarks is not None:
        from ._validate import check_indices

        check_indices(landmarks[0], "--landmarks (source)", source.n_vertices)
        check_indices(landmarks[1], "--landmarks (target)", target.n_vertices)
    values, names, per_face = read_values(args, source)
    if args.labels and (is_json(args.out) if per_face else is_face_file(args.out)):
        kinds = "triangle: write .seg," if per_face else "vertex: write .json,"
        raise CLIError(f"--out {args.out}: the labels are per {kinds} .txt or .npy")
    truth = None
    if args.truth:
        truth = read_truth(args.truth, names)
        where, n = ("triangle", target.n_faces) if per_face else ("vertex", target.n_vertices)
        if truth.shape != (n,):
            raise CLIError(f"truth file {args.truth}: expected one label per target {where} "
                           f"({n}), got shape {truth.shape}")
    k = args.k
    kmax = min(source.n_vertices, target.n_vertices) - 1
    if not 1 <= k <= kmax:
        raise CLIError(f"-k must be in [1, {kmax}], got {k}")
    C = p2p = None
    k_spec = min(2 * k, kmax) if kind == "estimate" else k
    if kind == "fmap":
        C = _read_array(rest[0], "fmap")
        if C.ndim != 2 or C.shape[0] != C.shape[1]:
            raise CLIError(f"fmap file {rest[0]}: expected a square k x k matrix, got shape {C.shape}")
        k = k_spec = C.shape[0]
    k_map = k_spec  # the estimated map's ZoomOut size; 'refined' continues it further
    if args.method == "refined":
        from ._refine import REFINE_EIGENPAIRS

        k_spec = min(max(k_spec, REFINE_EIGENPAIRS), kmax)
    if kind == "p2p":  # read and checked before the spectra, so a bad file costs nothing
        p2p = _read_array(rest[0], "p2p", dtype=int)
        if p2p.shape != (target.n_vertices,):
            raise CLIError(f"p2p file {rest[0]}: expected {target.n_vertices} source vertex indices in "
                           f"[0, {source.n_vertices}), got shape {p2p.shape}")
        from ._validate import check_indices

        try:
            p2p = check_indices(p2p, "p2p", source.n_vertices, what="source vertex indices")
        except ValueError as exc:
            raise CLIError(f"p2p file {rest[0]}: {exc}") from None
    sm = spectrum(source, k_spec, cache_dir=args.spectrum_cache)
    sn = spectrum(target, k_spec, cache_dir=args.spectrum_cache)
    print(f"spectra: {source.n_vertices} and {target.n_vertices} vertices, k = {k_spec}", file=sys.stderr)
    if kind == "p2p":
        from ._fmap import fmap_from_p2p

        C = np.asarray(fmap_from_p2p(sm, sn, p2p))
    elif kind == "estimate":
        if landmarks is None:
            warnings.warn("no --landmarks: an intrinsically symmetric shape may be matched to its "
                          "mirror image or turned front to back (an orientation term and a choice "
                          "among several starts make it less likely; two landmark pairs remove "
                          "it)", stacklevel=1)
        est = estimate_map(sm.truncate(k_map), sn.truncate(k_map), k=k, landmarks=landmarks,
                           refine_to=k_map, source_mesh=source, target_mesh=target,
                           starts=one_start(args, k))
        C, p2p = est.C, est.p2p
        print(f"estimated a {k}x{k} map (ZoomOut to {k_map})", file=sys.stderr)
        if est.start is not None:
            second = ("" if est.landmarks is None else
                      f", then {len(est.landmarks[0])} landmarks read off its map")
            turn = ", then swapped left and right (it was turned)" if est.swapped else ""
            print(f"no landmarks: kept start k0 = {est.start[0]}, WKS variance "
                  f"{est.start[1]:g}{second}{turn}; geodesic distortion {est.distortion:.4f}, "
                  f"orientation agreement {est.orientation:.1%}", file=sys.stderr)
            if est.turn_doubtful:
                warnings.warn(TURN_DOUBT, stacklevel=1)
    common = dict(C=C, p2p=p2p, method=args.method, mesh=source)
    if args.method == "refined":  # its continuation runs on the samples of the map's ZoomOut
        from ._map_estimate import ZOOMOUT_SAMPLES
        from ._sampling import subsample

        common["samples"] = (est.samples if kind == "estimate" else
                             (subsample(source, ZOOMOUT_SAMPLES),
                              subsample(target, ZOOMOUT_SAMPLES)))
    if args.labels and per_face:
        from ._face_labels import transfer_face_labels

        del common["mesh"]
        res = transfer_face_labels(sm, sn, values, source_mesh=source, target_mesh=target,
                                   threshold=args.threshold, **common)
    elif args.labels:
        res = transfer_labels(sm, sn, values, threshold=args.threshold, **common)
    if args.labels:
        result = res.labels.astype(np.int64)
        print(f"transferred {np.unique(values).size} labels "
              f"{'of triangles ' if per_face else ''}with {args.method}; unassigned: "
              f"{res.unassigned_share:.1%} of the target area", file=sys.stderr)
        if res.regime is not None:
            why = [] if res.agreement is None else [f"{res.agreement:.1%} of the area as the "
                                                    "input map's pull-back"]
            if res.confidence is not None and res.confidence < 1:  # a vote (n_vote > 1)
                why.append(f"vote confidence {res.confidence:.2f}")
            print(f"regime: {res.regime}" + (f" ({', '.join(why)})" if why else ""),
                  file=sys.stderr)
        if truth is not None:
            area = target.face_areas() if per_face else np.asarray(sn.mass)
            correct = result == truth
            print(f"accuracy against {args.truth}: {np.sum(area * correct) / np.sum(area):.1%} of "
                  f"the target area ({np.mean(correct):.1%} of its "
                  f"{'triangles' if per_face else 'vertices'})", file=sys.stderr)
    else:
        result = transfer_values(sm, sn, values, **common)
        result = result.T if result.ndim == 2 else result
    if args.mesh_out:
        coloured = coloured_data(result, bool(args.labels))
        save_mesh(args.mesh_out, target, **({"cell_data": coloured} if per_face
                                             else {"point_data": coloured}))
    _write_array(args.out, result, names)
    print(f"wrote {args.out}" + (f" and {args.mesh_out}" if args.mesh_out else ""), file=sys.stderr)
    return 0


def _cmd_example(args) -> int:
    from ._files import write_text_atomic
    from ._demo import example_landmarks
    from ._example import example_pair
    from ._mesh_write import save_mesh

    if not 1 <= args.levels <= 4:
        raise CLIError(f"--levels must be in [1, 4], got {args.levels}")
    pair = example_pair(levels=args.levels)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    save_mesh(out / "source.ply", pair.source)
    save_mesh(out / "target.ply", pair.target)
    lines = lambda a: "\n".join(str(int(x)) for x in a) + "\n"  # noqa: E731
    write_text_atomic(out / "labels.txt", lines(pair.labels))
    write_text_atomic(out / "target_labels.txt", lines(pair.labels[pair.p2p]))
    write_text_atomic(out / "p2p.txt", lines(pair.p2p))
    lm = ",".join(str(int(i)) for i in example_landmarks(pair))
    write_text_atomic(out / "landmarks.txt", f"{lm}:{lm}\n")
    print(f"wrote the built-in pair ({pair.source.n_vertices} vertices, "
          f"{len(pair.label_names)} parts: {', '.join(pair.label_names)}) to {out}/:\n"
          "  source.ply, target.ply    the two poses (vertex i <-> vertex i)\n"
          "  labels.txt                part label per source vertex\n"
          "  target_labels.txt         ground-truth part label per target vertex\n"
          "  p2p.txt                   ground-truth point map (source vertex per target vertex)\n"
          "  landmarks.txt             one landmark per part, 'source:target'\n"
          f"try:\n  bsfjax transfer {out}/source.ply {out}/target.ply --labels {out}/labels.txt "
          f"--landmarks {lm}:{lm} --truth {out}/target_labels.txt --out labels_out.txt "
          "--mesh-out coloured.ply")
    return 0


def _cmd_demo(args) -> int:
    from ._demo import format_table, run_demo

    print("bsfjax demo: the whole pipeline on the built-in example pair", flush=True)
    results = run_demo(args.out, k=args.k, n_functions=args.functions, seed=args.seed,
                       figures=not args.no_figures)
    print()
    print(format_table(results))
    print(f"\nwrote {Path(args.out) / 'results.json'}"
          + (f" and {len(results.get('figures', []))} PNG figures" if not args.no_figures else ""))
    return 0


def _cmd_spectrum(args) -> int:
    import numpy as np

    from ._files import atomic_path
    from ._mesh import load_mesh
    from ._spectrum import spectrum

    if Path(args.out).suffix != ".npz":
        raise CLIError(f"--out {args.out}: use a .npz file name")
    mesh = load_mesh(args.mesh)
    spec = spectrum(mesh, args.k, method=args.method)
    with atomic_path(args.out) as tmp, open(tmp, "wb") as fh:  # a handle: savez adds no suffix
        np.savez(fh, evals=spec.evals, evecs=spec.evecs, mass=spec.mass)
    print(f"{args.mesh}: {mesh.n_vertices} vertices, k={args.k}, method={args.method}, "
          f"lambda_2={spec.evals[1] if spec.k > 1 else 0:.6g}, wrote {args.out}")
    return 0


#: Options whose value may start with "-" (a negative number, or landmarks "-1,2:3,4"):
#: argparse would take such a value for an option and answer with its usage text.
_VALUE_OPTIONS = ("--landmarks", "--seed", "--functions", "--pairs", "--levels", "-k", "--k",
                  "--threshold", "--num-processes", "--process-id")


def _join_option_values(argv: list[str]) -> list[str]:
    """``--seed -5`` → ``--seed=-5``, so that the value reaches our own check, which names the
    option and prints the value as given."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a in _VALUE_OPTIONS and i + 1 < len(argv) and argv[i + 1].startswith("-") \
                and argv[i + 1] not in ("-h", "--help") and len(argv[i + 1]) > 1 \
                and (argv[i + 1][1].isdigit() or argv[i + 1][1] == "."):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


#: (attribute, option, smallest value) of the integer options, checked before any work.
_INT_OPTIONS = (("seed", "--seed", 0), ("functions", "--functions", 1), ("pairs", "--pairs", 1),
                ("k", "-k", 1), ("levels", "--levels", 1), ("batch", "--batch", 1))


def _check_transfer_form(args) -> None:
    """One target with ``--out`` or many with ``--out-dir``; each form's own options only."""
    if (args.out is None) == (args.out_dir is None):
        raise CLIError("give --out FILE (one target) or --out-dir DIR (one or more targets)")
    if args.out is not None:
        if len(args.target) != 1:
            raise CLIError(f"--out takes one target, got {len(args.target)}; use --out-dir DIR "
                           "for several")
        bad = [opt for attr, opt in _MANY_ONLY if getattr(args, attr) is not None]
        if args.overwrite:
            bad.append("--overwrite")
    else:
        bad = [opt for attr, opt in _ONE_ONLY if getattr(args, attr) is not None]
    if bad:
        form = "--out FILE" if args.out is not None else "--out-dir DIR"
        raise CLIError(f"{', '.join(bad)} cannot be used with {form}")


def _check_options(args) -> None:
    """Every integer option in range, every output path usable and distinct from the inputs,
    before any work (one line naming the option and the value as given)."""
    from ._files import check_outputs

    for attr, opt, lo in _INT_OPTIONS:
        v = getattr(args, attr, None)
        if isinstance(v, int) and v < lo:
            raise CLIError(f"{opt} must be an integer >= {lo}, got {v}")
    cmd = args.command
    if cmd == "transfer":
        _check_transfer_form(args)
        if args.out_dir is not None:
            for opt, path in (("source", args.source), ("--labels", args.labels),
                              ("--function", args.function),
                              ("--landmarks-file", args.landmarks_file)):
                if path is not None and not Path(path).is_file():
                    raise CLIError(f"{opt} {path}: " + ("is a folder" if Path(path).is_dir()
                                                         else "no such file"))
            if args.truth_dir is not None and not Path(args.truth_dir).is_dir():
                raise CLIError(f"--truth-dir {args.truth_dir}: no such folder")
            check_outputs({"--out-dir": args.out_dir, "--mesh-out-dir": args.mesh_out_dir},
                          {"source": args.source, "--labels": args.labels,
                           "--function": args.function}, folders=("--out-dir", "--mesh-out-dir"))
            return
        args.target = args.target[0]
        kind_file = args.map[1] if len(args.map) > 1 else None
        for opt, path in (("source", args.source), ("target", args.target),
                          ("--labels", args.labels), ("--function", args.function),
                          ("--map", kind_file), ("--truth", args.truth)):
            if path is not None and not Path(path).is_file():  # before the meshes are read
                raise CLIError(f"{opt} {path}: " + ("is a folder" if Path(path).is_dir()
                                                     else "no such file"))
        check_outputs({"--out": args.out, "--mesh-out": args.mesh_out},
                      {"source": args.source, "target": args.target, "--labels": args.labels,
                       "--function": args.function, "--map": kind_file,
                       "--truth": args.truth})
    elif cmd == "spectrum":
        check_outputs({"--out": args.out}, {"mesh": args.mesh})
    elif cmd in ("demo", "example"):
        check_outputs({"--out": args.out}, folders=("--out",))
    elif cmd == "reproduce":
        check_outputs({"--out": args.out, "--cache": args.cache}, {"--data": args.data},
                      folders=("--out", "--cache"))


def main(argv: list[str] | None = None) -> int:
    from . import _signals

    if not _signals.install():  # Ctrl-C: one line, exit 130, temporaries removed
        return _main(argv)  # (only in the command's own process, not when called from Python)
    try:
        status = _main(argv)
    except SystemExit as exc:  # argparse: --help, --version, usage errors
        if isinstance(exc.code, str):
            print(exc.code, file=sys.stderr)
        status = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    _signals.exit_now(status)  # no interpreter finalization (see _signals)


def _use_compilation_cache() -> None:
    """Keep compiled programs between runs in JAX's persistent compilation cache, so that a
    second ``bsfjax`` call on meshes of the same sizes skips compilation (most of a short
    call's time: docs/benchmarks.md).  The folder is ``$XDG_CACHE_HOME/bsfjax/jax`` (default
    ``~/.cache``); ``JAX_COMPILATION_CACHE_DIR`` chooses another, and setting it empty turns
    the cache off.  JAX keys entries by the program, its options and the backend.

    Every program is kept, however fast it compiled: JAX keeps by default only those that took
    a second or more, and most of ours take 0.05–1 s each, so a second ``bsfjax transfer`` of a
    5.5K-vertex target took 6.4 s instead of 4.1 s (one entry kept instead of 50, 0.46 MB in
    all; stop 29).  ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS`` still overrides it."""
    import os

    import jax

    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    if "JAX_COMPILATION_CACHE_DIR" in os.environ:  # JAX reads it itself ('' = off)
        return
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    jax.config.update("jax_compilation_cache_dir", os.path.join(base, "bsfjax", "jax"))


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(_join_option_values(sys.argv[1:] if argv is None else argv))
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 0
    warnings.filterwarnings("ignore", message="JAXopt is no longer maintained")
    _use_compilation_cache()
    try:
        from ._files import output_transaction

        _check_options(args)
        with output_transaction():  # all outputs of the command are renamed together, or none
            return int(args.func(args) or 0)
    except (ValueError, OSError) as exc:  # bad input: one line, no traceback
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"bsfjax {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # pragma: no cover
        print(f"bsfjax {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
