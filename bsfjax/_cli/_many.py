"""``bsfjax transfer SOURCE TARGET [TARGET ...] --out-dir DIR``: one source to many targets.

Targets are files, folders (their mesh files) or glob patterns.  Each target's result is
written as soon as it is computed, atomically: ``DIR/<stem>.txt`` (``DIR/<stem>.json`` with
the source's part names for ``.json`` labels, as [`bsfjax.save_labels`][bsfjax.save_labels];
``DIR/<stem>.seg`` for labels of triangles, as [`bsfjax.transfer_face_labels`][bsfjax.transfer_face_labels]; and
``MESH_DIR/<stem>.ply`` with ``--mesh-out-dir``); ``DIR/summary.json`` lists every target.
``--truth-dir`` holds ``<stem>.txt``, ``.npy``, ``.json`` or ``.seg``.  Every output path is
compared with every input path and with the others before any work (`check_run_paths`).
``DIR/manifest/<stem>.json`` records what each target's outputs were computed from (the
options, and sha256 checksums of the source, the labels, the target, its truth and
landmarks) and its summary row: a rerun skips the targets whose outputs are complete *and*
whose manifest matches (unless ``--overwrite``), so an interrupted run resumes, and a rerun
with other inputs or options recomputes the targets it changes.  A target that cannot be
read, solved, scored against its truth or written is reported in ``summary.json`` and
skipped, and the exit status is 1.  With ``--coordinator/--num-processes/--process-id`` (or
inside a SLURM or Open MPI job) the processes of ``jax.distributed`` share the targets; each
writes its own.
"""

from __future__ import annotations

import glob
import hashlib
import json
import sys
from pathlib import Path

from ._distributed import _initialize_distributed, check_backend, check_coordinator

MESH_SUFFIXES = (".off", ".ply", ".obj", ".stl", ".vtk", ".vtu", ".msh", ".mesh")
#: The truth files ``--truth-dir`` may hold per target, in the order they are looked for.
TRUTH_SUFFIXES = (".txt", ".npy", ".json", ".seg")
#: The folder of ``--out-dir`` holding each target's manifest, ``<stem>.json``.
MANIFEST_DIR = "manifest"


def expand_targets(patterns: list[str], error) -> list[Path]:
    """Files, folders (their mesh files, sorted) and glob patterns → distinct mesh paths."""
    out: list[Path] = []
    for pat in patterns:
        p = Path(pat)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in MESH_SUFFIXES)
            if not found:
                raise error(f"target folder {pat}: no mesh files ({', '.join(MESH_SUFFIXES)})")
        elif p.is_file():
            found = [p]
        elif glob.has_magic(pat):
            found = sorted(Path(q) for q in glob.glob(pat) if Path(q).is_file())
            if not found:
                raise error(f"target pattern {pat!r}: matches no file")
        else:
            raise error(f"target {pat}: no such file")
        out.extend(found)
    seen, unique = set(), []
    for p in out:
        r = p.resolve()
        if r not in seen:
            seen.add(r)
            unique.append(p)
    stems: dict[str, Path] = {}
    for p in unique:
        if p.stem in stems:
            raise error(f"targets {stems[p.stem]} and {p} have the same name {p.stem!r}: their "
                        "outputs would collide in --out-dir")
        stems[p.stem] = p
    return unique


def _read_landmarks_file(path: str | None, targets: list[Path], error) -> dict[int, tuple]:
    if path is None:
        return {}
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise error(f"--landmarks-file {path}: cannot read JSON ({exc})") from None
    if not isinstance(data, dict):
        raise error(f"--landmarks-file {path}: expected an object {{target file name: "
                    "[[source indices], [target indices]]}")
    out = {}
    by_name = {p.name: i for i, p in enumerate(targets)}
    by_stem = {p.stem: i for i, p in enumerate(targets)}
    unmatched = [key for key in data if by_name.get(key, by_stem.get(key)) is None]
    if unmatched:  # a typo or another run's targets: said, not silently dropped
        import warnings

        shown = ", ".join(repr(k) for k in unmatched[:5]) + (", …" if len(unmatched) > 5 else "")
        warnings.warn(f"--landmarks-file {path}: {len(unmatched)} entries match no target of "
                      f"this run (by file name or stem) and are not used: {shown}", stacklevel=2)
    for key, val in data.items():
        i = by_name.get(key, by_stem.get(key))
        if i is None:
            continue  # landmarks of a target not in this run (warned above)
        ok = (isinstance(val, list) and len(val) == 2 and all(isinstance(v, list) for v in val)
              and len(val[0]) == len(val[1]) > 0
              and all(isinstance(x, int) and not isinstance(x, bool) for v in val for x in v))
        if not ok:
            raise error(f"--landmarks-file {path}: entry {key!r} must be [[source indices], "
                        "[target indices]] of equal, non-zero length (integers)")
        out[i] = (val[0], val[1])
    return out


