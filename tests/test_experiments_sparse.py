"""The ``sparse`` experiment (beyond the paper): :mod:`bsfjax.experiments.sparse`."""

from __future__ import annotations

import csv

import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError
from bsfjax import experiments as ex
from bsfjax.cli import main
from bsfjax.experiments import load_dataset


@pytest.fixture(scope="module")
def body_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("body9")
    pair = bsfjax.example_pair(levels=2)
    bsfjax.save_mesh(d / "a.off", pair.source)
    bsfjax.save_mesh(d / "b.off", pair.target)
    return d


def test_sparse_experiment_rows_and_reproduce(body_dir, tmp_path):
    """`bsfjax reproduce sparse` writes its four files; rows per sparsity, map and transfer."""
    out = tmp_path / "o"
    rc = main(["reproduce", "sparse", "--data", str(body_dir), "--out", str(out), "--pairs", "1",
               "--functions", "2", "--k", "8", "--no-progress", "--cache", str(tmp_path / "c")])
    assert rc == 0
    for suffix in ("csv", "md", "png", "json"):
        assert (out / f"sparse.{suffix}").exists()
    md = (out / "sparse.md").read_text()
    assert "E_app, adaptive, lstsq" in md and "transfer error" in md
    with open(out / "sparse.csv") as fh:
        rows = list(csv.DictReader(fh))
    std = [r for r in rows if r["method"] == "std"]
    # sparsities ≤ k: (5,) ∪ {k = 8}; std: 2 sizes × 2 maps × 2 functions;
    # per frame: (omp S = 5 + lstsq) × 3 transfers × 2 functions
    assert len(std) == 2 * 2 * 2
    assert len(rows) == len(std) + 2 * 2 * 3 * 2
    assert {r["frame_transfer"] for r in rows} == {"-", "binary", "p2p"}
    for r in rows:
        if r["method"] == "omp":
            assert int(r["nonzeros"]) <= int(r["sparsity"]) == 5
        assert np.isfinite(float(r["error"])) and np.isfinite(float(r["approx_error"]))
    # the projection rows at k agree with table 1's std
    t1 = ex.approximation_experiment(load_dataset(body_dir), pairs=1, functions=2, ks=(8,),
                                     methods=("std",), cache_dir=tmp_path / "c",
                                     progress=False)
    np.testing.assert_allclose(sorted(float(r["approx_error"]) for r in std
                                      if r["sparsity"] == "8" and r["maps"] == "gt"),
                               sorted(r["error"] for r in t1), rtol=1e-4)
    with pytest.raises(BSFError, match="sparsities"):
        ex.sparse_experiment(load_dataset(body_dir), pairs=1, functions=1, k=8,
                             sparsities=(10,), progress=False)
