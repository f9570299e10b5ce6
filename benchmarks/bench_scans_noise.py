"""Noisy scan-like targets: ``bsfjax transfer`` with and without its default denoising (a part of
the scan suite ``bench_scans.py``).

From FAUST registrations with the SMPL 24 parts to FAUST targets with Gaussian vertex noise of
σ = a fraction of the target's height (deterministic seeds), for each pair and σ: the accuracy
(share of the target's area labelled right; truth: the SMPL labels, the registrations share
their vertex order; areas of the clean target) of ``bsfjax transfer`` run in this process
(``bsfjax.cli.main``, so exactly as the command runs) with 5 landmark pairs and without
landmarks (the command's landmark-free default), with the default denoising and with
``--no-denoise``, and on the clean pair; with ``--pyfm`` also pyFM's pipeline on the same
inputs and on `bsfjax.denoise`'s meshes.  Prints a Markdown table and writes it (``--out``,
atomically) with a JSON of the rows beside it.

    python benchmarks/bench_scans_noise.py --out R.md --pyfm
"""

from __future__ import annotations

import tempfile

import _harness as h

def run(data, folder, pairs, sigmas, landmark_free: bool, pyfm: bool = False,
        raw: bool = True, draw: int = 0) -> list[dict]:
    """One row per (pair, σ; σ = 0 the clean pair): ``pair``, ``sigma``, ``noise_level``,
    ``iterations``, the accuracies ``lm_denoise`` / ``free_denoise`` (the default command, 5
    landmarks / none), ``lm_raw`` / ``free_raw`` (``--no-denoise``; with ``raw``), ``pyfm`` /
    ``pyfm_denoise`` (with ``pyfm``) and the seconds of each run.  ``draw``: the noise's draw
    (0: the seed ``[source, target, round(σ·1e5)]``; ``d > 0`` appends ``d``)."""
    import numpy as np

    import bsfjax
    from bsfjax.internal import auto_iterations, vertex_areas

    truth = h.smpl_labels(data)
    lab_file = str(folder / "smpl.txt")
    np.savetxt(lab_file, truth, fmt="%d")
    out = str(folder / "out.txt")
    rows = []
    modes = [True, False] if landmark_free else [True]
    for p, (src, tgt) in enumerate(pairs):
        source = str(data / "faust" / f"tr_reg_{src:03d}.off")
        clean_path = str(data / "faust" / f"tr_reg_{tgt:03d}.off")
        clean = bsfjax.load_mesh(clean_path)
        mass = vertex_areas(clean)
        v = np.asarray(clean.vertices)
        height = float(np.ptp(v[:, 1]))
        for s_i, sigma in enumerate([0.0] + list(sigmas)):
            if sigma == 0:
                path = clean_path
            else:  # one deterministic noise per (pair, sigma)
                key = [src, tgt, round(sigma * 1e5)] + ([draw] if draw else [])
                rng = np.random.default_rng(key)
                noisy = bsfjax.Mesh(v + rng.normal(size=v.shape) * sigma * height, clean.faces)
                path = str(folder / f"noisy_{tgt:03d}_{s_i}.off")
                bsfjax.save_mesh(path, noisy)
            level = bsfjax.noise_level(bsfjax.load_mesh(path))
            iters = auto_iterations(level)  # as denoise_iterations(mesh) decides it
            row = {"pair": f"{src:03d}→{tgt:03d}", "sigma": sigma, "draw": draw,
                   "noise_level": level, "iterations": iters}
            for denoise in ([True] if sigma == 0 or not raw else [True, False]):
                for lm in modes:
                    t = h.time.perf_counter()
                    labels, _ = h.run_cli(source, path, lab_file, out, lm, denoise)
                    key = f"{'lm' if lm else 'free'}_{'denoise' if denoise else 'raw'}"
                    row[key] = h.accuracy(labels, truth, mass)
                    row[key + "_s"] = round(h.time.perf_counter() - t, 1)
                    print(f"  {row['pair']} σ={sigma:.2%} {key}: {row[key]:.1%} "
                          f"({row[key + '_s']} s)", file=h.sys.stderr, flush=True)
            if pyfm:
                src_mesh, tgt_mesh = bsfjax.load_mesh(source), bsfjax.load_mesh(path)
                row["pyfm"] = h.run_pyfm(src_mesh, tgt_mesh, truth, mass)
                if sigma:  # the same pipeline on bsfjax.denoise's geometry
                    row["pyfm_denoise"] = h.run_pyfm(bsfjax.denoise(src_mesh),
                                                   bsfjax.denoise(tgt_mesh), truth, mass)
                print(f"  {row['pair']} σ={sigma:.2%} pyFM: {row['pyfm']:.1%}, denoised "
                      f"{row.get('pyfm_denoise', row['pyfm']):.1%}", file=h.sys.stderr,
                      flush=True)
            rows.append(row)
    return rows