def _sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _truth_path(truth_dir, stem: str) -> Path | None:
    """The truth file of target ``stem`` (the first of ``TRUTH_SUFFIXES`` present)."""
    if truth_dir is None:
        return None
    return next((p for p in (Path(truth_dir) / f"{stem}{s}" for s in TRUTH_SUFFIXES)
                 if p.is_file()), None)


class _Run:
    """The output paths of one ``--out-dir`` run and its manifest: what each target's outputs
    were computed from (`key`), checked by `complete` on a rerun."""

    def __init__(self, args, targets: list[Path], landmarks: dict, suffix: str):
        from .._util import VERSION

        self.args, self.targets, self.landmarks, self.suffix = args, targets, landmarks, suffix
        self.out_dir = Path(args.out_dir)
        self.mesh_dir = Path(args.mesh_out_dir) if args.mesh_out_dir else None
        values = args.labels if args.labels is not None else args.function
        self.common = {"bsfjax": VERSION, "method": args.method, "k": args.k,
                       "threshold": args.threshold, "one_start": bool(args.one_start),
                       "partial": bool(args.partial),
                       "kind": "labels" if args.labels is not None else "function",
                       "output": suffix, "source": _sha256(args.source),
                       "values": _sha256(values), "denoise": not args.no_denoise}

    def outputs(self, p: Path) -> list[Path]:
        out = [self.out_dir / f"{p.stem}{self.suffix}"]
        return out + ([] if self.mesh_dir is None else [self.mesh_dir / f"{p.stem}.ply"])

    def manifest(self, p: Path) -> Path:
        return self.out_dir / MANIFEST_DIR / f"{p.stem}.json"

    def key(self, i: int) -> dict:
        p = self.targets[i]
        truth = _truth_path(self.args.truth_dir, p.stem)
        lm = self.landmarks.get(i)
        return dict(self.common, target=_sha256(p), landmarks=None if lm is None else list(lm),
                    truth=None if truth is None else _sha256(truth))

    def complete(self, i: int) -> dict | None:
        """The summary row of target ``i`` when its outputs are complete and its manifest
        says they were computed from this run's inputs and options; else ``None``."""
        p = self.targets[i]
        outs = self.outputs(p)
        if not all(q.is_file() for q in outs) or not self.manifest(p).is_file():
            return None
        try:
            m = json.loads(self.manifest(p).read_text())
            same = (m["key"] == json.loads(json.dumps(self.key(i)))
                    and {str(q.resolve()) for q in outs} <= set(m["outputs"]))
            return dict(m["record"], target=str(p)) if same else None
        except (OSError, ValueError, KeyError, TypeError):
            return None  # an unreadable manifest: computed again

    def write_manifest(self, i: int, record: dict) -> None:
        from .._util import write_text_atomic

        p = self.targets[i]
        body = {"key": self.key(i), "outputs": [str(q.resolve()) for q in self.outputs(p)],
                "record": record}
        write_text_atomic(self.manifest(p), json.dumps(body, indent=1) + "\n", immediate=True)


