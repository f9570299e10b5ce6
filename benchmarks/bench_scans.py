"""Scan-like FAUST targets, the whole suite: noise, holes, a missing arm and foot, noisy point
clouds and a raw-scan-like large mesh, each against its clean pair and pyFM's pipeline.

The suite of the issue "Real scans".  It runs the four part modules (each also a script of its
own, with the targets' construction in its docstring) and checks every result against the bars:

* ``noise`` (``bench_scans_noise.py``): Gaussian vertex noise of σ = 0.1 % and 0.25 % of the
  height;
* ``holes`` (``bench_scans_holes.py``): k ∈ {2, 5, 8} geodesic holes of radius 3.5 % of the
  height, 2 seeds, and the partial targets (an arm from the elbow down and a foot removed);
* ``clouds`` (``bench_point_clouds.py``): 15K points sampled from the target with noise of
  σ = 0.25 % of the height, 2 seeds;
* ``large`` (``bench_scans_large.py``): the ~105K-vertex raw-scan-like mesh (subdivided, noise,
  holes, a stray fragment, unreferenced and shuffled rows), without landmarks, the whole command
  timed in a child process.

Every target runs the default ``bsfjax transfer`` (in this process, as the command runs) with
the docs' 5 landmark pairs and without landmarks; ``Δ`` is the accuracy (share of the target's
area labelled right) minus the clean pair's, in points, for the same landmarks; the pyFM margin
is our accuracy minus pyFM's pipeline on the same mesh and landmarks (``--pyfm``; pyFM reads no
point clouds).  ``--draw D`` takes other draws of the noise, the holes' centres, the clouds'
points and the large scan, and another cut for the partial target (``bench_scans_holes``'s
``PARTIAL_CUTS[D mod 3]``: the left forearm and hand and the right foot, the mirror cut, the left
leg from the knee down); the held-out check: D = 0 is the draw the defaults were measured on.

Each part writes ``OUT/<part>.md`` and ``OUT/<part>.json`` (atomically) as it ends; the summary
``OUT/summary.md`` (and ``--figure``: a PNG of every Δ against its bar) is made from all the part
JSONs present in ``OUT``, so parts can be run at different times:

    python benchmarks/bench_scans.py --out R --pyfm                    # every part (~60 min)
    python benchmarks/bench_scans.py --out R --parts clouds            # one part, summary again
    python benchmarks/bench_scans.py --out R --summary-only --figure docs/img/scans.png
"""

from __future__ import annotations

import json
import tempfile

import _harness as h

PARTS = ("noise", "holes", "clouds", "large")
#: The bars of the issue, in points below the clean pair: (with 5 landmarks, without).  Without
#: landmarks the issue asks for "within 3–4 points": 4 is the bar, 3 the aim.
BARS = {"noise": (1.5, 4.0), "holes": (2.5, 4.0), "partial": (3.0, 4.0), "clouds": (3.0, 4.0),
        "large": (None, 4.0)}
#: The large scan's cost bars: wall seconds and peak resident memory (GB) of the whole command.
LARGE_SECONDS, LARGE_GB = 90.0, 6.0
#: The noise levels of the suite (fractions of the height); the bar holds up to 0.25 %.
SIGMAS = (0.001, 0.0025)
CLOUD_POINTS, CLOUD_NOISE = 15_000, 0.0025


def run_part(part: str, data, folder, pairs, draw: int, pyfm: bool) -> list[dict]:
    """The rows of one part (the part module's ``run``)."""
    if part == "noise":
        import bench_scans_noise

        return bench_scans_noise.run(data, folder, pairs, SIGMAS, True, pyfm, raw=False,
                                     draw=draw)
    if part == "holes":
        import bench_scans_holes

        return bench_scans_holes.run(data, folder, pairs, seeds=(2 * draw, 2 * draw + 1),
                                     pyfm=pyfm, cut=draw % len(bench_scans_holes.PARTIAL_CUTS))
    if part == "clouds":
        import bench_point_clouds

        return bench_point_clouds.run(
            data, folder, pairs=[(f"{a:03d}", f"{b:03d}") for a, b in pairs],
            points=(CLOUD_POINTS,), noise=CLOUD_NOISE, seeds=(2 * draw, 2 * draw + 1),
            clean=False)
    if part == "large":
        import bench_scans_large

        return bench_scans_large.run(h.Path(data), h.Path(folder), pairs, draw, True)
    raise ValueError(f"part must be one of {PARTS}, got {part!r}")


