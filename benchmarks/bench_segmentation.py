"""SMPL parts carried across FAUST and FAUST_5k pairs by every method.

Runs :func:`bsfjax.experiments.segmentation.segmentation_experiment` on named pairs of
``../shared/data`` (six FAUST pairs, same person and other person; three FAUST_5k pairs), all
methods through the default estimated map, and the fast ones also through the crude k = 20 and
the ground-truth maps; then times the default transfer (``transfer_labels``, method
``"refined"``) after the map on one FAUST pair: median of ``--repeats`` warm calls.

    python benchmarks/bench_segmentation.py --out /tmp/seg [--data ../shared/data] [--quick | --quick-maps]
    python benchmarks/bench_segmentation.py --out /tmp/seg --decimated
    python benchmarks/bench_segmentation.py --out /tmp/seg --stretched
    python benchmarks/bench_segmentation.py --out /tmp/seg --no-landmarks
    python benchmarks/bench_segmentation.py --out /tmp/seg --few-landmarks [--held-out]
    python benchmarks/bench_segmentation.py --out /tmp/seg --all-pairs
    python benchmarks/bench_segmentation.py --out /tmp/seg --triangles
    python benchmarks/bench_segmentation.py --out /tmp/seg --cross

Writes ``segmentation_bench.csv`` and ``segmentation_bench.md`` into ``--out``.

``--decimated``: the same check on triangulations that are not in ``../shared/data``: the
six FAUST pairs with the target decimated by 50, 70 and 85 % (quadric edge collapses by
``fast-simplification``, a benchmark-only dependency: ``pip install fast-simplification``;
3.4K, 2.1K and 1.0K irregular vertices against the source's 6890), p2p and ``refined``
through the three maps. The target's truth is the label of its nearest registration vertex,
which is also its ground-truth match on the source (the registrations share the vertex
order). Writes ``segmentation_decimated.csv`` and ``segmentation_decimated.md``.

``--stretched``: shapes that are not in ``../shared/data``: the six FAUST pairs with the
target's body proportions changed by a non-isometric deformation along its longest
axis (the standing body's height): taller (heights × 1.15), wider (the two other axes × 1.2),
and a longer torso (heights between the 45 % and 80 % height quantiles, roughly the hips and
the shoulders, × 1.3, the rest moved rigidly). The vertex order is kept, so the truth is the
registration's: the template's labels and the identity correspondence, stretched with the
body (as the SMPL bands are where the body's proportions differ). p2p and ``refined`` through
the three maps. Writes ``segmentation_stretched.csv`` and ``segmentation_stretched.md``.

``--no-landmarks``: p2p and ``refined`` on the nine pairs through the map ``bsfjax transfer``
estimates without ``--landmarks`` (several starts, landmarks read off the kept map) and through
a single start; then the two estimates' seconds on FAUST 000→010
(median of ``--repeats`` warm calls, the same run).  Writes ``segmentation_nolandmarks.csv``
and ``segmentation_nolandmarks.md``.

``--few-landmarks``: p2p and ``refined`` through the maps estimated with none, 1, 2 and the
default 5 landmarks (the first of the default map's farthest-point landmarks, with their
ground-truth images): how many a user needs.  Writes ``segmentation_fewlandmarks.csv`` and
``.md``.

``--held-out``: instead of the nine pairs, ten that no default was chosen on (eight FAUST,
two FAUST_5k); with ``--no-landmarks`` or ``--few-landmarks`` (or
alone: the default map).  The files' names end in ``_heldout``.

``--triangles``: the SMPL parts given per triangle (each triangle takes the label of the
majority of its corners; the PSB / COSEG form), on the nine pairs through the default and the
ground-truth maps: p2p and ``refined`` by :func:`bsfjax.transfer_face_labels`, beside the same
methods on the vertex labels; accuracy is the share of the target's area (triangles' areas,
vertices' masses) labelled correctly.  Then the two transfers' seconds after the map on FAUST
000→010 (median of ``--repeats`` warm calls, the same run).  Writes
``segmentation_triangles.csv`` and ``.md``.

``--cross``: from one triangulation to another, as a user carries the template's parts to a
shape meshed otherwise: every FAUST registration (6890 vertices, the template's mesh) to every
FAUST_5k remesh (36 pairs), p2p and ``refined`` through the default map and the map estimated
without landmarks.  The target's truth and its ground-truth map are its ``.vts`` labelling
(:func:`~bsfjax.experiments.segmentation.template_vertices`: the registrations are in the
template's vertex order).  About 6 minutes on 2 cores.  Writes ``segmentation_cross.csv`` and
``.md``.

``--all-pairs``: p2p and ``refined`` on every ordered pair of each folder (72 FAUST, 12
FAUST_5k), through the default map and the map estimated without landmarks (about 11 minutes
on 2 cores), summarized per folder, map and FAUST pair kind against a bar of ``refined``
≥ 97 % and ≥ p2p + 1.  Writes ``segmentation_allpairs.csv`` (one row per pair, map and
method) and ``segmentation_allpairs.md``.
"""

