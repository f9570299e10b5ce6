"""Fuzzing the mesh readers: malformed OFF / PLY / OBJ / STL bytes give MeshError, never a
crash, a hang or an unbounded allocation.

Two parts:

* a fixed table of known-bad files (truncated, wrong or huge counts, negative indices, binary
  garbage, headers that used to hang meshio), each asserting the message;
* a hypothesis fuzzer that mutates valid files (truncation, byte flips, inserted tokens such as
  huge or negative numbers, replaced header counts, spliced garbage) and also writes random
  headers with random counts.  It runs for a bounded time: ``BSFJAX_FUZZ_SECONDS`` (default
  15 s) of work, at most ``BSFJAX_FUZZ_EXAMPLES`` (default 4000) files; every read runs
  under a ``SIGALRM`` watchdog (``READ_TIMEOUT`` s) so a hang fails the test instead of
  stalling CI.
"""

from __future__ import annotations

import os
import re
import signal
import time
import warnings

import meshio
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import bsfjax
from bsfjax import MeshError

from .conftest import icosphere

FUZZ_SECONDS = float(os.environ.get("BSFJAX_FUZZ_SECONDS", "15"))
FUZZ_EXAMPLES = int(os.environ.get("BSFJAX_FUZZ_EXAMPLES", "4000"))
READ_TIMEOUT = 10.0


class ReaderHang(BaseException):
    """Raised by the watchdog; a BaseException so that no reader's ``except Exception`` eats it."""


def _alarm(signum, frame):
    raise ReaderHang()


def load_guarded(path):
    """``load_mesh(path)`` under a watchdog; returns the mesh or the MeshError raised."""
    watchdog = hasattr(signal, "SIGALRM")  # POSIX; elsewhere the read runs unguarded
    if watchdog:
        old = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, READ_TIMEOUT)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # cleaning warnings are expected on mutated meshes
            return bsfjax.load_mesh(path)
    except MeshError as exc:
        return exc
    finally:
        if watchdog:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)


def check_outcome(out, data: bytes):
    """A read either fails with MeshError or yields a valid mesh (or point cloud); anything
    else fails."""
    if isinstance(out, MeshError):
        assert str(out), "MeshError without a message"
        return
    assert isinstance(out, bsfjax.Mesh), f"load_mesh returned {type(out)} for {data[:200]!r}"
    assert np.isfinite(out.vertices).all()
    if out.is_point_cloud:  # e.g. an OBJ cut before its faces: a valid point file
        assert out.n_faces == 0 and isinstance(out, bsfjax.PointCloud)
        return
    assert out.faces.min() >= 0 and out.faces.max() < out.n_vertices
    assert (out.face_areas() > 0).all()


@pytest.fixture(scope="module")
def base_files(tmp_path_factory):
    """Valid files of a small icosphere in every format: ``{kind: (extension, bytes)}``."""
    d = tmp_path_factory.mktemp("fuzz_base")
    v, f = icosphere(1)
    mesh = bsfjax.Mesh(v, f)
    out = {}
    for ext in ("off", "ply", "obj", "stl"):
        p = d / f"base.{ext}"
        bsfjax.save_mesh(p, mesh)
        out[ext] = (ext, p.read_bytes())
    p = d / "ascii.ply"
    meshio.write(p, meshio.Mesh(v, [("triangle", f)]), binary=False)
    out["ply_ascii"] = ("ply", p.read_bytes())
    return out


# ----------------------------------------------------------------------------- fixed cases

_PLY_BIN = (b"ply\nformat binary_little_endian 1.0\nelement vertex {nv}\nproperty float x\n"
            b"property float y\nproperty float z\nelement face {nf}\n"
            b"property list uchar int vertex_indices\nend_header\n")
_PLY_ASC = (b"ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n"
            b"property float z\nelement face {nf}\nproperty list uchar int vertex_indices\n"
            b"end_header\n")
_TRI = b"0 0 0\n1 0 0\n0 1 0\n"