def check_run_paths(args, targets: list[Path], suffix: str, error) -> None:
    """Every output path of the run (each target's labels or values, coloured mesh and
    manifest, and ``summary.json``) against every input path (the source, the targets, the
    labels or function, the landmarks file, every possible truth file) and against each
    other, resolved, before any work: one line naming both (`bsfjax._util.check_path_clashes`).
    """
    from .._util import check_path_clashes

    out_dir = Path(args.out_dir)
    mesh_dir = Path(args.mesh_out_dir) if args.mesh_out_dir else None
    inputs = [("source", args.source), ("--labels", args.labels), ("--function", args.function),
              ("--landmarks-file", args.landmarks_file)]
    inputs += [("target", p) for p in targets]
    if args.truth_dir is not None:
        inputs += [(f"--truth-dir truth of target {p.name}", Path(args.truth_dir) / f"{p.stem}{s}")
                   for p in targets for s in TRUTH_SUFFIXES]
    outputs = [("--out-dir summary", out_dir / "summary.json")]
    for p in targets:
        outputs.append((f"--out-dir output of target {p.name}", out_dir / f"{p.stem}{suffix}"))
        outputs.append((f"manifest of target {p.name}", out_dir / MANIFEST_DIR / f"{p.stem}.json"))
        if mesh_dir is not None:
            outputs.append((f"--mesh-out-dir mesh of target {p.name}", mesh_dir / f"{p.stem}.ply"))
    try:
        check_path_clashes(outputs, inputs)
    except ValueError as exc:
        raise error(str(exc)) from None


def _remove_stale_temporaries(run: _Run) -> None:
    """Remove what a killed run (SIGKILL: no clean-up) left of its atomic writes: the
    ``.<name>.<8 random characters>.tmp<suffix>`` files of this run's outputs (the names of
    `bsfjax._util._files.atomic_path`), never the outputs themselves."""
    paths = [run.out_dir / "summary.json"]
    for p in run.targets:
        paths += run.outputs(p) + [run.manifest(p)]
    names: dict[Path, set[str]] = {}
    for path in paths:
        names.setdefault(path.parent, set()).add(path.name)
    for folder, ours in names.items():  # one listing per folder, not one per output
        if not folder.is_dir():
            continue
        for tmp in folder.iterdir():
            n = tmp.name
            cut = n.rfind(".tmp")
            base = n[1:cut] if n.startswith(".") and cut > 10 else ""
            name = base[:-9]
            if (len(base) > 9 and base[-9] == "." and name in ours
                    and n[cut:] == ".tmp" + Path(name).suffix):
                tmp.unlink(missing_ok=True)


