"""File rows stay file rows: the readers drop unreferenced vertices (and zero-area triangles),
yet every file the command line reads or writes is numbered by the rows of the user's file
(`Mesh.to_file_rows` / `Mesh.from_file_rows`); the dropped rows get -1 / NaN."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import bsfjax
from bsfjax.cli import main


def _write_off(path, v, f):
    lines = ["OFF", f"{len(v)} {len(f)} 0"]
    lines += [" ".join(f"{x:.17g}" for x in row) for row in v]
    lines += ["3 " + " ".join(map(str, row)) for row in f]
    path.write_text("\n".join(lines) + "\n")


def _with_extra_rows(mesh, positions, seed=0):
    """The mesh's vertices with unreferenced rows inserted before the given vertex positions
    (``n``: at the end); returns (vertices, faces, file row of each mesh vertex)."""
    n = mesh.n_vertices
    pos = np.sort(np.asarray(positions, np.int64))
    rows = np.arange(n) + np.searchsorted(pos, np.arange(n), side="right")
    v = np.random.default_rng(seed).normal(size=(n + len(pos), 3)) * 10
    v[rows] = mesh.vertices
    return v, rows[mesh.faces], rows


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    d = tmp_path_factory.mktemp("rows")
    pair = bsfjax.example_pair(levels=1)
    _write_off(d / "src.off", pair.source.vertices, pair.source.faces)
    _write_off(d / "tgt.off", pair.target.vertices, pair.target.faces)
    np.savetxt(d / "labels.txt", pair.labels, fmt="%d")
    np.savetxt(d / "p2p.txt", np.asarray(pair.p2p), fmt="%d")
    fun = np.stack([pair.source.vertices[:, 0], pair.labels.astype(float)], axis=1)
    np.savetxt(d / "fun.txt", fun)
    common = ["-k", "10", "--map", "p2p", str(d / "p2p.txt")]
    assert main(["transfer", str(d / "src.off"), str(d / "tgt.off"), "--labels",
                 str(d / "labels.txt"), "--out", str(d / "ref.txt"), *common]) == 0
    assert main(["transfer", str(d / "src.off"), str(d / "tgt.off"), "--function",
                 str(d / "fun.txt"), "--out", str(d / "ref_fun.txt"), *common]) == 0
    return d, pair, np.loadtxt(d / "ref.txt", dtype=int), np.loadtxt(d / "ref_fun.txt")


positions = st.lists(st.integers(0, 506), min_size=0, max_size=3)


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(src_pos=positions, tgt_pos=positions.filter(len), seed=st.integers(0, 2 ** 16))
def test_single_target_outputs_and_inputs_keep_file_rows(base, tmp_path_factory, src_pos,
                                                         tgt_pos, seed, capsys):
    d0, pair, ref, ref_fun = base
    d = tmp_path_factory.mktemp("case")
    rng = np.random.default_rng(seed)
    vs, fs, rows_s = _with_extra_rows(pair.source, src_pos, seed)
    vt, ft, rows_t = _with_extra_rows(pair.target, tgt_pos, seed + 1)
    _write_off(d / "src.off", vs, fs)
    _write_off(d / "tgt.off", vt, ft)
    # inputs in file rows: the extra rows hold junk that must be ignored
    labels = rng.integers(0, 3, len(vs))
    labels[rows_s] = pair.labels
    np.savetxt(d / "labels.txt", labels, fmt="%d")
    fun = rng.normal(size=(len(vs), 2))
    fun[rows_s] = np.loadtxt(d0 / "fun.txt")
    np.savetxt(d / "fun.txt", fun)
    p2p = rng.integers(0, len(vs), len(vt))
    p2p[rows_t] = rows_s[np.asarray(pair.p2p)]
    np.savetxt(d / "p2p.txt", p2p, fmt="%d")
    truth = rng.integers(0, 3, len(vt))
    truth[rows_t] = ref
    np.savetxt(d / "truth.txt", truth, fmt="%d")
    common = ["-k", "10", "--map", "p2p", str(d / "p2p.txt")]
    capsys.readouterr()
    assert main(["transfer", str(d / "src.off"), str(d / "tgt.off"), "--labels",
                 str(d / "labels.txt"), "--out", str(d / "out.txt"), "--truth",
                 str(d / "truth.txt"), "--mesh-out", str(d / "out.ply"), *common]) == 0
    err = capsys.readouterr().err
    assert "100.0% of the target area" in err  # the truth was read in file rows
    assert f"{len(tgt_pos)} rows of" in err  # the dropped rows are counted
    got = np.loadtxt(d / "out.txt", dtype=int, ndmin=1)
    extra = np.setdiff1d(np.arange(len(vt)), rows_t)
    assert got.shape == (len(vt),)
    np.testing.assert_array_equal(got[rows_t], ref)
    assert np.all(got[extra] == -1)
    import meshio

    m = meshio.read(d / "out.ply")
    np.testing.assert_allclose(m.points, vt)  # the file's own rows, geometry and triangles
    np.testing.assert_array_equal(m.cells[0].data, ft)
    np.testing.assert_array_equal(m.point_data["label"], got)
    assert main(["transfer", str(d / "src.off"), str(d / "tgt.off"), "--function",
                 str(d / "fun.txt"), "--out", str(d / "fun_out.txt"), "--mesh-out",
                 str(d / "fun.ply"), *common]) == 0
    fgot = np.loadtxt(d / "fun_out.txt", ndmin=2)
    m = meshio.read(d / "fun.ply")
    assert m.points.shape == vt.shape
    np.testing.assert_array_equal(np.isnan(m.point_data["value"]), np.isnan(fgot[:, 0]))
    assert fgot.shape == (len(vt), 2)
    np.testing.assert_allclose(fgot[rows_t], ref_fun, rtol=1e-6, atol=1e-9)
    assert np.isnan(fgot[extra]).all()


def test_landmarks_in_file_rows_and_a_landmark_on_a_dropped_row(base, tmp_path, capsys):
    d0, pair, *_ = base
    vt, ft, rows_t = _with_extra_rows(pair.target, [0, 200, 506])
    _write_off(tmp_path / "tgt.off", vt, ft)
    tgt_lm = [5, 300]  # and their images under the exact map (target → source)
    src_lm = [int(np.asarray(pair.p2p)[i]) for i in tgt_lm]
    argv = ["transfer", str(d0 / "src.off"), None, "--labels", str(d0 / "labels.txt"), "-k",
            "10", "--one-start", "--out", None, "--landmarks", None]

    def run(target, lm, out):
        argv[2], argv[9], argv[11] = str(target), str(out), lm
        return main(argv)

    assert run(d0 / "tgt.off", f"{src_lm[0]},{src_lm[1]}:{tgt_lm[0]},{tgt_lm[1]}",
               tmp_path / "plain.txt") == 0
    file_lm = [int(rows_t[i]) for i in tgt_lm]
    assert run(tmp_path / "tgt.off", f"{src_lm[0]},{src_lm[1]}:{file_lm[0]},{file_lm[1]}",
               tmp_path / "rows.txt") == 0
    plain, rows = np.loadtxt(tmp_path / "plain.txt"), np.loadtxt(tmp_path / "rows.txt")
    np.testing.assert_array_equal(rows[rows_t], plain)
    assert rows[0] == rows[201] == rows[-1] == -1
    capsys.readouterr()
    assert run(tmp_path / "tgt.off", f"{src_lm[0]},{src_lm[1]}:{file_lm[0]},201",
               tmp_path / "bad.txt") == 2
    err = capsys.readouterr().err
    assert "row 201" in err and "--landmarks (target)" in err
    assert not (tmp_path / "bad.txt").exists()


@settings(max_examples=2, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(src_pos=positions, tgt_pos=st.lists(st.integers(0, 506), min_size=1, max_size=3))
def test_collections_keep_file_rows(base, tmp_path_factory, src_pos, tgt_pos):
    """--out-dir, --mesh-out-dir, summary.json and --landmarks-file, in the files' rows."""
    d0, pair, *_ = base
    d = tmp_path_factory.mktemp("many")
    vs, fs, rows_s = _with_extra_rows(pair.source, src_pos)
    vt, ft, rows_t = _with_extra_rows(pair.target, tgt_pos, 1)
    _write_off(d / "src.off", vs, fs)
    (d / "plain").mkdir()
    (d / "rows").mkdir()
    _write_off(d / "plain" / "a.off", pair.target.vertices, pair.target.faces)
    _write_off(d / "rows" / "a.off", vt, ft)
    labels = np.full(len(vs), 7)
    labels[rows_s] = pair.labels
    np.savetxt(d / "labels.txt", labels, fmt="%d")
    tgt_lm = [5, 300]
    src_lm = [int(np.asarray(pair.p2p)[i]) for i in tgt_lm]
    (d / "lm_plain.json").write_text(json.dumps({"a": [src_lm, tgt_lm]}))
    (d / "lm_rows.json").write_text(json.dumps(
        {"a": [[int(rows_s[i]) for i in src_lm], [int(rows_t[i]) for i in tgt_lm]]}))
    for kind, src, lab in (("plain", d0 / "src.off", d0 / "labels.txt"),
                           ("rows", d / "src.off", d / "labels.txt")):
        assert main(["transfer", str(src), str(d / kind / "a.off"), "--labels", str(lab),
                     "--out-dir", str(d / f"out_{kind}"), "-k", "10", "--no-progress",
                     "--one-start", "--mesh-out-dir", str(d / f"ply_{kind}"),
                     "--landmarks-file", str(d / f"lm_{kind}.json")]) == 0
    plain = np.loadtxt(d / "out_plain" / "a.txt", dtype=int)
    got = np.loadtxt(d / "out_rows" / "a.txt", dtype=int)
    assert got.shape == (len(vt),)
    np.testing.assert_array_equal(got[rows_t], plain)
    assert np.all(got[np.setdiff1d(np.arange(len(vt)), rows_t)] == -1)
    rec = json.loads((d / "out_rows" / "summary.json").read_text())["targets"][0]
    assert rec["dropped_rows"] == len(tgt_pos) and rec["vertices"] == pair.target.n_vertices
    import meshio

    m = meshio.read(d / "ply_rows" / "a.ply")
    np.testing.assert_allclose(m.points, vt)
    np.testing.assert_array_equal(m.point_data["label"], got)


