"""Real segmentations: a part labelling of a template carried to other shapes.

Not in the paper.  A segmentation of the template (the SMPL body parts of the FAUST
registrations, ``../shared/data/segmentations/``) labels every shape of a ``--data`` folder:
a shape with the template's vertex count is in the template's vertex order (FAUST
registrations); a remeshed shape (``faust_5k``) is labelled through its ``.vts`` entries and the
folder's ``corres/sampleID.vts`` (template vertex of each ``.vts`` entry), a vertex named by no
entry taking the label of its Euclidean-nearest named vertex.

For each pair and each of three maps — ``default`` (what ``bsfjax transfer`` estimates: WKS +
5 landmarks by Euclidean FPS on the source with their ground-truth images, k = 30, ZoomOut
guided by them to 100 on 2000 samples per shape), ``crude`` (k = 20, no refinement, same landmarks) and ``truth`` (the ground-truth point
map and its functional map) — and, when asked for, two maps without landmarks (``no
landmarks``: what ``bsfjax transfer`` estimates without ``--landmarks``, several starts and
landmarks read off the kept map; ``no landmarks, one start``: the single start at k = 30 with
the orientation term, the landmark-free estimate of earlier versions) and two with fewer landmarks
(``1
landmark``, ``2 landmarks``: the default map's estimate with the first one or two of its 5
landmarks) — every method labels the target
through the same map, and the
rows give: area share labelled correctly, unassigned share, mean and worst per-part IoU
(area-weighted, over the parts of the true target labelling), accuracy in a band of
``BAND`` · √area around the true part borders, and seconds (after the map; first call
includes compilation).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import scipy.spatial
from tqdm.auto import tqdm

from .._util import BSFError
from .._maps import fmap_from_p2p
from .._pipeline import transfer_labels
from .._maps import MapEstimator, estimate_map
from .._mesh import load_labels
from .._mesh import mesh_edges
from .._maps import REFINE_EIGENPAIRS
from .._sampling import farthest_point_sampling, subsample
from .._spectral import spectrum
from ._datasets import Dataset
from ._io import Report, pivot_markdown

__all__ = ["segmentation_experiment", "segmentation_pair", "shape_labels", "template_vertices",
           "label_metrics", "MAPS", "DEFAULT_MAPS", "METHODS"]

DEFAULT_KS = (30,)
DESCRIPTION = ("Segmentation transfer (not in the paper): a template's part labelling carried "
               "to other shapes through the same map by each method; area accuracy, IoU, "
               "border accuracy.")
#: The maps a method can be run through (see the module doc).
MAPS = ("default", "crude", "truth", "no landmarks", "no landmarks, one start", "1 landmark",
        "2 landmarks")
#: The maps every method is run through unless ``maps=`` names others.
DEFAULT_MAPS = MAPS[:3]
#: Method labels → (method name, options): the BSF coders with the paper's and the adaptive
#: frame.
METHODS = {"p2p": ("p2p", {}), "refined": ("refined", {}), "std": ("std", {}),
           **{c: (c, {}) for c in ("omp", "omp_error", "lstsq", "lasso")},
           **{f"{c} adaptive": (c, {"taus": "adaptive"})
              for c in ("omp", "omp_error", "lstsq", "lasso")}}
#: Width of the border band, in units of √(target area).
BAND = 0.02
#: Landmarks of the estimated maps (Euclidean FPS on the source, ground-truth images).
N_LANDMARKS = 5
#: Eigenpairs of the spectra (the ``"refined"`` method continues the map to this size).
K_SPECTRA = REFINE_EIGENPAIRS


def shape_labels(dataset: Dataset, index: int, template: np.ndarray) -> np.ndarray:
    """The template labelling on shape ``index`` of ``dataset`` (see the module doc)."""
    return template[template_vertices(dataset, index, template.size)]


def template_vertices(dataset: Dataset, index: int, n_template: int) -> np.ndarray:
    """The template vertex of each vertex of shape ``index`` (the module doc's labelling, as a
    point map to the template, or to any registration in its vertex order): the identity on a
    shape of ``n_template`` vertices; on a remeshed shape, ``sampleID[k]`` at vertex
    ``vts[k]`` (a vertex listed twice: the first entry) and at any other vertex that of its
    Euclidean-nearest named vertex."""
    e = dataset.shapes[index]
    if e.mesh.n_vertices == n_template:
        return np.arange(n_template)
    folder = e.path.parent
    sid_path = next((p for p in (folder / "corres" / "sampleID.vts", folder / "sampleID.vts")
                     if p.is_file()), folder / "corres" / "sampleID.vts")
    if e.vts is None or not sid_path.is_file():
        raise BSFError(f"{e.name}: {e.mesh.n_vertices} vertices, not the template's "
                       f"{n_template}, and no {sid_path} to name template vertices")
    sid = np.loadtxt(sid_path, dtype=np.int64).ravel() - 1
    if sid.shape != e.vts.shape or sid.min() < 0 or sid.max() >= n_template:
        raise BSFError(f"{sid_path}: expected {e.vts.size} template indices in [1, "
                       f"{n_template}]")
    out = np.full(e.mesh.n_vertices, -1, np.int64)
    out[e.vts[::-1]] = sid[::-1]  # a vertex listed twice: the first entry wins
    named = np.flatnonzero(out >= 0)
    miss = out < 0
    if miss.any():
        nn = scipy.spatial.cKDTree(e.mesh.vertices[named]).query(e.mesh.vertices[miss])[1]
        out[miss] = out[named[nn]]
    return out


def label_metrics(pred: np.ndarray, truth: np.ndarray, mass: np.ndarray, mesh,
                  band: float = BAND) -> dict:
    """Area accuracy, unassigned share, mean / worst IoU over the true parts, and accuracy
    within ``band`` · √area (Euclidean) of a vertex on a true part border."""
    mass = np.asarray(mass, float)
    total = mass.sum()
    ok = pred == truth
    parts = np.unique(truth)
    inter = np.array([mass[(pred == p) & (truth == p)].sum() for p in parts])
    union = np.array([mass[(pred == p) | (truth == p)].sum() for p in parts])
    iou = inter / union
    e, _ = mesh_edges(mesh.faces)
    diff = truth[e[:, 0]] != truth[e[:, 1]]
    border = np.unique(e[diff].ravel())
    if border.size:
        d = scipy.spatial.cKDTree(mesh.vertices[border]).query(mesh.vertices)[0]
        near = d <= band * np.sqrt(mesh.area)
    else:
        near = np.zeros(truth.shape, bool)
    return {"accuracy": 100 * float(mass[ok].sum() / total),
            "unassigned": 100 * float(mass[pred < 0].sum() / total),
            "iou_mean": float(iou.mean()), "iou_worst": float(iou.min()),
            "border_accuracy": (100 * float(mass[ok & near].sum() / mass[near].sum())
                                if near.any() else float("nan"))}


def _kind(a: str, b: str) -> str:
    """FAUST naming (``tr_reg_PQR``: person ``PQ``): same person or not; else ``-``."""
    try:
        na, nb = int(a.rsplit("_", 1)[-1]), int(b.rsplit("_", 1)[-1])
    except ValueError:
        return "-"
    return "same person" if na // 10 == nb // 10 else "other person"


def _maps(sm, sn, gt, k: int, landmarks, meshes, names) -> dict:
    """``{map name: (C (k × k), p2p)}`` for the maps of the module doc named in ``names``."""
    mesh_kw = dict(source_mesh=meshes[0], target_mesh=meshes[1])
    # as the CLI: ZoomOut to 2k, guided by landmarks (given or read off a map) to every
    # eigenpair of the spectra (MapEstimator.guided_to)
    first = lambda n: estimate_map(sm, sn, k=k,  # noqa: E731
                                   landmarks=(landmarks[0][:n], landmarks[1][:n]),
                                   refine_to=2 * k, **mesh_kw)
    make = {
        "default": lambda: first(N_LANDMARKS),
        "1 landmark": lambda: first(1),
        "2 landmarks": lambda: first(2),
        "crude": lambda: estimate_map(sm.truncate(20), sn.truncate(20), k=20,
                                      landmarks=landmarks, refine_to=20),
        "no landmarks": lambda: estimate_map(sm, sn, k=k, refine_to=2 * k, **mesh_kw),
        "no landmarks, one start": lambda: estimate_map(
            sm.truncate(2 * k), sn.truncate(2 * k), k=k, refine_to=2 * k,
            starts=((k, MapEstimator().wks_variance),), **mesh_kw)}
    out = {}
    for name in names:
        if name == "truth":
            out[name] = (np.asarray(fmap_from_p2p(sm.truncate(k), sn.truncate(k), gt)), gt)
        else:
            est = make[name]()
            out[name] = (est.C, est.p2p)
    return out


def _check_choices(methods, maps) -> None:
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise BSFError(f"methods must be among {tuple(METHODS)}, got {bad}")
    bad = [m for m in maps if m not in MAPS]
    if bad:
        raise BSFError(f"maps must be among {MAPS}, got {bad}")


def segmentation_experiment(dataset: Dataset, *, segmentation, pairs: int = 6, k: int = 30,
                            methods=tuple(METHODS), maps=DEFAULT_MAPS, seed: int = 0,
                            cache_dir=None,
                            pair_list=None, keep_labels: int = 1,
                            progress: bool = True) -> list[dict]:
    """Every method × map on ``pairs`` pairs (or the ``(source, target)`` indices of
    ``pair_list``).

    **Arguments:**

    - `dataset`: the ``--data`` folder.
    - `segmentation`: template segmentation file ([`bsfjax.load_labels`][bsfjax.load_labels]).
    - `pairs`, `seed`: number of pairs drawn by `Dataset.pairs`.
    - `k`: basis size of the maps and of the spectral methods (spectra: ``K_SPECTRA``).
    - `methods`, `maps`: subsets of [`METHODS`][bsfjax.METHODS] and `MAPS` (default
      `DEFAULT_MAPS`).
    - `cache_dir`: eigenbasis cache folder.
    - `keep_labels`: the first ``keep_labels`` pairs keep their per-vertex labels in the rows
      (keys ``_labels``, ``_truth``, ``_mesh``, not written to the CSV) for the figure.
    - `progress`: progress bar.

    **Returns:**

    Rows ``{"source", "target", "kind", "map", "method", "accuracy", "unassigned",
    "iou_mean", "iou_worst", "border_accuracy", "seconds", "regime"}``.
    """
    template, _ = load_labels(segmentation)
    _check_choices(methods, maps)
    ids = list(pair_list) if pair_list is not None else dataset.pairs(pairs, seed)
    rows = []
    for n_pair, (i, j) in enumerate(tqdm(ids, desc="segmentation", disable=not progress)):
        src, tgt = dataset.shapes[i], dataset.shapes[j]
        k_spec = min(K_SPECTRA, src.n_vertices - 1, tgt.n_vertices - 1)
        sm = spectrum(src.mesh, k_spec, cache_dir=cache_dir)
        sn = spectrum(tgt.mesh, k_spec, cache_dir=cache_dir)
        rows += segmentation_pair(
            sm, sn, (src.mesh, tgt.mesh), shape_labels(dataset, i, template),
            shape_labels(dataset, j, template), dataset.ground_truth(i, j), k=k,
            methods=methods, maps=maps, seed=seed, names=(src.name, tgt.name),
            keep_labels=n_pair < keep_labels)
    return rows


def segmentation_pair(sm, sn, meshes, labels_m: np.ndarray, labels_n: np.ndarray,
                      gt: np.ndarray, *, k: int = 30, methods=tuple(METHODS), maps=DEFAULT_MAPS,
                      seed: int = 0, names=("source", "target"),
                      keep_labels: bool = False) -> list[dict]:
    """One pair of `segmentation_experiment`: every method through every map.

    **Arguments:**

    - `sm`, `sn`: the pair's spectra (``K_SPECTRA`` eigenpairs, or fewer on small meshes).
    - `meshes`: ``(source mesh, target mesh)``.
    - `labels_m`, `labels_n`: the source's labels and the target's true labels.
    - `gt`: the ground-truth point map (target vertex → source vertex).
    - `k`, `methods`, `maps`, `seed`: as in `segmentation_experiment`.
    - `names`: the row's ``source`` and ``target``.
    - `keep_labels`: keep the per-vertex labels in the rows (for the figure).
    """
    _check_choices(methods, maps)
    src_mesh, tgt_mesh = meshes
    lm_src = np.asarray(farthest_point_sampling(src_mesh, N_LANDMARKS, seed=seed))
    landmarks = (lm_src, gt_inverse(gt, lm_src, tgt_mesh, src_mesh))
    all_maps = _maps(sm, sn, gt, k, landmarks, meshes, maps)
    # "refined" continues on the samples the default map's ZoomOut used, whatever the map
    n_samples = MapEstimator().zoomout_samples
    samples = (subsample(src_mesh, n_samples), subsample(tgt_mesh, n_samples))
    rows = []
    for map_name in maps:
        C, p2p = all_maps[map_name]
        for name in methods:
            t0 = time.perf_counter()
            method, options = METHODS[name]
            res = transfer_labels(sm, sn, labels_m, method=method, C=C, p2p=p2p,
                                  mesh=src_mesh, samples=samples, **options)
            sec = time.perf_counter() - t0
            row = {"source": names[0], "target": names[1], "kind": _kind(*names),
                   "map": map_name, "method": name,
                   **label_metrics(res.labels, labels_n, np.asarray(sn.mass), tgt_mesh),
                   "seconds": round(sec, 3), "regime": res.regime or ""}
            if keep_labels:
                row.update(_labels=res.labels, _truth=labels_n, _mesh=tgt_mesh)
            rows.append(row)
    return rows


def gt_inverse(gt: np.ndarray, src_vertices: np.ndarray, target_mesh, source_mesh) -> np.ndarray:
    """Target vertices matching ``src_vertices`` under the ground truth ``gt`` (target →
    source): a target vertex mapped to the source vertex, else to its nearest mapped one."""
    hit = np.full(source_mesh.n_vertices, -1, np.int64)
    hit[gt[::-1]] = np.arange(gt.size)[::-1]
    mapped = np.flatnonzero(hit >= 0)
    nn = scipy.spatial.cKDTree(source_mesh.vertices[mapped]).query(
        source_mesh.vertices[src_vertices])[1]
    return hit[mapped[nn]]


def run(dataset, *, pairs, functions, ks, seed, cache_dir, progress, segmentation=None):
    """The registry's uniform call (``functions`` unused; ``ks[0]`` is k)."""
    if segmentation is None:
        raise BSFError("reproduce segmentation needs --segmentation FILE (the template's part "
                       "labels, e.g. ../shared/data/segmentations/smpl_vert_segmentation.json)")
    return segmentation_experiment(dataset, segmentation=segmentation, pairs=pairs, k=ks[0],
                                   seed=seed, cache_dir=cache_dir, progress=progress)


