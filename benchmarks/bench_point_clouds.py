"""Benchmark: SMPL part transfer from a FAUST mesh to point clouds (issue "Real scans").

Source: a FAUST registration (mesh, default ``tr_reg_000``) with the SMPL 24 parts.  Targets,
all from another registration (default ``tr_reg_010``):

* ``mesh``: the registration itself (the clean mesh pair; truth: the same parts);
* ``cloud``: ``N`` points drawn area-uniformly from its surface (sampling seed ``s``), for each
  ``N`` of ``--points`` (default 5K, 15K, 40K);
* ``noisy cloud``: the same points plus Gaussian noise of σ = ``--noise`` (a fraction of the
  body's height, its y extent; default 0.25 %), noise seed ``s + 1``.

Truth on a cloud: the SMPL part of the surface vertex nearest to the (clean) sampled point.
Every target gets the default ``bsfjax transfer SOURCE TARGET --labels L --out OUT`` (run in
this process; a cloud is written as an ``.xyz`` file, one point per row), with the 5 landmark
pairs 412, 3216, 5907, 6296, 2445 (on a cloud: the sampled point nearest to each of those
vertices) and without landmarks.  Accuracy: the share of the target's lumped area (the mass
of its Laplacian: mixed Voronoi areas on the mesh, the point-cloud Laplacian's areas on a
cloud, of the points as given) labelled right.  ``denoise`` is the Taubin iterations the
command chose (`bsfjax.denoise_iterations`).

    python benchmarks/bench_point_clouds.py --out bench-results
    python benchmarks/bench_point_clouds.py --pairs 000-010,001-011 --seeds 0,1

`run(data, folder, ...)` returns the rows (one dict per target and landmark setting) for
``benchmarks/bench_scans.py``; `markdown(rows)` is the table.
"""

from __future__ import annotations

import tempfile
import time
import warnings

import numpy as np

import _harness as h
import bsfjax
from bsfjax.cli import main as bsfjax_command
from bsfjax.internal import sample_surface

LANDMARKS = list(h.LANDMARKS)


def _transfer(folder, source_path, target_path, landmarks, labels_path):
    """The default ``bsfjax transfer`` to ``target_path`` (``landmarks``: the target's indices
    of `LANDMARKS`, or ``None``): ``(labels, seconds)``."""
    out = folder / "out.txt"
    cmd = ["transfer", str(source_path), str(target_path), "--labels", str(labels_path),
           "--out", str(out)]
    if landmarks is not None:
        cmd += ["--landmarks", f"{','.join(map(str, LANDMARKS))}:"
                               f"{','.join(str(int(i)) for i in landmarks)}"]
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = bsfjax_command(cmd)
    seconds = time.perf_counter() - t0
    if rc != 0:
        raise SystemExit(f"bsfjax transfer to {target_path} failed (status {rc})")
    return np.loadtxt(out, dtype=np.int64), seconds


