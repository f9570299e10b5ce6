"""Scan-like FAUST targets with holes and missing parts: ``bsfjax transfer`` against the clean pair.

From FAUST registrations with the SMPL 24 parts to FAUST targets made scan-like, deterministically:

* **holes**: ``k`` geodesic discs (graph distance along the edges) of radius ``r`` (a fraction
  of the target's height, default 3.5 %) removed around seeded random vertices
  (``k ∈ {2, 5, 8}``); the vertices inside are removed from the file, with every triangle that
  uses one, and so are the vertices no kept triangle uses;
* **partial**: one arm from the elbow down (SMPL ``leftForeArm``, ``leftHand``,
  ``leftHandIndex1``) and one foot (``rightFoot``, ``rightToeBase``) removed from the file
  (``run(..., cut=1)``: the mirror cut; ``cut=2``: the left leg from the knee down).

The target is a genuinely smaller mesh (its vertices in their original order, renumbered).
Truth: the SMPL labels of the kept vertices; accuracy: the share of the holed / partial
target's own area (barycentric vertex areas of the mesh as written) labelled right.  Each
target runs through the default ``bsfjax transfer`` in this process (``_harness.run_cli``)
with the 5 landmark pairs of the docs (those a cut removed are dropped) and without landmarks,
the clean pair with both, and with ``--pyfm`` pyFM's pipeline (``_harness.run_pyfm``) with
the same landmarks.  The partial rows list the source parts the command reported without a
counterpart.  Prints a Markdown table and writes it (``--out``) with a JSON of the rows.

    python benchmarks/bench_scans_holes.py --out R.md --pyfm
"""

from __future__ import annotations

import re
import tempfile

import _harness as h

#: SMPL parts removed from the partial targets: the left arm from the elbow down, the right foot.
PARTIAL_PARTS = ("leftForeArm", "leftHand", "leftHandIndex1", "rightFoot", "rightToeBase")
#: The cuts of the held-out draws (``bench_scans.py --draw D`` takes cut ``D mod 3``): the
#: mirror cut, and the left leg from the knee down; each with its name.
PARTIAL_CUTS = ((PARTIAL_PARTS, "left forearm + hand and right foot removed"),
                (("rightForeArm", "rightHand", "rightHandIndex1", "leftFoot", "leftToeBase"),
                 "right forearm + hand and left foot removed"),
                (("leftLeg", "leftFoot", "leftToeBase"), "left shin and foot removed"))
#: Hole radius, as a fraction of the target's height.
RADIUS = 0.035
PAIRS = ((0, 10), (1, 11), (2, 12))


def part_names(data) -> list[str]:
    """The SMPL part names in the order of ``smpl_labels``'s label numbers."""
    import json

    return sorted(json.loads((h.Path(data) / h.SMPL_SEGMENTATION).read_text()))


def submesh(mesh, remove):
    """``mesh`` without the vertices ``remove`` (a boolean mask), the triangles that use one,
    and the vertices no kept triangle uses: ``(vertices, faces, kept)``, ``kept`` the original
    index of each vertex (in order)."""
    import numpy as np

    f = np.asarray(mesh.faces)
    faces = f[~remove[f].any(axis=1)]
    kept = np.unique(faces)
    new = np.full(mesh.n_vertices, -1, np.int64)
    new[kept] = np.arange(kept.size)
    return np.asarray(mesh.vertices)[kept], new[faces], kept


def hole_mask(mesh, k: int, radius: float, seed) -> "np.ndarray":
    """Vertices within graph distance ``radius`` (along the edges) of ``k`` seeded random
    vertices."""
    import numpy as np
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    g = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(v),) * 2).tocsr()
    g = g.maximum(g.T)
    centres = np.random.default_rng(seed).choice(len(v), size=k, replace=False)
    d = dijkstra(g, indices=centres, limit=radius).min(axis=0)
    return d <= radius


