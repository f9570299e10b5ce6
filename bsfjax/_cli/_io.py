"""The files of ``bsfjax transfer``: what it reads (labels, functions, maps, truths) and writes.

Labels may come as one integer per vertex (``.txt`` / ``.npy``), as SMPL's ``.json``
``{part name: [vertex indices]}`` ([`bsfjax.load_labels`][bsfjax.load_labels]), or as one integer per triangle
(``.seg``, or a ``.txt`` / ``.npy`` with as many entries as the source has triangles;
[`bsfjax.transfer_face_labels`][bsfjax.transfer_face_labels]); a transfer of ``.json`` labels can be written as
``.json`` with the source's part names ([`bsfjax.save_labels`][bsfjax.save_labels]).  Every such file
is numbered by the rows of its mesh file, not by the vertices its reader kept
([`Mesh.to_file_rows`][bsfjax.Mesh.to_file_rows]).
"""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path


class CLIError(ValueError):
    """Bad command-line input (reported as one line)."""


def _read_array(path: str, what: str, dtype=None):
    import numpy as np

    from .._util import input_problem

    p = Path(path)
    if input_problem(p):
        raise CLIError(f"{what} file {p}: {input_problem(p)}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # loadtxt on an empty file
            arr = np.load(p, allow_pickle=False) if p.suffix == ".npy" else np.loadtxt(p, ndmin=1)
    except Exception as exc:
        raise CLIError(f"{what} file {p}: cannot read ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from exc
    if arr.size == 0:
        raise CLIError(f"{what} file {p}: no data")
    if not np.issubdtype(arr.dtype, np.number):
        raise CLIError(f"{what} file {p}: expected numbers, got dtype {arr.dtype}")
    if np.iscomplexobj(arr):  # not cut to the real part
        raise CLIError(f"{what} file {p}: expected real numbers, got complex values (dtype "
                       f"{arr.dtype})")
    if dtype is int and not np.issubdtype(arr.dtype, np.integer):
        from .._util import non_integer_entry

        i = non_integer_entry(arr)
        if i is not None:  # the value as read, not as a wrapped-around int64
            raise CLIError(f"{what} file {p}: expected integers, found {arr.reshape(-1)[i].item()!r} "
                           f"(entry {i})")
        arr = arr.astype(np.int64)
    return arr


def _write_array(path: str, arr, names=None) -> None:
    """``arr`` to ``path``, atomically: labels (1-D integers) by [`bsfjax.save_labels`][bsfjax.save_labels]
    (``.txt``, ``.npy``, ``.json`` with their part ``names``, ``.seg``), functions as ``.txt``
    or ``.npy``."""
    import numpy as np

    from .._util import atomic_path
    from .._mesh import save_labels

    p = Path(path)
    if arr.ndim == 1 and np.issubdtype(arr.dtype, np.integer):
        return save_labels(p, arr, names)
    if p.suffix not in (".npy", ".txt"):
        raise CLIError(f"--out {p}: use a .txt or .npy file name (labels: also .json or .seg)")
    with atomic_path(p) as tmp:
        if p.suffix == ".npy":
            with open(tmp, "wb") as fh:
                np.save(fh, arr)
        else:
            np.savetxt(tmp, arr, fmt="%.8g")


def is_json(path) -> bool:
    return path is not None and Path(path).suffix.lower() == ".json"


def read_labels(path: str, what: str):
    """``(labels (n,) int, names)`` of a labels file ([`bsfjax.load_labels`][bsfjax.load_labels], which reads
    every labels file of the command): ``names`` the part names of a ``.json`` file, else
    ``None``."""
    from .._mesh import read_label_file

    return read_label_file(path, what)


def read_truth(path: str, names):
    """A ``--truth`` labels file, its labels numbered as the ``--labels`` file's part ``names``
    where both are ``.json`` (each numbers its own parts in sorted order, so a truth that
    lacks a part the source has would otherwise be compared label for label with other
    parts)."""
    import numpy as np

    truth, truth_names = read_labels(path, "truth")
    if names is None or truth_names is None or truth_names == tuple(names):
        return truth
    index = {name: i for i, name in enumerate(names)}
    unknown = [n for n in truth_names if n not in index]
    if unknown:
        raise CLIError(f"truth file {path}: parts {unknown} are not parts of the labels file")
    return np.asarray([index[n] for n in truth_names])[truth]


def read_values(args, source, on_mesh: bool = True):
    """The ``--labels`` (int, ``(n,)``) or ``--function`` (``(m, n)``) of a transfer from the
    mesh ``source``, checked; the labels' part names (``.json`` labels; else ``None``); and
    whether the labels are one per triangle (a ``.seg`` file, or as many labels as ``source``
    has triangles and not vertices).  The files are read in the rows of the source's file;
    ``on_mesh``: the values are returned on the vertices (triangles) its reader kept, else in
    those rows."""
    from .._mesh import is_face_file

    import numpy as np

    # every file is read in its rows: n (m) rows of the source's file, mapped onto the
    # vertices (triangles) its reader kept
    names, per_face, n, m = None, False, source.n_file_rows, source.n_file_faces
    if args.labels:
        values, names = read_labels(args.labels, "labels")
        per_face = is_face_file(args.labels) or (
            not is_json(args.labels) and values.shape[-1] == m != n)
        if per_face and values.shape != (m,):
            raise CLIError(f"labels file {args.labels}: a .seg file has one label per triangle "
                           f"({m} on the source mesh), got {values.shape[-1]}")
        last = n - 1 if source.vertex_ids is None else int(source.vertex_ids[-1])
        if is_json(args.labels) and last < values.shape[-1] < n:  # dropped rows in no part
            values = np.concatenate([values, np.full(n - values.shape[-1], -1, values.dtype)])
    else:
        values = _read_array(args.function, "function")
    if not per_face and values.shape[0] != n:
        also = f" and {m} triangles" if args.labels else ""
        raise CLIError(f"{'labels' if args.labels else 'function'} file has {values.shape[0]} "
                       f"entries per function but the source mesh has {n} vertices{also}")
    if on_mesh:
        values = source.from_file_rows(values, faces=per_face)
    return (values.T if values.ndim == 2 else values), names, per_face


def part_list(ids, names=None) -> str:
    """``leftHand, rightFoot`` (``names``: part names by label; else the label numbers), or
    ``none``."""
    if len(ids) == 0:
        return "none"
    return ", ".join(names[i] if names is not None and 0 <= i < len(names) else str(i)
                     for i in map(int, ids))


def dropped_note(mesh, per_face: bool = False) -> str:
    """``"; ..."``: the rows of ``mesh``'s file its reader dropped, which an output leaves at
    -1 / NaN (empty when none)."""
    n = mesh.dropped_faces if per_face else mesh.dropped_rows
    if not n:
        return ""
    what = "triangles" if per_face else "rows"
    return f" ({n} {what} of {mesh.name or 'the target'} carry no surface: -1 / NaN there)"


def coloured_data(result, labels: bool) -> dict:
    """PLY properties of a transfer, per vertex or per triangle: the result and its colours."""
    import numpy as np

    if labels:
        from .._plot import label_colour  # the segmentation palette of the figures

        rgb = label_colour(result)
        data = {"label": result}
    else:
        from matplotlib import colormaps

        v = result if result.ndim == 1 else result[:, 0]
        seen = v[np.isfinite(v)]  # (NaN on the rows of the file without a vertex)
        lo, hi = (float(seen.min()), float(seen.max())) if seen.size else (0.0, 1.0)
        rgb = colormaps["viridis"]((v - lo) / (hi - lo if hi > lo else 1.0))[:, :3]
        data = {"value": v}
    rgb8 = np.clip(np.round(255 * rgb), 0, 255).astype(np.uint8)
    data.update(red=rgb8[:, 0], green=rgb8[:, 1], blue=rgb8[:, 2])
    return data


def map_estimator(args, k: int, refine_to: int | None = None):
    """The [`MapEstimator`][bsfjax.MapEstimator] of ``bsfjax transfer``: at ``k`` (ZoomOut to
    ``refine_to``), its single start ``(k, wks_variance)`` with ``--one-start``, else its
    default starts; ``--partial``: ``derived_guidance``."""
    from .._maps import MapEstimator

    default = MapEstimator(k=k, refine_to=refine_to,
                           derived_guidance=bool(getattr(args, "partial", False)))
    if not args.one_start:
        return default
    return dataclasses.replace(default, starts=((k, default.wks_variance),))


#: Said when [`bsfjax.estimate_map`][bsfjax.estimate_map]'s turn check could not tell which of its two maps is
#: turned front to back (``MapEstimate.turn_doubtful``).
TURN_DOUBT = ("the map may be turned front to back (left and right swapped): without "
              "landmarks the turn check's two measures disagree on this pair; give two landmark "
              "pairs")