from __future__ import annotations

import itertools
import sys
import time
from pathlib import Path

import numpy as np

import _harness as h
import bsfjax as bj
from _harness import write_csv, write_text
from bsfjax.internal import orientation_bases
from bsfjax.experiments import load_dataset
from bsfjax.experiments.segmentation import (K_SPECTRA, METHODS, report,
                                             segmentation_experiment, segmentation_pair,
                                             shape_labels, template_vertices)

#: The nine pairs (six FAUST, three FAUST_5k).
PAIRS = h.SEGMENTATION_PAIRS
#: Pairs no default was chosen on (``--held-out``).
HELD_OUT = {"faust": [("000", "012"), ("001", "010"), ("002", "020"), ("011", "021"),
                      ("021", "002"), ("022", "011"), ("002", "012"), ("010", "001")],
            "faust_5k": [("001", "010"), ("011", "000")]}
FAST = ("p2p", "refined", "std", "omp", "lstsq")
REDUCTIONS = (0.5, 0.7, 0.85)


def changed_targets(data: Path, seg: Path, out: Path, cache, variants, change, key: str,
                    stem: str) -> int:
    """The six FAUST pairs with each target changed by ``change(registration, variant)`` →
    ``(target mesh, its ground-truth map to the registration's vertices)``, for every variant:
    p2p and ``refined`` through the three maps.  The target's truth is the template's label
    through that map (the registrations share the vertex order).  Writes ``stem.csv`` and
    ``stem.md``, the rows tagged ``key`` = the variant."""
    template, _ = bj.load_labels(seg)
    names = sorted({n for pair in PAIRS["faust"] for n in pair})
    meshes = {n: bj.load_mesh(data / "faust" / f"tr_reg_{n}.off") for n in names}
    spectra = {n: bj.spectrum(m, K_SPECTRA, cache_dir=cache) for n, m in meshes.items()}
    md, rows = [], []
    for variant in variants:
        part, sizes = [], []
        for a, b in PAIRS["faust"]:
            tgt, gt = change(meshes[b], variant)
            sizes.append(tgt.n_vertices)
            sn = bj.spectrum(tgt, K_SPECTRA, cache_dir=cache)  # (the cache keys the vertices)
            part += segmentation_pair(spectra[a], sn, (meshes[a], tgt), template, template[gt],
                                      gt, methods=("p2p", "refined"),
                                      names=(f"tr_reg_{a}", f"tr_reg_{b}"))
            print(f"{a} -> {b}, {key} {variant} ({tgt.n_vertices} vertices): " + ", ".join(
                f"{r['map']} {r['method']} {r['accuracy']:.2f}" for r in part[-6:]),
                file=sys.stderr)
        for r in part:
            r[key] = variant
        rows += part
        span = f"{min(sizes)}" if min(sizes) == max(sizes) else f"{min(sizes)}–{max(sizes)}"
        md += [f"# Targets, {key} {variant} ({span} vertices)", "",
               report(part, (30,)).markdown, ""]
    write_csv(rows, out / f"{stem}.csv")
    write_text(out / f"{stem}.md", "\n".join(md))
    print("\n".join(md))
    return 0


