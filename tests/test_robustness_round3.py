"""Reliability, round 3: no non-finite result from finite input, no zero-mass spectrum, label
and function files checked before any allocation and without loose values, the common mesh
files that were refused, and the command's messages (warnings in one line, options checked
before any work, unmatched landmark keys said).  ``docs/robustness.md`` section 8 lists these
cases; `test_docs_list_round3_cases` checks it.
"""

from __future__ import annotations

import json
import os
import re
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError, MeshError

from .conftest import icosphere

DOC = Path(__file__).resolve().parents[1] / "docs" / "robustness.md"


@pytest.fixture(scope="module")
def ns():
    v, f = icosphere(1)
    mesh = bsfjax.Mesh(v, f, name="ico1")
    spec = bsfjax.spectrum(mesh, 10)
    F = np.asarray(bsfjax.random_indicators(mesh, 2, seed=1), np.float64)
    return SimpleNamespace(v=v, f=f, mesh=mesh, spec=spec, F=F, n=mesh.n_vertices)


def _cli(argv, capsys):
    from bsfjax.cli import main

    capsys.readouterr()
    rc = main([str(a) for a in argv])
    return rc, capsys.readouterr().err


def _one_error_line(rc, err, match):
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("bsfjax")]
    assert rc == 2 and "Traceback" not in err, err
    assert len(lines) == 1 and re.search(match, lines[0]), err


# --------------------------------------------------------------- 1. non-finite results


@pytest.mark.parametrize("scale", [1e39, 1e300, 1e-300])
def test_transfer_values_beyond_float32_is_right(ns, scale):
    """float64 values beyond float32 (`transfer-values-beyond-float32`): the unit-scale result
    times the scale, finite (was inf / NaN, or zeros at 1e-300)."""
    unit = bsfjax.transfer_values(ns.spec, ns.spec, ns.F, C=np.eye(10), mesh=ns.mesh)
    big = bsfjax.transfer_values(ns.spec, ns.spec, ns.F * scale, C=np.eye(10), mesh=ns.mesh)
    assert np.isfinite(big).all() and big.dtype == np.float64
    np.testing.assert_allclose(big / scale, unit, rtol=1e-6, atol=1e-6)


def test_transfer_values_ordinary_scale_keeps_dtype(ns):
    out = bsfjax.transfer_values(ns.spec, ns.spec, ns.F, C=np.eye(10), mesh=ns.mesh)
    assert out.dtype == np.asarray(bsfjax.transfer("omp", bsfjax.Pair(
        source=ns.spec, target=ns.spec, C=np.eye(10),
        centers=bsfjax.farthest_point_sampling(ns.mesh, 0.05)), ns.F).transferred).dtype


def test_engine_refuses_results_beyond_its_dtype(ns):
    """`transfer-engine-beyond-float32`: the engine computes in float32 by default; a result it
    cannot hold is a BSFError naming the range, not inf."""
    import jax

    if jax.config.jax_enable_x64:
        pytest.skip("float64 engine holds 1e300")
    pair = bsfjax.Pair(source=ns.spec, target=ns.spec, C=np.eye(10),
                       centers=bsfjax.farthest_point_sampling(ns.mesh, 8))
    with pytest.raises(BSFError, match=r"f has values up to 1e\+300: the results do not fit "
                                       r"in float32 \(max 3.4e\+38\)"):
        bsfjax.transfer("omp", pair, ns.F * 1e300)


def test_cli_function_beyond_float32_is_written_finite(tmp_path, capsys, ns):
    """`cli-function-beyond-float32`: a --function file of float64 values 1e39 gives finite
    values (was inf/nan with exit 0)."""
    src = tmp_path / "s.off"
    bsfjax.save_mesh(src, ns.mesh)
    np.savetxt(tmp_path / "p2p.txt", np.arange(ns.n), fmt="%d")
    out = {}
    for scale in (1.0, 1e39):
        np.savetxt(tmp_path / "f.txt", ns.F[0] * scale)
        rc, err = _cli(["transfer", src, src, "--function", tmp_path / "f.txt", "--map", "p2p",
                        tmp_path / "p2p.txt", "--method", "std", "-k", 10, "--out",
                        tmp_path / f"o{scale:g}.txt"], capsys)
        assert rc == 0, err
        out[scale] = np.loadtxt(tmp_path / f"o{scale:g}.txt")
    assert np.isfinite(out[1e39]).all()
    np.testing.assert_allclose(out[1e39] / 1e39, out[1.0], rtol=1e-6, atol=1e-6)