def make_target(data, folder, tgt: int, kind: str, k: int = 0, seed: int = 0,
                radius: float = RADIUS) -> dict:
    """Write one scan-like target and return ``path``, ``kept`` (original vertex of each kept
    one), ``truth``, ``mass`` (areas of the target as written) and ``name``."""
    import numpy as np

    import bsfjax
    from bsfjax.internal import vertex_areas

    mesh = bsfjax.load_mesh(str(h.Path(data) / "faust" / f"tr_reg_{tgt:03d}.off"))
    labels = h.smpl_labels(data)
    if kind == "holes" and k == 0:
        remove, name = np.zeros(mesh.n_vertices, bool), "clean"
    elif kind == "holes":
        height = float(np.ptp(np.asarray(mesh.vertices)[:, 1]))
        remove = hole_mask(mesh, k, radius * height, [tgt, k, seed])
        name = f"{k} holes, r = {100 * radius:.1f} %, seed {seed}"
    elif kind == "partial":  # (k: which of PARTIAL_CUTS)
        names = part_names(data)
        parts, name = PARTIAL_CUTS[k] if k else (PARTIAL_PARTS, PARTIAL_CUTS[0][1])
        remove = np.isin(labels, [names.index(p) for p in parts])
    else:
        raise ValueError(f"kind must be 'holes' or 'partial', got {kind!r}")
    v, f, kept = submesh(mesh, remove)
    out = bsfjax.Mesh(v, f)
    path = str(h.Path(folder) / f"{kind}_{tgt:03d}_{k}_{seed}.off")
    bsfjax.save_mesh(path, out)
    body = bsfjax.split_main_body(out).vertices  # (a landmark must lie on the main body)
    return {"path": path, "kept": kept, "truth": labels[kept], "mass": vertex_areas(out),
            "name": name, "mesh": out, "body": body}


def kept_landmarks(kept, body=None):
    """The docs' 5 landmark pairs that a cut kept (on the target's main body, the vertices
    ``body``, when given: a hole may cut a finger off): (source rows, target rows)."""
    on_body = set(range(len(kept))) if body is None else {int(i) for i in body}
    new = {int(o): i for i, o in enumerate(kept) if i in on_body}
    src = [lm for lm in h.LANDMARKS if lm in new]
    return src, [new[lm] for lm in src]


def missing_report(err: str) -> str:
    """The source parts the command reported without a counterpart (its printed line)."""
    m = re.search(r"no counterpart on the target.*?area\): (.*)", err)
    return m.group(1).strip() if m else ""


def run(data, folder, pairs=PAIRS, ks=(2, 5, 8), seeds=(0, 1), partial: bool = True,
        landmark_free: bool = True, pyfm: bool = False, radius: float = RADIUS,
        cut: int = 0) -> list[dict]:
    """One row per (pair, target): ``pair``, ``target``, ``clean_lm`` / ``clean_free`` (the
    clean pair), ``lm`` / ``free`` (the scan-like target), ``pyfm``, ``missing`` (the parts the
    command reported without a counterpart, with landmarks) and the seconds of each run."""
    import numpy as np

    names = part_names(data)
    truth = h.smpl_labels(data)
    lab_file = str(h.Path(folder) / "smpl.txt")
    np.savetxt(lab_file, truth, fmt="%d")
    out = str(h.Path(folder) / "out.txt")
    rows = []
    for src, tgt in pairs:
        source = str(h.Path(data) / "faust" / f"tr_reg_{src:03d}.off")
        specs = [("holes", k, s) for k in ks for s in seeds] + ([("partial", cut, 0)] if partial
                                                                 else [])
        clean = make_target(data, folder, tgt, "holes", 0, 0)  # (nothing removed)
        targets = [("clean", clean)] + [(spec, make_target(data, folder, tgt, *spec, radius))
                                        for spec in specs]
        base = {}
        for spec, t in targets:
            row = {"pair": f"{src:03d}→{tgt:03d}", "target": t["name"] if spec != "clean"
                   else "clean", "vertices": int(t["kept"].size)}
            lm = kept_landmarks(t["kept"], t["body"])
            row["landmarks"] = len(lm[0])
            for mode in (["lm", "free"] if landmark_free else ["lm"]):
                s0 = h.time.perf_counter()
                labels, err = h.run_cli(source, t["path"], lab_file, out,
                                         lm if mode == "lm" else False, True)
                row[mode] = h.accuracy(labels, t["truth"], t["mass"])
                row[mode + "_s"] = round(h.time.perf_counter() - s0, 1)
                if mode == "lm":
                    gone = missing_report(err)
                    row["missing"] = ", ".join(names[int(i)] for i in gone.split(", ")
                                               if i.isdigit()) or gone
                print(f"  {row['pair']} {row['target']} {mode}: {row[mode]:.1%} "
                      f"({row[mode + '_s']} s)", file=h.sys.stderr, flush=True)
            if spec == "clean":
                base = {"clean_lm": row.get("lm"), "clean_free": row.get("free")}
            row.update(base)
            if pyfm:
                import bsfjax

                row["pyfm"] = h.run_pyfm(bsfjax.load_mesh(source), t["mesh"], truth, t["mass"],
                                          landmarks=lm, target_truth=t["truth"])
                print(f"  {row['pair']} {row['target']} pyFM: {row['pyfm']:.1%}",
                      file=h.sys.stderr, flush=True)
            rows.append(row)
    return rows


