"""The main job, ``bsfjax demo``: the whole pipeline on the built-in example pair.

1. the built-in source/target pair ([`bsfjax.example_pair`][bsfjax.example_pair]: an articulated body in two poses,
   exact vertex-to-vertex ground truth, a 6-part segmentation);
2. both Laplace–Beltrami spectra;
3. the Binary Sparse Frame on the source (n_BSF = 5 % of the vertices by farthest point sampling,
   the paper's τ and γ);
4. two functional maps: ground truth (from the identity point map) and estimated (WKS
   descriptors + 6 landmarks, descriptor commutativity, then ZoomOut refinement);
5. random connected indicator functions and the segmentation, approximated on the source and
   transferred to the target with the pull-back through the point map (``p2p``), the pull-back
   through the refined map (``refined``, the default of ``bsfjax transfer``), the spectral
   projection (``std``) and the paper's BSF (``omp``), all through [`bsfjax.transfer`][bsfjax.transfer];
6. a compact table of errors (area-weighted, square-root form of paper Eq. 14/15) and timings,
   ``results.json`` and PNG figures.

Library use: `run_demo` returns the results dictionary that the CLI prints.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .._util import write_text_atomic
from .._util import check_int
from .._util import BSFError

__all__ = ["run_demo", "format_table", "example_landmarks"]


def example_landmarks(pair) -> np.ndarray:
    """One landmark per part of the example body: the vertex of the part farthest from the
    body's centroid (head top, hand and foot tips; the torso's farthest point).

    Computed on the source; the example's ground truth is the identity, so the same indices
    are the landmarks on the target.
    """
    v = np.asarray(pair.source.vertices)
    centre = v.mean(axis=0)
    far = np.linalg.norm(v - centre, axis=1)
    return np.array([np.flatnonzero(pair.labels == p)[np.argmax(far[pair.labels == p])]
                     for p in range(len(pair.label_names))])


class _Timer:
    def __init__(self, progress):
        self.times: dict[str, float] = {}
        self.progress = progress

    def __call__(self, name, fn, *args, **kwargs):
        import jax

        if self.progress:
            print(f"  {name} ...", end="", flush=True)
        t = time.perf_counter()
        out = jax.block_until_ready(fn(*args, **kwargs))
        self.times[name] = time.perf_counter() - t
        if self.progress:
            print(f" {self.times[name]:.2f} s", flush=True)
        return out


def run_demo(out_dir: str | Path | None = "bsfjax-demo", *, levels: int = 3, k: int = 30,
             k_refine: int = 60, n_functions: int = 50, seed: int = 0, figures: bool = True,
             progress: bool = True) -> dict:
    """Run the demonstration pipeline and return its results (also written to ``out_dir``).

    **Arguments:**

    - `out_dir`: folder for ``results.json`` and the PNG figures (``None``: write nothing).
    - `levels`: resolution of the built-in pair (3 → 8066 vertices).
    - `k`: eigenpairs used by every method (the paper's estimated-map setting is k = 30).
    - `k_refine`: ZoomOut's target size for refining the estimated map.
    - `n_functions`: random connected indicators (5–25 % of the area each).
    - `seed`: seed of the functions and of farthest point sampling.
    - `figures`: write PNG figures.
    - `progress`: print each stage and its time.
    """
    from .._mesh import example_pair
    from .._maps import fmap_from_p2p, fmap_to_p2p
    from .._frame import build_frame
    from .._sampling import geodesic_error
    from .._pipeline import transfer_labels
    from .._maps import MapEstimator
    from .._metrics import random_indicators
    from .._metrics import relative_error
    from .._maps import REFINE_EIGENPAIRS
    from .._sampling import farthest_point_sampling
    from .._spectral import spectrum
    from .._transfer import Pair, transfer

    # every argument is checked before the first (slow) stage runs
    check_int(k, "k", 2)
    check_int(k_refine, "k_refine", k)
    check_int(n_functions, "n_functions", 1)
    check_int(seed, "seed", 0)
    timer = _Timer(progress)
    t_all = time.perf_counter()
    pair = timer("example pair", example_pair, levels)
    if k_refine >= pair.source.n_vertices:
        raise BSFError(f"k_refine must be below the {pair.source.n_vertices} vertices of the "
                       f"example pair at levels={levels}, got {k_refine}")
    src, tgt = pair.source, pair.target
    n = src.n_vertices
    k_max = min(max(k, k_refine, REFINE_EIGENPAIRS), n - 1)  # 'refined' continues the map
    sm = timer("spectrum (source)", spectrum, src, k_max)
    sn = timer("spectrum (target)", spectrum, tgt, k_max)
    centers = timer("farthest point sampling", farthest_point_sampling, src, 0.05, seed=seed)
    frame = timer("frame build", build_frame, sm.truncate(k), centers)
    gt = np.asarray(pair.p2p)
    C_gt = timer("ground-truth map", fmap_from_p2p, sm.truncate(k), sn.truncate(k), gt)
    lm = example_landmarks(pair)
    est = timer("map estimation (WKS + landmarks, ZoomOut)", MapEstimator(k=k, refine_to=k_refine),
                sm, sn, (lm, lm), source_mesh=src, target_mesh=tgt)
    map_error = {"estimated": float(geodesic_error(src, np.asarray(fmap_to_p2p(est.C_initial, sm,
                                                                                sn)), gt)),
                 "refined": float(geodesic_error(src, est.p2p, gt))}
    F = random_indicators(src, n_functions, seed, area_fraction=(0.05, 0.25), mass=sm.mass)
    area = np.asarray(sn.mass)
    rows = []
    outputs = {}
    for map_name, C, p2p in (("ground truth", C_gt, gt), ("estimated", est.C, est.p2p)):
        inp = Pair(source=sm.truncate(k), target=sn.truncate(k), C=C, centers=centers, p2p=p2p)
        # 'refined' uses the whole spectra, and the samples of the estimate's ZoomOut
        full = Pair(source=sm, target=sn, C=C, p2p=p2p, samples=est.samples)
        for method in ("p2p", "refined", "std", "omp"):
            res = timer(f"{method} on {n_functions} functions, {map_name} map", transfer,
                        method, full if method == "refined" else inp, F, k=k)
            seg = transfer_labels(sm if method == "refined" else sm.truncate(k),
                                  sn if method == "refined" else sn.truncate(k), pair.labels,
                                  method=method, C=C, p2p=p2p, centers=centers,
                                  samples=est.samples)
            e_app = (None if res.approximation is None
                     else float(np.mean(relative_error(F, res.approximation, sm.mass))))
            e_tr = np.asarray(relative_error(F[:, gt], res.transferred, sn.mass))  # f∘T on N
            correct = seg.labels == pair.labels[gt]
            rows.append({"map": map_name, "method": method, "approximation_error": e_app,
                         "transfer_error": float(e_tr.mean()),
                         "segmentation_accuracy": float(np.sum(area * correct) / np.sum(area)),
                         "unassigned_share": seg.unassigned_share})
            outputs[(map_name, method)] = (res, seg.labels)
    total = time.perf_counter() - t_all
    results = {
        "example": {"n_vertices": n, "n_faces": src.n_faces, "labels": list(pair.label_names)},
        "settings": {"k": k, "k_refine": k_refine, "n_bsf": int(len(centers)),
                     "n_atoms": frame.n_atoms, "taus": [1e-3, 5e-3, 1e-2], "gamma": 0.75,
                     "omp_sparsity": 10, "n_functions": n_functions, "seed": seed,
                     "landmarks": lm.tolist()},
        "map_geodesic_error": map_error,
        "errors": rows,
        "timings_s": {**timer.times, "total": total},
    }
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        if figures:
            results["figures"] = _figures(out, pair, frame, centers, F, gt, outputs, timer)
        write_text_atomic(out / "results.json", json.dumps(results, indent=2) + "\n")
    results["timings_s"]["total"] = time.perf_counter() - t_all
    return results


def _figures(out: Path, pair, frame, centers, F, gt, outputs, timer) -> list[str]:
    from .._plot import plot_atoms, plot_error, plot_function, plot_segmentation
    from .._frame import SparseFrame

    names = pair.label_names
    files = {}

    def save(name, fn, *args, **kwargs):
        fn(*args, path=out / name, **kwargs)
        files[name] = True

    def draw():
        save("segmentation_source.png", plot_segmentation, pair.source, pair.labels,
             label_names=names, title="source: built-in segmentation")
        for (map_name, method), (_, labels_out) in outputs.items():
            if method != "omp":
                continue
            tag = "gt_map" if map_name == "ground truth" else "estimated_map"
            save(f"segmentation_target_bsf_{tag}.png", plot_segmentation, pair.target, labels_out,
                 label_names=names, title=f"target: BSF transfer ({map_name} map)")
        j = 0
        f_true = F[j][gt]
        save("indicator_source.png", plot_function, pair.source, F[j], title="source: indicator",
             vmin=0, vmax=1)
        for method in ("std", "omp"):
            res = outputs[("ground truth", method)][0]
            save(f"indicator_transfer_{method}.png", plot_function, pair.target,
                 np.asarray(res.transferred[j]), vmin=-0.25, vmax=1.25,
                 title=f"target: {'spectral projection' if method == 'std' else 'BSF (omp)'} transfer")
            save(f"indicator_error_{method}.png", plot_error, pair.target, f_true,
                 np.asarray(res.transferred[j]), title=f"|error| of the {method} transfer", vmax=1.0)
        c = 0
        n_c = len(centers)
        js = [c + s * n_c for s in range(3)]
        cols = (frame.atom_columns(js) if isinstance(frame, SparseFrame)
                else np.asarray(frame.atoms)[:, js])
        save("atoms.png", plot_atoms, pair.source, cols, [1e-3, 5e-3, 1e-2], center=int(centers[c]))

    timer("figures", draw)
    return sorted(files)


def format_table(results: dict) -> str:
    """The compact text table ``bsfjax demo`` prints."""
    s = results["settings"]
    lines = [
        f"built-in pair: {results['example']['n_vertices']} vertices; k = {s['k']}, "
        f"{s['n_bsf']} BSF centres, {s['n_atoms']} atoms, {s['n_functions']} random indicators",
        f"estimated map: mean geodesic error {results['map_geodesic_error']['estimated']:.4f} "
        f"-> {results['map_geodesic_error']['refined']:.4f} after ZoomOut (fraction of sqrt(area))",
        "",
        f"{'map':<13} {'method':<7} {'E_app':>7} {'E_tran':>7} {'seg. acc.':>9} {'unassigned':>10}",
    ]
    for r in results["errors"]:
        app = "-" if r["approximation_error"] is None else \
            f"{r['approximation_error']:.3f}"
        lines.append(f"{r['map']:<13} {r['method']:<7} {app:>7} "
                     f"{r['transfer_error']:>7.3f} {r['segmentation_accuracy']:>9.1%} "
                     f"{r['unassigned_share']:>10.1%}")
    lines.append("")
    lines.append("E = area-weighted relative error sqrt(sum A (f - f~)^2 / sum A f^2), mean over "
                 "functions; p2p = pull-back through the point map (no approximation), "
                 "refined = pull-back through the refined map (the default of 'bsfjax "
                 "transfer'), std = spectral projection, omp = the paper's BSF with OMP (S = 10)")
    t = results["timings_s"]
    lines.append("timings: " + ", ".join(f"{k} {v:.2f} s" for k, v in t.items()))
    return "\n".join(lines)