# --------------------------------------------------------------- 2. zero mass


@pytest.mark.parametrize("mass, match", [
    (np.zeros(42), r"positive, finite total, got 0"),
    (np.full(42, 1e307), r"positive, finite total, got inf"),
])
def test_spectrum_with_zero_total_mass_is_refused(ns, mass, match):
    """`spectrum-zero-mass`: an all-zero (or overflowing) area is refused at construction (was
    accepted, then 0/0 in every stage)."""
    with pytest.raises(BSFError, match=r"Spectrum.mass \(vertex areas\) must have a " + match):
        bsfjax.Spectrum(ns.spec.evals, ns.spec.evecs, mass)
    stacked = (np.stack([ns.spec.evals] * 2), np.stack([ns.spec.evecs] * 2),
               np.stack([ns.spec.mass, mass]))
    with pytest.raises(BSFError, match=r"spectrum 1 of the stack"):
        bsfjax.Spectrum(*stacked)


# --------------------------------------------------------------- 3. label and function files


def test_json_huge_vertex_index_is_refused_before_allocating(tmp_path, monkeypatch):
    """`labels-json-huge-index`: 10**12 is refused by its range (the file lists 3 indices)
    before any array is allocated."""
    import bsfjax._mesh._label_files as lf

    path = tmp_path / "parts.json"
    path.write_text(json.dumps({"arm": [0, 1], "leg": [10**12]}))
    real_full = np.full

    def guarded_full(shape, *a, **k):
        assert np.prod(shape) < 10**6, f"allocated {shape}"
        return real_full(shape, *a, **k)

    monkeypatch.setattr(lf.np, "full", guarded_full)
    with pytest.raises(BSFError, match=r"part 'leg' has vertex index 1000000000000, but the "
                                       r"file lists only 3 indices: at least 999999999998 "
                                       r"vertices are in no part"):
        bsfjax.load_labels(path)


@pytest.mark.parametrize("value, shown", [(0.7, "0.7"), ("12", '"12"'), (True, "true"),
                                          ([1], r"\[1\]"), (1.0, "1.0")])
def test_json_loose_label_values_are_refused(tmp_path, value, shown):
    """`labels-json-loose-values`: 0.7, "12", true were read as vertices 0, 12, 1."""
    path = tmp_path / "parts.json"
    path.write_text(json.dumps({"arm": [0, 1, 2], "leg": [3, value]}))
    with pytest.raises(BSFError, match=rf"part 'leg' has {shown}, not an integer vertex index"):
        bsfjax.load_labels(path)


def test_json_part_not_a_list_is_refused(tmp_path):
    path = tmp_path / "parts.json"
    path.write_text(json.dumps({"arm": [0, 1], "leg": 2}))
    with pytest.raises(BSFError, match=r"part 'leg' must be a list of vertex indices, got 2"):
        bsfjax.load_labels(path)


def test_complex_values_are_refused(ns, tmp_path, capsys):
    """`transfer-values-complex`, `cli-complex-function-file`: not cut to the real part."""
    with pytest.raises(BSFError, match=r"values must be real numbers, got dtype complex128"):
        bsfjax.transfer_values(ns.spec, ns.spec, ns.F + 1j, C=np.eye(10), mesh=ns.mesh)
    src = tmp_path / "s.off"
    bsfjax.save_mesh(src, ns.mesh)
    np.save(tmp_path / "f.npy", ns.F[0] + 0.5j)
    rc, err = _cli(["transfer", src, src, "--function", tmp_path / "f.npy", "--map", "p2p",
                    src, "--out", tmp_path / "o.txt"], capsys)
    _one_error_line(rc, err, r"function file .*f.npy: expected real numbers, got complex values")
    assert not (tmp_path / "o.txt").exists()


