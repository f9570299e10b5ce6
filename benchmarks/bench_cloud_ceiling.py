"""How far can the default transfer go on a noisy point cloud?  Ceilings with exact inputs.

The noisy 15K-point clouds of ``bench_point_clouds.py`` (the suite's ``clouds`` part) stay
1.6–3.6 points below their clean mesh pair with the default ``bsfjax transfer`` and 5
landmarks (3.1–4.3 before ZoomOut's larger step on clouds), where the issue "Real scans"
asks for 3.  This script gives the command inputs no
estimator can beat, and feeds the exact map through the estimator's own ZoomOut, to say which
stage the loss comes from.  Per pair (FAUST source → another registration), the clean mesh
pair and one noisy cloud (15K points sampled area-uniformly, seed ``s`` (``--seed``, default
0), Gaussian noise of σ = 0.25 % of the height, seed ``s + 1``: the suite's clouds):

* ``estimate, 5 lm``: the default (the docs' 5 landmarks; on the cloud the nearest points);
* ``estimate, 55 lm``: the default estimate with 50 more exact pairs (farthest points of the
  target, each with its ground-truth source vertex);
* ``exact p2p → refined``: ``--map p2p`` with the ground-truth point map and the default
  ``refined`` transfer (its ZoomOut continuation to 100 eigenpairs and the pull-back);
* ``exact C → refined``: ``--map fmap`` with the ground-truth ``30 × 30`` functional map in
  the command's bases;
* ``exact C → ZoomOut 60 (step s) → refined``: the same map first grown to ``60 × 60`` by
  the estimator's ZoomOut (steps of ``s`` eigenpairs on its 2000 samples per shape, as
  `MapEstimator` runs it after its descriptor-based ``C₀``: 2 on meshes, 6 where a shape is
  a point cloud, ``CLOUD_ZOOMOUT_STEP``), then ``--map fmap``: what the estimator's stages
  after ``C₀`` make of a perfect ``C₀``.

Truth on a cloud: the SMPL part of the registration vertex nearest to the clean sampled point
(its ground-truth source vertex: the same template vertex).  Accuracy: the share of the
target's lumped area (its Laplacian's mass) labelled right.

    python benchmarks/bench_cloud_ceiling.py --out R.md      # ~2 min on 2 cores
    python benchmarks/bench_cloud_ceiling.py --out R.md --pairs 0-10 --seed 2   # draw 1's
"""

from __future__ import annotations

import _harness as h

N_POINTS, NOISE, N_TRUE, K = 15_000, 0.0025, 50, 30


def _cloud(data, tgt: int, seed: int = 0):
    """The noisy cloud of target ``tgt``: points, ground-truth source vertex per point, and
    the 5 landmarks' nearest points."""
    import numpy as np
    from scipy.spatial import cKDTree

    import bsfjax
    from bsfjax.internal import sample_surface

    mesh = bsfjax.load_mesh(str(h.Path(data) / "faust" / f"tr_reg_{tgt:03d}.off"))
    pts, _, _ = sample_surface(mesh, N_POINTS, seed=seed)
    gt = cKDTree(mesh.vertices).query(pts)[1]
    height = float(np.ptp(np.asarray(mesh.vertices)[:, 1]))
    noisy = pts + np.random.default_rng(seed + 1).normal(scale=NOISE * height, size=pts.shape)
    lm = cKDTree(pts).query(np.asarray(mesh.vertices)[list(h.LANDMARKS)])[1]
    return noisy, gt, lm


def _exact_maps(source: str, target: str, gt, samples: int = 2000, steps=(2, 6)):
    """The ground-truth ``K × K`` map in the command's bases, and that map grown to ``2K``
    by ZoomOut as the estimator grows its ``C₀`` (each of ``steps``, on ``samples`` per
    shape)."""
    import numpy as np

    import bsfjax

    sp, tp = (bsfjax.prepare_scan(bsfjax.load_mesh(p), True).mesh for p in (source, target))
    sm, sn = bsfjax.spectrum(sp, 2 * K), bsfjax.spectrum(tp, 2 * K)
    C = np.asarray(bsfjax.fmap_from_p2p(sm, sn, gt))[:K, :K]
    sub = (bsfjax.subsample(sp, samples), bsfjax.subsample(tp, samples))
    return C, {s: np.asarray(bsfjax.zoomout(C, sm, sn, 2 * K, step=s, samples=sub))
               for s in steps}


def run(data, folder, pairs=((0, 10), (1, 11), (2, 12)), seed: int = 0) -> list[dict]:
    import numpy as np

    import bsfjax

    labels = h.smpl_labels(data)
    lab_file, out = (str(h.Path(folder) / n) for n in ("smpl.txt", "out.txt"))
    np.savetxt(lab_file, labels, fmt="%d")
    rows = []
    for src, tgt in pairs:
        source = str(h.Path(data) / "faust" / f"tr_reg_{src:03d}.off")
        pair = f"{src:03d}→{tgt:03d}"
        mesh_path = str(h.Path(data) / "faust" / f"tr_reg_{tgt:03d}.off")
        mesh = bsfjax.load_mesh(mesh_path)
        mass = np.asarray(bsfjax.laplacian(mesh)[1].diagonal())
        clean = h.run_cli(source, mesh_path, lab_file, out, True, True)[0]
        rows.append({"pair": pair, "target": "clean mesh",
                     "estimate, 5 lm": h.accuracy(clean, labels, mass)})
        noisy, gt, lm = _cloud(data, tgt, seed)
        path = str(h.Path(folder) / "cloud.xyz")
        np.savetxt(path, noisy, fmt="%.17g")
        cloud = bsfjax.load_mesh(path)
        mass = np.asarray(bsfjax.laplacian(cloud)[1].diagonal())
        truth = labels[gt]
        extra = [int(i) for i in bsfjax.farthest_point_sampling(cloud, N_TRUE, seed=0)]
        C, grown = _exact_maps(source, path, gt)
        files = {}
        for name, arr, fmt in (("gt", gt, "%d"), ("C", C, "%.17g"),
                               *((f"C60_{s}", g, "%.17g") for s, g in grown.items())):
            files[name] = str(h.Path(folder) / f"{name}.txt")
            np.savetxt(files[name], arr, fmt=fmt)
        runs = {
            "estimate, 5 lm": ([], (list(h.LANDMARKS), [int(i) for i in lm])),
            f"estimate, {N_TRUE + 5} lm": ([], (list(h.LANDMARKS) + [int(gt[i]) for i in extra],
                                                [int(i) for i in lm] + extra)),
            "exact p2p → refined": (["--map", "p2p", files["gt"], "--method", "refined"], False),
            "exact C → refined": (["--map", "fmap", files["C"]], False),
        }
        runs.update({f"exact C → ZoomOut 60 (step {s}) → refined":
                     (["--map", "fmap", files[f"C60_{s}"]], False) for s in grown})
        row = {"pair": pair, "target": f"noisy cloud, seed {seed}"}
        for name, (args, landmarks) in runs.items():
            got = h.run_cli(source, path, lab_file, out, landmarks, True, args)[0]
            row[name] = h.accuracy(got, truth, mass)
            print(f"  {pair} {name}: {row[name]:.1%}", file=h.sys.stderr, flush=True)
        rows.append(row)
    return rows


def main():
    h.ceiling_main(__doc__, run, "clean mesh",
                   "Δ: points from the clean mesh pair's default (5 landmarks); the issue's bar "
                   "for point clouds with 5 landmarks is −3.0.", seed=True)


if __name__ == "__main__":
    main()
