"""Triangle meshes: the immutable [`Mesh`][bsfjax.Mesh] container and reading/writing through meshio.

This is the first stage of the pipeline (mesh → spectrum → frame → coefficients → transfer →
metrics) and depends on nothing else in bsfjax.
"""

from __future__ import annotations

import dataclasses
import os
import re
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph

from .._util import MeshError

__all__ = ["Mesh", "MeshError", "MeshReport", "load_mesh", "mesh_edges", "edge_graph",
           "graph_from_edges", "mesh_report", "n_components"]


#: Largest accepted ``|coordinate|``.  Face areas are norms of cross products of edges, whose
#: squares grow as ``|x|⁴`` (up to ``192 |x|⁴``): below 10⁷⁵ they stay finite in float64.
MAX_COORDINATE = 1e75


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class Mesh:
    """An immutable triangle mesh.

    Attributes:
        vertices: ``(n, 3)`` float64 coordinates (read-only array).
        faces: ``(m, 3)`` int64 vertex indices of the triangles (read-only array).
        vertex_ids: ``(n,)`` int64 index of each vertex in the file it was read from, or
            ``None`` when vertex ``i`` is row ``i`` of the source.  ``load_mesh`` drops
            unreferenced vertices; per-vertex data indexed like the file (labels, ground-truth
            correspondences) is brought onto the mesh with ``data[mesh.vertex_ids]``.
        name: where the mesh came from (a path), for error messages.

    The constructor validates its input and raises [`MeshError`][bsfjax.MeshError] on NaN/inf, complex or
    overflowing (``|x| > MAX_COORDINATE``) coordinates, ragged or wrongly shaped arrays,
    non-integer, out-of-range or negative face indices and empty meshes.  It does not clean:
    degenerate faces, isolated or duplicate vertices and non-manifold edges are counted by
    [`mesh_report`][bsfjax.mesh_report] and removed or reported by `clean_mesh` / [`load_mesh`][bsfjax.load_mesh].
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_ids: np.ndarray | None = None
    name: str | None = None

    def __post_init__(self):
        where = f"{self.name}: " if self.name else ""
        try:
            v = np.asarray(self.vertices)
        except (TypeError, ValueError) as exc:  # ragged nested lists, objects numpy rejects
            raise MeshError(f"{where}vertices must be an (n, 3) array of numbers ({exc})") from None
        try:
            f = np.asarray(self.faces)
        except (TypeError, ValueError) as exc:
            raise MeshError(f"{where}faces must be an (m, 3) array of vertex indices ({exc})") \
                from None
        if v.ndim != 2 or v.shape[1] != 3:
            raise MeshError(f"{where}vertices must have shape (n, 3), got {v.shape}")
        if v.shape[0] == 0:
            raise MeshError(f"{where}mesh is empty (0 vertices)")
        if not np.issubdtype(v.dtype, np.number) or np.issubdtype(v.dtype, np.complexfloating):
            raise MeshError(f"{where}vertices must be real numbers, got dtype {v.dtype}")
        v = v.astype(np.float64)
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            raise MeshError(
                f"{where}{int(bad.sum())} vertices have NaN or infinite coordinates "
                f"(first: vertex {int(np.flatnonzero(bad)[0])})"
            )
        big = float(np.abs(v).max())
        if big > MAX_COORDINATE:
            raise MeshError(f"{where}coordinates up to {big:.3g} overflow the geometry "
                            f"(squared lengths, areas); the limit is {MAX_COORDINATE:.0e}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise MeshError(f"{where}faces must have shape (m, 3), got {f.shape}")
        if f.shape[0] == 0:
            raise MeshError(f"{where}mesh has no faces")
        if not np.issubdtype(f.dtype, np.integer):
            if np.issubdtype(f.dtype, np.floating) and np.all(np.mod(f, 1) == 0):
                f = f.astype(np.int64)
            else:
                raise MeshError(f"{where}faces must be integer indices, got dtype {f.dtype}")
        f = f.astype(np.int64)
        lo, hi = int(f.min()), int(f.max())
        if lo < 0 or hi >= v.shape[0]:
            raise MeshError(
                f"{where}face indices out of range: found [{lo}, {hi}] for {v.shape[0]} vertices"
            )
        object.__setattr__(self, "vertices", _readonly(v))
        object.__setattr__(self, "faces", _readonly(f))
        if self.vertex_ids is not None:
            ids = np.asarray(self.vertex_ids)
            if not np.issubdtype(ids.dtype, np.integer):
                raise MeshError(f"{where}vertex_ids must be integer row indices, got dtype "
                                f"{ids.dtype}")
            ids = ids.astype(np.int64)
            if ids.shape != (v.shape[0],):
                raise MeshError(f"{where}vertex_ids must have shape ({v.shape[0]},), got {ids.shape}")
            object.__setattr__(self, "vertex_ids", _readonly(ids))

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def face_areas(self) -> np.ndarray:
        """``(m,)`` triangle areas ½‖(v₁−v₀)×(v₂−v₀)‖."""
        v = self.vertices
        e1 = v[self.faces[:, 1]] - v[self.faces[:, 0]]
        e2 = v[self.faces[:, 2]] - v[self.faces[:, 0]]
        return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)

    @property
    def area(self) -> float:
        """Total surface area."""
        return float(self.face_areas().sum())

    def __repr__(self) -> str:
        name = f", name={self.name!r}" if self.name else ""
        return f"Mesh(n_vertices={self.n_vertices}, n_faces={self.n_faces}{name})"


def mesh_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges ``(e, 2)`` (sorted pairs, lexicographic order) and, per face,
    the index of its edges ``(m, 3)`` in the order (v0v1, v1v2, v2v0)."""
    faces = np.asarray(faces, dtype=np.int64)
    if faces.size == 0:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3), np.int64)
    half = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    lo, hi = half.min(axis=1), half.max(axis=1)
    # one int64 key per sorted pair (lo·n + hi sorts like the pair): a 1-D unique is several
    # times faster than np.unique(..., axis=0) on rows
    n = int(hi.max()) + 1
    keys, inv = np.unique(lo * n + hi, return_inverse=True)
    edges = np.stack([keys // n, keys % n], axis=1)
    return edges, inv.reshape(3, -1).T


def graph_from_edges(n: int, edges: np.ndarray, weights: np.ndarray) -> sp.csr_matrix:
    """Symmetric ``(n, n)`` sparse graph with ``weights`` on ``edges`` (both directions).

    scipy's csgraph reads an explicit 0 as "no edge", so zero weights (duplicate vertices) are
    raised to the smallest positive float: their endpoints stay connected at distance ~0.
    """
    w = np.maximum(np.asarray(weights, dtype=np.float64), np.finfo(np.float64).tiny)
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    return sp.csr_matrix((np.concatenate([w, w]), (rows, cols)), shape=(n, n))


def edge_graph(mesh: "Mesh") -> sp.csr_matrix:
    """The mesh's edge graph weighted by edge length (for Dijkstra), ``(n, n)`` CSR."""
    e, _ = mesh_edges(mesh.faces)
    lengths = np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    return graph_from_edges(mesh.n_vertices, e, lengths)


class MeshReport(NamedTuple):
    """What [`mesh_report`][bsfjax.mesh_report] counts on a mesh (every field an ``int``).

    Attributes:
        n_vertices, n_faces: sizes.
        degenerate_faces: faces with a repeated vertex index or zero area.
        duplicate_faces: faces whose vertex set equals that of an earlier face.
        duplicate_vertices: vertices with exactly the coordinates of an earlier vertex.
        isolated_vertices: vertices that no face references.
        non_manifold_edges: edges shared by more than two faces.
        boundary_edges: edges of a single face.
        components: connected components of the face graph (isolated vertices count as
            components of their own).
    """

    n_vertices: int
    n_faces: int
    degenerate_faces: int
    duplicate_faces: int
    duplicate_vertices: int
    isolated_vertices: int
    non_manifold_edges: int
    boundary_edges: int
    components: int


def n_components(mesh: "Mesh", edges: np.ndarray | None = None) -> int:
    """Connected components of the mesh's edge graph (an isolated vertex is one of its own);
    ``edges`` from `mesh_edges` if already at hand."""
    if edges is None:  # the faces' half-edges as they are: no de-duplication needed here
        f = np.asarray(mesh.faces, dtype=np.int64)
        e = np.stack([f.ravel(), np.roll(f, -1, axis=1).ravel()], axis=1)
    else:
        e = edges
    g = sp.coo_matrix((np.ones(len(e), np.int32), (e[:, 0], e[:, 1])),
                      shape=(mesh.n_vertices,) * 2).tocsr()
    return int(scipy.sparse.csgraph.connected_components(g, directed=False)[0])


def _row_keys(a: np.ndarray) -> np.ndarray:
    """One opaque scalar per row (equal rows ⇔ equal keys), for fast 1-D ``np.unique``."""
    a = np.ascontiguousarray(a)
    return a.view(np.dtype((np.void, a.dtype.itemsize * a.shape[1]))).ravel()


def mesh_report(mesh: "Mesh") -> MeshReport:
    """Count the defects of ``mesh`` that the pipeline handles but a user should know about.

    ``load_mesh`` removes degenerate faces and isolated vertices and warns about duplicate
    vertices and non-manifold edges; [`bsfjax.spectrum`][bsfjax.spectrum] warns about several components.
    Cost: a few sorts of the ``(m, 3)`` faces and ``(n, 3)`` vertices.
    """
    if not isinstance(mesh, Mesh):
        raise MeshError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    f = mesh.faces
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    degenerate = int(np.sum(repeated | (mesh.face_areas() == 0)))
    dup_faces = f.shape[0] - np.unique(_row_keys(np.sort(f, axis=1))).shape[0]
    dup_verts = mesh.n_vertices - np.unique(_row_keys(mesh.vertices + 0.0)).shape[0]  # −0 → +0
    used = np.zeros(mesh.n_vertices, dtype=bool)
    used[f.ravel()] = True
    edges, face_edges = mesh_edges(f)
    per_edge = np.bincount(face_edges.ravel(), minlength=len(edges))
    return MeshReport(
        n_vertices=mesh.n_vertices, n_faces=mesh.n_faces, degenerate_faces=degenerate,
        duplicate_faces=int(dup_faces), duplicate_vertices=int(dup_verts),
        isolated_vertices=int((~used).sum()), non_manifold_edges=int(np.sum(per_edge > 2)),
        boundary_edges=int(np.sum(per_edge == 1)), components=n_components(mesh, edges))


def _warn_defects(mesh: "Mesh", stacklevel: int) -> None:
    """Warn (with counts) about the kept defects: duplicate vertices, non-manifold edges."""
    where = f"{mesh.name}: " if mesh.name else ""
    rep = mesh_report(mesh)
    if rep.duplicate_vertices:
        warnings.warn(f"{where}{rep.duplicate_vertices} duplicate vertices (same coordinates as "
                      "another vertex; kept: faces on either copy are not connected there)",
                      stacklevel=stacklevel + 1)
    if rep.non_manifold_edges:
        warnings.warn(f"{where}{rep.non_manifold_edges} non-manifold edges (shared by more than "
                      "two faces; kept: the cotangent Laplacian sums every face, "
                      "laplacian(..., robust=True) is better suited)", stacklevel=stacklevel + 1)


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


def clean_mesh(vertices: np.ndarray, faces: np.ndarray, name: str | None = None,
               area_tol: float = 0.0) -> Mesh:
    """Build a [`Mesh`][bsfjax.Mesh], dropping zero-area faces and unreferenced vertices with a warning.

    Duplicate vertices and non-manifold edges are kept, with a warning that counts them
    (see [`mesh_report`][bsfjax.mesh_report]).

    A face is degenerate when two of its indices coincide or its area is ``<= area_tol`` times the
    mean face area.  Vertices no face references are removed; ``Mesh.vertex_ids`` records the
    original index of every kept vertex.
    """
    where = f"{name}: " if name else ""
    probe = Mesh(vertices, faces, name=name)  # validates shapes, finiteness, indices
    v, f = probe.vertices, probe.faces
    areas = probe.face_areas()
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    degenerate = repeated | (areas <= area_tol * max(areas.mean(), np.finfo(float).tiny))
    if degenerate.any():
        warnings.warn(f"{where}removed {int(degenerate.sum())} zero-area faces", stacklevel=3)
        f = f[~degenerate]
        if f.shape[0] == 0:
            raise MeshError(f"{where}every face has zero area")
    used = np.zeros(v.shape[0], dtype=bool)
    used[f.ravel()] = True
    if not used.all():
        warnings.warn(
            f"{where}removed {int((~used).sum())} unreferenced vertices "
            "(Mesh.vertex_ids maps kept vertices to file rows)",
            stacklevel=3,
        )
        remap = np.cumsum(used) - 1
        mesh = Mesh(v[used], remap[f], vertex_ids=np.flatnonzero(used), name=name)
    else:
        mesh = Mesh(v, f, name=name)
    _warn_defects(mesh, stacklevel=3)
    return mesh


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


def _read_meshio(p: Path) -> tuple[np.ndarray, np.ndarray]:
    import contextlib
    import io

    import meshio

    if p.suffix.lower() == ".ply":
        _check_ply(p)
    # meshio prints to stdout and calls sys.exit() when no reader accepts a file: capture both
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()), \
                warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # meshio's STL size probe overflows
            m = meshio.read(p)
    except (Exception, SystemExit) as exc:
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


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Read a triangle or polygon mesh (OFF, PLY, OBJ, STL, and whatever else meshio reads).

    OFF goes through bsfjax's own strict ASCII reader; other formats through meshio.
    Polygons are fan-triangulated; zero-area faces and unreferenced vertices are removed with a
    warning that says how many (``Mesh.vertex_ids`` maps kept vertices to file rows).  Missing or
    unreadable files, NaN/inf coordinates, out-of-range face indices and meshes without faces
    raise [`MeshError`][bsfjax.MeshError] naming the file.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise MeshError(f"path must be a str or os.PathLike, got {type(path).__name__}")
    p = Path(path)
    if not p.exists():
        raise MeshError(f"{p}: no such file")
    if p.is_dir():
        raise MeshError(f"{p}: is a directory, not a mesh file")
    try:
        pts, faces = _read_off(p) if p.suffix.lower() == ".off" else _read_meshio(p)
    except OSError as exc:
        raise MeshError(f"{p}: cannot read file ({exc.strerror or exc})") from exc
    if faces.shape[0] == 0:
        raise MeshError(f"{p}: mesh has no faces (only triangle/polygon meshes are supported)")
    return clean_mesh(pts, faces, name=str(p))
