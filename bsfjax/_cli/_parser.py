"""The ``bsfjax`` argument parser, and the checks of every option before any work."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._commands import _cmd_demo, _cmd_example, _cmd_spectrum
from ._io import CLIError
from ._transfer import _cmd_transfer
from ._view import add_view_parser, check_render_available


def build_parser() -> argparse.ArgumentParser:
    """The `argparse` parser of the `bsfjax` command, with one sub-command each for `demo`,
    `example`, `transfer`, `view`, `reproduce` and `spectrum`."""
    from .._util import VERSION

    parser = argparse.ArgumentParser(
        prog="bsfjax",
        description="Binary Sparse Frames: sparse representation and transfer of step functions "
                    "(segmentations, part labels, region indicators) between shapes.",
    )
    parser.add_argument("--version", action="version", version=f"bsfjax {VERSION}")
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
    p.add_argument("--partial", action="store_true",
                   help="for a target that misses parts (a cut limb): the landmarks read off "
                        "the first map also guide ZoomOut, and with --landmarks the turn check "
                        "follows their map (slower; on clean pairs sometimes less accurate; "
                        "the command does this by itself once a map misses source parts)")
    p.add_argument("--no-denoise", action="store_true",
                   help="use the meshes as they are (default: a noisy source or target is "
                        "smoothed before its spectrum, by Taubin iterations chosen from its "
                        "noise level; none on a clean mesh; the labels stay on its vertices)")
    p.add_argument("-k", type=int, default=30, help="spectral basis size (default 30)")
    p.add_argument("--method", default=None,
                   help="transfer method: refined (default: pull-back through the refined map; "
                        "with '--map p2p FILE' the default is p2p, the given map as it is), p2p "
                        "(pull-back; also for a '--map fmap FILE' that is already accurate), "
                        "omp, omp_error, lstsq, lasso (the paper's BSF coders), std, prod, geod, "
                        "heat")
    p.add_argument("--mesh-out", help="also write the target mesh coloured by the result (.ply)")
    p.add_argument("--mesh-out-dir", help="--out-dir: also write DIR/<target name>.ply coloured")
    p.add_argument("--render", metavar="DIR", help="also render each target's result next to the "
                   "source to DIR/<target name>_front.png and _back.png (polyscope, headless)")
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
    p.add_argument("--timeout", type=int, default=None, help="seconds jax.distributed may take "
                   "to start (default 90): an unreachable coordinator or a missing process is "
                   "then one error line")
    p.set_defaults(func=_cmd_transfer)

    add_view_parser(sub)

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
    from ..experiments import EXPERIMENTS  # the registry: one entry per experiment

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


#: Options of the multi-target form only, and of the one-target form only.
_MANY_ONLY = (("landmarks_file", "--landmarks-file"), ("truth_dir", "--truth-dir"),
              ("mesh_out_dir", "--mesh-out-dir"), ("coordinator", "--coordinator"),
              ("num_processes", "--num-processes"), ("process_id", "--process-id"),
              ("batch", "--batch"), ("timeout", "--timeout"))
_ONE_ONLY = (("out", "--out"), ("landmarks", "--landmarks"), ("mesh_out", "--mesh-out"),
             ("truth", "--truth"))


#: Options whose value may start with "-" (a negative number, or landmarks "-1,2:3,4"):
#: argparse would take such a value for an option and answer with its usage text.
_VALUE_OPTIONS = ("--landmarks", "--seed", "--functions", "--pairs", "--levels", "-k", "--k",
                  "--threshold", "--num-processes", "--process-id", "--timeout")


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
    from .._util import check_outputs, input_problem

    for attr, opt, lo in _INT_OPTIONS:
        v = getattr(args, attr, None)
        if isinstance(v, int) and v < lo:
            raise CLIError(f"{opt} must be an integer >= {lo}, got {v}")
    cmd = args.command
    if cmd == "transfer":
        _check_transfer_form(args)
        if args.render:
            check_render_available()
        t = args.threshold
        if t is not None and not 0 <= t < 1:  # nan fails both comparisons
            raise CLIError(f"--threshold must be a number in [0, 1), got {t!r}")
        estimate = args.out_dir is not None or not args.map or args.map[0] == "estimate"
        if estimate and args.k < 2:
            raise CLIError(f"-k must be an integer >= 2 to estimate a map (--map estimate), "
                           f"got {args.k}")
        if args.out_dir is not None:
            for opt, path in (("source", args.source), ("--labels", args.labels),
                              ("--function", args.function),
                              ("--landmarks-file", args.landmarks_file)):
                if path is not None and input_problem(path):
                    raise CLIError(f"{opt} {path}: {input_problem(path)}")
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
            if path is not None and input_problem(path):  # before the meshes are read
                raise CLIError(f"{opt} {path}: {input_problem(path)}")
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