def cmd_transfer_many(args, error) -> int:
    """The multi-target ``bsfjax transfer`` (see the module docstring)."""
    _initialize_distributed(args, error)  # (--coordinator checked first of all)
    check_backend(error)
    import jax
    import numpy as np
    from tqdm import tqdm

    from .._maps import check_fmap_memory
    from .._mesh import load_mesh
    from .._pipeline import process_share, transfer_collection
    from ._io import map_estimator, read_values

    targets = expand_targets(args.target, error)
    out_dir = Path(args.out_dir)
    landmarks = _read_landmarks_file(args.landmarks_file, targets, error)
    source = load_mesh(args.source)
    values, part_names, per_face = read_values(args, source, on_mesh=False)  # file rows
    # .json labels come back as .json, triangles' labels as .seg
    suffix = ".seg" if per_face else ".txt" if part_names is None else ".json"
    check_run_paths(args, targets, suffix, error)
    check_fmap_memory(args.k)  # (transfer_collection: again for its batch)
    run = _Run(args, targets, landmarks, suffix)
    out_dir.mkdir(parents=True, exist_ok=True)
    multi = jax.process_count() > 1
    if jax.process_index() == 0:  # before the first barrier: no process is writing yet
        _remove_stale_temporaries(run)
    if multi:  # every process lists the finished targets before any of them writes
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices("bsfjax transfer: start")
    done = {} if args.overwrite else {i: r for i in range(len(targets))
                                      if (r := run.complete(i)) is not None}
    todo = [i for i in range(len(targets)) if i not in done]
    if multi:
        multihost_utils.sync_global_devices("bsfjax transfer: listed")
    print(f"{len(targets)} targets: {len(done)} complete (skipped), {len(todo)} "
          f"to run" + (f" on {jax.process_count()} processes" if multi else ""), file=sys.stderr)
    records: dict[str, dict] = {}
    labels = args.labels is not None
    results = transfer_collection(
        source, values, [targets[i] for i in todo], labels=labels, faces=per_face,
        method=args.method, k=args.k,
        landmarks=lambda j: landmarks.get(todo[j]), threshold=args.threshold,
        errors="report", spectrum_cache=args.spectrum_cache, file_rows=True,
        batch=1 if args.batch is None else args.batch, estimator=map_estimator(args, args.k),
        denoise=not args.no_denoise)
    if not args.no_denoise:
        from .._mesh import prepare_scan

        # (of its main body, as transfer_collection measures it; its holes need not be closed
        # for the line: cheap beside the spectra)
        print(f"denoise: {prepare_scan(source, fill_holes=False).summary('source')} "
              "(per target: summary.json)",
              file=sys.stderr)
    mine = len(process_share(range(len(todo))))
    bar = tqdm(total=mine, desc="targets", unit="target", disable=args.no_progress,
               file=sys.stderr)
    for j, res in results:
        i, path = todo[j], targets[todo[j]]
        bar.update(1)
        try:
            if isinstance(res, Exception):
                raise res
            records[path.stem] = _write_target(args, run, i, res, part_names, per_face, error)
        except (ValueError, OSError) as exc:  # this target only: the others go on
            msg = " ".join(str(exc).split()) or type(exc).__name__
            tqdm.write(f"bsfjax transfer: {path}: error: {msg}", file=sys.stderr)
            records[path.stem] = {"target": str(path), "status": "error", "error": msg}
    bar.close()
    _write_summary(out_dir, targets, records, {targets[i].stem: r for i, r in done.items()},
                   multi)
    failed = sum(r["status"] == "error" for r in records.values())
    n_ok = len(records) - failed
    dropped = sum(bool(r.get("dropped_triangles" if per_face else "dropped_rows"))
                  for r in records.values())
    print(f"wrote {n_ok} targets to {out_dir}" + (f"; {failed} failed" if failed else "")
          + (f" ({dropped} with file rows that carry no surface: -1 / NaN there, counted in "
             "summary.json)" if dropped else ""), file=sys.stderr)
    if multi:
        from jax.experimental import multihost_utils

        failed = int(np.sum(multihost_utils.process_allgather(np.array([failed]))))
    return 1 if failed else 0


#: Said of a target whose first map's labels missed source parts (no --partial).
ESTIMATED_AGAIN = ("the first map's labels missed source parts: its map was estimated again "
                   "with the landmarks read off it guiding ZoomOut (as --partial; with given "
                   "landmarks, from their map)")


