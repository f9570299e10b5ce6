"""``bsfjax transfer SOURCE TARGET [TARGET ...] --out-dir DIR``: one source to many targets.

Targets are files, folders (their mesh files) or glob patterns.  Each target's result is
written as soon as it is computed, atomically: ``DIR/<stem>.txt`` (``DIR/<stem>.json`` with
the source's part names for ``.json`` labels, as [`bsfjax.save_labels`][bsfjax.save_labels];
``DIR/<stem>.seg`` for labels of triangles, as [`bsfjax.transfer_face_labels`][bsfjax.transfer_face_labels]; and
``MESH_DIR/<stem>.ply`` with ``--mesh-out-dir``); ``DIR/summary.json`` lists every target.
``--truth-dir`` holds ``<stem>.txt``, ``.npy``, ``.json`` or ``.seg``.  A rerun skips the
targets whose outputs are complete (unless ``--overwrite``), so an interrupted run resumes; a
target that cannot be read or solved is reported and skipped, and the exit status is 1.  With
``--coordinator/--num-processes/--process-id`` (or inside a SLURM or Open MPI job) the
processes of ``jax.distributed`` share the targets; each writes its own.
"""

from __future__ import annotations

import glob
import json
import os
import sys
from pathlib import Path

MESH_SUFFIXES = (".off", ".ply", ".obj", ".stl", ".vtk", ".vtu", ".msh", ".mesh")
#: Environment variables of the launchers whose cluster ``jax.distributed.initialize()``
#: detects by itself: (variable holding the process count, launcher).
_CLUSTER_SIZE_VARS = (("SLURM_NTASKS", "SLURM"), ("OMPI_COMM_WORLD_SIZE", "Open MPI"))


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


def _initialize_distributed(args, error) -> None:
    """``jax.distributed`` from the flags, or from the cluster's environment without them."""
    flags = (args.coordinator, args.num_processes, args.process_id)
    if any(f is not None for f in flags):
        if any(f is None for f in flags):
            raise error("--coordinator, --num-processes and --process-id go together")
        if args.num_processes < 1 or not 0 <= args.process_id < args.num_processes:
            raise error(f"--process-id must be in [0, {args.num_processes}) and --num-processes "
                        f">= 1, got {args.process_id} and {args.num_processes}")
        kwargs = dict(coordinator_address=args.coordinator, num_processes=args.num_processes,
                      process_id=args.process_id)
    else:
        launcher = next((name for var, name in _CLUSTER_SIZE_VARS
                         if os.environ.get(var, "1").isdigit() and int(os.environ.get(var, "1")) > 1),
                        None)
        if launcher is None:
            return
        kwargs = {}  # jax.distributed finds the coordinator and ranks in the environment
        print(f"bsfjax: {launcher} job detected: initializing jax.distributed", file=sys.stderr)
    import jax

    jax.config.update("jax_cpu_collectives_implementation", "gloo")  # CPU processes too
    jax.distributed.initialize(**kwargs)


def _complete(stem: str, out_dir: Path, mesh_dir: Path | None, suffix: str) -> bool:
    return (out_dir / f"{stem}{suffix}").is_file() and (
        mesh_dir is None or (mesh_dir / f"{stem}.ply").is_file())


def _remove_stale_temporaries(targets, out_dir: Path, mesh_dir: Path | None,
                              suffix: str) -> None:
    """Remove what a killed run (SIGKILL: no clean-up) left of its atomic writes: the
    ``.<name>.<8 random characters>.tmp<suffix>`` files of this run's outputs (the names of
    `bsfjax._util._files.atomic_path`), never the outputs themselves."""
    names = [(out_dir, "summary.json")] + [(out_dir, f"{p.stem}{suffix}") for p in targets]
    if mesh_dir is not None:
        names += [(mesh_dir, f"{p.stem}.ply") for p in targets]
    for folder, name in names:
        suffix = Path(name).suffix
        for tmp in folder.glob(f".{name}.????????.tmp{suffix}"):
            tmp.unlink(missing_ok=True)


