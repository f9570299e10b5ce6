"""Benchmark: SMPL part transfer from a FAUST mesh to a point cloud (issue "Real scans").

Source: FAUST ``tr_reg_000`` (mesh) with the SMPL 24 parts.  Targets, all from ``tr_reg_010``:

* ``mesh``: the registration itself (the clean mesh pair; truth: the same parts);
* ``cloud``: ``--points`` points drawn area-uniformly from its surface (seed ``--seed``);
* ``noisy cloud``: the same points plus Gaussian noise of σ = ``--noise`` (a fraction of the
  body's height, its y extent), seed ``--seed + 1``.

Truth on a cloud: the SMPL part of the surface vertex nearest to the (clean) sampled point.
Every target gets the default transfer, ``bsfjax transfer SOURCE TARGET --labels L --landmarks
…`` (run in this process; a cloud is written as an ``.xyz`` file, one point per row), with the
5 landmark pairs 412, 3216, 5907, 6296, 2445 (on a cloud: the sampled point nearest to each of
those vertices).  Accuracy: the share of the target's lumped area (the mass of its Laplacian:
mixed Voronoi areas on the mesh, the point-cloud Laplacian's areas on a cloud) labelled right.
Without landmarks a point cloud is refused (the landmark-free map's orientation term needs
triangles).

    python benchmarks/bench_point_clouds.py --out bench-results
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

LANDMARKS = [412, 3216, 5907, 6296, 2445]


def _transfer(folder, source_path, target_path, landmarks, labels_path):
    """The default ``bsfjax transfer`` to ``target_path``: ``(labels, seconds)``."""
    out = folder / "out.txt"
    lm = f"{','.join(map(str, LANDMARKS))}:{','.join(str(int(i)) for i in landmarks)}"
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = bsfjax_command(["transfer", str(source_path), str(target_path), "--labels", str(labels_path),
                   "--landmarks", lm, "--out", str(out)])
    seconds = time.perf_counter() - t0
    if rc != 0:
        raise SystemExit(f"bsfjax transfer to {target_path} failed (status {rc})")
    return np.loadtxt(out, dtype=np.int64), seconds


def run(data, folder, n_points: int, noise: float, seed: int) -> list[dict]:
    from scipy.spatial import cKDTree

    source_path, target_path = data / "faust" / "tr_reg_000.off", data / "faust" / "tr_reg_010.off"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tgt = bsfjax.load_mesh(target_path)
    labels = h.smpl_labels(data)
    labels_path = folder / "smpl.txt"
    np.savetxt(labels_path, labels, fmt="%d")
    pts, _, _ = sample_surface(tgt, n_points, seed=seed)
    height = float(np.ptp(tgt.vertices[:, 1]))
    sigma = noise * height
    noisy = pts + np.random.default_rng(seed + 1).normal(scale=sigma, size=pts.shape)
    truth_cloud = labels[cKDTree(tgt.vertices).query(pts)[1]]
    lm_cloud = cKDTree(pts).query(tgt.vertices[LANDMARKS])[1]
    rows = []
    np.savetxt(folder / "cloud.xyz", pts, fmt="%.17g")
    np.savetxt(folder / "noisy.xyz", noisy, fmt="%.17g")
    for name, path, lm, truth in (
            ("mesh tr_reg_010", target_path, LANDMARKS, labels),
            (f"cloud, {n_points} points", folder / "cloud.xyz", lm_cloud, truth_cloud),
            (f"noisy cloud, σ = {noise:.2%} of the height ({sigma * 1000:.1f} mm)",
             folder / "noisy.xyz", lm_cloud, truth_cloud)):
        got, seconds = _transfer(folder, source_path, path, lm, labels_path)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            target = bsfjax.load_mesh(path)
        mass = bsfjax.laplacian(target)[1].diagonal()
        acc = float(np.sum(mass * (got == truth)) / mass.sum())
        rows.append({"target": name, "n": target.n_vertices, "accuracy": acc,
                     "vertex_share": float(np.mean(got == truth)), "seconds": seconds})
        print(f"{name}: {acc:.2%} of the area ({seconds:.1f} s)", flush=True)
    cloud = bsfjax.load_mesh(folder / "noisy.xyz")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        src = bsfjax.load_mesh(source_path)
    try:
        bsfjax.estimate_map(bsfjax.spectrum(src, 30), bsfjax.spectrum(cloud, 30),
                            source_mesh=src, target_mesh=cloud)
        refusal = "not refused"
    except bsfjax.BSFError as exc:
        refusal = str(exc)
    rows.append({"target": "noisy cloud without landmarks", "refused": refusal})
    return rows


def main():
    ap = h.parser(__doc__)
    h.add_out(ap, default="bench-results")
    h.add_data(ap)
    ap.add_argument("--points", type=int, default=15_000, help="points of the cloud")
    ap.add_argument("--noise", type=float, default=0.0025,
                    help="Gaussian noise σ as a fraction of the height")
    ap.add_argument("--seed", type=int, default=0, help="sampling seed (noise: seed + 1)")
    args = ap.parse_args()
    data = h.Path(args.data)
    h.require_data(data / "faust" / "tr_reg_000.off", data / "faust" / "tr_reg_010.off",
                   data / h.SMPL_SEGMENTATION)
    with tempfile.TemporaryDirectory() as tmp:
        rows = run(data, h.Path(tmp), args.points, args.noise, args.seed)
    out = h.Path(args.out)
    h.write_json(out / "bench_point_clouds.json",
                 {"machine": h.short_machine(), "points": args.points, "noise": args.noise,
                  "seed": args.seed, "rows": rows})
    lines = ["| target (FAUST 000 → 010, 5 landmarks) | points | area labelled right | "
             "vertices / points right | bsfjax transfer (s) |",
             "|---|---|---|---|---|"]
    lines += [f"| {r['target']} | {r['n']} | {r['accuracy']:.1%} | {r['vertex_share']:.1%} | "
              f"{r['seconds']:.1f} |" for r in rows if "accuracy" in r]
    lines.append(f"\nwithout landmarks: {rows[-1]['refused']}")
    lines.append(f"\n{h.short_machine()}")
    h.write_text(out / "bench_point_clouds.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