def test_json_labels_and_dropped_triangles_keep_file_rows(base, tmp_path, capsys):
    """SMPL .json labels in and out by file rows; a zero-area triangle the reader drops keeps
    its row of a per-triangle .seg output (-1), and a .seg input is read by the file's
    triangles."""
    d0, pair, ref, _ = base
    vt, ft, rows_t = _with_extra_rows(pair.target, [0, 506])
    _write_off(tmp_path / "tgt.off", vt, ft)
    p2p = np.zeros(len(vt), int)
    p2p[rows_t] = np.asarray(pair.p2p)
    np.savetxt(tmp_path / "p2p.txt", p2p, fmt="%d")
    parts = {f"p{i}": np.flatnonzero(pair.labels == i).tolist() for i in np.unique(pair.labels)}
    (tmp_path / "parts.json").write_text(json.dumps(parts))
    assert main(["transfer", str(d0 / "src.off"), str(tmp_path / "tgt.off"), "--labels",
                 str(tmp_path / "parts.json"), "--map", "p2p", str(tmp_path / "p2p.txt"), "-k",
                 "10", "--out", str(tmp_path / "out.json")]) == 0
    got = bsfjax.load_labels(tmp_path / "out.json")
    lab = np.full(len(vt), -1)
    for name, idx in json.loads((tmp_path / "out.json").read_text()).items():
        if name != "unassigned":  # (the rows without a vertex, and unassigned vertices)
            lab[idx] = got.names.index(name)
    np.testing.assert_array_equal(lab[rows_t], ref)
    assert lab[0] == lab[-1] == -1
    # a zero-area triangle in the middle of the source's and target's triangle lists
    src = pair.source
    mid = src.n_faces // 2
    fs = np.insert(src.faces, mid, [[0, 0, 1]], axis=0)
    _write_off(tmp_path / "src_deg.off", src.vertices, fs)
    ft2 = np.insert(ft, 10, [[rows_t[2], rows_t[2], rows_t[3]]], axis=0)
    _write_off(tmp_path / "tgt_deg.off", vt, ft2)
    seg = np.asarray(pair.labels)[src.faces[:, 0]]
    (tmp_path / "in.seg").write_text("\n".join(map(str, np.insert(seg, mid, 99))) + "\n")
    capsys.readouterr()
    assert main(["transfer", str(tmp_path / "src_deg.off"), str(tmp_path / "tgt_deg.off"),
                 "--labels", str(tmp_path / "in.seg"), "--map", "p2p", str(tmp_path / "p2p.txt"),
                 "-k", "10", "--out", str(tmp_path / "out.seg")]) == 0
    assert "1 triangles of" in capsys.readouterr().err
    out = np.loadtxt(tmp_path / "out.seg", dtype=int)
    assert out.shape == (len(ft2),) and out[10] == -1 and 99 not in out
    assert np.all(out[np.arange(len(ft2)) != 10] >= 0)