def part_table(part: str, rows) -> str:
    """The part module's own Markdown table."""
    import bench_point_clouds
    import bench_scans_holes
    import bench_scans_large
    import bench_scans_noise

    return {"noise": lambda r: bench_scans_noise.table(r, True, any("pyfm" in x for x in r)),
            "holes": bench_scans_holes.table, "clouds": bench_point_clouds.markdown,
            "large": bench_scans_large.table}[part](rows)


# --- the summary -----------------------------------------------------------------------------


def deltas(parts: dict) -> list[dict]:
    """One record per scan-like target and landmark setting: ``case`` (a key of ``BARS``),
    ``pair``, ``target``, ``landmarks`` (5 or 0), ``accuracy``, ``clean``, ``delta`` (points)
    and ``pyfm`` (pyFM's accuracy on the same input, where measured), all in %."""
    out = []

    def add(case, pair, target, lm, acc, clean, pyfm=None):
        if acc is None or clean is None:
            return
        out.append(dict(case=case, pair=pair, target=target, landmarks=lm,
                        accuracy=100 * acc, clean=100 * clean, delta=100 * (acc - clean),
                        pyfm=None if pyfm is None or lm == 0 else 100 * pyfm))

    for r in parts.get("noise", []):
        clean = next(c for c in parts["noise"] if c["pair"] == r["pair"] and c["sigma"] == 0)
        if r["sigma"] == 0:
            continue
        target = f"σ = {100 * r['sigma']:.2f} %"
        add("noise", r["pair"], target, 5, r.get("lm_denoise"), clean.get("lm_denoise"),
            r.get("pyfm"))
        add("noise", r["pair"], target, 0, r.get("free_denoise"), clean.get("free_denoise"))
    for r in parts.get("holes", []):
        if r["target"] == "clean":
            continue
        case = "partial" if "removed" in r["target"] else "holes"
        add(case, r["pair"], r["target"], 5, r.get("lm"), r.get("clean_lm"), r.get("pyfm"))
        add(case, r["pair"], r["target"], 0, r.get("free"), r.get("clean_free"))
    clouds = parts.get("clouds", [])
    for r in clouds:
        if r["target"] == "mesh":
            continue
        mesh = next((c for c in clouds if c["pair"] == r["pair"] and c["target"] == "mesh"
                     and c["landmarks"] == r["landmarks"]), None)
        add("clouds", r["pair"], f"{r['target']}, {r['points']} points, seed {r['seed']}",
            r["landmarks"], r["accuracy"], mesh and mesh["accuracy"])
    large = parts.get("large", [])
    for r in large:
        if r["target"] == "clean":
            continue
        clean = next((c for c in large if c["pair"] == r["pair"] and c["target"] == "clean"),
                     None)
        if clean:
            add("large", r["pair"], f"raw scan, {r['vertices']} vertices", 0,
                r["accuracy"] / 100, clean["accuracy"] / 100)
    return out


def summary(parts: dict) -> str:
    """The bars against the worst draw of each case, as Markdown."""
    recs = deltas(parts)
    names = {"noise": "noise, σ ≤ 0.25 % of the height", "holes": "2–8 holes of radius 3.5 %",
             "partial": next((r["target"] for r in parts.get("holes", [])
                              if "removed" in r["target"]), "a limb part removed"),
             "clouds": f"noisy point cloud, {CLOUD_POINTS // 1000}K points",
             "large": "raw-scan-like mesh, ~105K vertices"}
    lines = ["| scan-like target | targets | bar with 5 landmarks: worst Δ (met) | bar without: "
             "worst Δ (met) | lowest margin over pyFM |", "|---|---|---|---|---|"]

    def cell(case, lm):
        bar = BARS[case][0 if lm else 1]
        got = [r["delta"] for r in recs if r["case"] == case and r["landmarks"] == lm]
        if bar is None or not got:
            return "–"
        worst = min(got)
        ok = sum(d >= -bar for d in got)
        verdict = "met" if ok == len(got) else f"**not met**: {ok} of {len(got)} within"
        return f"−{bar:g}: {worst:+.1f} ({verdict})"

    for case in BARS:
        mine = [r for r in recs if r["case"] == case]
        if not mine:
            continue
        margins = [r["accuracy"] - r["pyfm"] for r in mine if r["pyfm"] is not None]
        margin = f"{min(margins):+.1f} ({len(margins)} targets)" if margins else "–"
        n = len({(r["pair"], r["target"]) for r in mine})
        lines.append(f"| {names[case]} | {n} | {cell(case, 5)} | {cell(case, 0)} | {margin} |")
    for r in parts.get("large", []):
        if r["target"] != "clean":
            ok = (r["seconds"] <= LARGE_SECONDS and r["peak_rss_gb"] <= LARGE_GB
                  and r["rows_ok"] and r["strays_unassigned"])
            lines.append(f"| {names['large']} {r['pair']}: cost | | | {r['seconds']} s "
                         f"(≤ {LARGE_SECONDS:g}), {r['peak_rss_gb']} GB (≤ {LARGE_GB:g}), one "
                         f"row per file row: {'yes' if r['rows_ok'] else 'NO'} "
                         f"({'met' if ok else '**not met**'}) | |")
    return "\n".join(lines) + "\n"


