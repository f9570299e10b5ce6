"""Every notebook in notebooks/ runs top to bottom (small sizes), so they never rot."""

from __future__ import annotations

from pathlib import Path

import pytest

from .conftest import DATA

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs(path, monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    if "real_meshes" in path.name and not (DATA / "faust").exists():
        pytest.skip(f"real-mesh data not found at {DATA}")
    monkeypatch.setenv("BSFJAX_NOTEBOOK_SMALL", "1")
    monkeypatch.setenv("BSFJAX_DATA", str(DATA))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(path.parent)}})
    client.execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors
    # every figure cell produced an image
    images = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if "image/png" in o.get("data", {})]
    assert len(images) >= sum("plot." in c.source for c in nb.cells if c.cell_type == "code")