def triangles_report(data: Path, seg: Path, out: Path, cache, repeats: int) -> int:
    """``--triangles`` (module doc)."""
    from bsfjax.experiments.segmentation import N_LANDMARKS, _maps, gt_inverse

    template, _ = bj.load_labels(seg)
    rows, timing = [], ""
    for name, pairs in PAIRS.items():
        ds = load_dataset(data / name)
        index = {e.name: i for i, e in enumerate(ds.shapes)}
        for a, b in pairs:
            i, j = index[f"tr_reg_{a}"], index[f"tr_reg_{b}"]
            src, tgt = ds.shapes[i].mesh, ds.shapes[j].mesh
            sm, sn = (bj.spectrum(m, K_SPECTRA, cache_dir=cache) for m in (src, tgt))
            lab_m, lab_n = shape_labels(ds, i, template), shape_labels(ds, j, template)
            tri_m = bj.face_labels_from_vertices(src, lab_m)
            tri_n = bj.face_labels_from_vertices(tgt, lab_n)
            gt = ds.ground_truth(i, j)
            lm = np.asarray(bj.farthest_point_sampling(src, N_LANDMARKS))
            maps = _maps(sm, sn, gt, 30, (lm, gt_inverse(gt, lm, tgt, src)), (src, tgt),
                         ("default", "truth"))
            n_samples = bj.MapEstimator().zoomout_samples
            samples = (bj.subsample(src, n_samples), bj.subsample(tgt, n_samples))
            area, mass = tgt.face_areas(), np.asarray(sn.mass)
            for map_name, (C, p2p) in maps.items():
                kw = dict(C=C, p2p=p2p, samples=samples)
                for method in ("p2p", "refined"):
                    by_vertex = bj.transfer_labels(sm, sn, lab_m, method=method, mesh=src, **kw)
                    by_triangle = bj.transfer_face_labels(sm, sn, tri_m, source_mesh=src,
                                                          target_mesh=tgt, method=method, **kw)
                    rows.append({"source": f"{name}/tr_reg_{a}", "target": f"tr_reg_{b}",
                                 "map": map_name, "method": method,
                                 "vertices %": round(100 * float(np.sum(
                                     mass * (by_vertex.labels == lab_n)) / mass.sum()), 2),
                                 "triangles %": round(100 * float(np.sum(
                                     area * (by_triangle.labels == tri_n)) / area.sum()), 2)})
                    print(rows[-1], file=sys.stderr)
            if (name, a, b) == ("faust", "000", "010"):
                C, p2p = maps["default"]
                kw = dict(C=C, p2p=p2p, samples=samples)
                calls = {"vertices": lambda: bj.transfer_labels(sm, sn, lab_m, **kw),
                         "triangles": lambda: bj.transfer_face_labels(
                             sm, sn, tri_m, source_mesh=src, target_mesh=tgt, **kw)}
                med = {what: h.timed(call, repeats).median for what, call in calls.items()}
                timing = (f"'refined' after the default map, FAUST 000→010 (6890 vertices, "
                          f"13776 triangles, 24 parts), median of {repeats} warm calls: "
                          f"triangles {med['triangles']:.3f} s, vertices {med['vertices']:.3f} "
                          f"s in the same run; {h.cpus_note(arch=False)}.")
    write_csv(rows, out / "segmentation_triangles.csv")
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    for map_name in ("default", "truth"):
        for method in ("p2p", "refined"):
            sel = [r for r in rows if r["map"] == map_name and r["method"] == method]
            lines.append(f"| mean | | {map_name} | {method} | "
                         f"{np.mean([r['vertices %'] for r in sel]):.2f} | "
                         f"{np.mean([r['triangles %'] for r in sel]):.2f} |")
    md = "\n".join(lines) + "\n\n" + timing + "\n"
    write_text(out / "segmentation_triangles.md", md)
    print(md)
    return 0