def _load(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return bsfjax.load_mesh(path)


def run(data, folder, *, pairs=(("000", "010"),), points=(5_000, 15_000, 40_000),
        noise: float = 0.0025, seeds=(0,), landmarks=(True, False), mesh: bool = True,
        clean: bool = True) -> list[dict]:
    """Rows of the benchmark: one per (pair, seed, target, landmarks), each with ``pair``,
    ``seed``, ``target`` (``"mesh"``, ``"cloud"``, ``"noisy cloud"``), ``points``, ``noise``
    (σ as a fraction of the height), ``landmarks`` (5 or 0), ``denoise`` (Taubin iterations),
    ``accuracy`` (share of the lumped area), ``point_share`` and ``seconds``.

    **Arguments:** `data` (the shared data folder), `folder` (a scratch folder), `pairs`
    (FAUST numbers, source → target), `points` (cloud sizes), `noise`, `seeds` (sampling
    seeds; noise: seed + 1), `landmarks` (with 5 / without), `mesh` (also the clean mesh
    pair, once per pair), `clean` (also the clean clouds).
    """
    from scipy.spatial import cKDTree

    folder = h.Path(folder)
    labels = h.smpl_labels(data)
    labels_path = folder / "smpl.txt"
    np.savetxt(labels_path, labels, fmt="%d")
    rows = []

    def one(pair, seed, target, n, sigma, path, lm, truth):
        cloud = _load(path)
        n_it = bsfjax.denoise_iterations(cloud)
        mass = bsfjax.laplacian(cloud)[1].diagonal()
        for use in landmarks:
            got, seconds = _transfer(folder, source_path, path, lm if use else None,
                                     labels_path)
            acc = float(np.sum(mass * (got == truth)) / mass.sum())
            rows.append({"pair": pair, "seed": seed, "target": target, "points": n,
                         "noise": sigma, "landmarks": 5 if use else 0, "denoise": n_it,
                         "accuracy": acc, "point_share": float(np.mean(got == truth)),
                         "seconds": seconds})
            print(f"{pair} seed {seed} {target} {n} σ={sigma:.2%} "
                  f"{'5 landmarks' if use else 'no landmarks'} (denoise {n_it}): "
                  f"{acc:.2%} ({seconds:.0f} s)", flush=True)

    for a, b in pairs:
        pair = f"{a}→{b}"
        source_path = data / "faust" / f"tr_reg_{a}.off"
        target_path = data / "faust" / f"tr_reg_{b}.off"
        tgt = _load(target_path)
        if mesh:
            one(pair, None, "mesh", tgt.n_vertices, 0.0, target_path, LANDMARKS, labels)
        height = float(np.ptp(tgt.vertices[:, 1]))
        for seed in seeds:
            for n in points:
                pts, _, _ = sample_surface(tgt, n, seed=seed)
                truth = labels[cKDTree(tgt.vertices).query(pts)[1]]
                lm = cKDTree(pts).query(tgt.vertices[LANDMARKS])[1]
                noisy = pts + np.random.default_rng(seed + 1).normal(scale=noise * height,
                                                                     size=pts.shape)
                todo = ([("cloud", pts, 0.0)] if clean else []) + [("noisy cloud", noisy, noise)]
                for target, p, sigma in todo:
                    path = folder / "cloud.xyz"
                    np.savetxt(path, p, fmt="%.17g")
                    one(pair, seed, target, n, sigma, path, lm, truth)
    return rows


def markdown(rows: list[dict]) -> str:
    """The rows as a markdown table: one line per target, the accuracy with 5 landmarks and
    without."""
    keys = []
    for r in rows:
        k = (r["pair"], r["seed"], r["target"], r["points"], r["noise"], r["denoise"])
        if k not in keys:
            keys.append(k)
    lines = ["| pair | seed | target | points | noise σ (of the height) | denoise (Taubin it.) | "
             "5 landmarks | no landmarks | seconds (5 / none) |", "|---|---|---|---|---|---|---|---|---|"]
    for k in keys:
        got = {r["landmarks"]: r for r in rows
               if (r["pair"], r["seed"], r["target"], r["points"], r["noise"], r["denoise"]) == k}
        acc = [f"{got[m]['accuracy']:.1%}" if m in got else "" for m in (5, 0)]
        sec = " / ".join(f"{got[m]['seconds']:.0f}" for m in (5, 0) if m in got)
        lines.append(f"| {k[0]} | {'' if k[1] is None else k[1]} | {k[2]} | {k[3]} | "
                     f"{'clean' if k[4] == 0 else f'{k[4]:.2%}'} | {k[5]} | {acc[0]} | {acc[1]} | "
                     f"{sec} |")
    return "\n".join(lines)


def main():
    ap = h.parser(__doc__)
    h.add_out(ap, default="bench-results")
    h.add_data(ap)
    ap.add_argument("--points", default="5000,15000,40000", help="cloud sizes, comma-separated")
    ap.add_argument("--noise", type=float, default=0.0025,
                    help="Gaussian noise σ as a fraction of the height")
    ap.add_argument("--seeds", default="0", help="sampling seeds (noise: seed + 1)")
    ap.add_argument("--pairs", default="000-010", help="FAUST pairs SRC-TGT, comma-separated")
    ap.add_argument("--no-clean", action="store_true", help="noisy clouds only")
    ap.add_argument("--no-mesh", action="store_true", help="without the clean mesh pair")
    ap.add_argument("--landmarks", choices=("both", "5", "none"), default="both",
                    help="with 5 landmark pairs, without, or both")
    args = ap.parse_args()
    data = h.Path(args.data)
    pairs = tuple(tuple(p.split("-")) for p in args.pairs.split(","))
    h.require_data(*(data / "faust" / f"tr_reg_{x}.off" for p in pairs for x in p),
                   data / h.SMPL_SEGMENTATION)
    with tempfile.TemporaryDirectory() as tmp:
        rows = run(data, h.Path(tmp), pairs=pairs,
                   points=tuple(int(x) for x in args.points.split(",")), noise=args.noise,
                   seeds=tuple(int(x) for x in args.seeds.split(",")), clean=not args.no_clean,
                   mesh=not args.no_mesh,
                   landmarks={"both": (True, False), "5": (True,), "none": (False,)}[args.landmarks])
    out = h.Path(args.out)
    h.write_json(out / "bench_point_clouds.json",
                 {"machine": h.short_machine(), "noise": args.noise, "rows": rows})
    text = markdown(rows) + f"\n\n{h.short_machine()}\n"
    h.write_text(out / "bench_point_clouds.md", text)
    print(text)


if __name__ == "__main__":
    main()
