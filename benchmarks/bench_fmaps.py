"""Benchmark: the functional-map pipeline, bsfjax vs pyFM (PyPI ``pyfmaps``), same pairs, same run.

Pipeline (the paper's setting): WKS + WKS at one landmark → 30×30 functional map → point map,
then ZoomOut 30 → 100 → point map; scored by the mean geodesic error against the FAUST
ground truth (identity), Dijkstra distances on the source mesh over all 6890 target vertices,
normalized by √area (``bsfjax.geodesic_error``).

Both libraries run on the **same spectra**: ``bsfjax.spectrum(mesh, 200)`` (cotangent / mixed
Voronoi mass, shift-invert Lanczos) is written into each pyFM ``TriMesh`` (``eigenvalues``,
``eigenvectors``, ``mass``), so ``preprocess(k_process=200)`` only truncates; spectra are not
timed.  pyFM settings, mirrored on the bsfjax side:

* descriptors: ``preprocess(n_descr=100, descr_type="WKS", k_descr=128)`` (100 WKS energies
  from 128 eigenpairs, pyFM's automatic energies, σ = 7·range/100, ``scaled``), plus 100 WKS
  energies centred at the landmark, added with ``add_descriptors(sg.mesh_WKS(mesh, 100,
  landmarks=[lm], k=128))`` (L2-normalized like ``preprocess`` does).  This is exactly what
  ``preprocess(landmarks=…)`` computes; it is called this way because pyFM 1.3.1's
  ``_parse_landmarks`` squeezes a single landmark to a 0-d array and raises ``IndexError``.
  bsfjax: ``wks(s, 100, k=128)`` and ``wks(s, 100, k=128, landmarks=[lm])`` concatenated.
* landmark: FAUST template vertex 2446 (a fingertip of the hand on the +x side of
  tr_reg_000), the same index on both shapes since the ground truth is the identity.
* estimation: ``fit(K=30)`` with pyFM's defaults — weights w_descr = 0.1, w_lap = 1e-3,
  w_dcomm = 1, w_orient = 0, resolvent Laplacian mask (γ = 0.5), canonical weight normalization,
  L-BFGS-B (factr = 1e7, pgtol = 1e-5) from zeros with the first column fixed.  bsfjax:
  ``estimate_fmap(k=30)`` with the same energy, weights and normalization, solved exactly
  (optimistix Gauss–Newton on the normal equations).
* point maps: pyFM ``get_p2p`` (``FM_to_p2p``, use_adj=False; it dispatches to scikit-learn's
  brute-force search above 8 dimensions) vs ``bsfjax.fmap_to_p2p``; also scipy's ``cKDTree``
  (all cores) on the same embedding.
* ZoomOut: ``zoomout_refine(nit=14, step=5)`` vs ``bsfjax.zoomout(C, …, 100, step=5)``.
* ``--orient w``: both pipelines again with the orientation-preserving term (pyFM
  ``fit(w_orient=w)``; bsfjax ``FmapWeights(orient=w)`` with the meshes); pyFM builds one
  sparse operator per descriptor, so its fit is timed over ``max(1, repeats // 2)`` runs.

Timings: median of ``--repeats`` runs after one warm-up run (for bsfjax the warm-up is the jit
compilation, reported separately as ``compile``); pyFM's ZoomOut (~10 s) is timed over
``max(1, repeats // 2)`` runs.  bsfjax runs in float32 (JAX's default;
``--x64`` for float64); pyFM in float64.  Speed-ups are pyFM time / bsfjax time (> 1: bsfjax is
faster); error ratios are bsfjax / pyFM (≤ 1: bsfjax at least as accurate).

    python benchmarks/bench_fmaps.py --out bench-results            # ~5 min on 2 cores
    python benchmarks/bench_fmaps.py --pairs 000-001 010-012 --repeats 5
    python benchmarks/bench_fmaps.py --orient 1   # also with the orientation term (slower)
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np

import _harness as h

DATA = h.DATA
LANDMARK = 2446
K_FIT, K_ZO, STEP, K_DESCR, N_DESCR = 30, 100, 5, 128, 100


def timed(fn, repeats):
    """(first-call seconds, median seconds of ``repeats`` further calls, last result); every
    call until ``jax.block_until_ready`` of its result."""
    t = h.timed(fn, repeats)
    return t.first, t.median, t.out


def run_pair(src_id, tgt_id, repeats, cache, orient):
    import pyFM.signatures as sg
    from pyFM.functional import FunctionalMapping
    from pyFM.spectral import FM_to_p2p
    from scipy.spatial import cKDTree

    import bsfjax

    meshes = [bsfjax.load_mesh(DATA / "faust" / f"tr_reg_{i}.off") for i in (src_id, tgt_id)]
    spectra = [bsfjax.spectrum(m, 200, cache_dir=cache) for m in meshes]
    sm, sn = spectra
    lm = np.array([LANDMARK])
    row = dict(pair=f"{src_id}→{tgt_id}", n=meshes[0].n_vertices)

    # ---- descriptors
    def ours_descr():
        return [np.concatenate([np.asarray(bsfjax.wks(s, N_DESCR, k=K_DESCR)),
                                np.asarray(bsfjax.wks(s, N_DESCR, k=K_DESCR, landmarks=lm))],
                               axis=1) for s in spectra]

    row["descr_compile_s"], row["descr_bsfjax_s"], (dm, dn) = timed(ours_descr, repeats)
    model = FunctionalMapping(*[h.pyfm_mesh(m, s, bsfjax.laplacian(m)[0])
                                for m, s in zip(meshes, spectra)])
    model.preprocess(n_descr=N_DESCR, descr_type=None, k_process=200)  # spectra only

    def pyfm_descr():
        model.descr1 = model.descr2 = None
        model.compute_spectral_descriptors(n_descr=N_DESCR, descr_type="WKS", k_descr=K_DESCR)
        model.add_descriptors(sg.mesh_WKS(model.mesh1, N_DESCR, landmarks=lm, k=K_DESCR),
                              sg.mesh_WKS(model.mesh2, N_DESCR, landmarks=lm, k=K_DESCR))

    _, row["descr_pyfm_s"], _ = timed(pyfm_descr, repeats)

    # ---- estimation 30×30
    row["fit_compile_s"], row["fit_bsfjax_s"], C = timed(
        lambda: bsfjax.estimate_fmap(sm, sn, dm, dn, k=K_FIT), repeats)
    C = np.asarray(C)
    _, row["fit_pyfm_s"], _ = timed(lambda: model.fit(K=K_FIT), repeats)
    C_py = model.FM_12
    row["energy_bsfjax"] = float(bsfjax.fmap_energy(C, sm, sn, dm, dn))
    row["energy_pyfm"] = float(bsfjax.fmap_energy(C_py, sm, sn, dm, dn))

    # ---- point maps at k = 30 and k = 100 (ground-truth map at 100)
    sm30, sn30 = sm.truncate(K_FIT), sn.truncate(K_FIT)
    gt = np.arange(sn.n_vertices)
    C_gt = np.asarray(bsfjax.fmap_from_p2p(sm.truncate(K_ZO), sn.truncate(K_ZO), gt))
    for kk, CC, a, b in ((K_FIT, C, sm30, sn30), (K_ZO, C_gt, sm.truncate(K_ZO),
                                                    sn.truncate(K_ZO))):
        row[f"p2p{kk}_compile_s"], row[f"p2p{kk}_bsfjax_s"], p_ours = timed(
            lambda: bsfjax.fmap_to_p2p(CC, a, b), repeats)
        _, row[f"p2p{kk}_pyfm_s"], p_py = timed(
            lambda: FM_to_p2p(CC, a.evecs, b.evecs), repeats)
        emb_m, emb_n = a.evecs @ CC.T, b.evecs
        _, row[f"p2p{kk}_ckdtree_s"], p_kd = timed(
            lambda: cKDTree(emb_m).query(emb_n, workers=-1)[1], repeats)
        row[f"p2p{kk}_agree_ckdtree"] = float(np.mean(np.asarray(p_ours) == p_kd))
        row[f"p2p{kk}_agree_pyfm"] = float(np.mean(np.asarray(p_ours) == p_py))
    p30 = np.asarray(bsfjax.fmap_to_p2p(C, sm30, sn30))
    p30_py = model.get_p2p(C_py)

    # ---- ZoomOut 30 → 100
    row["zo_compile_s"], row["zo_bsfjax_s"], C_zo = timed(
        lambda: bsfjax.zoomout(C, sm, sn, K_ZO, step=STEP), repeats)
    nit = (K_ZO - K_FIT) // STEP
    _, row["zo_pyfm_s"], C_zo_py = timed(lambda: model.zoomout_refine(C_py, nit=nit, step=STEP),
                                         max(1, repeats // 2))
    p100 = np.asarray(bsfjax.fmap_to_p2p(C_zo, sm, sn))
    p100_py = model.get_p2p(C_zo_py)

    maps = {"err30_bsfjax": p30, "err30_pyfm": p30_py, "err100_bsfjax": p100,
            "err100_pyfm": p100_py}

    # ---- optional: the same pipeline with the orientation-preserving term
    if orient > 0:
        w = bsfjax.FmapWeights(orient=orient)
        row["fitor_compile_s"], row["fitor_bsfjax_s"], Co = timed(lambda: bsfjax.estimate_fmap(
            sm, sn, dm, dn, k=K_FIT, weights=w, source_mesh=meshes[0], target_mesh=meshes[1]),
            repeats)
        _, row["fitor_pyfm_s"], _ = timed(lambda: model.fit(K=K_FIT, w_orient=orient),
                                          max(1, repeats // 2))
        Co, Co_py = np.asarray(Co), model.FM_12
        maps["or30_bsfjax"] = np.asarray(bsfjax.fmap_to_p2p(Co, sm30, sn30))
        maps["or30_pyfm"] = model.get_p2p(Co_py)
        maps["or100_bsfjax"] = np.asarray(bsfjax.fmap_to_p2p(
            bsfjax.zoomout(Co, sm, sn, K_ZO, step=STEP), sm, sn))
        maps["or100_pyfm"] = model.get_p2p(model.zoomout_refine(Co_py, nit=nit, step=STEP))

    # ---- geodesic errors (one Dijkstra pass for all maps)
    t = time.perf_counter()
    errs = bsfjax.geodesic_error(meshes[0], np.stack(list(maps.values())), gt)
    row["geodesic_s"] = time.perf_counter() - t
    row.update({key: float(e) for key, e in zip(maps, errs)})
    return row


def markdown(rows, machine, repeats, dtype, versions):
    speed = lambda r, key: r[f"{key}_pyfm_s"] / r[f"{key}_bsfjax_s"]  # noqa: E731
    out = [f"Functional maps on FAUST, bsfjax ({dtype}) vs pyFM {versions['pyfmaps']} "
           f"({machine}; median of {repeats}; speed-up = pyFM / bsfjax, error ratio = bsfjax / "
           "pyFM)", "",
           "Mean geodesic error (Dijkstra, ÷√area, all 6890 vertices):", "",
           "| pair | 30×30 bsfjax | pyFM | ratio | ZoomOut→100 bsfjax | pyFM | ratio | "
           "energy bsfjax | pyFM |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['pair']} | {r['err30_bsfjax']:.4f} | {r['err30_pyfm']:.4f} | "
                   f"{r['err30_bsfjax'] / r['err30_pyfm']:.3f} | {r['err100_bsfjax']:.4f} | "
                   f"{r['err100_pyfm']:.4f} | {r['err100_bsfjax'] / r['err100_pyfm']:.3f} | "
                   f"{r['energy_bsfjax']:.6f} | {r['energy_pyfm']:.6f} |")
    if "or30_bsfjax" in rows[0]:
        out += ["", "With the orientation-preserving term (same weights + w_orient):", "",
                "| pair | 30×30 bsfjax | pyFM | ratio | ZoomOut→100 bsfjax | pyFM | ratio | "
                "fit bsfjax | pyFM | speed-up |", "|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            out.append(f"| {r['pair']} | {r['or30_bsfjax']:.4f} | {r['or30_pyfm']:.4f} | "
                       f"{r['or30_bsfjax'] / r['or30_pyfm']:.3f} | {r['or100_bsfjax']:.4f} | "
                       f"{r['or100_pyfm']:.4f} | {r['or100_bsfjax'] / r['or100_pyfm']:.3f} | "
                       f"{1e3 * r['fitor_bsfjax_s']:.0f} ms | {1e3 * r['fitor_pyfm_s']:.0f} ms | "
                       f"{speed(r, 'fitor'):.1f}× |")
    out += ["", "Time (bsfjax compile time in parentheses, paid once per shape signature):", "",
            "| pair | stage | bsfjax | pyFM | speed-up | scipy cKDTree | agree w/ cKDTree |",
            "|---|---|---|---|---|---|---|"]
    stages = [("descr", "WKS + landmark WKS (both shapes)"), ("fit", "estimate 30×30 / fit"),
              ("p2p30", "point map, k=30"), ("p2p100", "point map, k=100"),
              ("zo", "ZoomOut 30→100")]
    for r in rows:
        for key, name in stages:
            kd = (f"{1e3 * r[key + '_ckdtree_s']:.0f} ms" if key + "_ckdtree_s" in r else "")
            ag = (f"{100 * r[key + '_agree_ckdtree']:.2f} %" if key + "_agree_ckdtree" in r
                  else "")
            out.append(f"| {r['pair']} | {name} | {1e3 * r[key + '_bsfjax_s']:.0f} ms "
                       f"({r[key + '_compile_s']:.1f} s) | {1e3 * r[key + '_pyfm_s']:.0f} ms | "
                       f"{speed(r, key):.1f}× | {kd} | {ag} |")
    return "\n".join(out) + "\n"


def main(argv=None):
    ap = h.parser(__doc__)
    h.add_out(ap, default="bench-results")
    h.add_repeats(ap, 3)
    ap.add_argument("--pairs", nargs="+", default=["000-001", "000-010"],
                    help="FAUST pairs SRC-TGT (registration ids)")
    ap.add_argument("--x64", action="store_true", help="run bsfjax in float64")
    ap.add_argument("--orient", type=float, default=0.0,
                    help="also run both pipelines with this orientation weight (pyFM w_orient)")
    h.add_cache(ap, Path(tempfile.gettempdir()) / "bsfjax-bench-spectra")
    args = ap.parse_args(argv)
    h.require_data(*(DATA / "faust" / f"tr_reg_{i}.off" for p in args.pairs
                     for i in p.split("-")), option=None)
    import jax

    if args.x64:
        jax.config.update("jax_enable_x64", True)
    from importlib.metadata import version

    versions = {p: version(p) for p in ("pyfmaps", "jax", "optimistix", "numpy", "scipy")}
    rows = []
    for pair in args.pairs:
        src, tgt = pair.split("-")
        rows.append(run_pair(src, tgt, args.repeats, args.cache, args.orient))
        print(json.dumps(rows[-1], indent=1), flush=True)
    machine = h.short_machine(device=True)
    dtype = "float64" if args.x64 else "float32"
    md = markdown(rows, machine, args.repeats, dtype, versions)
    out = Path(args.out)
    h.write_json(out / "fmaps.json",
                 {"machine": machine, "dtype": dtype, "versions": versions, "rows": rows})
    h.write_text(out / "fmaps.md", md)
    print(md)


if __name__ == "__main__":
    main()
