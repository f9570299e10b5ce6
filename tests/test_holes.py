"""Holes and partial shapes (issue "Real scans"): boundary loops, hole patches for the spectrum
only (original vertices first and unchanged, outputs in the file's rows) and the report of the
source parts a partial target has no counterpart for."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp

import bsfjax
from bsfjax.cli import main
from bsfjax._cli import _transfer as cli_transfer

from .conftest import icosphere


def _cut(mesh: bsfjax.Mesh, remove: np.ndarray):
    """``mesh`` without the vertices ``remove`` (mask) and their triangles: (mesh, kept)."""
    f = np.asarray(mesh.faces)
    faces = f[~remove[f].any(axis=1)]
    kept = np.unique(faces)
    new = np.full(mesh.n_vertices, -1)
    new[kept] = np.arange(kept.size)
    return bsfjax.Mesh(np.asarray(mesh.vertices)[kept], new[faces]), kept


@pytest.fixture(scope="module")
def holed_sphere():
    v, f = icosphere(3)
    remove = (v[:, 2] > 0.8) | (v[:, 0] > 0.85) | (v[:, 1] < -0.9)  # three caps
    return _cut(bsfjax.Mesh(v, f), remove)


def _directed_edges(faces):
    return np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])


def test_boundary_loops_follow_the_boundary_edges(holed_sphere):
    mesh, _ = holed_sphere
    loops = bsfjax.boundary_loops(mesh)
    assert len(loops) == 3
    he = {tuple(e) for e in _directed_edges(np.asarray(mesh.faces)).tolist()}
    undirected = np.sort(_directed_edges(np.asarray(mesh.faces)), axis=1)
    _, count = np.unique(undirected, axis=0, return_counts=True)
    n_boundary = int(np.sum(count == 1))
    assert sum(len(lp) for lp in loops) == n_boundary  # every boundary edge in one loop
    for lp in loops:  # each step a → b is an edge of a triangle, the reverse of none
        for a, b in zip(lp, np.roll(lp, -1)):
            assert (a, b) in he and (b, a) not in he
    assert bsfjax.boundary_loops(bsfjax.Mesh(*icosphere(1))) == []


def test_fill_closes_the_holes_and_keeps_the_original_vertices(holed_sphere):
    mesh, _ = holed_sphere
    fill = bsfjax.fill_holes(mesh)
    out = fill.mesh
    n, m = mesh.n_vertices, mesh.n_faces
    assert fill.n_added > 0 and len(fill.loops) == 3
    np.testing.assert_array_equal(out.vertices[:n], mesh.vertices)  # unchanged and first
    np.testing.assert_array_equal(out.faces[:m], mesh.faces)
    assert bsfjax.boundary_loops(out) == []
    # a closed, consistently oriented 2-manifold: every directed edge once, its reverse once
    he = _directed_edges(np.asarray(out.faces))
    assert np.unique(he, axis=0).shape[0] == he.shape[0]
    assert {tuple(e) for e in he.tolist()} == {tuple(e) for e in he[:, ::-1].tolist()}
    n_edges = he.shape[0] // 2
    assert out.n_vertices - n_edges + out.n_faces == 2  # a sphere again
    # the patches continue the sphere: close to its area, points near radius 1
    assert abs(out.area - 4 * np.pi) / (4 * np.pi) < 0.03
    r = np.linalg.norm(out.vertices[n:], axis=1)
    assert r.min() > 0.85 and r.max() < 1.02
    assert np.all(out.face_areas() > 0)


def test_fill_positions_are_the_thin_plate_solution(holed_sphere):
    """The added vertices solve (L² x)_U = 0 for the uniform graph Laplacian of the filled
    mesh (dense float64 numpy), the original vertices fixed."""
    mesh, _ = holed_sphere
    out = bsfjax.fill_holes(mesh).mesh
    n = out.n_vertices
    e = _directed_edges(np.asarray(out.faces))
    adj = np.zeros((n, n))
    adj[e[:, 0], e[:, 1]] = adj[e[:, 1], e[:, 0]] = 1.0
    lap = np.diag(adj.sum(axis=1)) - adj
    residual = (lap @ lap @ np.asarray(out.vertices))[mesh.n_vertices:]
    assert np.abs(residual).max() < 1e-9


def test_extend_restrict_and_the_size_bound(holed_sphere):
    mesh, _ = holed_sphere
    fill = bsfjax.fill_holes(mesh)
    vals = np.arange(mesh.n_vertices) * 2
    ext = fill.extend(vals)
    assert ext.shape == (fill.mesh.n_vertices,)
    np.testing.assert_array_equal(fill.restrict(ext), vals)
    # an added vertex takes the value of the nearest vertex of its loop
    loop_vertices = np.concatenate(fill.loops)
    assert np.isin(fill.nearest, loop_vertices).all()
    d_own = np.linalg.norm(fill.mesh.vertices[mesh.n_vertices:] - mesh.vertices[fill.nearest],
                           axis=1)
    d_any = np.linalg.norm(fill.mesh.vertices[mesh.n_vertices:, None]
                           - mesh.vertices[loop_vertices][None], axis=2).min(axis=1)
    assert np.all(d_own <= d_any + 0.3)  # its own loop's nearest (loops are far apart)
    faces = fill.extend(np.arange(mesh.n_faces), faces=True)
    assert faces.shape == (fill.mesh.n_faces,)
    small = bsfjax.fill_holes(mesh, max_share=0.1)  # π ρ²: 14 %, 12 %, 9 % of the area
    assert len(small.loops) == 1 and len(small.loops[0]) == len(fill.loops[-1])
    with pytest.raises(bsfjax.MeshError, match="one row per original vertex"):
        fill.extend(vals[:-1])


def test_prepare_scan_fills_and_to_whole_gives_the_file_rows(holed_sphere):
    mesh, _ = holed_sphere
    prep = bsfjax.prepare_scan(mesh)
    assert prep.n_added > 0 and prep.body.n_vertices == mesh.n_vertices
    labels = np.arange(prep.mesh.n_vertices)
    np.testing.assert_array_equal(prep.to_whole(labels), np.arange(mesh.n_vertices))
    np.testing.assert_array_equal(prep.to_whole(labels[:mesh.n_vertices]),
                                  np.arange(mesh.n_vertices))
    assert prep.to_whole(np.arange(prep.mesh.n_faces), faces=True).shape == (mesh.n_faces,)
    assert bsfjax.prepare_scan(mesh, fill_holes=False).mesh is not prep.mesh
    assert bsfjax.prepare_scan(mesh, fill_holes=False).n_added == 0
    cloud = bsfjax.PointCloud(np.asarray(mesh.vertices))
    assert bsfjax.prepare_scan(cloud).n_added == 0  # a point cloud has no boundary


def test_missing_labels_against_a_direct_count():
    rng = np.random.default_rng(0)
    src = rng.integers(0, 5, 400)
    area_m = rng.uniform(0.5, 1.5, 400)
    tgt = src[:300].copy()
    tgt[tgt == 3] = 0  # part 3 gone, part 4 thinned to a quarter below
    four = np.flatnonzero(tgt == 4)
    tgt[four[: int(0.85 * four.size)]] = 1
    area_n = rng.uniform(0.5, 1.5, 300)
    got = bsfjax.missing_labels(src, area_m, tgt, area_n)
    share_m = np.array([area_m[src == i].sum() for i in range(5)]) / area_m.sum()
    share_n = np.array([area_n[tgt == i].sum() for i in range(5)]) / area_n.sum()
    np.testing.assert_array_equal(got, np.flatnonzero(share_n < 0.25 * share_m))
    assert 3 in got and 4 in got and 0 not in got
    with pytest.raises(bsfjax.BSFError, match="matching 1-D arrays"):
        bsfjax.missing_labels(src, area_m[:-1], tgt, area_n)


@pytest.fixture(scope="module")
def partial_files(tmp_path_factory):
    """The example pair with the target's left arm cut off and two holes: files, the kept
    vertices and the point map (the truth)."""
    d = tmp_path_factory.mktemp("holes")
    pair = bsfjax.example_pair(levels=2)
    arm = pair.label_names.index("left_arm")
    v = np.asarray(pair.target.vertices)
    remove = pair.labels == arm
    for c in (100, 1500):  # two holes of radius 0.05 on the body
        remove |= np.linalg.norm(v - v[c], axis=1) < 0.05
    target, kept = _cut(pair.target, remove)
    bsfjax.save_mesh(d / "src.ply", pair.source)
    bsfjax.save_mesh(d / "tgt.off", target)
    np.savetxt(d / "labels.txt", pair.labels, fmt="%d")
    np.save(d / "p2p.npy", kept)
    (d / "labels.json").write_text(json.dumps(
        {name: np.flatnonzero(pair.labels == i).tolist()
         for i, name in enumerate(pair.label_names)}))
    return d, pair, target, kept, arm


def test_transfer_to_a_partial_target_keeps_the_file_rows(partial_files, tmp_path, capsys):
    d, pair, target, kept, arm = partial_files
    assert len(bsfjax.boundary_loops(target)) == 3
    truth = pair.labels[kept]
    np.savetxt(tmp_path / "truth.txt", truth, fmt="%d")
    out, ply = tmp_path / "out.txt", tmp_path / "out.ply"
    base = ["transfer", str(d / "src.ply"), str(d / "tgt.off"), "--map", "p2p",
            str(d / "p2p.npy"), "-k", "20", "--method", "p2p"]
    assert main([*base, "--labels", str(d / "labels.txt"), "--out", str(out), "--mesh-out",
                 str(ply), "--truth", str(tmp_path / "truth.txt")]) == 0
    err = capsys.readouterr().err
    got = np.loadtxt(out, dtype=int)
    assert got.shape == (target.n_vertices,)  # one row per file row: patches dropped
    np.testing.assert_array_equal(got, truth)  # the given map's pull-back
    assert "3 holes closed for the spectrum" in err
    assert "accuracy against" in err and "100.0% of the target area" in err
    assert f"no counterpart on the target (under 25% of their source share of the area): {arm}" \
        in err
    import meshio

    m = meshio.read(ply)
    assert m.points.shape[0] == target.n_vertices
    np.testing.assert_array_equal(m.point_data["label"], got)
    # part names from a .json labels file; per-triangle labels (.seg) keep the file's triangles
    assert main([*base, "--labels", str(d / "labels.json"), "--out", str(tmp_path / "o.json")]) == 0
    assert "area): left_arm" in capsys.readouterr().err
    seg = bsfjax.face_labels_from_vertices(pair.source, pair.labels)
    np.savetxt(tmp_path / "parts.seg", seg, fmt="%d")
    assert main([*base, "--labels", str(tmp_path / "parts.seg"), "--out",
                 str(tmp_path / "o.seg")]) == 0
    assert np.loadtxt(tmp_path / "o.seg", dtype=int).shape == (target.n_faces,)
    assert f"area): {arm}\n" in capsys.readouterr().err  # (no names: the label number)


def test_python_results_name_the_missing_part(partial_files):
    d, pair, target, kept, arm = partial_files
    prep = bsfjax.prepare_scan(target)
    sm, sn = bsfjax.spectrum(pair.source, 20), bsfjax.spectrum(prep.mesh, 20)
    res = bsfjax.transfer_labels(sm, sn, pair.labels, method="p2p",
                                 p2p=prep.extend(kept))
    assert res.missing == (arm,)
    np.testing.assert_array_equal(prep.to_whole(res.labels), pair.labels[kept])


def test_collection_of_partial_targets_reports_and_keeps_the_file_rows(partial_files,
                                                                       tmp_path, capsys):
    """``--out-dir`` (transfer_collection): the filled target's patches are dropped from every
    output and ``summary.json`` names the missing part.  With landmarks too, the target that
    misses a part has its map estimated again (phases 3 and 4 after the landmarks' map), with
    the labels of the one-target command."""
    d, pair, target, kept, arm = partial_files
    targets = tmp_path / "targets"
    targets.mkdir()
    bsfjax.save_mesh(targets / "partial.off", target)
    rows = [0, 400, 800, 1200, 1600]  # landmarks: target rows and their source vertices
    (tmp_path / "lm.json").write_text(json.dumps(
        {"partial": [[int(kept[r]) for r in rows], rows]}))
    out = tmp_path / "out"
    assert main(["transfer", str(d / "src.ply"), str(targets / "partial.off"), "--labels",
                 str(d / "labels.json"), "--landmarks-file", str(tmp_path / "lm.json"),
                 "--out-dir", str(out), "--no-progress", "-k", "20"]) == 0
    summary = json.loads((out / "summary.json").read_text())["targets"][0]
    assert summary["missing_parts"] == ["left_arm"]
    assert summary["filled_vertices"] > 0
    assert summary["estimated_again"] is True
    labels, names = bsfjax.load_labels(out / "partial.json")
    assert labels.shape == (target.n_vertices,)  # one row per file row
    ours = np.asarray([pair.label_names.index(n) for n in names])[labels]
    assert np.mean(ours == pair.labels[kept]) > 0.8
    capsys.readouterr()
    one = tmp_path / "one.json"
    assert main(["transfer", str(d / "src.ply"), str(targets / "partial.off"), "--labels",
                 str(d / "labels.json"), "--landmarks",
                 f"{','.join(str(int(kept[r])) for r in rows)}:{','.join(map(str, rows))}",
                 "--out", str(one), "-k", "20"]) == 0
    assert cli_transfer.PARTIAL_AGAIN_LANDMARKS in capsys.readouterr().err
    labels_one, names_one = bsfjax.load_labels(one)
    assert names_one == names
    np.testing.assert_array_equal(labels_one, labels)