def _write_target(args, run: _Run, i: int, res, part_names, per_face: bool, error) -> dict:
    """Score target ``i`` against its truth and write its outputs, then its manifest;
    returns its summary row.  Raises for this target alone (a truth of the wrong length, an
    output that cannot be written, a part name `save_labels` reserves)."""
    import numpy as np
    from tqdm import tqdm

    from .._mesh import save_labels, save_mesh
    from .._util import atomic_path
    from ._io import TURN_DOUBT, coloured_data

    path, labels = run.targets[i], args.labels is not None
    # every output has the rows of the target's file (-1 / NaN on the dropped ones)
    target = res.mesh
    rec = {"target": str(path), "status": "ok", "vertices": res.n_vertices,
           "dropped_rows": target.dropped_rows, "map_energy": res.map_energy,
           "seconds": round(res.seconds, 4), "denoise_iterations": res.denoise_iterations}
    if per_face:
        rec["dropped_triangles"] = target.dropped_faces
    parts = res.main_body  # other components: labelled from the main body's nearest surface
    rec.update(other_components=0 if parts is None else parts.n_other_components,
               other_component_vertices=0 if parts is None else int(parts.other.size),
               unassigned_fragment_vertices=0 if parts is None else parts.n_unassigned)
    if parts is not None:
        tqdm.write(f"bsfjax transfer: {path}: {parts.summary()}", file=sys.stderr)
    if res.turn_doubtful is not None:
        rec["turn_doubtful"] = res.turn_doubtful
        if res.turn_doubtful:
            tqdm.write(f"bsfjax transfer: {path}: warning: {TURN_DOUBT}", file=sys.stderr)
    if labels:
        rec.update(unassigned_share=res.unassigned_share, regime=res.regime,
                   confidence=res.confidence, agreement=res.agreement,
                   missing_parts=[part_names[j] if part_names is not None
                                  and 0 <= j < len(part_names) else j for j in res.missing],
                   filled_vertices=res.filled_vertices, estimated_again=res.estimated_again)
        if res.estimated_again:
            tqdm.write(f"bsfjax transfer: {path}: {ESTIMATED_AGAIN}", file=sys.stderr)
        if res.missing:
            from ._io import part_list

            tqdm.write(f"bsfjax transfer: {path}: source parts with no counterpart on the "
                       f"target: {part_list(res.missing, part_names)}", file=sys.stderr)
        truth = _truth(args.truth_dir, path.stem, len(res.labels), part_names, error,
                       per_face)
        if truth is not None:
            mass = target.file_mesh().face_areas() if per_face else res.mass
            rec["accuracy"] = float(np.sum(mass * (res.labels == truth)) / np.sum(mass))
        result = res.labels.astype(np.int64)
    else:
        result = res.values.T if res.values.shape[0] > 1 else res.values[0]
    run.manifest(path).unlink(missing_ok=True)  # the old outputs are being replaced
    out, *mesh_out = run.outputs(path)
    if mesh_out:
        coloured = coloured_data(result, labels)
        save_mesh(mesh_out[0], target.file_mesh(), immediate=True,
                  **({"cell_data": coloured} if per_face else {"point_data": coloured}))
    if labels:
        save_labels(out, result, part_names, immediate=True)
    else:
        with atomic_path(out, immediate=True) as tmp:
            np.savetxt(tmp, result, fmt="%.8g")
    run.write_manifest(i, rec)
    if args.render:  # PNGs of the source and the result (bsfjax.plot.render)
        from ._view import render_run

        render_run(args, path, result, part_names, per_face,
                   _truth_path(args.truth_dir, path.stem))
    return rec


def _truth(truth_dir, stem: str, n: int, names, error, per_face: bool = False):
    if truth_dir is None:
        return None
    from ._io import read_truth

    p = _truth_path(truth_dir, stem)
    if p is None:
        return None
    arr = read_truth(str(p), names)
    if arr.shape != (n,):
        raise error(f"truth file {p}: expected {n} labels (one per target "
                    f"{'triangle' if per_face else 'vertex'}), got shape {arr.shape}")
    return arr


def _write_summary(out_dir: Path, targets, records, done, multi: bool) -> None:
    """``summary.json``: this run's records, and for the complete targets it skipped the rows
    their manifests keep (so a resumed run keeps the figures of what a killed run finished).
    Under ``jax.distributed`` each process writes its part; process 0 merges them."""
    from .._util import write_text_atomic

    part = out_dir / f".summary.part{_pid()}.json"
    if multi:
        from jax.experimental import multihost_utils

        write_text_atomic(part, json.dumps(records), immediate=True)
        multihost_utils.sync_global_devices("bsfjax transfer: parts written")
        if _pid() != 0:
            return
        merged = {}
        for p in sorted(out_dir.glob(".summary.part*.json")):
            merged.update(json.loads(p.read_text()))
        records = merged
    rows = [records.get(p.stem) or done.get(p.stem) or {"target": str(p), "status": "skipped"}
            for p in targets]
    # at once, not at the end of the command's output transaction: the processes of a
    # distributed run read each other's parts, and a killed run keeps what it finished
    write_text_atomic(out_dir / "summary.json", json.dumps({"targets": rows}, indent=1) + "\n",
                      immediate=True)
    if multi:
        for p in out_dir.glob(".summary.part*.json"):
            p.unlink(missing_ok=True)


def _pid() -> int:
    import jax

    return jax.process_index()


__all__ = ["check_backend", "check_coordinator", "check_run_paths", "cmd_transfer_many",
           "expand_targets", "MESH_SUFFIXES"]
