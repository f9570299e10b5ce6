"""How far can any map go on the segmentation pairs?  Ceilings of the SMPL-part accuracy.

Two questions, answered on the pairs of ``bench_segmentation.py``:

1. **FAUST_5k: how good is the truth?**  A remeshed shape's labels are built through
   ``sampleID.vts`` (``bsfjax.experiments.segmentation.shape_labels``): vertex ``A.vts[i]``
   takes the label of template vertex ``sampleID[i]``, a vertex named by no entry that of its
   nearest named vertex.  The remeshes are LRVD remeshes of the registrations in
   ``../shared/data/faust``, so each 5K vertex also has a *geometric* label: that of the
   nearest registration vertex, after a similarity (Procrustes) fit of the ``.vts`` vertices to
   their template vertices.  The two truths are compared, and three maps are scored against
   both: the ``.vts`` ground truth (what the benchmark's truth shares its construction with), the
   *geometric* exact map (target vertex → nearest target-registration vertex = template vertex
   → the source registration's same vertex → nearest source 5K vertex), and the default map's
   pull-back and ``refined`` (the CLI default).
2. **FAUST: the spectral point-map step.**  The nearest-neighbour point map of the ground-truth
   functional map ``C = Φ_Nᵀ A_N Φ_M[gt]`` at k = 60 … 300 eigenpairs, both ways of
   :func:`bsfjax.fmap_to_p2p` (``Φ_N`` against ``Φ_M Cᵀ``, the default, and ``Φ_N C`` against
   ``Φ_M``, ``adjoint=True``): how much a spectral point-map step loses even when its
   functional map is exact.
3. **Both: mean geodesic error against label accuracy.**  For each of the 9 pairs, the mean
   geodesic error (:func:`bsfjax.geodesic_error`, units of √area, against the ground-truth
   point map) and the SMPL-part accuracy of the maps above: the default map's pull-back, its
   ``refined`` point map, the exact functional map at 60 and 100 eigenpairs converted both
   ways, and ``refined`` started from the ground truth.  It says whether the remaining errors
   are a matter of how far the map is off on average, or of which way.
4. **What true landmarks on the torso buy.**  The default map estimated again with its 5
   landmarks and ``n`` more inside the source's torso parts (hips, spine, spine1, spine2:
   their farthest points, Euclidean, seed 0), each with its ground-truth image, for ``n`` in
   :data:`TORSO_LANDMARKS`: pull-back and ``refined``.  Then whether geodesic distances from
   those landmarks could tell the registration from the default map: the area-weighted mean
   over the target's torso of ``|d_N(y, l) − d_M(T(y), l')|`` over the landmark pairs
   ``(l', l)`` (units of √area), for ``T`` the ground truth and the default map.

    python benchmarks/bench_segmentation_ceiling.py --out R [--data ../shared/data]

Writes ``segmentation_ceiling.md`` into ``--out``.  Needs the FAUST registrations of the remeshed
shapes (``faust/tr_reg_000, 001, 010, 011``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.spatial

import _harness as h
import bsfjax as bj
from bsfjax.experiments import load_dataset
from bsfjax.experiments.segmentation import (N_LANDMARKS, _maps, gt_inverse, label_metrics,
                                             shape_labels)

FAUST_PAIRS = h.SEGMENTATION_PAIRS["faust"]
REMESHED_PAIRS = h.SEGMENTATION_PAIRS["faust_5k"]
KS = (60, 100, 150, 200, 300)
TORSO_PARTS = ("hips", "spine", "spine1", "spine2")
TORSO_LANDMARKS = (8, 20)
#: The farthest-point samples the default map's ZoomOut runs on.
ZOOMOUT_SAMPLES = bj.MapEstimator().zoomout_samples


def similarity_fit(X: np.ndarray, Y: np.ndarray):
    """The scale, rotation and translation that best carry the rows of ``X`` to ``Y``."""
    mx, my = X.mean(0), Y.mean(0)
    U, S, Vt = np.linalg.svd((X - mx).T @ (Y - my))
    d = np.sign(np.linalg.det(U @ Vt))
    R = U @ np.diag([1.0, 1.0, d]) @ Vt
    s = (S * [1.0, 1.0, d]).sum() / ((X - mx) ** 2).sum()
    return lambda Z: s * (Z - mx) @ R + my


def geometric(data: Path, ds, index: int, sample_id: np.ndarray):
    """A remeshed shape's registration, its 5K vertices fitted onto it, the template vertex
    nearest each of them, and the fit's mean residual (units of the registration)."""
    e = ds.shapes[index]
    reg = bj.load_mesh(data / "faust" / f"{e.name}.off")
    fit = similarity_fit(e.mesh.vertices[e.vts], reg.vertices[sample_id])
    residual = float(np.linalg.norm(fit(e.mesh.vertices[e.vts]) - reg.vertices[sample_id],
                                    axis=1).mean())
    aligned = fit(e.mesh.vertices)
    nearest = scipy.spatial.cKDTree(reg.vertices).query(aligned)[1]
    return reg, aligned, nearest, residual


