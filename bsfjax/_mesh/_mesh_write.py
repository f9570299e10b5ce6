"""Writing meshes, with per-vertex and per-triangle data (a transferred segmentation, its
colours).  meshio writes every format; PLY files with per-triangle data are written here,
because meshio's PLY writer drops them (MeshLab shows ``red``/``green``/``blue`` face
properties as face colours)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._util import BSFError, MeshError
from .._util import atomic_path
from ._mesh import Mesh
from ._interop import as_mesh

__all__ = ["save_mesh"]

#: PLY property types of the array dtypes written (64-bit integers go as 32-bit: PLY has none).
_PLY_TYPES = {"f8": "double", "f4": "float", "i4": "int", "u4": "uint", "i2": "short",
              "u2": "ushort", "i1": "char", "u1": "uchar"}


def _checked(data: dict | None, n: int, what: str, where: str, small_ints: bool) -> dict:
    out = {}
    for key, val in (data or {}).items():
        arr = np.asarray(val)
        if arr.shape[:1] != (n,):
            raise MeshError(f"{what}[{key!r}] has {arr.shape[0] if arr.ndim else 'no'} rows, "
                            f"mesh has {n} {where}")
        if small_ints and arr.dtype == np.int64:
            arr = arr.astype(np.int32)
        if arr.dtype == np.bool_:
            arr = arr.astype(np.uint8)
        out[key] = arr
    return out


def save_mesh(path: str | os.PathLike, mesh: Mesh, point_data: dict | None = None, *,
              cell_data: dict | None = None, immediate: bool = False) -> None:
    """Write ``mesh`` (and optional per-vertex arrays) atomically; format from the extension.

    ``point_data`` maps names to arrays of length ``n_vertices`` (e.g. a transferred
    segmentation or an error map).  PLY keeps them as vertex properties that MeshLab shows;
    ``red``/``green``/``blue`` uint8 arrays become vertex colours.  ``cell_data``: the same per
    triangle (``n_faces`` rows; PLY files only), e.g. a segmentation given per triangle and its
    face colours.  ``immediate``: as `bsfjax._util._files.atomic_path` (in place at once, even
    inside an output transaction).
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    import meshio

    if not isinstance(mesh, Mesh):
        raise MeshError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    import contextlib
    import io

    from meshio._helpers import _filetypes_from_path  # format lookup by extension

    dest = Path(path)
    try:
        _filetypes_from_path(dest)
    except Exception as exc:
        raise MeshError(f"{dest}: cannot write mesh (unknown format {dest.suffix!r}; use .ply, "
                        ".off, .obj, .stl, ...)") from exc
    small_ints = dest.suffix.lower() == ".ply"  # PLY has no 64-bit integers
    data = _checked(point_data, mesh.n_vertices, "point_data", "vertices", small_ints)
    if cell_data:
        if not small_ints:
            raise MeshError(f"{dest}: per-triangle data (cell_data) is written to .ply files only")
        cells = _checked(cell_data, mesh.n_faces, "cell_data", "triangles", True)
        with atomic_path(dest, immediate=immediate) as tmp:
            _write_ply(tmp, mesh, data, cells)
        return
    faces = np.asarray(mesh.faces, dtype=np.int32 if small_ints else np.int64)
    out = meshio.Mesh(np.asarray(mesh.vertices), [("triangle", faces)], point_data=data)
    try:
        with atomic_path(dest, immediate=immediate) as tmp, \
                contextlib.redirect_stdout(io.StringIO()):
            meshio.write(tmp, out)  # the temp name keeps the extension meshio reads
    except MeshError:
        raise
    except BSFError as exc:  # an OSError, already worded with the user's path
        raise MeshError(str(exc)) from None
    except (meshio.WriteError, ValueError, KeyError) as exc:
        raise MeshError(f"{dest}: cannot write mesh ({exc})") from exc


def _ply_columns(data: dict) -> tuple[list[str], list[np.ndarray], list[str]]:
    """Header lines, columns and ``%`` formats of one-column or many-column arrays (columns
    ``name_0``, ``name_1``, … of a 2-D array)."""
    header, cols, fmts = [], [], []
    for key, arr in data.items():
        code = arr.dtype.str[1:]
        if code not in _PLY_TYPES:
            raise MeshError(f"{key!r}: PLY has no property type for dtype {arr.dtype}")
        flat = arr.reshape(arr.shape[0], -1)
        names = [key] if arr.ndim == 1 else [f"{key}_{j}" for j in range(flat.shape[1])]
        header += [f"property {_PLY_TYPES[code]} {name}" for name in names]
        cols += list(flat.T)
        fmts += ["%.17g" if arr.dtype.kind == "f" else "%d"] * len(names)
    return header, cols, fmts


def _write_ply(tmp, mesh: Mesh, point_data: dict, cell_data: dict) -> None:
    """ASCII PLY to the temporary path ``tmp`` of an atomic write: coordinates and
    ``point_data`` per vertex, the triangle and ``cell_data`` per face.  ASCII because
    meshio's (and so [`bsfjax.load_mesh`][bsfjax.load_mesh]'s) binary PLY reader cannot read faces with
    properties; its ASCII reader can."""
    vhead, vcols, vfmt = _ply_columns(point_data)
    fhead, fcols, ffmt = _ply_columns(cell_data)
    header = ["ply", "format ascii 1.0", f"element vertex {mesh.n_vertices}",
              "property double x", "property double y", "property double z", *vhead,
              f"element face {mesh.n_faces}", "property list uchar int vertex_indices", *fhead,
              "end_header"]
    v = np.asarray(mesh.vertices)
    verts = np.rec.fromarrays([v[:, 0], v[:, 1], v[:, 2], *vcols])
    f = np.asarray(mesh.faces)
    faces = np.rec.fromarrays([np.full(mesh.n_faces, 3), f[:, 0], f[:, 1], f[:, 2], *fcols])
    with open(tmp, "w") as fh:
        fh.write("\n".join(header) + "\n")
        np.savetxt(fh, verts, fmt=["%.17g"] * 3 + vfmt)
        np.savetxt(fh, faces, fmt=["%d"] * 4 + ffmt)
