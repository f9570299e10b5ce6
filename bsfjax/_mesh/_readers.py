"""Reading mesh files with [`load_mesh`][bsfjax.load_mesh]. Owner of bsfjax's strict ASCII OFF
reader and its one-pass numpy fast path for the common layout (`_read_off`,
`_read_plain_off`), the PLY header check that guards meshio (`_check_ply`) and the meshio path
for every other format (`_read_meshio`, polygons fan-triangulated by `_triangulate`), and the
``.xyz`` point reader (`_read_xyz`).  A file with vertices and no faces is a
[`PointCloud`][bsfjax.PointCloud].
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import numpy as np

from .._util import MeshError
from .._util import not_regular
from ._clean import clean_mesh
from ._mesh import Mesh, PointCloud

__all__ = ["load_mesh"]


def _triangulate(cells) -> np.ndarray:
    """Fan-triangulate every polygon cell block (triangles pass through unchanged)."""
    tris = []
    for block in cells:
        data = np.asarray(block.data)
        if block.type in ("vertex", "line") or data.ndim != 2 or data.shape[1] < 3:
            continue
        if not block.type.startswith(("triangle", "quad", "polygon")):
            continue  # volume cells (tetra, hexahedron, ...) have no surface meaning here
        p = data.shape[1]
        for j in range(1, p - 1):  # p - 2 triangles per polygon: a loop over polygon size only
            tris.append(data[:, [0, j, j + 1]])
    if not tris:
        return np.zeros((0, 3), dtype=np.int64)
    return np.concatenate(tris, axis=0).astype(np.int64)


_BLANK = np.zeros(256, bool)
_BLANK[[9, 10, 13, 32]] = True
_ODD = np.zeros(256, bool)  # bytes that would make the fast reader's lines differ from splitlines'
_ODD[[0, 11, 12, 28, 29, 30, 31, 35]] = True  # NUL, VT, FF, FS…US, '#'
_ODD[128:] = True


def _read_plain_off(raw: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """The common OFF layout — a line ``OFF``, a line of three counts, ``nv`` lines of three
    coordinates, ``nf`` lines ``3 i j k``, no comments — parsed by numpy in one pass (2–6× the
    line-by-line reader on FAUST); ``None`` for anything else, which the strict reader then
    handles (and words its errors).  The layout is checked token by token per line first, so
    a file this path accepts gives exactly the strict reader's arrays."""
    b = np.frombuffer(raw, np.uint8)
    if b.size == 0 or _ODD[b].any():
        return None
    cr = np.flatnonzero(b == 13)
    if cr.size and (cr[-1] + 1 >= b.size or np.any(b[cr + 1] != 10)):
        return None  # a lone CR is a line break for splitlines: leave it to the strict reader
    blank = _BLANK[b]
    start = ~blank
    start[1:] &= blank[:-1]
    per_line = np.bincount(np.cumsum(b == 10)[start])
    per_line = per_line[per_line > 0]
    if per_line.size < 2 or per_line[0] != 1 or per_line[1] != 3:
        return None
    head = raw.split(None, 4)
    if head[0] != b"OFF":
        return None
    try:
        nv, nf = int(head[1]), int(head[2])
    except ValueError:
        return None
    if (nv <= 0 or nf < 0 or per_line.size != 2 + nv + nf or np.any(per_line[2:2 + nv] != 3)
            or np.any(per_line[2 + nv:] != 4)):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a token numpy cannot read: the count below says so
        try:
            values = np.fromstring(head[4], dtype=np.float64, sep=" ")
        except ValueError:
            return None
    if values.size != 3 * nv + 4 * nf:
        return None
    faces = values[3 * nv:].reshape(nf, 4)
    if np.any(faces[:, 0] != 3) or np.any(faces != np.round(faces)) \
            or np.any(np.abs(faces) >= 2.0 ** 53):
        return None
    return values[:3 * nv].reshape(nv, 3), faces[:, 1:].astype(np.int64)


