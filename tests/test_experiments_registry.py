"""The experiments package: its registry, ``reproduce``, the CLI's choices, and its layout (one
engine adapter, small modules)."""

from __future__ import annotations

import ast
import csv
import json
from pathlib import Path

import pytest

import bsfjax
from bsfjax import BSFError
from bsfjax import experiments as ex
from bsfjax.cli import build_parser, main
from bsfjax.experiments import EXPERIMENTS, Experiment, Report, fig10

PACKAGE = Path(ex.__file__).parent


@pytest.fixture(scope="module")
def tiny_dir(tmp_path_factory):
    """The built-in example pair at its smallest useful size (506 vertices) as a data folder."""
    d = tmp_path_factory.mktemp("tiny")
    pair = bsfjax.example_pair(levels=1)
    bsfjax.save_mesh(d / "a.off", pair.source)
    bsfjax.save_mesh(d / "b.off", pair.target)
    return d


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("spectra")


def test_every_registry_entry_is_complete():
    for name, exp in EXPERIMENTS.items():
        assert exp.name == name and exp.default_ks and callable(exp.run) and callable(exp.report)
        assert exp.description


# A table and a figure end to end through the registry; every experiment's rows are tested in
# tests/test_experiments*.py (running all eight here again took ~100 s of the suite).
@pytest.mark.parametrize("name", ["table3", "fig10"])
def test_registered_experiments_run_end_to_end(name, tiny_dir, cache, tmp_path, monkeypatch):
    """A registry entry, through ``reproduce``, on one tiny pair at k = 6: rows, CSV,
    Markdown (header with the entry's description), JSON, and the PNG when it is a figure."""
    monkeypatch.setattr(fig10, "SWEEPS", {"gamma": (0.6,), "sparsity": (2,)})  # fig10: short
    exp = EXPERIMENTS[name]
    assert exp.name == name and exp.default_ks and callable(exp.run) and callable(exp.report)
    out = tmp_path / "out"
    res = ex.reproduce(name, tiny_dir, out, pairs=1, functions=2, ks=(6,), cache_dir=cache,
                       progress=False)
    assert res["rows"] and res["seconds"] > 0
    with open(out / f"{name}.csv") as fh:
        assert len(list(csv.DictReader(fh))) == len(res["rows"])
    md = (out / f"{name}.md").read_text()
    assert md.startswith(f"# {name}\n\n{exp.description}\n") and "- settings: " in md
    assert ("functions per shape: 2" in md) == exp.uses_functions
    assert json.loads((out / f"{name}.json").read_text())["experiment"] == name
    png = out / f"{name}.png"
    assert [Path(f).name for f in res["files"]] == [f"{name}.csv", f"{name}.md"] + (
        [png.name] if png.exists() else [])
    if name in ("fig7", "fig10", "sparse"):
        assert png.exists()


def test_reproduce_rejects_unknown_names_listing_the_registry(tiny_dir, tmp_path, capsys):
    with pytest.raises(BSFError, match="experiment must be one of") as err:
        ex.reproduce("table9", tiny_dir, tmp_path / "o")
    assert all(repr(n) in str(err.value) for n in EXPERIMENTS)
    assert not (tmp_path / "o").exists()
    with pytest.raises(SystemExit) as stop:
        main(["reproduce", "table9", "--data", str(tiny_dir), "--out", str(tmp_path / "o")])
    assert stop.value.code == 2
    msg = capsys.readouterr().err
    assert "invalid choice: 'table9'" in msg and all(n in msg for n in EXPERIMENTS)


def test_registering_an_experiment_is_one_entry(tiny_dir, tmp_path, monkeypatch):
    """A new entry is all ``reproduce`` and the CLI need (no other code names experiments)."""
    seen = {}

    def run(dataset, *, pairs, functions, ks, seed, cache_dir, progress):
        seen.update(pairs=pairs, functions=functions, ks=ks, shapes=len(dataset.shapes))
        return [{"method": "x", "k": k, "error": 0.25} for k in ks]

    def report(rows, ks):
        return Report(ex.pivot_markdown(rows, "method", "k"),
                      [("t", "k", {"x": ([r["k"] for r in rows], [0.25] * len(rows))}, False)],
                      f"dummy settings, ks = {ks}")

    monkeypatch.setitem(EXPERIMENTS, "dummy", Experiment("dummy", "A dummy study.", run, (3, 4),
                                                         report))
    parser = build_parser()
    sub = next(a for a in parser._subparsers._group_actions[0].choices["reproduce"]._actions
               if a.dest == "name")
    assert tuple(sub.choices) == tuple(EXPERIMENTS)
    rc = main(["reproduce", "dummy", "--data", str(tiny_dir), "--out", str(tmp_path / "o"),
               "--pairs", "1", "--functions", "3", "--no-progress"])
    assert rc == 0 and seen == {"pairs": 1, "functions": 3, "ks": (3, 4), "shapes": 2}
    md = (tmp_path / "o" / "dummy.md").read_text()
    assert "A dummy study." in md and "- settings: dummy settings, ks = (3, 4)" in md
    assert "| method \\ k | 3 | 4 |" in md and (tmp_path / "o" / "dummy.png").exists()


def _imports(path: Path) -> set[str]:
    """Modules imported by ``path``, relative ones resolved against ``bsfjax.experiments``."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = {0: "", 1: "bsfjax.experiments", 2: "bsfjax"}[node.level]
            mod = ".".join(p for p in (base, node.module or "") if p)
            out.add(mod)
            if node.module is None:  # from . import x
                out.update(f"{mod}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


def test_only_the_engine_adapter_imports_the_engine():
    engine = {"bsfjax._transfer", "bsfjax._coding", "bsfjax._frame", "bsfjax._transfer._methods", "bsfjax._transfer._engine", "bsfjax._coding._encode", "bsfjax._coding._coders",
              "bsfjax._frame._build", "bsfjax._frame._dense_frame", "bsfjax._frame._sparse_frame"}
    files = sorted(PACKAGE.glob("*.py"))
    assert {f.name for f in files} >= {"__init__.py", "_registry.py", "_engine.py", "_io.py",
                                       "_shapes.py", "_datasets.py"}
    for f in files:
        used = _imports(f) & engine
        if f.name == "_engine.py":
            assert used
        else:
            assert not used, f"{f.name} imports the engine ({used}); go through _engine"


def test_modules_are_small_and_reexports_are_kept():
    for f in PACKAGE.glob("*.py"):
        assert len(f.read_text().splitlines()) < 600, f.name
    for name in ex.__all__ + ["_functions", "prepare_shapes", "N_LANDMARKS", "KN_METHODS",
                              "SWEEPS", "cli"]:
        assert hasattr(ex, name), name
    assert set(EXPERIMENTS) >= {"table1", "table2", "fig7", "table3", "table4", "table5",
                                "fig10", "sparse"}
    assert ex.DEFAULT_KS == (10, 30, 50, 70, 90) and "p2p" not in ex.APPROX_METHODS
