"""Large scans without landmarks: the landmark-free map chosen on decimated proxies and carried
back to the whole meshes (`MapEstimator.proxy_above`, `bsfjax.decimate`), issue "Real scans".
The thresholds are lowered so that small meshes take the large-mesh path."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import bsfjax
from bsfjax.cli import main
from bsfjax.internal import subdivide, vertex_areas

#: The estimator of these tests: few starts, a map of 20 → 40 eigenpairs.
FIELDS = dict(k=20, refine_to=40, starts=((10, 3.5), (20, 7.0), (30, 14.0)))


@pytest.fixture(scope="module")
def fine_pair():
    """The example pair (levels 1, 506 vertices) with its target Loop-subdivided once (2018
    vertices; vertex ``i < 506`` is the original vertex ``i``), the truth of every target
    vertex (the part of the nearest original vertex) and spectra of 40 eigenpairs."""
    from scipy.spatial import cKDTree

    pair = bsfjax.example_pair(levels=1)
    target = subdivide(pair.target, "loop", 1)
    near = cKDTree(np.asarray(pair.target.vertices)).query(np.asarray(target.vertices))[1]
    return (pair.source, target, pair.labels, pair.labels[near],
            bsfjax.spectrum(pair.source, 40), bsfjax.spectrum(target, 40))


def _accuracy(labels, p2p, truth, mesh) -> float:
    area = vertex_areas(mesh)
    return float(np.sum(area * (labels[p2p] == truth)) / area.sum())


def test_decimate_keeps_the_shape_and_matches_nearest_vertices():
    """About the asked number of vertices, one component, the area within 2 %, and the two
    correspondences are the nearest vertices (brute force in float64)."""
    mesh = bsfjax.example_mesh("source", levels=3)  # 8066 vertices
    dec = bsfjax.decimate(mesh, 1000)
    proxy = dec.mesh
    assert abs(proxy.n_vertices - 1000) <= 100
    assert bsfjax.split_main_body(proxy).n_other_components == 0
    assert proxy.area == pytest.approx(mesh.area, rel=0.02)
    v, pv = np.asarray(mesh.vertices, np.float64), np.asarray(proxy.vertices, np.float64)
    rows = np.random.default_rng(0).choice(mesh.n_vertices, 300, replace=False)
    d_to = np.linalg.norm(v[rows, None] - pv[None], axis=2)
    np.testing.assert_allclose(d_to[np.arange(rows.size), dec.to_proxy[rows]], d_to.min(1))
    d_from = np.linalg.norm(pv[:, None] - v[None], axis=2)
    np.testing.assert_allclose(d_from[np.arange(pv.shape[0]), dec.from_proxy], d_from.min(1))
    same = bsfjax.decimate(mesh, mesh.n_vertices)  # no larger than asked: itself
    np.testing.assert_array_equal(same.mesh.faces, mesh.faces)
    np.testing.assert_array_equal(same.to_proxy, np.arange(mesh.n_vertices))


def test_decimate_refuses_what_it_cannot_decimate():
    mesh = bsfjax.example_mesh("source", levels=1)
    with pytest.raises(bsfjax.BSFError, match="n_vertices"):
        bsfjax.decimate(mesh, 2)
    with pytest.raises(bsfjax.BSFError, match="point cloud"):
        bsfjax.decimate(bsfjax.PointCloud(mesh.vertices), 100)
    with pytest.raises(bsfjax.BSFError, match="proxy_above"):
        bsfjax.MapEstimator(proxy_above=-1)


def test_proxy_path_is_close_to_the_direct_map(fine_pair):
    """Above ``proxy_above`` the choice runs on proxies: their sizes are reported, the start
    is the one chosen on them, and the carried map labels the target about as well as the
    direct choice on the whole meshes (both right on > 90 % of the area).  Below the threshold
    the result is the direct one, bit for bit."""
    source, target, labels, truth, sm, sn = fine_pair
    meshes = dict(source_mesh=source, target_mesh=target)
    quick = dict(derived_landmarks=0, turn_check=False, **FIELDS)
    direct = bsfjax.MapEstimator(proxy_above=None, **quick)(sm, sn, **meshes)
    proxied = bsfjax.MapEstimator(proxy_above=1000, proxy_vertices=500, **quick)(
        sm, sn, **meshes)
    assert direct.proxy is None
    assert proxied.proxy[0] == source.n_vertices  # (below the threshold: its own proxy)
    assert abs(proxied.proxy[1] - 500) <= 50
    assert proxied.p2p.shape == (target.n_vertices,) and proxied.C.shape == (20, 20)
    a_direct = _accuracy(labels, direct.p2p, truth, target)
    a_proxy = _accuracy(labels, proxied.p2p, truth, target)
    assert a_direct > 0.9 and a_proxy > 0.9 and a_proxy > a_direct - 0.03
    below = bsfjax.MapEstimator(proxy_above=target.n_vertices, **quick)(sm, sn, **meshes)
    np.testing.assert_array_equal(below.p2p, direct.p2p)
    assert below.proxy is None


def test_the_command_runs_a_large_scan_through_the_proxy(fine_pair, tmp_path, monkeypatch,
                                                         capsys):
    """``bsfjax transfer`` without landmarks on a target above the (lowered) threshold with
    unreferenced vertices and shuffled rows: one output row per file row, ``-1`` on the
    unreferenced ones, the labels right on > 90 % of the area, and a line names the
    proxies."""
    import bsfjax._cli._transfer as cli_transfer

    source, target, labels, truth, _, _ = fine_pair
    plain = cli_transfer.map_estimator
    monkeypatch.setattr(cli_transfer, "map_estimator", lambda *a, **kw: dataclasses.replace(
        plain(*a, **kw), proxy_above=1000, proxy_vertices=500, starts=FIELDS["starts"],
        derived_landmarks=0, turn_check=False))
    rng = np.random.default_rng(1)
    v = np.concatenate([np.asarray(target.vertices), rng.random((3, 3))])  # 3 unreferenced
    order = rng.permutation(len(v))
    rank = np.argsort(order)
    f = rank[np.asarray(target.faces)]
    path = tmp_path / "scan.off"
    with open(path, "w") as fh:
        fh.write(f"OFF\n{len(v)} {len(f)} 0\n")
        np.savetxt(fh, v[order], fmt="%.8f")
        np.savetxt(fh, np.column_stack([np.full(len(f), 3), f]), fmt="%d")
    bsfjax.save_mesh(tmp_path / "source.off", source)
    np.savetxt(tmp_path / "labels.txt", labels, fmt="%d")
    out = tmp_path / "out.txt"
    with pytest.warns(UserWarning):
        assert main(["transfer", str(tmp_path / "source.off"), str(path), "--labels",
                     str(tmp_path / "labels.txt"), "--out", str(out), "-k", "20"]) == 0
    got = np.loadtxt(out, dtype=np.int64)
    assert got.shape == (len(v),)
    file_truth = np.concatenate([truth, [-1, -1, -1]])[order]
    assert np.all(got[file_truth == -1] == -1)
    area = np.concatenate([vertex_areas(target), np.zeros(3)])[order]
    assert np.sum(area * (got == file_truth)) / area.sum() > 0.9
    assert "proxies of" in capsys.readouterr().err
