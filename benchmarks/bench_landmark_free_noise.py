"""The landmark-free map on noisy scan-like targets: the turn check before and after its limb
alternatives (``MapEstimator(turn_candidates="mirror")`` against the default ``"limbs"``).

From FAUST registrations with the SMPL 24 parts to FAUST targets with Gaussian vertex noise of
σ = a fraction of the target's height, for each pair, σ (0: the clean target) and noise draw:
what ``bsfjax transfer`` does without landmarks (``prepare_scan`` of both meshes, so noisy
targets are denoised; spectra of 100 eigenpairs; ``MapEstimator(k=30, refine_to=60)`` on 60;
the ``refined`` pull-back), once with the earlier turn check and once with the default. Each
row: the accuracy (share of the target's area labelled right; truth: the SMPL labels, the
registrations share their vertex order; areas of the clean target) of the ``refined`` labels
and of the point map's pull-back, and whether the turn check swapped the map. Draw 0 is the
noise of ``bench_scans_noise.py`` (seed ``[source, target, round(σ·1e5)]``); draw ``s > 0`` appends
``s`` to that seed. Prints a Markdown table; ``--out`` writes it (atomically) with a JSON of
the rows beside it.

    python benchmarks/bench_landmark_free_noise.py --pairs 0-10,1-11,2-12,21-11 \\
        --sigmas 0.001,0.0025 --draws 0,1 --out R.md
"""

from __future__ import annotations

import _harness as h

#: The turn checks compared: the earlier one ("before") and the default ("after").
MODES = (("before", "mirror"), ("after", "limbs"))


def noisy_target(clean, src: int, tgt: int, sigma: float, draw: int):
    """The clean target with Gaussian vertex noise of ``sigma`` times its height (draw 0: the
    noise of bench_scans_noise.py)."""
    import numpy as np

    import bsfjax

    if sigma == 0:
        return clean
    v = np.asarray(clean.vertices)
    key = [src, tgt, round(sigma * 1e5)] + ([draw] if draw else [])
    rng = np.random.default_rng(key)
    return bsfjax.Mesh(v + rng.normal(size=v.shape) * sigma * float(np.ptp(v[:, 1])),
                       clean.faces)


def run(data, pairs, sigmas, draws, modes=MODES) -> list[dict]:
    """One row per (pair, σ, draw): ``pair``, ``sigma``, ``draw``, and per mode of ``modes``
    (``(name, turn_candidates)``) ``{name}`` (``refined`` accuracy), ``{name}_p2p``
    (pull-back accuracy), ``{name}_swapped`` and ``{name}_s`` (seconds of the map)."""
    import numpy as np

    import bsfjax
    from bsfjax.internal import vertex_areas

    truth = h.smpl_labels(data)
    rows = []
    for src, tgt in pairs:
        source = bsfjax.prepare_scan(bsfjax.load_mesh(str(data / "faust" /
                                                          f"tr_reg_{src:03d}.off"))).mesh
        clean = bsfjax.load_mesh(str(data / "faust" / f"tr_reg_{tgt:03d}.off"))
        mass = vertex_areas(clean)
        sm = bsfjax.spectrum(source, 100)
        for sigma in sigmas:
            for draw in (draws if sigma else [0]):
                prep = bsfjax.prepare_scan(noisy_target(clean, src, tgt, sigma, draw))
                sn = bsfjax.spectrum(prep.mesh, 100)
                row = {"pair": f"{src:03d}→{tgt:03d}", "sigma": sigma, "draw": draw,
                       "iterations": prep.denoise_iterations}
                for name, candidates in modes:
                    t = h.time.perf_counter()
                    with h.warnings.catch_warnings():
                        h.warnings.simplefilter("ignore")
                        est = bsfjax.MapEstimator(k=30, refine_to=60,
                                                  turn_candidates=candidates)(
                            sm.truncate(60), sn.truncate(60), source_mesh=source,
                            target_mesh=prep.mesh)
                        row[name + "_s"] = round(h.time.perf_counter() - t, 1)
                        labels = bsfjax.transfer_labels(
                            sm, sn, truth, C=est.C, p2p=est.p2p, method="refined",
                            mesh=source, samples=est.samples).labels
                    row[name] = float(np.sum(mass * (labels == truth)) / mass.sum())
                    row[name + "_p2p"] = float(np.sum(mass * (truth[est.p2p] == truth))
                                               / mass.sum())
                    row[name + "_swapped"] = bool(est.swapped)
                print(f"  {row['pair']} σ={sigma:.2%} draw {draw}: " + ", ".join(
                    f"{name} {row[name]:.1%} ({row[name + '_s']} s)" for name, _ in modes),
                    file=h.sys.stderr, flush=True)
                rows.append(row)
    return rows


def table(rows, modes=MODES) -> str:
    head = "| pair | σ (of the height) | draw | Taubin iterations |"
    sep = "|---|---|---|---|"
    for name, candidates in modes:
        head += f" {name} (`{candidates}`): refined / p2p |"
        sep += "---|"
    lines = [head, sep]
    for r in rows:
        sig = "clean" if r["sigma"] == 0 else f"{100 * r['sigma']:.2f} %"
        cells = [r["pair"], sig, "" if r["sigma"] == 0 else str(r["draw"]), str(r["iterations"])]
        for name, _ in modes:
            swap = " (swapped)" if r[name + "_swapped"] else ""
            cells.append(f"{100 * r[name]:.1f} / {100 * r[name + '_p2p']:.1f} %{swap}")
        lines.append("| " + " | ".join(cells) + " |")
    n = len(rows)
    mean = ["**mean**", "", "", ""] + [
        f"**{100 * sum(r[name] for r in rows) / n:.1f}** / "
        f"{100 * sum(r[name + '_p2p'] for r in rows) / n:.1f} %" for name, _ in modes]
    lines.append("| " + " | ".join(mean) + " |")
    return "\n".join(lines) + "\n"


def main():
    ap = h.parser(__doc__)
    h.add_out(ap, required=False, help="output Markdown file (a .json of the rows beside it)")
    h.add_data(ap)
    ap.add_argument("--pairs", default="0-10,1-11,2-12,21-11",
                    help="source-target registration numbers, comma-separated "
                         "(default 0-10,1-11,2-12,21-11)")
    ap.add_argument("--sigmas", default="0,0.001,0.0025",
                    help="noise σ as fractions of the height, 0: the clean target "
                         "(default 0,0.001,0.0025)")
    ap.add_argument("--draws", default="0,1", help="noise draws (default 0,1)")
    ap.add_argument("--modes", default="before,after",
                    help="the turn checks to run, of " + ", ".join(n for n, _ in MODES) +
                         " (default before,after)")
    args = ap.parse_args()
    modes = tuple(m for m in MODES if m[0] in h.name_list(args.modes))
    h.require_data(h.Path(args.data) / "faust", h.Path(args.data) / h.SMPL_SEGMENTATION)
    pairs = [tuple(int(x) for x in p.split("-")) for p in args.pairs.split(",")]
    rows = run(h.Path(args.data), pairs, [float(s) for s in args.sigmas.split(",")],
               list(h.int_list(args.draws)), modes)
    text = table(rows, modes) + (f"\n{h.short_machine()}; truth: the SMPL parts (the registrations "
                          "share their vertex order); areas of the clean target.\n")
    print(text)
    if args.out:
        h.write_text(args.out, text)
        h.write_json(h.Path(args.out).with_suffix(".json"), {"rows": rows})


if __name__ == "__main__":
    main()
