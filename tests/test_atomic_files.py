"""Files bsfjax writes are atomic (old or new file, never a partial one) and caches recompute
when corrupt.

Each writer is interrupted midway by making its serializer write some bytes to the temporary
file and then raise; the previous file must survive byte for byte and no temporary file may be
left behind.
"""

from __future__ import annotations

import ast
import csv
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

import bsfjax
import bsfjax._util._files as _files
from .conftest import icosphere

PKG = Path(bsfjax.__file__).parent


class Interrupted(Exception):
    pass


def _partial_then_raise(exc=Interrupted):
    """A stand-in serializer: writes a few bytes to its first argument, then raises ``exc``."""

    def writer(target, *args, **kwargs):
        if hasattr(target, "write"):
            target.write(b"PARTIAL")
        else:
            Path(target).write_bytes(b"PARTIAL")
        raise exc("interrupted")

    return writer


def _only(folder: Path, names: list[str]) -> None:
    assert sorted(p.name for p in folder.iterdir()) == sorted(names)


@pytest.fixture(scope="module")
def mesh():
    v, f = icosphere(1)
    return bsfjax.Mesh(v, f, name="ico1")


@pytest.mark.parametrize("exc", [Interrupted, KeyboardInterrupt])
def test_atomic_path_keeps_old_file(tmp_path, exc):
    p = tmp_path / "out.txt"
    _files.write_text_atomic(p, "old\n")
    with pytest.raises(exc):
        with _files.atomic_path(p) as tmp:
            tmp.write_text("half")
            raise exc()
    assert p.read_text() == "old\n"
    _only(tmp_path, ["out.txt"])
    _files.write_text_atomic(p, "new\n")  # and a completed write replaces it
    assert p.read_text() == "new\n"
    umask = os.umask(0)
    os.umask(umask)
    assert p.stat().st_mode & 0o777 == 0o666 & ~umask  # permissions as a plain open() gives


@pytest.mark.parametrize("exc", [Interrupted, KeyboardInterrupt])
def test_save_mesh_interrupted(tmp_path, mesh, monkeypatch, exc):
    import meshio

    p = tmp_path / "m.ply"
    bsfjax.save_mesh(p, mesh)
    before = p.read_bytes()
    monkeypatch.setattr(meshio, "write", _partial_then_raise(exc))
    with pytest.raises(exc):
        bsfjax.save_mesh(p, mesh, point_data={"x": np.zeros(mesh.n_vertices)})
    assert p.read_bytes() == before
    _only(tmp_path, ["m.ply"])


def test_spectrum_cache_interrupted_write(tmp_path, mesh, monkeypatch):
    monkeypatch.setattr(np, "savez", _partial_then_raise())
    with pytest.raises(Interrupted):
        bsfjax.spectrum(mesh, 6, cache_dir=tmp_path)
    _only(tmp_path, [])  # neither a cache file nor a temporary one
    monkeypatch.undo()
    s = bsfjax.spectrum(mesh, 6, cache_dir=tmp_path)
    assert len(list(tmp_path.iterdir())) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an intact cache loads silently
        again = bsfjax.spectrum(mesh, 6, cache_dir=tmp_path)
    np.testing.assert_array_equal(again.evecs, s.evecs)


