"""``bsfjax view``: the polyscope viewer of a source and its targets, their part labels, a
result and its truth (`bsfjax.plot.view`), or their PNG renders without a display
(``--screenshot DIR``, `bsfjax.plot.render`); and ``bsfjax transfer --render DIR``, the renders
of each target of a run.

Every labels file is read in the rows of its mesh's file (as ``bsfjax transfer`` writes them):
a ``.json`` ``{part: [vertices]}`` file is numbered by the source's part names (its
``unassigned`` part is ``−1``), a ``.txt`` / ``.npy`` file holds one integer per row, ``−1``
unassigned.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ._io import CLIError

#: The cameras of ``bsfjax transfer --render`` (each target: one PNG per view).
RENDER_VIEWS = ("front", "back")


def add_view_parser(sub) -> None:
    """The ``view`` sub-command of the ``bsfjax`` parser."""
    p = sub.add_parser("view", help="look at meshes, their part labels and a transfer's result "
                       "in polyscope (pip install 'bsfjax[view]'), or render them to PNGs")
    p.add_argument("source", help="source mesh or point cloud (OFF, PLY, OBJ, ...)")
    p.add_argument("target", nargs="*", help="target meshes, shown next to the source")
    p.add_argument("--labels", help="part labels of the source (.json, .txt, .npy, .seg)")
    p.add_argument("--result", nargs="+", default=None, metavar="R",
                   help="labels on each target (as bsfjax transfer --out wrote them), one file "
                        "per target")
    p.add_argument("--truth", nargs="+", default=None, metavar="T",
                   help="true labels of each target (one file per target, or one for all): "
                        "wrong areas in red, accuracy and per-part IoU")
    p.add_argument("--function", nargs="+", default=None, metavar="F",
                   help="per-vertex values (.txt / .npy) of the source, then of the targets")
    p.add_argument("--layout", choices=("side", "one"), default="side",
                   help="side by side (default) or one shape at a time")
    p.add_argument("--up", default="y", help="up axis of the shapes: x, y, z, -x, -y, -z "
                   "(default y)")
    p.add_argument("--screenshot", metavar="DIR", help="render PNGs to DIR headless (EGL) "
                   "instead of opening a window")
    p.add_argument("--views", default="front", help="--screenshot: comma-separated cameras "
                   "front, back, side, right or angles in degrees (default front)")
    p.add_argument("--size", default="1200x600", help="--screenshot: WIDTHxHEIGHT in pixels "
                   "(default 1200x600)")
    p.add_argument("--prefix", default="view", help="--screenshot: file name start (default "
                   "view)")
    p.add_argument("--backend", choices=("auto", "window", "egl", "mock"), default="auto",
                   help="polyscope backend (default auto: a window with a display, else EGL "
                        "for --screenshot; mock: no rendering, for tests)")
    p.set_defaults(func=_cmd_view)


def check_render_available() -> None:
    """A one-line error, before a run, when ``--render`` cannot work (no polyscope)."""
    import importlib.util

    if importlib.util.find_spec("polyscope") is None:
        raise CLIError("--render needs polyscope: pip install 'bsfjax[view]'")


def _read_on(path: str, mesh, names, what: str):
    """Labels of ``mesh`` from a file in its file's rows (per vertex, or per triangle)."""
    import numpy as np

    from .._mesh import UNASSIGNED_PART, is_face_file, load_labels

    if Path(path).suffix.lower() == ".json":
        lab, own = load_labels(path)
        if names is not None:
            index = {n: i for i, n in enumerate(names)}
            index[UNASSIGNED_PART] = -1
            unknown = [n for n in own if n not in index]
            if unknown:
                raise CLIError(f"{what} {path}: parts {unknown} are not parts of the labels file")
            lab = np.asarray([index[n] for n in own], np.int64)[lab]
        elif UNASSIGNED_PART in own:
            un = own.index(UNASSIGNED_PART)
            lab = np.where(lab == un, -1, lab - (lab > un))
        n = mesh.n_file_rows
        if lab.shape[0] < n:  # the last rows in no part (dropped rows)
            lab = np.concatenate([lab, np.full(n - lab.shape[0], -1, np.int64)])
    else:
        from ._io import _read_array

        lab = _read_array(path, what)
        if lab.ndim != 1 or not np.all(np.mod(lab, 1) == 0):
            raise CLIError(f"{what} {path}: expected one integer label per row, got shape "
                           f"{lab.shape}")
        lab = lab.astype(np.int64)
    faces = is_face_file(path) or (lab.shape[0] == mesh.n_file_faces != mesh.n_file_rows)
    n = mesh.n_file_faces if faces else mesh.n_file_rows
    if lab.shape != (n,):
        raise CLIError(f"{what} {path}: expected one label per {'triangle' if faces else 'row'} "
                       f"of {mesh.name} ({n}), got {lab.shape[0]}")
    return mesh.from_file_rows(lab, faces=faces)


