"""Render the README's figure and the viewer how-to's scan figures from real data with the
default method, through ``bsfjax transfer`` and ``bsfjax view --screenshot`` (polyscope, EGL).

The SMPL 24-part segmentation of FAUST ``tr_reg_000`` carried by ``bsfjax transfer`` (its
default: the map estimated from five landmarks, the ``refined`` pull-back) to ``tr_reg_010``
(another person, another pose), and to four scan-like versions of ``tr_reg_010`` built here
with numpy (deterministic seeds): Gaussian vertex noise (σ = 0.25 % of the height), 6 holes of
radius 4 % of the height, the left arm cut away, a point cloud of 15K surface points with
noise σ = 0.25 %.  Each PNG shows the source, the target and its errors against the SMPL truth:

    python docs/figures.py            # docs/img/faust_default_transfer.png, docs/img/scan_*.png

Needs ``../shared/data`` (FAUST registrations and the SMPL segmentation), polyscope
(``pip install -e ".[view]"``) and EGL (or a display).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

import bsfjax
from bsfjax.cli import main as main_cli
from bsfjax.internal import sample_surface

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
SMPL = DATA / "segmentations" / "smpl_vert_segmentation.json"
LANDMARKS = [412, 3216, 5907, 6296, 2445]  # the same vertex on every FAUST registration
SIZE = "1000x480"
SIZE_POINTS = "800x384"  # 15K shaded points compress less: under 300 KB


def _off(path: Path, v: np.ndarray, f: np.ndarray) -> Path:
    rows = [" ".join(f"{x:.6f}" for x in p) for p in v] + [f"3 {a} {b} {c}" for a, b, c in f]
    path.write_text(f"OFF\n{len(v)} {len(f)} 0\n" + "\n".join(rows) + "\n")
    return path


def scans(tmp: Path, target: bsfjax.Mesh, labels: np.ndarray) -> dict:
    """The scan-like targets: name -> (file, truth per file row, target landmark rows)."""
    v, f = target.vertices, target.faces
    height = np.ptp(v[:, 1])
    rng = np.random.default_rng(0)
    out = {"scan_noise": (_off(tmp / "noise.off", v + rng.normal(0, 0.0025 * height, v.shape), f),
                          labels, LANDMARKS, LANDMARKS)}
    centres = np.random.default_rng(1).choice(len(v), 6, replace=False)
    near = (np.linalg.norm(v[:, None] - v[centres][None], axis=2) < 0.04 * height).any(1)
    keep = ~near[f].any(1)  # the removed vertices stay as rows no triangle uses
    lm = [i for i in LANDMARKS if not near[i]]  # the landmarks left on the surface
    out["scan_holes"] = (_off(tmp / "holes.off", v, f[keep]), labels, lm, lm)
    names = sorted(json.loads(SMPL.read_text()))
    arm = np.isin(labels, [names.index(n) for n in ("leftArm", "leftForeArm", "leftHand",
                                                     "leftHandIndex1")])
    keep = ~arm[f].any(1)
    used = np.zeros(len(v), bool)
    used[f[keep]] = True
    lm = [i for i in LANDMARKS if used[i]]
    out["scan_arm"] = (_off(tmp / "arm.off", v, f[keep]), labels, lm, lm)
    pts, face, bary = sample_surface(target, 15000, seed=2)
    pts = pts + np.random.default_rng(3).normal(0, 0.0025 * height, pts.shape)
    corner = f[face, np.argmax(bary, axis=1)]  # the truth: the nearest corner's part
    lm = [int(np.argmin(np.linalg.norm(pts - v[i], axis=1))) for i in LANDMARKS]
    out["scan_cloud"] = (_off(tmp / "cloud.off", pts, np.zeros((0, 3), int)), labels[corner],
                         LANDMARKS, lm)
    return out


def render(out_dir: Path) -> dict:
    """Transfer the SMPL parts to each target with ``bsfjax transfer`` and render each with
    ``bsfjax view --screenshot``; returns the accuracy printed per figure."""
    source = DATA / "faust" / "tr_reg_000.off"
    target_path = DATA / "faust" / "tr_reg_010.off"
    parts = bsfjax.load_labels(SMPL)
    done = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        jobs = {"faust_default_transfer": (target_path, parts.labels, LANDMARKS, LANDMARKS)}
        jobs.update(scans(tmp, bsfjax.load_mesh(target_path), parts.labels))
        for name, (path, truth, src_lm, lm) in jobs.items():
            truth_file = tmp / f"{name}_truth.txt"
            np.savetxt(truth_file, truth, fmt="%d")
            result = tmp / f"{name}.json"
            status = main_cli(["transfer", str(source), str(path), "--labels", str(SMPL),
                               "--out", str(result), "--landmarks",
                               f"{','.join(map(str, src_lm))}:{','.join(map(str, lm))}"])
            if status != 0:
                raise SystemExit(f"bsfjax transfer failed for {name} ({status})")
            status = main_cli(["view", str(source), str(path), "--labels", str(SMPL),
                               "--result", str(result), "--truth", str(truth_file),
                               "--screenshot", str(out_dir), "--prefix", name, "--size",
                               SIZE_POINTS if name == "scan_cloud" else SIZE])
            if status != 0:
                raise SystemExit(f"bsfjax view failed for {name} ({status})")
            got = out_dir / f"{name}_front.png"
            final = out_dir / f"{name}.png"
            got.replace(final)
            done[name] = final
    return done


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", type=Path, default=ROOT / "docs" / "img")
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        raise SystemExit(f"docs/figures.py needs {DATA} (FAUST and the SMPL segmentation)")
    for name, path in render(args.out_dir).items():
        print(f"wrote {path} ({path.stat().st_size // 1024} KB)")


if __name__ == "__main__":
    main()