def _read_off(p: Path) -> tuple[np.ndarray, np.ndarray]:
    """Read an ASCII OFF file (OFF/COFF/NOFF headers, polygons of any size, '#' comments).

    meshio's OFF reader accepts triangles only and exits the interpreter on bad input, so OFF,
    the format of the common shape-correspondence datasets, gets this strict reader.  Counts
    are checked against the file before anything is allocated.
    """
    raw = p.read_bytes()
    raw = raw[3:] if raw.startswith(b"\xef\xbb\xbf") else raw  # a UTF-8 byte-order mark
    fast = _read_plain_off(raw)
    if fast is not None:
        return fast
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        raise MeshError(f"{p}: cannot read mesh (not an ASCII OFF file; binary OFF is not "
                        "supported)") from exc
    lines = [ln.split("#", 1)[0].split() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    if not lines or not lines[0][0].upper().endswith("OFF"):
        raise MeshError(f"{p}: cannot read mesh (missing OFF header)")
    head = lines[0][1:] if len(lines[0]) > 1 else (lines[1] if len(lines) > 1 else [])
    body = lines[1:] if len(lines[0]) > 1 else lines[2:]
    try:
        nv, nf = int(head[0]), int(head[1])
    except (IndexError, ValueError) as exc:
        raise MeshError(f"{p}: cannot read mesh (bad OFF counts line {head!r})") from exc
    if nv < 0 or nf < 0:
        raise MeshError(f"{p}: cannot read mesh (negative counts {nv} vertices, {nf} faces)")
    if nv + nf > len(body):
        raise MeshError(f"{p}: cannot read mesh (header declares {nv} vertices and {nf} faces "
                        f"but the file has only {len(body)} data lines: truncated?)")
    if nv == 0:
        raise MeshError(f"{p}: mesh is empty (0 vertices)")
    short = [i for i, ln in enumerate(body[:nv]) if len(ln) < 3]
    if short:
        raise MeshError(f"{p}: cannot read mesh (every vertex line needs 3 coordinates; "
                        f"{len(short)} do not, first: vertex {short[0]})")
    try:
        verts = np.array([ln[:3] for ln in body[:nv]], dtype=np.float64)
    except ValueError as exc:
        raise MeshError(f"{p}: cannot read mesh (bad vertex line: {exc})") from exc
    groups: dict[int, list] = {}
    for ln in body[nv:nv + nf]:  # faces grouped by polygon size, then triangulated per group
        try:
            size = int(ln[0])
            idx = [int(t) for t in ln[1:1 + size]]
        except ValueError as exc:
            raise MeshError(f"{p}: cannot read mesh (bad face line {' '.join(ln)!r})") from exc
        if size < 3 or len(idx) != size:
            raise MeshError(f"{p}: cannot read mesh (bad face line {' '.join(ln)!r})")
        groups.setdefault(size, []).append(idx)
    tris = []
    for size, polys in groups.items():
        try:
            arr = np.asarray(polys, dtype=np.int64)
        except OverflowError:
            raise MeshError(f"{p}: face indices out of range (beyond 64-bit integers) for "
                            f"{nv} vertices") from None
        tris.extend(arr[:, [0, j, j + 1]] for j in range(1, size - 1))
    faces = np.concatenate(tris) if tris else np.zeros((0, 3), np.int64)
    return verts, faces


_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2,
              "uint16": 2, "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4,
              "double": 8, "float64": 8}


