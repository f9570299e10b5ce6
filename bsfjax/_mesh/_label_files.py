"""Segmentation files: one label per vertex, in the forms users have them.

* ``.json`` ``{part name: [vertex indices]}``, the SMPL body-part format (the 24-part
  ``smpl_vert_segmentation.json`` of the SMPL / FAUST template).  A vertex listed in several
  parts takes the first in sorted name order (the SMPL file lists some border vertices twice);
  every vertex up to the largest index must be listed.  Label ``l`` is the ``l``-th name in
  sorted order.
* ``.txt`` / ``.npy``: one non-negative integer per vertex (no names: a label is its own
  name, and an id of 10¹² allocates nothing).
* ``.seg``: one non-negative integer per *triangle*, the form of the Princeton Segmentation
  Benchmark and COSEG (`is_face_file`; transferred with
  [`bsfjax.transfer_face_labels`][bsfjax.transfer_face_labels]).  A ``.txt`` / ``.npy`` file with one label per
  triangle is read the same way; which one it is, only the mesh tells.

[`load_labels`][bsfjax.load_labels] reads both; [`save_labels`][bsfjax.save_labels] writes a segmentation atomically, a
transferred one in the form and with the part names of its source (``bsfjax transfer --labels
parts.json --out target_parts.json``).
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._util import BSFError
from .._util import atomic_path, write_text_atomic
from .._util import non_integer_entry
from .._util import input_problem

__all__ = ["LabelFile", "load_labels", "save_labels", "is_face_file", "UNASSIGNED_PART"]

#: Suffixes of files with one label per triangle.
FACE_SUFFIXES = (".seg",)

#: The part under which [`save_labels`][bsfjax.save_labels] lists unassigned vertices (label −1) in ``.json``.
UNASSIGNED_PART = "unassigned"


def is_face_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` names a file of one label per triangle (``.seg``) by its suffix."""
    return Path(path).suffix.lower() in FACE_SUFFIXES


class LabelFile(NamedTuple):
    """A segmentation read by [`load_labels`][bsfjax.load_labels]."""

    labels: np.ndarray  # (n,) int64, one label ≥ 0 per vertex
    names: tuple[str, ...] | None  # names[l]: the name of label l (.json); None otherwise


def load_labels(path: str | os.PathLike) -> LabelFile:
    """Read a segmentation file (module doc): ``(labels, names)``.

    **Arguments:**

    - `path`: a ``.json`` ``{part name: [vertex indices]}`` file, a ``.txt`` / ``.npy``
      file of one non-negative integer label per vertex, or a ``.seg`` file of one per
      triangle.

    **Returns:**

    [`LabelFile`][bsfjax.LabelFile] ``(labels (n,) int64, names)``.
    """
    return read_label_file(path, "labels")


def read_label_file(path, what: str) -> LabelFile:
    """[`load_labels`][bsfjax.load_labels], its messages naming the file as ``what`` (``bsfjax transfer``'s
    ``--truth`` files are read here too)."""
    path = Path(path)
    if input_problem(path):
        raise BSFError(f"{what} file {path}: {input_problem(path)}")
    if path.suffix.lower() == ".json":
        return _load_json(path, what)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # loadtxt on an empty file
            lab = np.load(path, allow_pickle=False) if path.suffix.lower() == ".npy" \
                else np.loadtxt(path, ndmin=1)
    except (OSError, ValueError) as exc:
        why = (str(exc) or type(exc).__name__).splitlines()[0]
        raise BSFError(f"{what} file {path}: unreadable ({why})") from None
    lab = np.asarray(lab)
    expected = (f"{what} file {path}: expected one non-negative integer label per "
                f"{'triangle' if is_face_file(path) else 'vertex'}")
    if lab.ndim != 1 or lab.size == 0 or not np.issubdtype(lab.dtype, np.number):
        raise BSFError(f"{expected}, got {'no data' if lab.size == 0 else f'shape {lab.shape}'}"
                       f"{'' if np.issubdtype(lab.dtype, np.number) else f' of {lab.dtype}'}")
    i = non_integer_entry(lab, negative=False)
    if i is not None:
        raise BSFError(f"{expected}, found {lab[i].item()!r} (entry {i})")
    return LabelFile(lab.astype(np.int64), None)