#: (file name, content, message excerpt).  docs/robustness.md lists these.
READER_CASES = [
    ("empty.off", b"", "missing OFF header"),
    ("no_header.off", b"3 1 0\n" + _TRI + b"3 0 1 2\n", "missing OFF header"),
    ("bad_counts.off", b"OFF\nthree one 0\n", "bad OFF counts line"),
    ("negative_counts.off", b"OFF\n-3 1 0\n" + _TRI + b"3 0 1 2\n", "negative counts"),
    ("huge_counts.off", b"OFF\n999999999999 1 0\n" + _TRI + b"3 0 1 2\n", "truncated?"),
    ("truncated.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n", "truncated?"),
    ("short_vertex.off", b"OFF\n3 1 0\n0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "3 coordinates"),
    ("nan_vertex.off", b"OFF\n3 1 0\nnan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "NaN or infinite"),
    ("negative_index.off", b"OFF\n3 1 0\n" + _TRI + b"3 0 -1 2\n", "face indices out of range"),
    ("index_too_big.off", b"OFF\n3 1 0\n" + _TRI + b"3 0 1 7\n", "face indices out of range"),
    ("index_beyond_int64.off", b"OFF\n3 1 0\n" + _TRI + b"3 0 1 99999999999999999999999\n",
     "beyond 64-bit integers"),
    ("short_face.off", b"OFF\n3 1 0\n" + _TRI + b"3 0 1\n", "bad face line"),
    ("huge_polygon.off", b"OFF\n3 1 0\n" + _TRI + b"2147483647 0 1 2\n", "bad face line"),
    ("binary.off", b"OFF\n\x00\xff\xfe garbage\x81", "not an ASCII OFF file"),
    ("zero_area.off", b"OFF\n3 1 0\n0 0 0\n0 0 0\n0 0 0\n3 0 1 2\n", "every face has zero area"),
    ("short_row.xyz", b"0 0 0\n1 0\n", "every row needs x y z"),
    ("no_end_header.ply", b"ply\nformat ascii 1.0\nelement vertex 3\n", "end_header"),
    ("end_header_in_comment.ply", b"ply\nformat binary_little_endian 1.0\n"
     b"comment made by x, end_header\nelement vertex 3\n", "end_header"),
    ("end_header_no_newline.ply", b"ply\nformat ascii 1.0\nend_header", "end_header"),
    ("huge_count_binary.ply", _PLY_BIN.replace(b"{nv}", b"1000000000000").replace(b"{nf}", b"1"),
     "truncated?"),
    ("huge_count_extra_token.ply",
     _PLY_BIN.replace(b"{nv}", b"99999999999 junk").replace(b"{nf}", b"1"), "truncated?"),
    ("huge_faces_binary.ply",
     _PLY_BIN.replace(b"{nv}", b"3").replace(b"{nf}", b"4000000000") + b"\x00" * 36,
     "truncated?"),
    ("huge_count_ascii.ply", _PLY_ASC.replace(b"{nv}", b"3000000000").replace(b"{nf}", b"1")
     + _TRI + b"3 0 1 2\n", "truncated?"),
    ("negative_count.ply", _PLY_ASC.replace(b"{nv}", b"-3").replace(b"{nf}", b"1") + _TRI,
     "bad PLY element line"),
    ("negative_index.ply", _PLY_ASC.replace(b"{nv}", b"3").replace(b"{nf}", b"1") + _TRI
     + b"3 0 -5 2\n", "face indices out of range"),
    ("garbage_header.ply", b"ply\n\xff\xfe\x00\nend_header\n", "not text"),
    ("random_bytes.ply", b"ply\n" + bytes(range(256)) * 4, "not text"),
    ("negative_index.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -3\n", "out of range"),
    ("zero_index.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "out of range"),
    ("index_too_big.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "out of range"),
    ("index_beyond_int64.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n",
     "bad face indices"),
    ("ragged_vertex.obj", b"v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", "cannot read mesh"),
    ("text_in_vertex.obj", b"v 0 zero 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "cannot read mesh"),
    ("text_in_point.xyz", b"0 0 zero\n", "bad number"),
    ("binary.obj", b"\x00\x81\xff" * 50, "cannot read mesh"),
    ("truncated.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n", "cannot read"),
    ("huge_count.stl", b"\x00" * 80 + (2**32 - 1).to_bytes(4, "little") + b"\x00" * 50,
     "mesh is empty"),
    ("huge_coordinates.off", b"OFF\n3 1 0\n1e300 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "overflow"),
    ("unknown.xyzw", b"0 0 0\n", "cannot read mesh"),
]


@pytest.mark.parametrize("name,data,message", READER_CASES, ids=[c[0] for c in READER_CASES])
def test_malformed_file_gives_mesh_error(tmp_path, name, data, message):
    p = tmp_path / name
    p.write_bytes(data)
    t0 = time.perf_counter()
    out = load_guarded(p)
    assert isinstance(out, MeshError), f"{name}: expected MeshError, got {out!r}"
    assert message in str(out), str(out)
    assert str(p) in str(out)  # the message names the file
    assert time.perf_counter() - t0 < 5.0


def test_obj_extra_vertex_columns_are_dropped(tmp_path):
    """``v x y z w`` and ``v x y z r g b`` are valid OBJ: positions are the first three."""
    p = tmp_path / "colours.obj"
    p.write_bytes(b"v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n")
    m = bsfjax.load_mesh(p)
    np.testing.assert_array_equal(m.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


# ----------------------------------------------------------------------------- fuzzer

_TOKENS = [b"-1", b"0", b"-0", b"3", b"99999999999", b"2147483647", b"4294967295",
           b"-2147483648", b"1e308", b"-1e308", b"nan", b"inf", b"-inf", b"", b"\x00", b"\xff\xfe",
           b"abc", b"end_header", b"comment", b"element vertex 1000000000", b"element face -1",
           b"property list uint int vertex_indices", b"format binary_big_endian 1.0", b"OFF",
           b"f -1 -2 -3", b"f 0 0 0", b"v 1 2", b"v nan nan nan", b"facet normal", b"endsolid",
           b"\r\n", b"\x1c", b"#"]

_op = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("flip"), st.lists(st.tuples(st.floats(0, 1), st.integers(0, 255)),
                                        min_size=1, max_size=8)),
    st.tuples(st.just("insert"), st.floats(0, 1), st.sampled_from(_TOKENS),
              st.sampled_from([b" ", b"\n", b""])),
    st.tuples(st.just("number"), st.integers(0, 40), st.sampled_from(_TOKENS)),
    st.tuples(st.just("splice"), st.floats(0, 1), st.binary(max_size=200)),
    st.tuples(st.just("repeat"), st.floats(0, 1), st.floats(0, 1)),
)


def _mutate(data: bytes, ops) -> bytes:
    buf = bytearray(data)
    for op in ops:
        kind = op[0]
        pos = int(op[1] * len(buf)) if kind not in ("flip", "number") else 0
        if kind == "truncate":
            del buf[pos:]
        elif kind == "flip" and buf:
            for frac, byte in op[1]:
                buf[min(int(frac * len(buf)), len(buf) - 1)] = byte
        elif kind == "insert":
            buf[pos:pos] = op[2] + op[3]
        elif kind == "number":  # replace the i-th integer token (header counts come first)
            hits = list(re.finditer(rb"-?\d+", bytes(buf[:2000])))
            if hits:
                m = hits[op[1] % len(hits)]
                buf[m.start():m.end()] = op[2]
        elif kind == "splice":
            buf[pos:pos] = op[2]
        elif kind == "repeat":
            end = max(pos, int(op[2] * len(buf)))
            buf[pos:pos] = buf[pos:end]
    return bytes(buf)


_START: dict[str, float] = {}
#: Share of ``FUZZ_SECONDS`` each fuzz test may use.
_SHARE = {"mutated": 0.7, "headers": 0.3}


def _budget_left(which: str) -> bool:
    start = _START.setdefault(which, time.monotonic())
    return time.monotonic() - start < _SHARE[which] * FUZZ_SECONDS


@settings(max_examples=FUZZ_EXAMPLES, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(kind=st.sampled_from(["off", "ply", "ply_ascii", "obj", "stl"]),
       ops=st.lists(_op, min_size=1, max_size=4))
def test_fuzz_mutated_files(base_files, tmp_path_factory, kind, ops):
    if not _budget_left("mutated"):
        return  # time budget spent: the remaining examples are no-ops
    ext, data = base_files[kind]
    data = _mutate(data, ops)
    p = tmp_path_factory.getbasetemp() / f"fuzz_mutated.{ext}"
    p.write_bytes(data)
    check_outcome(load_guarded(p), data)


_count = st.one_of(st.integers(-5, 50), st.sampled_from([2**31 - 1, 2**32, 10**12, 10**18]))


@settings(max_examples=max(FUZZ_EXAMPLES // 4, 1), deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(fmt=st.sampled_from(["off", "ply_ascii", "ply_binary"]), nv=_count, nf=_count,
       body=st.binary(max_size=400))
def test_fuzz_random_headers(tmp_path_factory, fmt, nv, nf, body):
    """Well-formed headers with arbitrary counts in front of arbitrary bytes."""
    if not _budget_left("headers"):
        return
    if fmt == "off":
        data, ext = b"OFF\n%d %d 0\n" % (nv, nf) + body, "off"
    else:
        head = _PLY_ASC if fmt == "ply_ascii" else _PLY_BIN
        data, ext = head.replace(b"{nv}", b"%d" % nv).replace(b"{nf}", b"%d" % nf) + body, "ply"
    p = tmp_path_factory.getbasetemp() / f"fuzz_header.{ext}"
    p.write_bytes(data)
    check_outcome(load_guarded(p), data)