# --------------------------------------------------------------- 4. common files


_QUAD = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"


@pytest.mark.parametrize("name, text", [
    ("seams.obj", _QUAD + "vt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\nvt .5 .5\nvn 0 0 1\n"
     "f 1/1/1 2/2/1 3/3/1\nf 2/5/1 4/4/1 3/3/1\n"),
    ("shared_normals.obj", _QUAD + "vn 0 0 1\nf 1//1 2//1 3//1\nf 2//1 4//1 3//1\n"),
    ("quad_seams.obj", _QUAD + "vt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\nvt .5 .5\n"
     "f 1/1 2/5 4/4 3/3\n"),
])
def test_textured_obj_is_read_by_position(tmp_path, name, text):
    """`obj-texture-seams`, `obj-shared-normals`: texture and normal indices are ignored."""
    path = tmp_path / name
    path.write_text(text)
    m = bsfjax.load_mesh(path)
    assert m.n_vertices == 4
    assert sorted(map(sorted, np.asarray(m.faces).tolist())) in (
        [[0, 1, 2], [1, 2, 3]], [[0, 1, 3], [0, 2, 3]])


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_face_list_named_vertex_index(tmp_path, fmt):
    """`ply-vertex-index`: the face list ``vertex_index`` (not ``vertex_indices``)."""
    head = (f"ply\nformat {fmt} 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            "property float z\nelement face 1\nproperty list uchar int vertex_index\n"
            "end_header\n").encode()
    if fmt == "ascii":
        body = b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    else:
        body = np.array([0, 0, 0, 1, 0, 0, 0, 1, 0], "<f4").tobytes() + b"\x03" \
            + np.array([0, 1, 2], "<i4").tobytes()
    path = tmp_path / "t.ply"
    path.write_bytes(head + body)
    m = bsfjax.load_mesh(path)
    assert m.n_vertices == 3 and np.asarray(m.faces).tolist() == [[0, 1, 2]]


def test_off_with_byte_order_mark(tmp_path):
    """`off-byte-order-mark`: a UTF-8 BOM (Windows editors) is not 'binary OFF'."""
    path = tmp_path / "t.off"
    path.write_bytes(b"\xef\xbb\xbfOFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    m = bsfjax.load_mesh(path)
    assert m.n_vertices == 3 and np.asarray(m.faces).tolist() == [[0, 1, 2]]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs")
def test_fifo_is_not_a_regular_file(tmp_path, capsys, ns):
    """`input-fifo`: a named pipe is named as such (was 'no such file'; a read would block)."""
    import signal

    def hang(*_):
        raise AssertionError("reading the FIFO blocked")

    fifo = tmp_path / "pipe.off"
    os.mkfifo(fifo)
    old = signal.signal(signal.SIGALRM, hang)
    signal.alarm(60)  # a regression would block on the FIFO forever
    try:
        _fifo_checks(tmp_path, capsys, ns, fifo)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _fifo_checks(tmp_path, capsys, ns, fifo):
    with pytest.raises(MeshError, match=r"pipe.off: is a named pipe \(FIFO\), not a regular "):
        bsfjax.load_mesh(fifo)
    with pytest.raises(BSFError, match=r"labels file .*pipe.off: is a named pipe \(FIFO\)"):
        bsfjax.load_labels(fifo)
    src = tmp_path / "s.off"
    bsfjax.save_mesh(src, ns.mesh)
    rc, err = _cli(["transfer", src, src, "--labels", fifo, "--map", "p2p", src, "--out",
                    tmp_path / "o.txt"], capsys)
    _one_error_line(rc, err, r"--labels .*pipe.off: is a named pipe \(FIFO\), not a regular file")
    from bsfjax._cli._io import _read_array

    with pytest.raises(ValueError, match=r"function file .*: is a named pipe"):
        _read_array(str(fifo), "function")


# --------------------------------------------------------------- 5. messages


def test_cli_warnings_are_one_line(tmp_path, capsys, ns):
    """`cli-warning-one-line`: a warning during a command is ``bsfjax: warning: …`` (no file,
    line number or source line); Python's own display is back after the command."""
    src = tmp_path / "s.off"
    bsfjax.save_mesh(src, ns.mesh)
    faces = np.concatenate([ns.f, [[0, 0, 1]]])  # a zero-area face (no vertex removed)
    (tmp_path / "z.off").write_text(
        f"OFF\n{ns.n} {len(faces)} 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in ns.v)
        + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces))
    np.savetxt(tmp_path / "p2p.txt", np.arange(ns.n), fmt="%d")
    np.savetxt(tmp_path / "f.txt", ns.F[0])
    import sys

    before = warnings.formatwarning
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        # what Python does outside pytest (which records warnings instead of printing them)
        warnings._showwarnmsg_impl = lambda msg: sys.stderr.write(warnings._formatwarnmsg(msg))
        rc, err = _cli(["transfer", tmp_path / "z.off", src, "--function", tmp_path / "f.txt",
                        "--map", "p2p", tmp_path / "p2p.txt", "--method", "p2p", "--out",
                        tmp_path / "o.txt"], capsys)
    assert rc == 0, err
    warn = [ln for ln in err.splitlines() if "zero-area" in ln]
    assert warn == [ln for ln in warn if ln.startswith("bsfjax: warning: ")] and len(warn) == 1
    assert "UserWarning" not in err and ".py:" not in err, err
    assert warnings.formatwarning is before