def _check_ply(p: Path) -> None:
    """Reject PLY files whose header is unterminated or whose counts exceed the file.

    meshio's PLY reader loops forever on a header without an ``end_header`` line and
    allocates whatever a header declares, so the header is parsed here first, line by line as
    meshio reads it (lines split at ``\\n``, stripped, ``comment`` lines skipped), and its
    element counts are checked against the bytes actually present.
    """
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(1 << 20)
    lines, offset, ended = [], 0, False
    while offset < len(head):
        nl = head.find(b"\n", offset)
        if nl < 0:
            break  # a header line must end with a newline (meshio reads to EOF otherwise)
        try:
            line = head[offset:nl].decode().strip()
        except UnicodeDecodeError:
            raise MeshError(f"{p}: cannot read mesh (PLY header is not text)") from None
        offset = nl + 1
        if line == "end_header":
            ended = True
            break
        lines.append(line)
    if not lines or lines[0] != "ply" or not ended:
        raise MeshError(f"{p}: cannot read mesh (PLY header missing or not terminated by an "
                        "end_header line)")
    body = size - offset
    fmt, min_bytes, rows_needed, current = "ascii", 0, 0, None
    for line in lines[1:]:
        if not line or line.startswith("comment"):
            continue
        tok = line.split()
        if tok[0] == "format" and len(tok) > 1:
            fmt = tok[1]
        elif line.startswith("element"):
            m = re.match(r"element (\S+) (\d+)", line)  # meshio's element regexes, generalized
            if m is None:
                raise MeshError(f"{p}: cannot read mesh (bad PLY element line {line!r})")
            current = int(m.group(2))
            rows_needed += current
        elif line.startswith("property") and current is not None:
            if len(tok) >= 5 and tok[1] == "list":  # a list holds at least its count
                min_bytes += current * _PLY_SIZES.get(tok[2], 1)
            elif len(tok) >= 3:
                min_bytes += current * _PLY_SIZES.get(tok[1], 1)
    if fmt == "ascii":
        # each element row is at least one line (two bytes) of the body
        if 2 * rows_needed > body + 1:
            raise MeshError(f"{p}: cannot read mesh (PLY header declares {rows_needed} element "
                            f"rows but only {body} bytes follow: truncated?)")
    elif min_bytes > body:
        raise MeshError(f"{p}: cannot read mesh (PLY header declares at least {min_bytes} bytes "
                        f"of data but only {body} follow: truncated?)")


def _ply_face_alias(p: Path):
    """``p``, or an in-memory copy whose face list ``vertex_index`` (the name some exporters
    use) is renamed ``vertex_indices``, the only name meshio reads."""
    import io

    with open(p, "rb") as fh:
        head = fh.read(1 << 20)
    end = head.find(b"end_header")
    alias = re.compile(rb"^(property\s+list\s+\S+\s+\S+\s+)vertex_index(\s*)$", re.M)
    if end < 0 or not alias.search(head[:end]):
        return p
    data = p.read_bytes()
    return io.BytesIO(alias.sub(rb"\1vertex_indices\2", data[:end]) + data[end:])


def _read_obj(p: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """Positions and faces of an OBJ file by position index, texture (``vt``) and normal
    (``vn``) indices ignored, or ``None`` when the file is not such an OBJ (meshio's message
    then stands).  meshio refuses the most common textured exports: more ``vt`` than ``v``
    (texture seams) or shared normals (``f a/b/c`` with fewer ``vn``)."""
    try:
        lines = p.read_text().splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    verts, polys = [], []
    for ln in lines:
        tok = ln.split("#", 1)[0].split()
        if not tok:
            continue
        if tok[0] == "v":
            if len(tok) < 4:
                return None
            try:
                verts.append([float(t) for t in tok[1:4]])
            except ValueError:
                return None
        elif tok[0] == "f":
            try:  # 1-based, as meshio reads them (relative indices are not supported)
                polys.append([int(t.split("/", 1)[0]) - 1 for t in tok[1:]])
            except ValueError:
                return None
            if len(polys[-1]) < 3:
                return None
    if not verts or not polys:
        return None
    tris = [[q[0], q[j], q[j + 1]] for q in polys for j in range(1, len(q) - 1)]
    try:
        faces = np.asarray(tris, dtype=np.int64)
    except OverflowError:
        return None
    return np.asarray(verts, np.float64), faces


def _read_meshio(p: Path) -> tuple[np.ndarray, np.ndarray]:
    import contextlib
    import io

    import meshio

    source = p
    if p.suffix.lower() == ".ply":
        _check_ply(p)
        source = _ply_face_alias(p)
    # meshio prints to stdout and calls sys.exit() when no reader accepts a file: capture both
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()), \
                warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # meshio's STL size probe overflows
            m = meshio.read(source, file_format=None if source is p else "ply")
    except (Exception, SystemExit) as exc:
        obj = _read_obj(p) if p.suffix.lower() == ".obj" else None
        if obj is not None:  # texture seams, shared normals: meshio wants one vt/vn per v
            return obj
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if isinstance(exc, SystemExit):
            msg = "unrecognized or malformed file"
        raise MeshError(f"{p}: cannot read mesh ({msg})") from exc
    pts = np.asarray(m.points)
    if pts.ndim != 2 or pts.shape[0] == 0:
        raise MeshError(f"{p}: mesh is empty (0 vertices)")
    if pts.shape[1] == 2:
        pts = np.concatenate([pts, np.zeros((pts.shape[0], 1))], axis=1)
    elif pts.shape[1] > 3:  # OBJ "v x y z w" or "v x y z r g b": the position comes first
        pts = pts[:, :3]
    try:
        faces = _triangulate(m.cells)
    except (OverflowError, TypeError, ValueError) as exc:  # e.g. indices beyond int64
        raise MeshError(f"{p}: cannot read mesh (bad face indices: {exc})") from None
    return pts, faces