_DEFAULT_MAPS: dict = {}


def default_map(ds, i: int, j: int, sm, sn, gt):
    """``(C, p2p)``: pair ``i → j``'s default map as ``bench_segmentation.py`` estimates it (5
    farthest-point landmarks with their images under the ground truth ``gt``), estimated once
    per run."""
    key = (str(ds.shapes[i].path), str(ds.shapes[j].path))
    if key not in _DEFAULT_MAPS:
        src, tgt = ds.shapes[i].mesh, ds.shapes[j].mesh
        lm = np.asarray(bj.farthest_point_sampling(src, N_LANDMARKS, seed=0))
        _DEFAULT_MAPS[key] = _maps(sm, sn, gt, 30, (lm, gt_inverse(gt, lm, tgt, src)),
                                   (src, tgt), ("default",))["default"]
    return _DEFAULT_MAPS[key]


def remeshed(data: Path, template: np.ndarray, cache: str) -> list[str]:
    ds = load_dataset(data / "faust_5k")
    index = {e.name: i for i, e in enumerate(ds.shapes)}
    sample_id = np.loadtxt(data / "faust_5k" / "corres" / "sampleID.vts", dtype=np.int64) - 1
    lines = ["| FAUST_5k pair | truths agree | .vts ground truth | geometric exact map | "
             "default p2p | default refined |", "|---|---|---|---|---|---|"]
    for a, b in REMESHED_PAIRS:
        i, j = index[f"tr_reg_{a}"], index[f"tr_reg_{b}"]
        sm, sn = (bj.spectrum(ds.shapes[t].mesh, 100, cache_dir=cache) for t in (i, j))
        mass, tgt = np.asarray(sn.mass), ds.shapes[j].mesh
        reg_m, pos_m, near_m, res_m = geometric(data, ds, i, sample_id)
        reg_n, _, near_n, res_n = geometric(data, ds, j, sample_id)
        truth = {"sampleID": (shape_labels(ds, i, template), shape_labels(ds, j, template)),
                 "geometric": (template[near_m], template[near_n])}
        # target vertex -> template vertex -> that vertex on the source registration -> the
        # nearest source 5K vertex (both registrations share the template's vertex order)
        exact = scipy.spatial.cKDTree(pos_m).query(reg_m.vertices[near_n])[1]
        gt = ds.ground_truth(i, j)
        C, p2p = default_map(ds, i, j, sm, sn, gt)
        cells = []
        for lab_m, lab_n in truth.values():
            acc = [label_metrics(pred, lab_n, mass, tgt)["accuracy"] for pred in (
                lab_m[gt], lab_m[exact], lab_m[np.asarray(p2p)],
                bj.transfer_labels(sm, sn, lab_m, C=C, p2p=p2p, mesh=ds.shapes[i].mesh).labels)]
            cells.append(acc)
        agree = 100 * float(mass[truth["sampleID"][1] == truth["geometric"][1]].sum()
                            / mass.sum())
        lines.append(f"| {a}→{b} | {agree:.2f} % | " + " | ".join(
            f"{s:.2f} / {g:.2f}" for s, g in zip(*cells)) + " |")
        print(lines[-1], f"(fit residuals {res_m:.4f}, {res_n:.4f})", file=sys.stderr)
    return lines