def _decimate(reg, reduction: float):
    """``--decimated``'s target: ``reg`` decimated, each vertex's truth its nearest
    registration vertex."""
    import fast_simplification
    from scipy.spatial import cKDTree

    v, f = fast_simplification.simplify(np.asarray(reg.vertices, np.float32),
                                        np.asarray(reg.faces, np.int32),
                                        target_reduction=reduction)
    tgt = bj.Mesh(v.astype(np.float64), f.astype(np.int64))
    return tgt, cKDTree(reg.vertices).query(tgt.vertices)[1]


def _stretch(reg, kind: str):
    """``--stretched``'s target (module doc): ``reg`` re-proportioned along its longest axis
    (a standing body's height), the vertex order kept."""
    v = np.array(reg.vertices, np.float64)
    up = int(np.argmax(np.ptp(v, axis=0)))
    side = [a for a in range(3) if a != up]
    if kind == "taller":
        v[:, up] = v[:, up].mean() + 1.15 * (v[:, up] - v[:, up].mean())
    elif kind == "wider":
        v[:, side] = v[:, side].mean(axis=0) + 1.2 * (v[:, side] - v[:, side].mean(axis=0))
    elif kind == "longer torso":  # the band between the two quantiles stretched, the rest moved
        lo, hi = np.quantile(v[:, up], (0.45, 0.80))
        v[:, up] += 0.3 * np.clip(v[:, up] - lo, 0.0, hi - lo)
    else:
        raise ValueError(f"unknown deformation {kind!r}")
    return bj.Mesh(v, reg.faces), np.arange(reg.n_vertices)


def no_landmarks_report(rows, data: Path, out: Path, args, tail: str = "") -> int:
    """``--no-landmarks``: the rows' tables, and both estimates timed on FAUST 000→010."""
    ds = load_dataset(data / "faust")
    src, tgt = ds.shapes[0], ds.shapes[[e.name for e in ds.shapes].index("tr_reg_010")]
    sm, sn = (bj.spectrum(e.mesh, 100, cache_dir=args.cache).truncate(60) for e in (src, tgt))
    kw = dict(k=30, refine_to=60, source_mesh=src.mesh, target_mesh=tgt.mesh)
    peers = {"several starts (default)": {}, "one start": dict(starts=((30, 7.0),))}
    med = {}
    for name, extra in peers.items():
        t = h.timed(lambda: bj.estimate_map(sm, sn, **kw, **extra), args.repeats)
        med[name], est = t.median, t.out
        if est.start is not None:
            chosen = (f"kept start {est.start}, derived landmarks "
                      f"{'kept' if est.landmarks is not None else 'not kept'}, distortion "
                      f"{est.distortion:.4f}, orientation {est.orientation:.3f}")
    scans = orientation_sharing(sm, sn, src.mesh, tgt.mesh, args.repeats)
    rep = report(rows, (30,))
    write_csv(rows, out / f"segmentation_nolandmarks{tail}.csv")
    timing = (f"estimate_map without landmarks on FAUST 000→010 (k = 30, ZoomOut to 60), median "
              f"of {args.repeats} warm calls: " + ", ".join(f"{n} {m:.2f} s" for n, m in
                                                           med.items()) +
              f" ({med['several starts (default)'] / med['one start']:.1f}× the one start); "
              f"{chosen}. Its 15 starts' estimates (WKS given): {scans[0]:.2f} s with the meshes "
              f"(a face scan per estimate), {scans[1]:.2f} s with the pair's "
              f"orientation_bases (one scan per shape, included; {scans[0] / scans[1]:.2f}× "
              f"faster; the same maps); {h.cpus_note(load=True)}.")
    write_text(out / f"segmentation_nolandmarks{tail}.md", rep.markdown + "\n\n" + timing + "\n")
    print(rep.markdown)
    print(timing)
    return 0