def cmd_transfer_many(args, error) -> int:
    """The multi-target ``bsfjax transfer`` (see the module docstring)."""
    _initialize_distributed(args, error)
    import jax
    import numpy as np
    from tqdm import tqdm

    from .._pipeline import process_share, transfer_collection
    from .._util import atomic_path
    from .._mesh import save_labels
    from .._mesh import load_mesh
    from .._mesh import save_mesh

    targets = expand_targets(args.target, error)
    out_dir = Path(args.out_dir)
    mesh_dir = Path(args.mesh_out_dir) if args.mesh_out_dir else None
    landmarks = _read_landmarks_file(args.landmarks_file, targets, error)
    source = load_mesh(args.source)
    from ._io import read_values
    from ._io import TURN_DOUBT, map_estimator

    values, part_names, per_face = read_values(args, source)
    # .json labels come back as .json, triangles' labels as .seg
    suffix = ".seg" if per_face else ".txt" if part_names is None else ".json"
    out_dir.mkdir(parents=True, exist_ok=True)
    multi = jax.process_count() > 1
    if jax.process_index() == 0:  # before the first barrier: no process is writing yet
        _remove_stale_temporaries(targets, out_dir, mesh_dir, suffix)
    if multi:  # every process lists the finished targets before any of them writes
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices("bsfjax transfer: start")
    todo = [i for i, p in enumerate(targets)
            if args.overwrite or not _complete(p.stem, out_dir, mesh_dir, suffix)]
    if multi:
        multihost_utils.sync_global_devices("bsfjax transfer: listed")
    print(f"{len(targets)} targets: {len(targets) - len(todo)} complete (skipped), {len(todo)} "
          f"to run" + (f" on {jax.process_count()} processes" if multi else ""), file=sys.stderr)
    records: dict[str, dict] = {}
    failed = 0
    labels = args.labels is not None
    results = transfer_collection(
        source, values, [targets[i] for i in todo], labels=labels, faces=per_face,
        method=args.method, k=args.k,
        landmarks=lambda j: landmarks.get(todo[j]), threshold=args.threshold,
        errors="report", spectrum_cache=args.spectrum_cache,
        batch=1 if args.batch is None else args.batch, estimator=map_estimator(args, args.k))
    mine = len(process_share(range(len(todo))))
    bar = tqdm(total=mine, desc="targets", unit="target", disable=args.no_progress,
               file=sys.stderr)
    for j, res in results:
        path = targets[todo[j]]
        bar.update(1)
        if isinstance(res, Exception):
            failed += 1
            msg = " ".join(str(res).split())
            tqdm.write(f"bsfjax transfer: {path}: error: {msg}", file=sys.stderr)
            records[path.stem] = {"target": str(path), "status": "error", "error": msg}
            continue
        rec = {"target": str(path), "status": "ok", "vertices": res.n_vertices,
               "map_energy": res.map_energy, "seconds": round(res.seconds, 4)}
        if res.turn_doubtful is not None:
            rec["turn_doubtful"] = res.turn_doubtful
            if res.turn_doubtful:
                tqdm.write(f"bsfjax transfer: {path}: warning: {TURN_DOUBT}", file=sys.stderr)
        # the target mesh, read again only for the coloured mesh or a triangle truth's areas
        target = (load_mesh(path) if mesh_dir is not None or (per_face and args.truth_dir)
                  else None)
        if labels:
            rec.update(unassigned_share=res.unassigned_share, regime=res.regime,
                       confidence=res.confidence, agreement=res.agreement)
            truth = _truth(args.truth_dir, path.stem, len(res.labels), part_names, error,
                           per_face)
            if truth is not None:
                mass = target.face_areas() if per_face else res.mass
                rec["accuracy"] = float(np.sum(mass * (res.labels == truth)) / np.sum(mass))
            result = res.labels.astype(np.int64)
        else:
            result = res.values.T if res.values.shape[0] > 1 else res.values[0]
        if mesh_dir is not None:
            from ._io import coloured_data

            coloured = coloured_data(result, labels)
            save_mesh(mesh_dir / f"{path.stem}.ply", target, immediate=True,
                      **({"cell_data": coloured} if per_face else {"point_data": coloured}))
        if labels:
            save_labels(out_dir / f"{path.stem}{suffix}", result, part_names, immediate=True)
        else:
            with atomic_path(out_dir / f"{path.stem}{suffix}", immediate=True) as tmp:
                np.savetxt(tmp, result, fmt="%.8g")
        records[path.stem] = rec
    bar.close()
    _write_summary(out_dir, targets, records, multi)
    n_ok = sum(r["status"] == "ok" for r in records.values())
    print(f"wrote {n_ok} targets to {out_dir}" + (f"; {failed} failed" if failed else ""),
          file=sys.stderr)
    if multi:
        from jax.experimental import multihost_utils

        failed = int(np.sum(multihost_utils.process_allgather(np.array([failed]))))
    return 1 if failed else 0


def _truth(truth_dir, stem: str, n: int, names, error, per_face: bool = False):
    if truth_dir is None:
        return None
    from ._io import read_truth

    for suffix in (".txt", ".npy", ".json", ".seg"):
        p = Path(truth_dir) / f"{stem}{suffix}"
        if p.is_file():
            arr = read_truth(str(p), names)
            if arr.shape != (n,):
                raise error(f"truth file {p}: expected {n} labels (one per target "
                            f"{'triangle' if per_face else 'vertex'}), got shape {arr.shape}")
            return arr
    return None


def _write_summary(out_dir: Path, targets, records, multi: bool) -> None:
    """``summary.json``: this run's records, and the earlier run's for the skipped targets.
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
    old = {}
    summary = out_dir / "summary.json"
    if summary.is_file():
        try:
            old = {r["target"]: r for r in json.loads(summary.read_text()).get("targets", [])}
        except (OSError, ValueError, AttributeError, KeyError, TypeError):
            old = {}  # an unreadable summary is rewritten from this run
    rows = []
    for p in targets:
        if p.stem in records:
            rows.append(records[p.stem])
        elif str(p) in old:
            rows.append(old[str(p)])
        else:
            rows.append({"target": str(p), "status": "skipped"})
    # at once, not at the end of the command's output transaction: the processes of a
    # distributed run read each other's parts, and a killed run keeps what it finished
    write_text_atomic(summary, json.dumps({"targets": rows}, indent=1) + "\n", immediate=True)
    if multi:
        for p in out_dir.glob(".summary.part*.json"):
            p.unlink(missing_ok=True)


def _pid() -> int:
    import jax

    return jax.process_index()


__all__ = ["cmd_transfer_many", "expand_targets", "MESH_SUFFIXES"]
