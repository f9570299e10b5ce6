"""The bsfjax command line: help, version, and clean one-line errors."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

import bsfjax
from bsfjax.cli import main


def run(*args):
    return subprocess.run([sys.executable, "-m", "bsfjax.cli", *args], capture_output=True, text=True,
                          timeout=120)


def test_help_and_version():
    r = run("--help")
    assert r.returncode == 0 and "usage: bsfjax" in r.stdout
    r = run("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"bsfjax {bsfjax.__version__}"


def test_spectrum_command(tmp_path, sphere_mesh, capsys):
    mesh_path = tmp_path / "s.ply"
    bsfjax.save_mesh(mesh_path, sphere_mesh)
    out = tmp_path / "spec.npz"
    assert main(["spectrum", str(mesh_path), "-k", "8", "--out", str(out)]) == 0
    with np.load(out) as z:
        np.testing.assert_allclose(z["evals"], bsfjax.spectrum(sphere_mesh, 8).evals)


def test_bad_input_is_one_line_without_traceback(tmp_path):
    out = tmp_path / "never.npz"
    r = run("spectrum", str(tmp_path / "missing.off"), "--out", str(out))
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0 and "no such file" in r.stderr
    assert not out.exists()