def orientation_sharing(sm, sn, source_mesh, target_mesh, repeats: int) -> tuple[float, float]:
    """Seconds (medians of ``repeats`` warm runs) of the 15 landmark-free starts' estimates
    (``estimate_fmap`` with the orientation term, WKS computed beforehand): with the meshes,
    and with the pair's ``orientation_bases`` (computed in the timed run).  Raises if the two
    give different maps."""
    defaults = bj.MapEstimator()
    starts = defaults.landmark_free_starts
    d = {s: [bj.wks(x, 100, k=s[0], variance=s[1]) for x in (sm, sn)] for s in starts}
    w = bj.FmapWeights(orient=defaults.orient_weight)

    def each(**geometry):
        return [np.asarray(bj.estimate_fmap(sm, sn, *d[s], k=s[0], weights=w, **geometry))
                for s in starts]

    def shared():
        return each(orientation_bases=orientation_bases(
            sm, sn, source_mesh, target_mesh, max(k0 for k0, _ in starts)))

    med = []
    for run in (lambda: each(source_mesh=source_mesh, target_mesh=target_mesh), shared):
        t = h.timed(run, repeats)
        med.append((t.median, t.out))
    for a, b in zip(med[0][1], med[1][1]):
        np.testing.assert_allclose(b, a, atol=1e-5 * np.abs(a).max())
    return med[0][0], med[1][0]


def cross_triangulations(data: Path, seg: Path, out: Path, cache) -> int:
    """``--cross`` (module doc)."""
    template, _ = bj.load_labels(seg)
    regs, remeshed = load_dataset(data / "faust"), load_dataset(data / "faust_5k")
    # each remesh's template vertices: its ground-truth map to every registration
    targets = [(b.mesh, bj.spectrum(b.mesh, K_SPECTRA, cache_dir=cache),
                template_vertices(remeshed, j, template.size))
               for j, b in enumerate(remeshed.shapes)]
    rows = []
    for a in regs.shapes:
        sm = bj.spectrum(a.mesh, K_SPECTRA, cache_dir=cache)
        for b, (mesh, sn, gt) in zip(remeshed.shapes, targets):
            part = segmentation_pair(sm, sn, (a.mesh, mesh), template, template[gt], gt,
                                     methods=("p2p", "refined"),
                                     maps=("default", "no landmarks"), names=(a.name, b.name))
            for r in part:  # (bar_summary's folder: the pair's two folders)
                r["source"] = f"faust→faust_5k/{r['source']}"
            rows += part
            print(f"{a.name} → faust_5k/{b.name}: " + ", ".join(
                f"{r['map']} {r['method']} {r['accuracy']:.2f}" for r in part), file=sys.stderr)
    md = bar_summary(rows) + "\n\n" + report(rows, (30,)).markdown
    write_csv(rows, out / "segmentation_cross.csv")
    write_text(out / "segmentation_cross.md", md + "\n")
    print(md)
    return 0


def _without_labels(rows):
    """The rows without their per-vertex labels (keys ``_…``, kept for the figure)."""
    return [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]


def tables_only(rows, out: Path, stem: str) -> int:
    """The rows' tables alone, as ``stem.csv`` and ``stem.md``."""
    rep = report(rows, (30,))
    write_csv(_without_labels(rows), out / f"{stem}.csv")
    write_text(out / f"{stem}.md", rep.markdown + "\n")
    print(rep.markdown)
    return 0