def table(rows) -> str:
    def pc(x):
        return "" if x is None else f"{100 * x:.1f} %"

    def delta(x, ref):
        return "" if x is None or ref is None else f" ({100 * (x - ref):+.1f})"

    lines = ["| pair | target | vertices | clean pair, 5 landmarks / none | with landmarks (Δ) | "
             "without landmarks (Δ) | pyFM pipeline | parts reported missing |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["target"] == "clean":
            continue
        n_lm = "" if r["landmarks"] == 5 else f" ({r['landmarks']} landmarks)"
        lines.append(
            f"| {r['pair']} | {r['target']} | {r['vertices']} | {pc(r['clean_lm'])} / "
            f"{pc(r.get('clean_free'))} | {pc(r['lm'])}{delta(r['lm'], r['clean_lm'])}"
            f"{n_lm} | "
            f"{pc(r.get('free'))}{delta(r.get('free'), r.get('clean_free'))} | "
            f"{pc(r.get('pyfm'))} | {r.get('missing', '')} |")
    return "\n".join(lines) + "\n"


def main():
    ap = h.parser(__doc__)
    h.add_out(ap, help="output Markdown file (a .json of the rows beside it)")
    h.add_data(ap)
    ap.add_argument("--pairs", default="0-10,1-11,2-12",
                    help="source-target registration numbers (default 0-10,1-11,2-12)")
    ap.add_argument("--holes", default="2,5,8", help="numbers of holes (default 2,5,8)")
    ap.add_argument("--seeds", default="0,1", help="seeds of the hole centres (default 0,1)")
    ap.add_argument("--radius", type=float, default=RADIUS,
                    help=f"hole radius, a fraction of the height (default {RADIUS})")
    ap.add_argument("--no-partial", action="store_true", help="skip the partial targets")
    ap.add_argument("--cut", type=int, default=0, choices=range(len(PARTIAL_CUTS)),
                    help="the partial target's cut, PARTIAL_CUTS[CUT] (default 0; "
                         "bench_scans.py --draw D takes D mod 3)")
    ap.add_argument("--landmarks-only", action="store_true", help="skip the landmark-free runs")
    ap.add_argument("--pyfm", action="store_true", help="also pyFM's pipeline (pyfmaps)")
    args = ap.parse_args()
    h.require_data(h.Path(args.data) / "faust", h.Path(args.data) / h.SMPL_SEGMENTATION)
    pairs = h.pair_list(args.pairs)
    with tempfile.TemporaryDirectory() as tmp:
        rows = run(h.Path(args.data), h.Path(tmp), pairs, h.int_list(args.holes),
                   h.int_list(args.seeds), not args.no_partial, not args.landmarks_only,
                   args.pyfm, args.radius, args.cut)
    text = table(rows)
    note = (f"\n{h.short_machine()}; truth: the SMPL parts of the kept vertices; areas of the "
            "holed / partial target as written; Δ: points from the clean pair.\n")
    print(text + note)
    h.write_text(args.out, text + note)
    h.write_json(h.Path(args.out).with_suffix(".json"),
                 {"rows": [{k: v for k, v in r.items()} for r in rows]})


if __name__ == "__main__":
    main()