def _load_json(path: Path, what: str) -> LabelFile:
    try:
        parts = json.loads(path.read_text())
        if not isinstance(parts, dict):
            raise TypeError(f"the file holds a {type(parts).__name__}, not an object")
    except (ValueError, TypeError, UnicodeDecodeError) as exc:
        raise BSFError(f"{what} file {path}: expected {{part name: [vertex indices]}} "
                       f"({exc})") from None
    names = tuple(sorted(parts))
    total = sum(len(v) for v in parts.values() if isinstance(v, list))
    for name in names:  # every value checked in Python, before anything is allocated
        val = parts[name]
        if not isinstance(val, list):
            raise BSFError(f"{what} file {path}: part {name!r} must be a list of vertex "
                           f"indices, got {json.dumps(val)[:40]}")
        for x in val:  # JSON true, 0.7 and "12" are not vertex indices
            if type(x) is not int:
                raise BSFError(f"{what} file {path}: part {name!r} has {json.dumps(x)[:40]}, "
                               "not an integer vertex index")
            if x < 0:
                raise BSFError(f"{what} file {path}: part {name!r} has {x}: negative vertex "
                               "indices are not vertices")
            if x >= total:
                raise BSFError(f"{what} file {path}: part {name!r} has vertex index {x}, but "
                               f"the file lists only {total} indices: at least "
                               f"{x + 1 - total} vertices are in no part")
    if not total:
        raise BSFError(f"{what} file {path}: no parts or no vertices")
    idx = [np.asarray(parts[n], dtype=np.int64) for n in names]
    lab = np.full(1 + max(int(i.max()) for i in idx if i.size), -1, np.int64)
    for i in reversed(range(len(names))):  # reversed: the first name wins
        lab[idx[i]] = i
    if (lab < 0).any():
        raise BSFError(f"{what} file {path}: {int((lab < 0).sum())} vertices are in no part "
                       f"(first: {int(np.flatnonzero(lab < 0)[0])})")
    return LabelFile(lab, names)


def save_labels(path: str | os.PathLike, labels, names=None, *, immediate: bool = False) -> None:
    """Write a segmentation atomically, in the form the suffix names (module doc).

    **Arguments:**

    - `path`: ``.json``, ``.txt``, ``.npy`` or (labels of triangles) ``.seg``.
    - `labels`: ``(n,)`` integer labels, ``-1`` for unassigned vertices (or triangles).
    - `names`: the name of each label (``.json``; default ``"0"``, ``"1"``, …).  Every name
      is written, a part with no vertex as an empty list, so a transferred segmentation keeps
      its source's parts; unassigned vertices go under `UNASSIGNED_PART`.
    - `immediate`: put the file in place at once even inside an output transaction
      (``bsfjax transfer --out-dir`` keeps each target's file as it finishes).
    """
    path = Path(path)
    lab = np.asarray(labels)
    if lab.ndim != 1 or not np.issubdtype(lab.dtype, np.integer) or (lab.size and lab.min() < -1):
        raise BSFError(f"labels must be (n,) integers >= -1, got shape {lab.shape} dtype "
                       f"{lab.dtype}")
    suffix = path.suffix.lower()
    if suffix not in (".json", ".txt", ".npy", *FACE_SUFFIXES):
        raise BSFError(f"labels file {path}: use a .json, .txt, .npy or .seg file name")
    if suffix == ".npy":
        with atomic_path(path, immediate=immediate) as tmp, open(tmp, "wb") as fh:  # (no suffix)
            np.save(fh, lab.astype(np.int64))
        return
    if suffix != ".json":  # one integer per line
        write_text_atomic(path, "".join(f"{v}\n" for v in lab.tolist()), immediate=immediate)
        return
    write_text_atomic(path, _json_text(lab, names), immediate=immediate)


def _json_text(lab: np.ndarray, names) -> str:
    """The ``.json`` form of [`save_labels`][bsfjax.save_labels] (checked labels)."""
    n_labels = int(lab.max()) + 1 if lab.size else 0
    names = tuple(str(i) for i in range(n_labels)) if names is None else tuple(map(str, names))
    if len(names) < n_labels or len(set(names)) != len(names):
        raise BSFError(f"names must be {n_labels} or more distinct part names, got {len(names)}")
    parts = {name: np.flatnonzero(lab == i).tolist() for i, name in enumerate(names)}
    if (lab < 0).any():
        if UNASSIGNED_PART in parts:
            raise BSFError(f"a part is named {UNASSIGNED_PART!r}, the name under which the "
                           f"unassigned vertices are written: rename it")
        parts[UNASSIGNED_PART] = np.flatnonzero(lab < 0).tolist()
    return json.dumps(parts) + "\n"
