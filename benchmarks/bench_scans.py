"""Noisy scan-like targets: ``bsfjax transfer`` with and without its default denoising.

From FAUST registrations with the SMPL 24 parts to FAUST targets with Gaussian vertex noise of
σ = a fraction of the target's height (deterministic seeds), for each pair and σ: the accuracy
(share of the target's area labelled right; truth: the SMPL labels, the registrations share
their vertex order; areas of the clean target) of ``bsfjax transfer`` run in this process
(``bsfjax.cli.main``, so exactly as the command runs) with 5 landmark pairs and without
landmarks (the command's landmark-free default), with the default denoising and with
``--no-denoise``, and on the clean pair; with ``--pyfm`` also pyFM's pipeline on the same
inputs and on `bsfjax.denoise`'s meshes.  Prints a Markdown table and writes it (``--out``,
atomically) with a JSON of the rows beside it.

    python benchmarks/bench_scans.py --out docs/results/scans.md --pyfm
"""

from __future__ import annotations

import contextlib
import io
import tempfile

import _harness as h

#: The landmark vertices of the tests and docs (the same on every registration).
LANDMARKS = (412, 3216, 5907, 6296, 2445)


def accuracy(labels, truth, mass) -> float:
    import numpy as np

    return float(np.sum(mass * (labels == truth)) / np.sum(mass))


def run_cli(source: str, target: str, labels: str, out: str, landmarks: bool, denoise: bool):
    """``bsfjax transfer`` in this process: the labels written, the stderr text.  ``landmarks``:
    ``True`` (the 5 pairs ``LANDMARKS``), ``False`` (none) or ``(source rows, target rows)``."""
    import numpy as np

    from bsfjax.cli import main

    argv = ["transfer", source, target, "--labels", labels, "--out", out]
    if landmarks:
        src, tgt = (LANDMARKS, LANDMARKS) if landmarks is True else landmarks
        argv += ["--landmarks", f"{','.join(map(str, src))}:{','.join(map(str, tgt))}"]
    if not denoise:
        argv.append("--no-denoise")
    err = io.StringIO()
    with contextlib.redirect_stderr(err), h.warnings.catch_warnings():
        h.warnings.simplefilter("ignore")
        rc = main(argv)
    if rc:
        raise RuntimeError(f"bsfjax transfer failed ({rc}): {err.getvalue()}")
    return np.loadtxt(out, dtype=np.int64), err.getvalue()


def run_pyfm(source, target, truth, mass, landmarks=None, target_truth=None) -> float:
    """pyFM's own pipeline (its README's: WKS with the 5 landmarks, a 35 × 35 map, ZoomOut
    15 steps on 2000 samples) from ``source`` to ``target``: the accuracy of the pulled-back
    labels.  ``landmarks``: ``(source rows, target rows)`` instead of ``LANDMARKS`` on both;
    ``target_truth``: the target's labels when its vertices are not the source's (``truth``:
    the source's)."""
    import numpy as np
    from pyFM.functional import FunctionalMapping
    from pyFM.mesh import TriMesh

    model = FunctionalMapping(*[TriMesh(np.array(m.vertices), np.array(m.faces))
                                for m in (source, target)])
    lm = np.stack(landmarks or [LANDMARKS, LANDMARKS], axis=1)
    with h.warnings.catch_warnings():
        h.warnings.simplefilter("ignore")
        model.preprocess(n_descr=100, descr_type="WKS", landmarks=lm, subsample_step=5,
                         k_process=200, verbose=False)
        model.fit(K=(35, 35), w_descr=1e0, w_lap=1e-2, w_dcomm=1e-1, w_orient=0)
        model.zoomout_refine(nit=15, step=1, subsample=2000, verbose=False)
    return accuracy(truth[model.get_p2p()], truth if target_truth is None else target_truth,
                    mass)


def run(data, folder, pairs, sigmas, landmark_free: bool, pyfm: bool = False) -> list[dict]:
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
                rng = np.random.default_rng([src, tgt, round(sigma * 1e5)])
                noisy = bsfjax.Mesh(v + rng.normal(size=v.shape) * sigma * height, clean.faces)
                path = str(folder / f"noisy_{tgt:03d}_{s_i}.off")
                bsfjax.save_mesh(path, noisy)
            level = bsfjax.noise_level(bsfjax.load_mesh(path))
            iters = auto_iterations(level)  # as denoise_iterations(mesh) decides it
            row = {"pair": f"{src:03d}→{tgt:03d}", "sigma": sigma, "noise_level": level,
                   "iterations": iters}
            for denoise in ([True] if sigma == 0 else [True, False]):
                for lm in modes:
                    t = h.time.perf_counter()
                    labels, _ = run_cli(source, path, lab_file, out, lm, denoise)
                    key = f"{'lm' if lm else 'free'}_{'denoise' if denoise else 'raw'}"
                    row[key] = accuracy(labels, truth, mass)
                    row[key + "_s"] = round(h.time.perf_counter() - t, 1)
                    print(f"  {row['pair']} σ={sigma:.2%} {key}: {row[key]:.1%} "
                          f"({row[key + '_s']} s)", file=h.sys.stderr, flush=True)
            if pyfm:
                src_mesh, tgt_mesh = bsfjax.load_mesh(source), bsfjax.load_mesh(path)
                row["pyfm"] = run_pyfm(src_mesh, tgt_mesh, truth, mass)
                if sigma:  # the same pipeline on bsfjax.denoise's geometry
                    row["pyfm_denoise"] = run_pyfm(bsfjax.denoise(src_mesh),
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
    ap.add_argument("--pyfm", action="store_true",
                    help="also pyFM's pipeline with the 5 landmarks (pyfmaps), on the noisy "
                         "meshes and on bsfjax.denoise's")
    args = ap.parse_args()
    h.require_data(h.Path(args.data) / "faust", h.Path(args.data) / h.SMPL_SEGMENTATION)
    pairs = h.pair_list(args.pairs)
    sigmas = [float(s) for s in args.sigmas.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        rows = run(h.Path(args.data), h.Path(tmp), pairs, sigmas, not args.landmarks_only,
                   args.pyfm)
    text = table(rows, not args.landmarks_only, args.pyfm)
    note = (f"\n{h.short_machine()}; truth: the SMPL parts (the registrations share their "
            "vertex order); areas of the clean target.\n")
    print(text + note)
    h.write_text(args.out, text + note)
    h.write_json(h.Path(args.out).with_suffix(".json"), {"rows": rows})


if __name__ == "__main__":
    main()