@pytest.mark.parametrize("extra, match", [
    (["--threshold", "nan"], r"--threshold must be a number in \[0, 1\), got nan"),
    (["--threshold", "1.5"], r"--threshold must be a number in \[0, 1\), got 1.5"),
    (["-k", "1"], r"-k must be an integer >= 2 to estimate a map \(--map estimate\), got 1"),
])
def test_cli_late_checks_come_first(tmp_path, capsys, ns, monkeypatch, extra, match):
    """`cli-threshold-nan`, `cli-k-one-estimate`: refused with the option checks, before any
    mesh is read (were refused after the spectra and the map)."""
    import bsfjax._mesh

    src = tmp_path / "s.off"
    bsfjax.save_mesh(src, ns.mesh)
    np.savetxt(tmp_path / "lab.txt", (ns.F[0] > 0).astype(int), fmt="%d")

    def no_work(*a, **k):
        raise AssertionError("a mesh was read before the option checks")

    monkeypatch.setattr(bsfjax._mesh, "load_mesh", no_work)
    rc, err = _cli(["transfer", src, src, "--labels", tmp_path / "lab.txt", "--out",
                    tmp_path / "o.txt", *extra], capsys)
    _one_error_line(rc, err, match)


def test_unmatched_landmark_keys_are_named(tmp_path):
    """`cli-landmarks-file-unmatched`: keys that match no target are warned about by name
    (were dropped without a word); matched keys are used."""
    from bsfjax._cli._many import _read_landmarks_file

    path = tmp_path / "lm.json"
    path.write_text(json.dumps({"tr_reg_001": [[0, 1], [2, 3]], "tr_reg_0O2.off": [[0], [1]],
                                "typo": [[0], [1]]}))
    targets = [Path("a/tr_reg_001.off"), Path("a/tr_reg_002.off")]
    with pytest.warns(UserWarning, match=r"--landmarks-file .*lm.json: 2 entries match no "
                                         r"target of this run .*'tr_reg_0O2.off', 'typo'"):
        got = _read_landmarks_file(str(path), targets, ValueError)
    assert got == {0: ([0, 1], [2, 3])}


def test_docs_list_round3_cases():
    text = DOC.read_text()
    ids = ["transfer-values-beyond-float32", "transfer-engine-beyond-float32",
           "cli-function-beyond-float32", "spectrum-zero-mass", "labels-json-huge-index",
           "labels-json-loose-values", "transfer-values-complex", "cli-complex-function-file",
           "obj-texture-seams", "obj-shared-normals", "ply-vertex-index", "off-byte-order-mark",
           "input-fifo", "cli-warning-one-line", "cli-threshold-nan", "cli-k-one-estimate",
           "cli-landmarks-file-unmatched"]
    missing = [i for i in ids if f"`{i}`" not in text]
    assert not missing, f"docs/robustness.md does not list {missing}"
