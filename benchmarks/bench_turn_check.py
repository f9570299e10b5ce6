"""The turn check's doubt on a real pair (moved from the test suite, where it took 46 s).

FAUST ``tr_reg_020`` → the remeshed FAUST_5k ``tr_reg_001`` without landmarks: the turn
check swaps a right map for a turned one (about a third of the SMPL parts right), by a local
distortion 2 % lower against an orientation agreement 0.08 lower.  It cannot tell, and says
so (``MapEstimate.turn_doubtful``; docs/results/segmentation.md, "Without landmarks").  The
script prints what the default estimate does on the pair and exits with status 1 when the
estimate no longer says it is in doubt.  The doubt's rule itself (`measures_disagree`) and the
command's warning are in the tests (``tests/test_map_estimate.py``, ``tests/test_cli.py``).

    python benchmarks/bench_turn_check.py     # ~40 s on 2 cores
"""

from __future__ import annotations

import sys

import _harness as h


def main() -> int:
    import numpy as np

    import bsfjax
    from bsfjax.experiments._datasets import load_dataset
    from bsfjax.experiments.segmentation import shape_labels

    ap = h.parser(__doc__)
    h.add_data(ap)
    args = ap.parse_args()
    data = h.Path(args.data)
    h.require_data(data / "faust", data / "faust_5k", data / h.SMPL_SEGMENTATION)
    template, _ = bsfjax.load_labels(data / h.SMPL_SEGMENTATION)
    src = bsfjax.load_mesh(data / "faust" / "tr_reg_020.off")
    remeshed = load_dataset(data / "faust_5k")
    j = [e.name for e in remeshed.shapes].index("tr_reg_001")
    tgt, truth = remeshed.shapes[j].mesh, shape_labels(remeshed, j, template)
    sm, sn = bsfjax.spectrum(src, 60), bsfjax.spectrum(tgt, 60)
    est = bsfjax.estimate_map(sm, sn, k=30, refine_to=60, source_mesh=src, target_mesh=tgt)
    mass = np.asarray(sn.mass)
    acc = float(np.sum(mass * (template[est.p2p] == truth)) / mass.sum())
    print(f"FAUST 020 -> FAUST_5k 001, no landmarks: swapped {est.swapped}, turn_doubtful "
          f"{est.turn_doubtful}, SMPL parts right {acc:.1%} of the area")
    return 0 if est.swapped and est.turn_doubtful is True and acc < 0.4 else 1


if __name__ == "__main__":
    sys.exit(main())