def report(rows, ks) -> Report:
    """Mean over pairs per (map, method) and the per-pair table; the figure: the first pair's
    target coloured by the truth and by each method through the default map."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    maps = list(dict.fromkeys(r["map"] for r in rows))
    summary = []
    for mp in maps:
        base = {(r["source"], r["target"]): r["accuracy"] for r in rows
                if r["map"] == mp and r["method"] == "p2p"}
        for m in methods:
            sel = [r for r in rows if r["map"] == mp and r["method"] == m]
            if not sel:
                continue
            gain = [r["accuracy"] - base[(r["source"], r["target"])] for r in sel
                    if (r["source"], r["target"]) in base]
            summary.append({"map": mp, "method": m,
                            "accuracy %": np.mean([r["accuracy"] for r in sel]),
                            "vs p2p (mean)": np.mean(gain) if gain else float("nan"),
                            "vs p2p (min)": np.min(gain) if gain else float("nan"),
                            "unassigned %": np.mean([r["unassigned"] for r in sel]),
                            "IoU mean": np.mean([r["iou_mean"] for r in sel]),
                            "IoU worst": np.mean([r["iou_worst"] for r in sel]),
                            "border %": np.mean([r["border_accuracy"] for r in sel]),
                            "s": np.median([r["seconds"] for r in sel])})
    md = ["## Mean over pairs (accuracy: % of the target's area labelled correctly; vs p2p: "
          "points over the pull-back through the same map)", "", _table(summary), "",
          "## Accuracy per pair (%)", "",
          pivot_markdown(rows, index=("map", "method"), columns=("source", "target"),
                         value="accuracy", fmt="{:.2f}", best="max")]
    fig_rows = [r for r in rows if "_labels" in r and r["map"] == "default"]
    figure = (lambda path: _figure(fig_rows, path)) if fig_rows else None
    return Report("\n".join(md), None, f"k = {ks[0]}, spectra of {K_SPECTRA} eigenpairs, "
                  f"{N_LANDMARKS} landmarks (FPS + ground-truth images), border band "
                  f"{BAND}·√area", figure)


def _table(summary: list[dict]) -> str:
    keys = list(summary[0]) if summary else []
    out = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for s in summary:
        out.append("| " + " | ".join(f"{v:.2f}" if isinstance(v, float) else str(v)
                                     for v in s.values()) + " |")
    return "\n".join(out)


def _figure(rows: list[dict], path) -> Path:
    """The target coloured by the truth and by each method, side by side (one PNG)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .._util import atomic_path
    from .._plot import label_colour, Scene

    first = (rows[0]["source"], rows[0]["target"])
    rows = [r for r in rows if (r["source"], r["target"]) == first]
    mesh = rows[0]["_mesh"]
    panels = [("truth", rows[0]["_truth"])] + [(f"{r['method']} {r['accuracy']:.1f} %",
                                                r["_labels"]) for r in rows]
    ncols = min(len(panels), 6)
    nrows = -(-len(panels) // ncols)
    fig = Figure(figsize=(1.7 * ncols, 2.2 * nrows), dpi=130)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax in axes[len(panels):]:
        ax.set_axis_off()
    scene = Scene(mesh, ["front"], "y")
    for ax, (title, lab) in zip(axes, panels):
        face = np.asarray(lab)[mesh.faces]
        # a face takes the label of its first vertex unless the other two agree
        fl = np.where(face[:, 1] == face[:, 2], face[:, 1], face[:, 0])
        scene.draw(ax, 0, label_colour(fl), title)
        ax.title.set_fontsize(7)
    fig.suptitle(f"{first[0]} → {first[1]}, default map", fontsize=8)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=1 - 0.1 / nrows, wspace=0.0,
                        hspace=0.12)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return path