def table(rows, landmark_free: bool, pyfm: bool = False) -> str:
    def pc(x):
        return "" if x is None else f"{100 * x:.1f} %"

    head = ("| pair | noise σ (of the height) | noise level → Taubin iterations | 5 landmarks, "
            "denoised (default) | 5 landmarks, `--no-denoise` |")
    sep = "|---|---|---|---|---|"
    if landmark_free:
        head += " no landmarks, denoised (default) | no landmarks, `--no-denoise` |"
        sep += "---|---|"
    if pyfm:
        head += " pyFM pipeline, 5 landmarks | pyFM pipeline on `bsfjax.denoise`'s meshes |"
        sep += "---|---|"
    lines = [head, sep]
    for r in rows:
        sig = "clean" if r["sigma"] == 0 else f"{100 * r['sigma']:.2f} %"
        cells = [r["pair"], sig, f"{r['noise_level']:.3f} → {r['iterations']}",
                 pc(r.get("lm_denoise")), pc(r.get("lm_raw"))]
        if landmark_free:
            cells += [pc(r.get("free_denoise")), pc(r.get("free_raw"))]
        if pyfm:
            cells += [pc(r.get("pyfm")), pc(r.get("pyfm_denoise"))]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main():
    ap = h.parser(__doc__)
    h.add_out(ap, help="output Markdown file (a .json of the rows beside it)")
    h.add_data(ap)
    ap.add_argument("--pairs", default="0-10,1-11",
                    help="source-target registration numbers, comma-separated (default 0-10,1-11)")
    ap.add_argument("--sigmas", default="0.001,0.0025,0.003",
                    help="noise σ as fractions of the height (default 0.001,0.0025,0.003)")
    ap.add_argument("--landmarks-only", action="store_true", help="skip the landmark-free runs")
    ap.add_argument("--draw", type=int, default=0, help="the noise's draw (default 0)")
    ap.add_argument("--no-raw", action="store_true", help="skip the --no-denoise runs")
    ap.add_argument("--pyfm", action="store_true",
                    help="also pyFM's pipeline with the 5 landmarks (pyfmaps), on the noisy "
                         "meshes and on bsfjax.denoise's")
    args = ap.parse_args()
    h.require_data(h.Path(args.data) / "faust", h.Path(args.data) / h.SMPL_SEGMENTATION)
    pairs = h.pair_list(args.pairs)
    sigmas = [float(s) for s in args.sigmas.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        rows = run(h.Path(args.data), h.Path(tmp), pairs, sigmas, not args.landmarks_only,
                   args.pyfm, not args.no_raw, args.draw)
    text = table(rows, not args.landmarks_only, args.pyfm)
    note = (f"\n{h.short_machine()}; truth: the SMPL parts (the registrations share their "
            "vertex order); areas of the clean target.\n")
    print(text + note)
    h.write_text(args.out, text + note)
    h.write_json(h.Path(args.out).with_suffix(".json"), {"rows": rows})


if __name__ == "__main__":
    main()
