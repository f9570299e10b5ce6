"""Benchmark: the cost of the input checks, and a longer reader-fuzzing campaign.

* ``load_mesh`` on the real meshes, split into reading and the defect scan
  (``bsfjax.mesh_report``: duplicate vertices/faces, non-manifold edges, components);
* ``bsfjax.internal.mesh_edges`` (1-D int64 keys) against the former
  ``np.unique(..., axis=0)`` on sorted edge rows (same output, checked);
* ``--fuzz SECONDS``: mutated OFF/PLY/OBJ/STL files through ``load_mesh`` for that long
  (the same mutations as ``tests/test_fuzz_readers.py``, drawn with ``random``), counting
  outcomes; any exception other than ``MeshError`` is reported.

Median of ``--repeats`` runs.  Writes JSON and a Markdown table to ``--out`` (a folder).

    python benchmarks/bench_validation.py --out bench-results --fuzz 120
"""

from __future__ import annotations

import random
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import _harness as h
import bsfjax
from bsfjax import mesh_report
from bsfjax.internal import mesh_edges

ROOT = h.ROOT
DATA = h.DATA
MESHES = ["faust/tr_reg_000.off", "faust_5k/tr_reg_000.off", "tosca_10k/cat/cat0.off",
          "tosca/cat/cat0.off"]


def _old_edges(faces):
    half = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges, inv = np.unique(np.sort(half, axis=1), axis=0, return_inverse=True)
    return edges, inv.reshape(3, -1).T


def bench_meshes(repeats):
    rows = []
    for rel in MESHES:
        p = DATA / rel
        if not p.exists():
            print(f"skip {rel}: not found", file=sys.stderr)
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mesh = bsfjax.load_mesh(p)
            t_load = h.timed(lambda: bsfjax.load_mesh(p), repeats).median
        t_report = h.timed(lambda: mesh_report(mesh), repeats).median
        new, old = mesh_edges(mesh.faces), _old_edges(mesh.faces)
        assert all(np.array_equal(a, b) for a, b in zip(new, old))
        t_new = h.timed(lambda: mesh_edges(mesh.faces), repeats).median
        t_old = h.timed(lambda: _old_edges(mesh.faces), repeats).median
        rows.append({"mesh": rel, "n_vertices": mesh.n_vertices, "load_mesh_s": t_load,
                     "mesh_report_s": t_report, "edges_new_s": t_new, "edges_old_s": t_old})
        print(rows[-1], flush=True)
    return rows


def fuzz(seconds):
    sys.path.insert(0, str(ROOT))
    from tests.conftest import icosphere
    from tests.test_fuzz_readers import _TOKENS, _mutate

    import meshio

    v, f = icosphere(1)
    mesh = bsfjax.Mesh(v, f)
    d = Path(tempfile.mkdtemp())
    bases = {}
    for ext in ("off", "ply", "obj", "stl"):
        bsfjax.save_mesh(d / f"b.{ext}", mesh)
        bases[ext] = (ext, (d / f"b.{ext}").read_bytes())
    meshio.write(d / "a.ply", meshio.Mesh(v, [("triangle", f)]), binary=False)
    bases["ply_ascii"] = ("ply", (d / "a.ply").read_bytes())
    rng = random.Random(0)
    counts: dict[str, int] = {}
    failures = []
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        kind = rng.choice(sorted(bases))
        ext, data = bases[kind]
        ops = []
        for _ in range(rng.randint(1, 4)):
            c = rng.randrange(6)
            ops.append([("truncate", rng.random()),
                        ("flip", [(rng.random(), rng.randrange(256))
                                  for _ in range(rng.randint(1, 8))]),
                        ("insert", rng.random(), rng.choice(_TOKENS), rng.choice([b" ", b"\n"])),
                        ("number", rng.randrange(40), rng.choice(_TOKENS)),
                        ("splice", rng.random(), rng.randbytes(rng.randrange(200))),
                        ("repeat", rng.random(), rng.random())][c])
        p = d / f"x.{ext}"
        p.write_bytes(_mutate(data, ops))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                bsfjax.load_mesh(p)
            outcome = "mesh"
        except bsfjax.MeshError:
            outcome = "MeshError"
        except Exception as exc:  # a finding: record it
            outcome = type(exc).__name__
            failures.append((kind, repr(exc)[:200]))
        counts[f"{kind}:{outcome}"] = counts.get(f"{kind}:{outcome}", 0) + 1
    return {"seconds": seconds, "files": sum(counts.values()), "outcomes": counts,
            "failures": failures}


def main():
    ap = h.parser(__doc__)
    h.add_out(ap, default="bench-results")
    h.add_repeats(ap, 5)
    ap.add_argument("--fuzz", type=float, default=0.0, help="seconds of reader fuzzing")
    args = ap.parse_args()
    h.require_data(DATA, option=None)
    machine = h.machine_facts(with_jax=False)
    res = {"machine": machine["arch"], "python": machine["python"],
           "meshes": bench_meshes(args.repeats)}
    if args.fuzz > 0:
        res["fuzz"] = fuzz(args.fuzz)
        print(res["fuzz"]["files"], "files,", len(res["fuzz"]["failures"]), "failures")
    out = Path(args.out)
    h.write_json(out / "bench_validation.json", res, indent=1)
    lines = ["| mesh | n | load_mesh (s) | mesh_report (s) | edges new (s) | edges old (s) |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {r['mesh']} | {r['n_vertices']} | {r['load_mesh_s']:.3f} | "
              f"{r['mesh_report_s']:.4f} | {r['edges_new_s']:.4f} | {r['edges_old_s']:.4f} |"
              for r in res["meshes"]]
    if "fuzz" in res:
        lines.append(f"\nfuzz: {res['fuzz']['files']} files in {args.fuzz:.0f} s, "
                     f"{len(res['fuzz']['failures'])} non-MeshError failures")
    h.write_text(out / "bench_validation.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
