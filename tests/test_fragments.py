"""Scans in several pieces: the main body is matched, the other components are labelled from
the nearest main-body vertex (or left unassigned when far), and the spectrum the map uses has
one zero eigenvalue (issue "Real scans", fragments)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import bsfjax
from bsfjax.cli import main

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
FAUST = DATA / "faust"
SEG = DATA / "segmentations" / "smpl_vert_segmentation.json"
LANDMARKS = "412,3216,5907,6296,2445"


def _write_off(path, v, f):
    with open(path, "w") as fh:
        fh.write(f"OFF\n{len(v)} {len(f)} 0\n")
        np.savetxt(fh, v, fmt="%.8f")
        np.savetxt(fh, np.column_stack([np.full(len(f), 3), f]), fmt="%d")


def fragmented_scan(mesh: bsfjax.Mesh, labels: np.ndarray, hand: int, *, shift=0.005,
                    far=0.5, n_unreferenced=2):
    """``mesh`` plus a copy of the region labelled ``hand`` moved by ``shift`` (a detached
    hand), a few triangles moved ``far`` away (debris) and unreferenced vertices: ``(vertices,
    faces, rows of the hand copy, rows of the debris, rows of the unreferenced vertices,
    the original vertex of each hand-copy row)``."""
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    n = len(v)
    region = np.flatnonzero(labels == hand)
    hf = f[np.all(np.isin(f, region), axis=1)]
    used = np.unique(hf)
    new = np.full(n, -1)
    new[used] = n + np.arange(used.size)
    hand_v = v[used] + np.array([shift, 0.0, 0.0])
    debris_f = f[100:103]
    d_used = np.unique(debris_f)
    dnew = np.full(n, -1)
    start = n + used.size
    dnew[d_used] = start + np.arange(d_used.size)
    debris_v = v[d_used] + np.array([far, 0.0, 0.0])
    unref = np.array([[far, far, far]] * n_unreferenced) + np.arange(n_unreferenced)[:, None]
    verts = np.vstack([v, hand_v, debris_v, unref])
    faces = np.vstack([f, new[hf], dnew[debris_f]])
    rows_hand = n + np.arange(used.size)
    rows_debris = start + np.arange(d_used.size)
    rows_unref = start + d_used.size + np.arange(n_unreferenced)
    return verts, faces, rows_hand, rows_debris, rows_unref, used


def _sphere(n_lat: int, radius: float):
    """A UV sphere: poles and ``n_lat - 1`` rings of ``2 n_lat`` vertices."""
    n_lon = 2 * n_lat
    th = np.linspace(0, np.pi, n_lat + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    v = np.vstack([[0, 0, 1], ring, [0, 0, -1]]) * radius
    idx = lambda i, j: 1 + i * n_lon + j % n_lon  # noqa: E731
    f = [[0, idx(0, j), idx(0, j + 1)] for j in range(n_lon)]
    for i in range(n_lat - 2):
        for j in range(n_lon):
            f += [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)],
                  [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]]
    last = len(v) - 1
    f += [[last, idx(n_lat - 2, j + 1), idx(n_lat - 2, j)] for j in range(n_lon)]
    return v, np.array(f)


class _Shape:
    def __init__(self, v, f):
        self.vertices, self.faces = v, f


def test_two_spheres_synthetic():
    a, b = _Shape(*_sphere(16, 1.0)), _Shape(*_sphere(4, 0.2))
    near = np.asarray(b.vertices) + np.array([1.25, 0.0, 0.0])  # 0.05 from the big sphere
    far = np.asarray(b.vertices) + np.array([5.0, 0.0, 0.0])
    na, nb = len(a.vertices), len(b.vertices)
    v = np.vstack([a.vertices, near, far])
    f = np.vstack([a.faces, b.faces + na, b.faces + na + nb])
    mesh = bsfjax.Mesh(v, f)
    parts = bsfjax.split_main_body(mesh)
    assert parts.mesh.n_vertices == na and parts.n_other_components == 2
    assert parts.other.size == 2 * nb
    assert parts.n_labelled == nb - np.sum(  # the small sphere's far side is beyond reach
        np.linalg.norm(near, axis=1) - 1.0 > parts.reach)
    assert parts.n_unassigned == 2 * nb - parts.n_labelled
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # one component: no warning about zero eigenvalues
        spec = bsfjax.spectrum(parts.mesh, 8)
    assert np.sum(np.abs(np.asarray(spec.evals)) < 1e-8) == 1
    with pytest.warns(UserWarning, match="3 connected components"):
        assert np.sum(np.abs(np.asarray(bsfjax.spectrum(mesh, 8).evals)) < 1e-8) == 3
    lab = (np.asarray(a.vertices)[:, 0] > 0).astype(np.int64)
    out = parts.to_whole(lab)
    assert out.shape == (mesh.n_vertices,)
    assert np.all(out[na + nb:] == -1)  # the far sphere
    assert np.all(out[:na] == lab)
    ok = parts.nearest >= 0
    assert np.all(out[parts.other[ok]] == 1)  # the near sphere lies on the x > 0 side
    fl = parts.to_whole(np.ones(parts.mesh.n_faces, np.int64), faces=True)
    assert fl.shape == (mesh.n_faces,) and np.all(fl[-len(b.faces):] == -1)
    assert "labelled from the nearest surface" in parts.summary()
    # the main body keeps the file's rows: landmarks and labels read onto it
    assert np.array_equal(parts.mesh.vertex_ids, np.arange(na))
    assert parts.mesh.n_file_rows == mesh.n_vertices
    with pytest.raises(bsfjax.MeshError, match="not on the main body"):
        parts.index([na + 1])
    # a point cloud or a single component: itself
    one = bsfjax.split_main_body(bsfjax.Mesh(a.vertices, a.faces))
    assert one.n_other_components == 0 and one.whole is one.mesh


@pytest.mark.skipif(not (FAUST / "tr_reg_010.off").exists() or not SEG.exists(),
                    reason="FAUST registrations or SMPL labels not in ../shared/data")
def test_faust_scan_with_fragments(tmp_path):
    tgt = bsfjax.load_mesh(FAUST / "tr_reg_010.off")
    labels, names = bsfjax.load_labels(SEG)
    hand = names.index("leftHand")
    v, f, rows_hand, rows_debris, rows_unref, orig = fragmented_scan(tgt, labels, hand)
    _write_off(tmp_path / "scan.off", v, f)
    np.savetxt(tmp_path / "labels.txt", labels, fmt="%d")
    np.savetxt(tmp_path / "truth.txt", np.concatenate(
        [labels, labels[orig], np.full(len(rows_debris) + len(rows_unref), -1)]), fmt="%d")
    scan = bsfjax.load_mesh(tmp_path / "scan.off")
    parts = bsfjax.split_main_body(scan)
    assert parts.n_other_components == 3  # the hand copy and two pieces of debris
    spec = bsfjax.spectrum(parts.mesh, 20)
    assert np.sum(np.abs(np.asarray(spec.evals)) < 1e-8 * float(spec.evals[-1])) == 1
    lm = f"{LANDMARKS}:{LANDMARKS}"
    clean_out, scan_out = tmp_path / "clean.txt", tmp_path / "scan.txt"
    assert main(["transfer", str(FAUST / "tr_reg_000.off"), str(FAUST / "tr_reg_010.off"),
                 "--labels", str(tmp_path / "labels.txt"), "--landmarks", lm,
                 "--out", str(clean_out)]) == 0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(["transfer", str(FAUST / "tr_reg_000.off"), str(tmp_path / "scan.off"),
                     "--labels", str(tmp_path / "labels.txt"), "--landmarks", lm,
                     "--out", str(scan_out)]) == 0
    assert not [w for w in caught if "connected components" in str(w.message)]
    clean, out = np.loadtxt(clean_out, dtype=int), np.loadtxt(scan_out, dtype=int)
    assert out.shape == (len(v),)  # one row per file row
    body = out[:tgt.n_vertices]
    acc_clean, acc_body = np.mean(clean == labels), np.mean(body == labels)
    assert abs(acc_clean - acc_body) <= 0.005, (acc_clean, acc_body)
    assert np.all(out[rows_debris] == -1) and np.all(out[rows_unref] == -1)
    from scipy.spatial import cKDTree

    _, nearest = cKDTree(v[:tgt.n_vertices]).query(v[rows_hand])
    assert np.array_equal(out[rows_hand], body[nearest])  # the nearest main-body label
    assert np.mean(out[rows_hand] == body[orig]) > 0.9  # mostly its original vertex's


@pytest.mark.skipif(not (FAUST / "tr_reg_010.off").exists() or not SEG.exists(),
                    reason="FAUST registrations or SMPL labels not in ../shared/data")
def test_faust_collection_with_fragments(tmp_path):
    import json

    tgt = bsfjax.load_mesh(FAUST / "tr_reg_010.off")
    labels, names = bsfjax.load_labels(SEG)
    v, f, rows_hand, rows_debris, rows_unref, orig = fragmented_scan(
        tgt, labels, names.index("leftHand"))
    d = tmp_path / "targets"
    d.mkdir()
    _write_off(d / "scan.off", v, f)
    _write_off(d / "clean.off", np.asarray(tgt.vertices), np.asarray(tgt.faces))
    np.savetxt(tmp_path / "labels.txt", labels, fmt="%d")
    lm = [int(x) for x in LANDMARKS.split(",")]
    (tmp_path / "lm.json").write_text(json.dumps({"scan": [lm, lm], "clean": [lm, lm]}))
    out = tmp_path / "out"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(["transfer", str(FAUST / "tr_reg_000.off"), str(d / "clean.off"),
                     str(d / "scan.off"), "--labels", str(tmp_path / "labels.txt"),
                     "--landmarks-file", str(tmp_path / "lm.json"), "--out-dir", str(out),
                     "--no-progress"]) == 0
    assert not [w for w in caught if "connected components" in str(w.message)]
    clean, scan = np.loadtxt(out / "clean.txt", dtype=int), np.loadtxt(out / "scan.txt", dtype=int)
    assert scan.shape == (len(v),)
    assert abs(np.mean(clean == labels) - np.mean(scan[:len(labels)] == labels)) <= 0.005
    assert np.all(scan[rows_debris] == -1) and np.all(scan[rows_unref] == -1)
    assert np.mean(scan[rows_hand] == scan[orig]) > 0.9
    rows = {r["target"].split("/")[-1]: r for r in
            json.loads((out / "summary.json").read_text())["targets"]}
    assert rows["scan.off"]["other_components"] == 3
    assert rows["scan.off"]["other_component_vertices"] == len(rows_hand) + len(rows_debris)
    assert rows["scan.off"]["unassigned_fragment_vertices"] == len(rows_debris)
    assert rows["clean.off"]["other_components"] == 0
