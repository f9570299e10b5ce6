"""Reading a ``--data`` folder of meshes with ground-truth correspondences.

Accepted layouts (mesh files: ``.off``, ``.ply``, ``.obj``, ``.stl``; any case):

1. **Shared vertex order** (FAUST registrations, ``faust/``, ``tosca_10k/cat/``)::

       DIR/tr_reg_000.off  DIR/tr_reg_001.off  ...

   No ``.vts`` files: every mesh of the folder must have the same vertex count, and vertex ``i``
   of one shape corresponds to vertex ``i`` of every other (identity ground truth).  The face
   arrays may differ (as in ``tosca/cat``).

2. **Correspondence files** (the remeshed ``faust_5k/``, ``tosca_5k/<class>/``)::

       DIR/tr_reg_000.off ... and DIR/corres/tr_reg_000.vts ...   (or the .vts beside the mesh)

   ``X.vts`` holds one **1-based** vertex index of ``X`` per line; for shapes ``A`` and ``B``,
   vertex ``A.vts[k]`` corresponds to ``B.vts[k]``.  As soon as a folder has a ``corres/``
   subfolder or any ``.vts`` file, every mesh needs its ``<stem>.vts`` and all of them must have
   the same length.  Other ``.vts`` files (``*.sym.vts``, ``sampleID.vts``) are ignored.

3. **Classes** (TOSCA): ``DIR/<class>/`` subfolders, each of layout 1 or 2, and no meshes in
   ``DIR`` itself.  Pairs are formed only within a class.

Ground-truth point map of a pair (source ``M``, target ``N``): ``gt[i]`` is the source vertex of
target vertex ``i``.  With ``.vts`` files, target vertices listed there get their partner;
a target vertex not listed (a few per remeshed shape) takes the partner of the nearest listed
target vertex (Euclidean, on ``N``); if a target vertex is listed twice, the first entry wins.

Bad folders raise [`bsfjax.BSFError`][bsfjax.BSFError] naming the folder or file: a missing folder, no
meshes, a missing or malformed ``.vts``, out-of-range indices, ``.vts`` files of different
lengths, or meshes of different sizes without correspondence files.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property
from pathlib import Path

import numpy as np
import scipy.spatial

from .._util import BSFError, MeshError
from .._mesh import Mesh, load_mesh

__all__ = ["Dataset", "ShapeEntry", "load_dataset", "MESH_SUFFIXES"]

MESH_SUFFIXES = (".off", ".ply", ".obj", ".stl")


@dataclasses.dataclass(frozen=True)
class ShapeEntry:
    """One shape of a dataset: name, class, file, its mesh and its ``.vts`` indices."""

    name: str
    group: str
    path: Path
    mesh: Mesh
    vts: np.ndarray | None  #: 0-based vertex indices of the shared correspondence list

    @property
    def n_vertices(self) -> int:
        return self.mesh.n_vertices


@dataclasses.dataclass(frozen=True)
class Dataset:
    """The shapes of a ``--data`` folder (see the module doc for the layouts)."""

    root: Path
    shapes: tuple[ShapeEntry, ...]

    @cached_property
    def groups(self) -> dict[str, list[int]]:
        out: dict[str, list[int]] = {}
        for i, s in enumerate(self.shapes):
            out.setdefault(s.group, []).append(i)
        return out

    def all_pairs(self) -> list[tuple[int, int]]:
        """Every unordered pair ``(i, j)``, ``i < j``, of shapes in the same class."""
        return [(a, b) for idx in self.groups.values() for ia, a in enumerate(idx)
                for b in idx[ia + 1:]]

    def pairs(self, count: int | None = None, seed: int = 0) -> list[tuple[int, int]]:
        """``count`` pairs (source, target) drawn without repetition from `all_pairs`
        (all of them when ``count`` is ``None``), in a seed-determined order; classes take
        turns so that every class is represented when ``count ≥ number of classes``."""
        rng = np.random.default_rng(seed)
        per_group = []
        for idx in self.groups.values():
            ps = [(a, b) for ia, a in enumerate(idx) for b in idx[ia + 1:]]
            per_group.append([ps[i] for i in rng.permutation(len(ps))])
        order = [p for rnd in range(max(map(len, per_group), default=0))
                 for g in per_group if rnd < len(g) for p in [g[rnd]]]
        if not order:
            raise BSFError(f"{self.root}: need at least two shapes in one class to form a pair")
        if count is None:
            return order
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
            raise BSFError(f"pairs must be a positive int, got {count!r}")
        if count > len(order):
            raise BSFError(f"{self.root}: asked for {count} pairs but the folder only has "
                           f"{len(order)} ({len(self.shapes)} shapes)")
        return order[:count]

    def ground_truth(self, source: int, target: int) -> np.ndarray:
        """``(n_target,)`` int64 ground-truth map: source vertex of every target vertex."""
        s, t = self.shapes[source], self.shapes[target]
        if s.group != t.group:
            raise BSFError(f"{s.name} and {t.name} are in different classes ({s.group}, "
                           f"{t.group}): no ground truth")
        if s.vts is None:
            return np.arange(t.n_vertices, dtype=np.int64)
        gt = np.full(t.n_vertices, -1, dtype=np.int64)
        # reversed so that the first occurrence of a repeated target vertex is written last
        gt[t.vts[::-1]] = s.vts[::-1]
        listed = gt >= 0
        if not listed.all():
            tree = scipy.spatial.cKDTree(t.mesh.vertices[listed])
            _, nn = tree.query(t.mesh.vertices[~listed])
            gt[~listed] = gt[np.flatnonzero(listed)[nn]]
        return gt


def _mesh_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)


def _read_vts(path: Path, mesh: Mesh) -> np.ndarray:
    try:
        raw = np.loadtxt(path, dtype=np.int64, ndmin=1)
    except (ValueError, OSError) as exc:
        raise BSFError(f"{path}: not a .vts file (one 1-based integer vertex index per line): "
                       f"{exc}") from exc
    if raw.ndim != 1 or raw.size == 0:
        raise BSFError(f"{path}: expected one 1-based vertex index per line, got shape {raw.shape}")
    idx = raw - 1
    n_file = mesh.n_file_rows  # (rows the loader dropped included)
    if idx.min() < 0 or idx.max() >= n_file:
        raise BSFError(f"{path}: indices must be in 1..{n_file} (the vertices of the mesh), found "
                       f"{raw.min()}..{raw.max()}")
    if mesh.vertex_ids is not None:  # the loader dropped unreferenced vertices: renumber
        remap = np.full(n_file, -1, dtype=np.int64)
        remap[mesh.vertex_ids] = np.arange(mesh.n_vertices)
        idx = remap[idx]
        if idx.min() < 0:
            raise BSFError(f"{path}: lists vertices that the mesh loader removed (unreferenced)")
    return idx


def _load_group(folder: Path, group: str) -> list[ShapeEntry]:
    files = _mesh_files(folder)
    corres = folder / "corres"
    has_vts = corres.is_dir() or any(p.suffix.lower() == ".vts" for p in folder.iterdir())
    entries = []
    for p in files:
        try:
            mesh = load_mesh(p)
        except (MeshError, ValueError) as exc:
            raise BSFError(f"{p}: cannot read mesh: {exc}") from exc
        vts = None
        if has_vts:
            cands = [corres / f"{p.stem}.vts", folder / f"{p.stem}.vts"]
            found = next((c for c in cands if c.is_file()), None)
            if found is None:
                raise BSFError(f"{folder}: has correspondence files but none for mesh {p.name}: "
                               f"expected {cands[0] if corres.is_dir() else cands[1]}")
            vts = _read_vts(found, mesh)
        entries.append(ShapeEntry(p.stem, group, p, mesh, vts))
    if has_vts:
        lengths = {e.vts.size for e in entries}
        if len(lengths) > 1:
            detail = ", ".join(f"{e.name}.vts: {e.vts.size}" for e in entries)
            raise BSFError(f"{folder}: .vts files must all have the same length (entry k of each "
                           f"corresponds), got {detail}")
    else:
        sizes = {e.n_vertices for e in entries}
        if len(sizes) > 1:
            detail = ", ".join(f"{e.path.name} ({e.n_vertices} vertices)" for e in entries)
            raise BSFError(f"{folder}: meshes of different sizes and no correspondence files "
                           f"(corres/<name>.vts): {detail}")
    return entries


def load_dataset(path) -> Dataset:
    """Load every mesh of a ``--data`` folder and check its correspondences (module doc).

    **Raises:**

    - `BSFError`: a missing folder, no meshes, unreadable meshes, missing / malformed /
      inconsistent ``.vts`` files, or meshes of different sizes without ``.vts`` — the
      message names the folder or file.
    """
    root = Path(path)
    if not root.exists():
        raise BSFError(f"{root}: data folder does not exist")
    if not root.is_dir():
        raise BSFError(f"{root}: --data must be a folder of meshes, got a file")
    if _mesh_files(root):
        shapes = _load_group(root, root.name)
    else:
        subs = sorted(d for d in root.iterdir() if d.is_dir() and d.name != "corres"
                      and _mesh_files(d))
        if not subs:
            raise BSFError(f"{root}: no mesh files ({', '.join(MESH_SUFFIXES)}) in the folder or "
                           "in its class subfolders")
        shapes = [e for d in subs for e in _load_group(d, d.name)]
    return Dataset(root, tuple(shapes))