def test_mesh_helpers_go_back_and_forth(tmp_path):
    v = np.array([[9, 9, 9], [0, 0, 0], [1, 0, 0], [0, 1, 0], [8, 8, 8], [1, 1, 0], [7, 7, 7.]])
    f = np.array([[1, 2, 3], [2, 5, 3], [1, 1, 2]])
    _write_off(tmp_path / "m.off", v, f)
    with pytest.warns(UserWarning, match=r"removed 3 unreferenced vertices \(file rows 0, 4, 6"):
        m = bsfjax.load_mesh(tmp_path / "m.off")
    assert (m.n_file_rows, m.dropped_rows, m.n_file_faces, m.dropped_faces) == (7, 3, 3, 1)
    np.testing.assert_array_equal(m.to_file_rows(np.arange(4)), [-1, 0, 1, 2, -1, 3, -1])
    assert np.isnan(m.to_file_rows(np.arange(4.0))[[0, 4, 6]]).all()
    np.testing.assert_array_equal(m.to_file_rows(np.array([5, 6]), faces=True), [5, 6, -1])
    np.testing.assert_array_equal(m.from_file_rows(m.to_file_rows(np.arange(4))), np.arange(4))
    np.testing.assert_array_equal(m.from_file_rows(np.arange(3), faces=True), [0, 1])
    np.testing.assert_array_equal(m.file_row_index([1, 5]), [0, 3])
    with pytest.raises(bsfjax.MeshError, match="landmarks: row 4 .* unreferenced"):
        m.file_row_index([1, 4], "landmarks")
    with pytest.raises(bsfjax.MeshError, match=r"row 7 is out of range \[0, 7\)"):
        m.file_row_index([7])
    back = m.file_mesh()
    np.testing.assert_array_equal(back.vertices, v)
    np.testing.assert_array_equal(back.faces, f)
    plain = bsfjax.Mesh(v[1:4], [[0, 1, 2]])
    assert plain.file_mesh() is plain and plain.dropped_rows == 0
    np.testing.assert_array_equal(plain.to_file_rows([1, 2, 3]), [1, 2, 3])