def bar_summary(rows) -> str:
    """``--all-pairs``: per folder, map and pair kind, p2p against ``refined`` pair by pair
    (means, the gain's mean / worst / best, and how many pairs meet each half of the bar)."""
    by = {}
    for r in rows:
        key = (r["source"], r["target"], r["kind"], r["map"])
        by.setdefault(key, {})[r["method"]] = r["accuracy"]
    groups = {}
    for (src, _, kind, map_name), acc in by.items():
        folder = src.split("/")[0]
        for key in ((folder, map_name, "all"), (folder, map_name, kind)):
            groups.setdefault(key, []).append((acc["p2p"], acc["refined"]))
    head = ("| folder | map | pair kind | n | p2p % | refined % | gain mean / worst / best | "
            "refined ≥ 97 % | ≥ p2p + 1 | both | below p2p | lowest refined % |")
    lines = [head, "|" + "---|" * 12]
    for (folder, map_name, kind), pairs in sorted(groups.items()):
        if kind == "-":  # (not FAUST naming: "all" says it)
            continue
        p, q = np.array(pairs).T
        gain = q - p
        lines.append(f"| {folder} | {map_name} | {kind} | {len(p)} | {p.mean():.2f} | "
                     f"{q.mean():.2f} | {gain.mean():+.2f} / {gain.min():+.2f} / "
                     f"{gain.max():+.2f} | {(q >= 97).sum()} | {(gain >= 1).sum()} | "
                     f"{((q >= 97) & (gain >= 1)).sum()} | {(gain < 0).sum()} | "
                     f"{q.min():.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = h.parser(__doc__)
    h.add_data(ap, type=str)
    h.add_out(ap)
    h.add_cache(ap, h.HOME_CACHE)
    h.add_repeats(ap, 5)
    ap.add_argument("--quick", action="store_true", help="only p2p and refined, default map")
    ap.add_argument("--quick-maps", action="store_true",
                    help="only p2p and refined, through all three maps")
    ap.add_argument("--decimated", action="store_true",
                    help="only p2p and refined on the FAUST pairs with decimated targets")
    ap.add_argument("--stretched", action="store_true",
                    help="only p2p and refined on the FAUST pairs with re-proportioned targets")
    ap.add_argument("--no-landmarks", action="store_true",
                    help="only p2p and refined through the maps estimated without landmarks")
    ap.add_argument("--few-landmarks", action="store_true",
                    help="only p2p and refined through maps with 0, 1, 2 and 5 landmarks")
    ap.add_argument("--held-out", action="store_true",
                    help="the ten held-out pairs instead of the nine")
    ap.add_argument("--all-pairs", action="store_true",
                    help="p2p and refined on every ordered pair, default and landmark-free maps")
    ap.add_argument("--triangles", action="store_true",
                    help="the parts given per triangle: p2p and refined, default and true maps")
    ap.add_argument("--cross", action="store_true",
                    help="FAUST registrations to FAUST_5k remeshes, with and without landmarks")
    args = ap.parse_args(argv)
    data = Path(args.data)
    seg = data / h.SMPL_SEGMENTATION
    h.require_data(seg, data / "faust")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.decimated:
        return changed_targets(data, seg, out, args.cache, REDUCTIONS, _decimate, "reduction",
                               "segmentation_decimated")
    if args.triangles:
        return triangles_report(data, seg, out, args.cache, args.repeats)
    if args.cross:
        return cross_triangulations(data, seg, out, args.cache)
    if args.stretched:
        return changed_targets(data, seg, out, args.cache, ("taller", "wider", "longer torso"),
                               _stretch, "deformation", "segmentation_stretched")
    rows = []
    for name, pairs in (HELD_OUT if args.held_out else PAIRS).items():
        ds = load_dataset(data / name)
        index = {e.name: i for i, e in enumerate(ds.shapes)}
        ids = ([(index[f"tr_reg_{a}"], index[f"tr_reg_{b}"]) for a, b in pairs]
               if not args.all_pairs else
               list(itertools.permutations(range(len(ds.shapes)), 2)))
        free = ("no landmarks", "no landmarks, one start")
        few = ("no landmarks", "1 landmark", "2 landmarks", "default")
        runs = ([(("p2p", "refined"), ("default", "no landmarks"))] if args.all_pairs else
                [(("p2p", "refined"), free)] if args.no_landmarks else
                [(("p2p", "refined"), few)] if args.few_landmarks else
                [(("p2p", "refined"), ("default",))] if args.quick or args.held_out else
                [(("p2p", "refined"), ("default", "crude", "truth"))] if args.quick_maps else
                [(tuple(METHODS), ("default",)), (FAST, ("crude", "truth"))])
        for methods, maps in runs:
            t0 = time.perf_counter()
            part = segmentation_experiment(ds, segmentation=seg, methods=methods, maps=maps,
                                           cache_dir=args.cache, pair_list=ids,
                                           keep_labels=int(name == "faust" and
                                                           not args.all_pairs),
                                           progress=True)
            for r in part:  # the two folders share shape names
                r["source"] = f"{name}/{r['source']}"
            rows += part
            print(f"{name} {maps}: {len(part)} rows in {time.perf_counter() - t0:.0f} s",
                  file=sys.stderr)
    tail = "_heldout" if args.held_out else ""
    if args.all_pairs:
        md = bar_summary(rows)
        write_csv(rows, out / "segmentation_allpairs.csv")
        write_text(out / "segmentation_allpairs.md", md + "\n")
        print(md)
        return 0
    if args.few_landmarks:
        return tables_only(rows, out, "segmentation_fewlandmarks" + tail)
    if args.held_out and not args.no_landmarks:
        return tables_only(rows, out, "segmentation_heldout")
    if args.no_landmarks:
        return no_landmarks_report(rows, data, out, args, tail)
    # the default transfer after the map, warm (FAUST 000 -> 010, the CLI's default map)
    ds = load_dataset(data / "faust")
    template, _ = bj.load_labels(seg)
    src, tgt = ds.shapes[0], ds.shapes[[e.name for e in ds.shapes].index("tr_reg_010")]
    sm, sn = (bj.spectrum(e.mesh, 100, cache_dir=args.cache) for e in (src, tgt))
    lm = bj.farthest_point_sampling(src.mesh, 5)
    est = bj.estimate_map(sm.truncate(60), sn.truncate(60), k=30, landmarks=(lm, lm),
                          refine_to=60, source_mesh=src.mesh, target_mesh=tgt.mesh)
    lab = shape_labels(ds, 0, template)
    # peers in the same run: the pull-back, and the vote of the last three maps of a
    # continuation on every vertex
    peers = {"refined": dict(samples=est.samples), "p2p": dict(method="p2p"),
             "refined, 3 maps on every vertex": dict(method=bj.RefinedPullBack(n_vote=3))}
    timed = {name: h.timed(lambda: bj.transfer_labels(sm, sn, lab, C=est.C, p2p=est.p2p, **kw),
                           args.repeats) for name, kw in peers.items()}
    rep = report(rows, (30,))
    if rep.figure is not None:
        rep.figure(out / "segmentation_bench.png")
    write_csv(_without_labels(rows), out / "segmentation_bench.csv")
    med = {name: t.median for name, t in timed.items()}
    timing = (f"Default transfer after the map (transfer_labels, 'refined' on the map's 2000 "
              f"samples, 24 parts, FAUST 000→010, 6890 vertices): first call "
              f"{timed['refined'].first:.2f} s (compiled earlier in the run if a pair had these "
              f"sizes), median of {args.repeats} warm calls "
              f"{med['refined']:.3f} s; in the same run " + ", ".join(
                  f"{name} {m:.3f} s" for name, m in med.items() if name != "refined") +
              f" ({med['refined, 3 maps on every vertex'] / med['refined']:.2f}× faster than "
              f"the vote on every vertex); {h.cpus_note(load=True)}.")
    write_text(out / "segmentation_bench.md", rep.markdown + "\n\n" + timing + "\n")
    print(timing)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
