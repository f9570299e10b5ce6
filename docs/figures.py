"""Render the README's figure from real data with the default method.

The SMPL 24-part segmentation of FAUST ``tr_reg_000`` carried to ``tr_reg_010`` (another
person, another pose) by `bsfjax.transfer_labels` with its default method (`refined`) through
the map `bsfjax.estimate_map` estimates from five landmarks, as `bsfjax transfer` does:

    python docs/figures.py                    # writes docs/img/demo_transfer.png (about 30 s)

Needs ``../shared/data`` (FAUST registrations and the SMPL segmentation).
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import bsfjax  # noqa: E402
from bsfjax import plot  # noqa: E402
from bsfjax.cli import main as main_cli  # noqa: E402
from bsfjax.internal import vertex_areas  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
LANDMARKS = [412, 3216, 5907, 6296, 2445]  # the same vertex on every FAUST registration


def render(out: Path) -> float:
    source = bsfjax.load_mesh(DATA / "faust" / "tr_reg_000.off")
    target = bsfjax.load_mesh(DATA / "faust" / "tr_reg_010.off")
    segmentation = DATA / "segmentations" / "smpl_vert_segmentation.json"
    parts = bsfjax.load_labels(segmentation)
    lm = ",".join(map(str, LANDMARKS))
    with tempfile.TemporaryDirectory() as tmp:  # exactly what `bsfjax transfer` writes
        out_json = Path(tmp) / "parts_010.json"
        status = main_cli(["transfer", str(DATA / "faust" / "tr_reg_000.off"),
                           str(DATA / "faust" / "tr_reg_010.off"), "--labels", str(segmentation),
                           "--out", str(out_json), "--landmarks", f"{lm}:{lm}"])
        if status != 0:
            raise SystemExit(f"bsfjax transfer failed ({status})")
        got = bsfjax.load_labels(out_json)
    index = {name: i for i, name in enumerate(parts.names)}  # the same parts, by name
    labels = np.array([index[got.names[l]] if l >= 0 else -1 for l in got.labels])
    truth = parts.labels  # FAUST registrations share the template's vertices
    right = labels == truth
    area = vertex_areas(target)  # barycentric: a third of each incident triangle
    accuracy = float(np.sum(area * right) / np.sum(area))
    res_labels = labels
    panels = [
        (source, parts.labels, "source: FAUST 000, SMPL parts"),
        (target, res_labels, f"target: FAUST 010, default transfer ({100 * accuracy:.1f} %)"),
        (target, np.where(right, 0, 1), "wrong label (red)"),
    ]
    with tempfile.TemporaryDirectory() as tmp:
        images = []
        for i, (mesh, labels, _) in enumerate(panels):
            path = Path(tmp) / f"{i}.png"
            if i < 2:
                plot.plot_segmentation(mesh, labels, views=("front",), legend=False,
                                       figsize=(3.2, 4.2), dpi=110, path=path)
            else:
                plot.plot_function(mesh, labels.astype(float), views=("front",),
                                   cmap="Reds", vmin=0, vmax=1, colorbar=False, figsize=(3.2, 4.2),
                                   dpi=110, path=path)
            images.append(mpimg.imread(path))
    fig, axes = plt.subplots(1, 3, figsize=(10, 4.6), dpi=110)
    for ax, img, (_, _, title) in zip(axes, images, panels):
        ax.imshow(img)
        ax.set_title(title, fontsize=9)
        ax.axis("off")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp_out = out.with_name(out.name + ".tmp.png")
    fig.savefig(tmp_out)
    os.replace(tmp_out, out)
    return accuracy


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img" / "demo_transfer.png")
    args = ap.parse_args(argv)
    if not DATA.is_dir():
        raise SystemExit(f"docs/figures.py needs {DATA} (FAUST and the SMPL segmentation)")
    accuracy = render(args.out)
    print(f"wrote {args.out}: {100 * accuracy:.1f} % of the target's area labelled right")


if __name__ == "__main__":
    main()