def figure(parts: dict, path) -> None:
    """Every Δ (points from the clean pair) per case, with 5 landmarks and without, and the bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    recs = deltas(parts)
    cases = [c for c in BARS if any(r["case"] == c for r in recs)]
    fig, ax = plt.subplots(figsize=(7.5, 3.6), dpi=130)
    for i, case in enumerate(cases):
        for lm, dx, colour in ((5, -0.15, "tab:blue"), (0, 0.15, "tab:orange")):
            d = np.array([r["delta"] for r in recs if r["case"] == case and r["landmarks"] == lm])
            if d.size:
                x = i + dx + np.linspace(-0.06, 0.06, d.size)
                ax.scatter(x, np.maximum(d, -12), s=14, color=colour,
                           label=("5 landmarks" if lm else "no landmarks") if i == 0 else None)
            bar = BARS[case][0 if lm else 1]
            if bar is not None:
                ax.hlines(-bar, i + dx - 0.12, i + dx + 0.12, color=colour, lw=2)
    ax.axhline(0, color="grey", lw=0.6)
    ax.set_xticks(range(len(cases)), cases)
    ax.set_ylim(-12.5, 4)
    ax.set_ylabel("Δ accuracy from the clean pair (points)")
    ax.set_title("Scan-like FAUST targets (bars: the issue's limits; below −12 drawn at −12)",
                 fontsize=9)
    ax.legend(fontsize=8, loc="upper center", ncol=2)
    fig.tight_layout()
    tmp = h.Path(path).with_suffix(".tmp.png")
    fig.savefig(tmp)
    plt.close(fig)
    tmp.replace(path)


def load_parts(out) -> dict:
    parts = {}
    for part in PARTS:
        f = h.Path(out) / f"{part}.json"
        if f.exists():
            parts[part] = json.loads(f.read_text())["rows"]
    return parts


def main():
    ap = h.parser(__doc__)
    h.add_out(ap, help="output folder (one .md and .json per part, summary.md)")
    h.add_data(ap)
    ap.add_argument("--parts", default=",".join(PARTS),
                    help=f"parts to run, comma-separated (default {','.join(PARTS)})")
    ap.add_argument("--pairs", default="0-10,1-11,2-12",
                    help="source-target registration numbers (default 0-10,1-11,2-12; the "
                         "large part takes the first two)")
    ap.add_argument("--draw", type=int, default=0,
                    help="draw of the noise, holes, clouds and large scan (default 0)")
    ap.add_argument("--pyfm", action="store_true", help="also pyFM's pipeline (pyfmaps)")
    ap.add_argument("--summary-only", action="store_true",
                    help="run nothing: the summary of the part JSONs in --out")
    ap.add_argument("--figure", help="also write the figure of every Δ to this PNG")
    args = ap.parse_args()
    out = h.Path(args.out)
    if not args.summary_only:
        h.require_data(h.Path(args.data) / "faust", h.Path(args.data) / h.SMPL_SEGMENTATION)
        pairs = h.pair_list(args.pairs)
        for part in h.name_list(args.parts):
            with tempfile.TemporaryDirectory() as tmp:
                rows = run_part(part, h.Path(args.data), h.Path(tmp),
                                pairs[:2] if part == "large" else pairs, args.draw, args.pyfm)
            note = f"\nDraw {args.draw}; {h.short_machine()}, {h.cpus_note(load=True)}.\n"
            h.write_text(out / f"{part}.md", part_table(part, rows) + note)
            h.write_json(out / f"{part}.json", {"draw": args.draw, "rows": rows})
    parts = load_parts(out)
    text = summary(parts)
    print(text)
    h.write_text(out / "summary.md", text)
    if args.figure:
        figure(parts, args.figure)


if __name__ == "__main__":
    main()