def spectral_ceiling(data: Path, template: np.ndarray, cache: str) -> list[str]:
    ds = load_dataset(data / "faust")
    index = {e.name: i for i, e in enumerate(ds.shapes)}
    lines = ["| FAUST pair | conversion | " + " | ".join(f"k = {k}" for k in KS) + " |",
             "|---|---|" + "---|" * len(KS)]
    for a, b in FAUST_PAIRS:
        i, j = index[f"tr_reg_{a}"], index[f"tr_reg_{b}"]
        sm, sn = (bj.spectrum(ds.shapes[t].mesh, max(KS), cache_dir=cache) for t in (i, j))
        mass = np.asarray(sn.mass)
        gt, lab_m = ds.ground_truth(i, j), shape_labels(ds, i, template)
        lab_n = shape_labels(ds, j, template)
        rows = {"default": [], "adjoint": []}
        for k in KS:
            sm_k, sn_k = sm.truncate(k), sn.truncate(k)
            C = bj.fmap_from_p2p(sm_k, sn_k, gt)
            for name in rows:
                p2p = np.asarray(bj.fmap_to_p2p(C, sm_k, sn_k, adjoint=name == "adjoint"))
                rows[name].append(label_metrics(lab_m[p2p], lab_n, mass,
                                                ds.shapes[j].mesh)["accuracy"])
        for name, row in rows.items():
            lines.append(f"| {a}→{b} | {name} | " + " | ".join(f"{x:.2f}" for x in row) + " |")
            print(lines[-1], file=sys.stderr)
    return lines


def nine_pairs(data: Path, template: np.ndarray, cache: str):
    """The 9 pairs of ``bench_segmentation.py``, each as ``(name, ds, i, j, src, tgt, sm, sn,
    gt, labels_m, labels_n)``: spectra of 100, the ground-truth map and the SMPL labels."""
    for folder, pairs in (("faust", FAUST_PAIRS), ("faust_5k", REMESHED_PAIRS)):
        ds = load_dataset(data / folder)
        index = {e.name: i for i, e in enumerate(ds.shapes)}
        for a, b in pairs:
            i, j = index[f"tr_reg_{a}"], index[f"tr_reg_{b}"]
            src, tgt = ds.shapes[i].mesh, ds.shapes[j].mesh
            sm, sn = (bj.spectrum(m, 100, cache_dir=cache) for m in (src, tgt))
            yield (f"{folder} {a}→{b}", ds, i, j, src, tgt, sm, sn, ds.ground_truth(i, j),
                   shape_labels(ds, i, template), shape_labels(ds, j, template))