@pytest.mark.parametrize("corruption", ["truncate", "flip", "garbage", "wrong_shape"])
def test_corrupt_spectrum_cache_is_recomputed(tmp_path, mesh, corruption):
    fresh = bsfjax.spectrum(mesh, 6, cache_dir=tmp_path)
    (path,) = tmp_path.iterdir()
    raw = path.read_bytes()
    if corruption == "truncate":
        path.write_bytes(raw[: len(raw) // 2])
    elif corruption == "flip":  # inside the evecs payload: only the checksum notices
        buf = bytearray(raw)
        buf[len(buf) // 2] ^= 0xFF
        path.write_bytes(bytes(buf))
    elif corruption == "garbage":
        path.write_bytes(os.urandom(len(raw)))
    else:  # a well-formed archive with the wrong content
        with open(path, "wb") as fh:
            np.savez(fh, evals=np.zeros(3), evecs=np.zeros((2, 3)), mass=np.ones(2),
                     checksum=np.array("x"))
    with pytest.warns(UserWarning, match="is corrupt; recomputing"):
        again = bsfjax.spectrum(mesh, 6, cache_dir=tmp_path)
    np.testing.assert_array_equal(again.evecs, fresh.evecs)
    np.testing.assert_array_equal(again.evals, fresh.evals)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the recomputed cache was written back intact
        bsfjax.spectrum(mesh, 6, cache_dir=tmp_path)
    _only(tmp_path, [path.name])


@pytest.mark.parametrize("suffix, dtype", [(".txt", float), (".npy", float), (".npy", int)])
def test_cli_output_interrupted(tmp_path, monkeypatch, suffix, dtype):
    from bsfjax._cli import _io as cli

    p = tmp_path / f"out{suffix}"
    cli._write_array(str(p), np.arange(5, dtype=dtype))  # a function, or labels (save_labels)
    before = p.read_bytes()
    monkeypatch.setattr(np, "savetxt" if suffix == ".txt" else "save", _partial_then_raise())
    with pytest.raises(Interrupted):
        cli._write_array(str(p), np.arange(7, dtype=dtype))
    assert p.read_bytes() == before
    _only(tmp_path, [p.name])


def test_cli_spectrum_output_interrupted(tmp_path, mesh, monkeypatch):
    from bsfjax.cli import main

    src = tmp_path / "s.off"
    bsfjax.save_mesh(src, mesh)
    out = tmp_path / "sp.npz"
    assert main(["spectrum", str(src), "-k", "4", "--out", str(out)]) == 0
    before = out.read_bytes()
    monkeypatch.setattr(np, "savez", _partial_then_raise(OSError))
    assert main(["spectrum", str(src), "-k", "5", "--out", str(out)]) == 2
    assert out.read_bytes() == before
    _only(tmp_path, ["s.off", "sp.npz"])


def test_results_csv_interrupted(tmp_path, monkeypatch):
    from bsfjax.experiments import write_csv

    p = tmp_path / "table.csv"
    write_csv([{"a": 1, "b": 2}], p)
    before = p.read_bytes()

    def half(self, rows):
        self.writerow(rows[0])
        raise Interrupted()

    monkeypatch.setattr(csv.DictWriter, "writerows", half)
    with pytest.raises(Interrupted):
        write_csv([{"a": 3, "b": 4}, {"a": 5, "b": 6}], p)
    assert p.read_bytes() == before
    _only(tmp_path, ["table.csv"])


def test_plot_output_interrupted(tmp_path, mesh, monkeypatch):
    from matplotlib.figure import Figure

    from bsfjax.plot import plot_function

    p = tmp_path / "f.png"
    plot_function(mesh, mesh.vertices[:, 0], views=("front",), path=p)
    before = p.read_bytes()
    monkeypatch.setattr(Figure, "savefig",
                        lambda self, target, **kw: _partial_then_raise()(target))
    with pytest.raises(Interrupted):
        plot_function(mesh, mesh.vertices[:, 1], views=("front",), path=p)
    assert p.read_bytes() == before
    _only(tmp_path, ["f.png"])


# serializer calls and the argument position of their destination
_WRITERS = {"savefig": 0, "savez": 0, "savez_compressed": 0, "savetxt": 0, "save": 0,
            "write_text": None, "write_bytes": None, "dump": 1}


def _destination_ok(call: ast.Call, name: str) -> bool:
    """The destination is the temporary path of ``atomic_path`` (``tmp``), a handle opened on
    it (``fh``) or an in-memory buffer (``buf``)."""
    if name in ("write_text", "write_bytes"):
        target = call.func.value  # tmp.write_text(...)
    else:
        pos = _WRITERS[name]
        if len(call.args) <= pos:
            return False
        target = call.args[pos]
    return isinstance(target, ast.Name) and target.id in ("tmp", "fh", "buf")


def test_every_writer_goes_through_atomic_path():
    """Static check over the package: every serializer call writes to an atomic temp path."""
    offenders, checked = [], 0
    for path in sorted(PKG.rglob("*.py")):
        if path.name == "_files.py":
            continue
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if isinstance(func, ast.Attribute) and name == "write" and \
                    getattr(func.value, "id", None) == "meshio":
                ok = isinstance(node.args[0], ast.Name) and node.args[0].id == "tmp"
            elif name == "open" and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant) \
                    and any(c in str(node.args[1].value) for c in "wax+"):
                ok = isinstance(node.args[0], ast.Name) and node.args[0].id == "tmp"
            elif name in _WRITERS and isinstance(func, ast.Attribute):
                ok = _destination_ok(node, name)
            else:
                continue
            checked += 1
            if not ok:
                offenders.append(f"{path.name}:{node.lineno}")
    assert checked >= 10  # the scan sees the package's writers (mesh, cache, CLI, results, plots)
    assert not offenders, f"writes that bypass bsfjax._util._files.atomic_path: {offenders}"