def _label_names(path):
    from .._mesh import load_labels

    return load_labels(path).names if path and Path(path).suffix.lower() == ".json" else None


def _size(text: str):
    try:
        w, h = (int(x) for x in text.lower().split("x"))
        return w, h
    except ValueError:
        raise CLIError(f"--size must be WIDTHxHEIGHT in pixels, got {text!r}") from None


def _cmd_view(args) -> int:
    import numpy as np

    from .._mesh import load_mesh
    from .._plot import render, view
    from ._io import _read_array

    source = load_mesh(args.source)
    targets = [load_mesh(t) for t in args.target]
    meshes = [source, *targets]
    names = _label_names(args.labels)
    labels = None if args.labels is None else _read_on(args.labels, source, names, "labels")
    results = truths = None
    if args.result is not None:
        if len(args.result) != len(targets):
            raise CLIError(f"--result: give one file per target ({len(targets)}), got "
                           f"{len(args.result)}")
        results = [_read_on(p, t, names, "result") for p, t in zip(args.result, targets)]
    if args.truth is not None:
        if results is None:
            raise CLIError("--truth compares a result with the truth: give --result too")
        files = args.truth * len(targets) if len(args.truth) == 1 else args.truth
        if len(files) != len(targets):
            raise CLIError(f"--truth: give one file, or one per target ({len(targets)}), got "
                           f"{len(args.truth)}")
        truths = [_read_on(p, t, names, "truth") for p, t in zip(files, targets)]
    function = None
    if args.function is not None:
        if len(args.function) > len(meshes):
            raise CLIError(f"--function: at most one file per shape ({len(meshes)})")
        function = [m.from_file_rows(_read_array(p, "function").reshape(m.n_file_rows, -1)[:, 0])
                    for p, m in zip(args.function, meshes)]
    shown = [Path(m.name).stem for m in meshes]
    shown = shown if len(set(shown)) == len(shown) else [f"{i}: {s}" for i, s in enumerate(shown)]
    common = dict(labels=labels, results=results, truth=truths, function=function, names=shown,
                  label_names=names, layout=args.layout, up=args.up, backend=args.backend)
    if args.screenshot:
        views = [v.strip() for v in args.views.split(",") if v.strip()]
        views = [float(v) if v.lstrip("-").replace(".", "", 1).isdigit() else v for v in views]
        scene = render(source, targets, args.screenshot, views=views, size=_size(args.size),
                       prefix=args.prefix, **common)
        print(f"wrote {len(scene.paths)} PNGs to {args.screenshot}: "
              + ", ".join(p.name for p in scene.paths))
    else:
        scene = view(source, targets, **common)
    for name, sc in scene.scores.items():
        worst = min(sc["iou"].items(), key=lambda kv: kv[1])
        print(f"{name}: {sc['accuracy']:.1%} of the area right, {sc['unassigned']:.1%} "
              f"unassigned, mean IoU {np.mean(list(sc['iou'].values())):.3f} (worst: {worst[0]} "
              f"{worst[1]:.3f})")
    return 0


def render_run(args, target, result, names, per_face: bool, truth_path=None) -> None:
    """``bsfjax transfer --render DIR``: the source (its ``--labels`` or ``--function``) and
    ``target`` (a path) with ``result`` (in the target file's rows), and the errors against
    ``truth_path`` where given, to ``DIR/<target name>_<view>.png``."""
    import numpy as np

    from .._mesh import load_mesh
    from .._plot import render
    from ._io import read_values

    source, tgt = load_mesh(args.source), load_mesh(target)
    values, _, _ = read_values(args, source)
    res = tgt.from_file_rows(np.asarray(result), faces=per_face)
    stem = Path(target).stem
    common = dict(names=["source", stem], label_names=names, views=RENDER_VIEWS, prefix=stem)
    if args.labels:
        truth = None if truth_path is None else [_read_on(str(truth_path), tgt, names, "truth")]
        scene = render(source, tgt, args.render, labels=values, results=[res.astype(np.int64)],
                       truth=truth, **common)
    else:
        src_f = values[0] if values.ndim == 2 else values  # the first function
        tgt_f = res[:, 0] if res.ndim == 2 else res
        scene = render(source, tgt, args.render, function=[src_f, tgt_f], **common)
    print(f"rendered {', '.join(str(p) for p in scene.paths)}", file=sys.stderr)