def geodesic_vs_labels(data: Path, template: np.ndarray, cache: str) -> list[str]:
    names = ("default p2p", "refined", "exact 60", "exact 60 adjoint", "exact 100",
             "exact 100 adjoint", "refined from truth")
    lines = ["| pair | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for name, ds, i, j, src, tgt, sm, sn, gt, lab_m, lab_n in nine_pairs(data, template, cache):
        _, p2p = default_map(ds, i, j, sm, sn, gt)
        # "refined" continues on the samples the default map's ZoomOut ran on
        samples = tuple(bj.subsample(m, ZOOMOUT_SAMPLES) for m in (src, tgt))
        last = lambda start: np.asarray(bj.refine_point_maps(  # noqa: E731
            sm, sn, start, n_keep=1, samples=samples))[-1]
        maps = [np.asarray(p2p), last(p2p)]
        for k in (60, 100):
            C = bj.fmap_from_p2p(sm.truncate(k), sn.truncate(k), gt)
            maps += [np.asarray(bj.fmap_to_p2p(C, sm.truncate(k), sn.truncate(k),
                                               adjoint=adj)) for adj in (False, True)]
        maps.append(last(gt))
        err = np.asarray(bj.geodesic_error(src, np.stack(maps), gt))
        acc = [label_metrics(lab_m[t], lab_n, np.asarray(sn.mass), tgt)["accuracy"]
               for t in maps]
        lines.append(f"| {name} | " + " | ".join(
            f"{100 * e:.2f} / {x:.2f}" for e, x in zip(err, acc)) + " |")
        print(lines[-1], file=sys.stderr)
    return lines


def torso_landmarks(data: Path, template: np.ndarray, part_names, cache: str) -> list[str]:
    torso_ids = [part_names.index(t) for t in TORSO_PARTS]
    head = [f"+{n} torso: p2p / refined" for n in TORSO_LANDMARKS]
    lines = ["| pair | 5 landmarks: p2p / refined | " + " | ".join(head) + " | torso "
             "distance defect × 100, truth / default |", "|---|---|" + "---|" * len(head) + "---|"]
    for name, ds, i, j, src, tgt, sm, sn, gt, lab_m, lab_n in nine_pairs(data, template, cache):
        mass = np.asarray(sn.mass)
        acc = lambda labels: label_metrics(labels, lab_n, mass, tgt)["accuracy"]  # noqa: E731
        five = np.asarray(bj.farthest_point_sampling(src, N_LANDMARKS, seed=0))
        torso = np.flatnonzero(np.isin(lab_m, torso_ids))
        C, p2p = default_map(ds, i, j, sm, sn, gt)
        # "refined" continues on the samples each map's ZoomOut ran on, as the CLI's does
        samples = tuple(bj.subsample(m, ZOOMOUT_SAMPLES) for m in (src, tgt))
        cells = [(acc(lab_m[np.asarray(p2p)]), acc(bj.transfer_labels(
            sm, sn, lab_m, C=C, p2p=p2p, samples=samples).labels))]
        for n in TORSO_LANDMARKS:
            # the torso's own farthest points (Euclidean, seed 0)
            ls = np.concatenate([five, torso[bj.farthest_point_sampling(
                src.vertices[torso], n, seed=0)]])
            lt = gt_inverse(gt, ls, tgt, src)
            # the default map's recipe (bsfjax.experiments.segmentation), more landmarks
            est = bj.estimate_map(sm.truncate(60), sn.truncate(60), k=30, landmarks=(ls, lt),
                                  refine_to=60, source_mesh=src, target_mesh=tgt)
            cells.append((acc(lab_m[np.asarray(est.p2p)]), acc(bj.transfer_labels(
                sm, sn, lab_m, C=est.C, p2p=est.p2p, samples=est.samples).labels)))
        # with the last landmarks: how well each map keeps the distances to them
        d_m = bj.geodesic_distances(src, ls).T / np.sqrt(src.area)
        d_n = bj.geodesic_distances(tgt, lt).T / np.sqrt(tgt.area)
        rows = np.flatnonzero(np.isin(lab_n, torso_ids))
        defect = [float(np.average(np.abs(d_n[rows] - d_m[np.asarray(t)[rows]]).mean(1),
                                   weights=mass[rows])) for t in (gt, p2p)]
        lines.append(f"| {name} | " + " | ".join(
            f"{p:.2f} / {r:.2f}" for p, r in cells)
            + f" | {100 * defect[0]:.3f} / {100 * defect[1]:.3f} |")
        print(lines[-1], file=sys.stderr)
    return lines


def main(argv=None) -> int:
    ap = h.parser(__doc__)
    h.add_data(ap, type=str)
    h.add_out(ap)
    h.add_cache(ap, h.HOME_CACHE)
    args = ap.parse_args(argv)
    data, out = Path(args.data), Path(args.out)
    h.require_data(data / h.SMPL_SEGMENTATION, data / "faust", data / "faust_5k")
    out.mkdir(parents=True, exist_ok=True)
    template, part_names = bj.load_labels(data / h.SMPL_SEGMENTATION)
    text = ["Accuracy % against the `.vts` (sampleID) truth / the geometric truth:", "",
            *remeshed(data, template, args.cache), "",
            "Nearest-neighbour point map of the ground-truth functional map, accuracy %:", "",
            *spectral_ceiling(data, template, args.cache), "",
            "Mean geodesic error × 100 (units of √area) / accuracy % of each map:", "",
            *geodesic_vs_labels(data, template, args.cache), "",
            "True landmarks inside the torso: accuracy % of each map, and how far each map is "
            "from keeping the geodesic distances to the 5 + "
            f"{TORSO_LANDMARKS[-1]} landmarks on the target's torso:", "",
            *torso_landmarks(data, template, part_names, args.cache)]
    h.write_text(out / "segmentation_ceiling.md", "\n".join(text) + "\n")
    print("\n".join(text))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