def test_spectrum_command_keeps_file_rows(base, tmp_path):
    """``bsfjax spectrum``: one eigenvector row per file row (NaN and zero mass where the
    reader dropped an unreferenced vertex), the kept rows those of the mesh without them."""
    d, pair, _, _ = base
    v, f, rows = _with_extra_rows(pair.source, [0, 100, pair.source.n_vertices])
    _write_off(tmp_path / "m.off", v, f)
    assert main(["spectrum", str(d / "src.off"), "-k", "6", "--out", str(tmp_path / "a.npz")]) == 0
    with pytest.warns(UserWarning):
        assert main(["spectrum", str(tmp_path / "m.off"), "-k", "6",
                     "--out", str(tmp_path / "b.npz")]) == 0
    a, b = np.load(tmp_path / "a.npz"), np.load(tmp_path / "b.npz")
    assert b["evecs"].shape == (len(v), 6) and b["mass"].shape == (len(v),)
    dropped = np.setdiff1d(np.arange(len(v)), rows)
    assert np.isnan(b["evecs"][dropped]).all() and (b["mass"][dropped] == 0).all()
    np.testing.assert_allclose(b["evals"], a["evals"], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(b["mass"][rows], a["mass"], rtol=1e-12)
    # eigenvectors up to sign
    sign = np.sign(np.sum(b["evecs"][rows] * a["evecs"], axis=0))
    np.testing.assert_allclose(b["evecs"][rows] * sign, a["evecs"], atol=1e-6)