def _read_xyz(p: Path) -> tuple[np.ndarray, np.ndarray]:
    """An ``.xyz`` point file: one point per row, ``x y z`` first (more columns, such
    as normals or colours, are ignored), blank lines and ``#`` comments skipped."""
    try:
        text = p.read_bytes().decode("ascii")
    except UnicodeDecodeError as exc:
        raise MeshError(f"{p}: cannot read points (not an ASCII .xyz file)") from exc
    rows = []
    for i, line in enumerate(text.splitlines()):
        tok = line.split("#", 1)[0].replace(",", " ").split()
        if not tok:
            continue
        if len(tok) < 3:
            raise MeshError(f"{p}: cannot read points (line {i + 1} has {len(tok)} numbers; "
                            "every row needs x y z)")
        rows.append(tok[:3])
    if not rows:
        raise MeshError(f"{p}: mesh is empty (0 vertices)")
    try:
        pts = np.array(rows, dtype=np.float64)
    except ValueError as exc:
        raise MeshError(f"{p}: cannot read points (bad number: {exc})") from exc
    return pts, np.zeros((0, 3), np.int64)


POINT_SUFFIXES = (".xyz",)


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Read a triangle or polygon mesh (OFF, PLY, OBJ, STL, and whatever else meshio reads).

    OFF goes through bsfjax's own strict ASCII reader; ``.xyz`` (one ``x y z`` row
    per point) through a plain text reader; other formats through meshio.  Polygons are
    fan-triangulated; zero-area faces and unreferenced vertices are removed with a warning that
    says how many ([`Mesh.to_file_rows`][bsfjax.Mesh.to_file_rows] maps results back
    to the file's rows).

    A file with vertices and no faces (PLY or OBJ with vertices only, an OFF with 0 faces, an
    ``.xyz`` file) gives a [`PointCloud`][bsfjax.PointCloud]: every point in its file row,
    none dropped or reordered.

    Missing or unreadable files, NaN/inf coordinates and out-of-range face indices raise
    [`MeshError`][bsfjax.MeshError] naming the file.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise MeshError(f"path must be a str or os.PathLike, got {type(path).__name__}")
    p = Path(path)
    if not p.exists():
        raise MeshError(f"{p}: no such file")
    if p.is_dir():
        raise MeshError(f"{p}: is a directory, not a mesh file")
    if not_regular(p):  # a FIFO would block the read
        raise MeshError(f"{p}: is {not_regular(p)}, not a regular file")
    try:
        suffix = p.suffix.lower()
        if suffix == ".off":
            pts, faces = _read_off(p)
        elif suffix in POINT_SUFFIXES:
            pts, faces = _read_xyz(p)
        else:
            pts, faces = _read_meshio(p)
    except OSError as exc:
        raise MeshError(f"{p}: cannot read file ({exc.strerror or exc})") from exc
    if faces.shape[0] == 0:
        return PointCloud(pts, name=str(p))
    return clean_mesh(pts, faces, name=str(p))
