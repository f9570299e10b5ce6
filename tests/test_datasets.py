"""--data folders: the accepted layouts, ground truth, and clear errors for bad folders."""

from __future__ import annotations

import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError
from bsfjax.experiments import load_dataset

from .conftest import data_path, icosphere


def _save(path, subdiv=1, seed=0):
    v, f = icosphere(subdiv)
    v = v * (1 + 0.05 * np.random.default_rng(seed).uniform(size=(len(v), 1)))
    bsfjax.save_mesh(path, bsfjax.Mesh(v, f))
    return len(v)


def test_faust_shared_vertex_order_is_identity():
    ds = load_dataset(data_path("faust"))
    assert len(ds.shapes) == 9 and list(ds.groups) == ["faust"]
    assert all(s.vts is None for s in ds.shapes)
    pairs = ds.pairs(3, seed=0)
    assert pairs == ds.pairs(3, seed=0) and len(set(pairs)) == 3
    assert pairs != ds.pairs(3, seed=1)
    np.testing.assert_array_equal(ds.ground_truth(*pairs[0]), np.arange(6890))
    assert len(ds.all_pairs()) == 36
    with pytest.raises(BSFError, match="asked for 40 pairs"):
        ds.pairs(40)


def test_faust_5k_vts_ground_truth():
    ds = load_dataset(data_path("faust_5k"))
    names = [s.name for s in ds.shapes]
    assert names == ["tr_reg_000", "tr_reg_001", "tr_reg_010", "tr_reg_011"]
    a, b = ds.shapes[0], ds.shapes[1]
    assert a.vts.shape == b.vts.shape == (5000,)
    gt = ds.ground_truth(0, 1)
    assert gt.shape == (b.n_vertices,) and gt.min() >= 0 and gt.max() < a.n_vertices
    # every target vertex listed exactly once gets exactly its listed partner
    uniq, counts = np.unique(b.vts, return_counts=True)
    once = np.isin(b.vts, uniq[counts == 1])
    np.testing.assert_array_equal(gt[b.vts[once]], a.vts[once])
    # the partner is geometrically close (both shapes are near-isometric bodies, same scale)
    scale = np.sqrt(a.mesh.area)
    d = np.linalg.norm(a.mesh.vertices[gt] - b.mesh.vertices, axis=1) / scale
    assert np.median(d) < 0.2


def test_tosca_classes_pair_within_class():
    ds = load_dataset(data_path("tosca_5k"))
    assert set(ds.groups) == {"cat", "wolf"}
    for i, j in ds.pairs(None):
        assert ds.shapes[i].group == ds.shapes[j].group
    first = {ds.shapes[p[0]].group for p in ds.pairs(2)}
    assert first == {"cat", "wolf"}  # classes take turns
    cat, wolf = ds.groups["cat"][0], ds.groups["wolf"][0]
    with pytest.raises(BSFError, match="different classes"):
        ds.ground_truth(cat, wolf)


def test_missing_and_empty_folders(tmp_path):
    with pytest.raises(BSFError, match="does not exist"):
        load_dataset(tmp_path / "nope")
    with pytest.raises(BSFError, match="no mesh files"):
        load_dataset(tmp_path)
    (tmp_path / "x.txt").write_text("hi")
    with pytest.raises(BSFError, match="got a file"):
        load_dataset(tmp_path / "x.txt")


def test_different_sizes_without_correspondence_names_files(tmp_path):
    _save(tmp_path / "a.off", 1)
    _save(tmp_path / "b.off", 2)
    with pytest.raises(BSFError, match=r"different sizes.*a\.off \(42 vertices\).*b\.off "
                                       r"\(162 vertices\)"):
        load_dataset(tmp_path)


def test_vts_layout_and_its_errors(tmp_path):
    na = _save(tmp_path / "a.off", 1)
    nb = _save(tmp_path / "b.off", 2)
    (tmp_path / "corres").mkdir()
    (tmp_path / "corres" / "a.vts").write_text("\n".join(map(str, range(1, 11))))
    with pytest.raises(BSFError, match=r"none for mesh b\.off: expected .*corres/b\.vts"):
        load_dataset(tmp_path)
    (tmp_path / "corres" / "b.vts").write_text("\n".join(map(str, range(11, 21))))
    ds = load_dataset(tmp_path)
    gt = ds.ground_truth(0, 1)
    assert gt.shape == (nb,)
    np.testing.assert_array_equal(gt[np.arange(10, 20)], np.arange(10))
    assert gt.max() < na
    (tmp_path / "corres" / "b.vts").write_text("1\n2\n")
    with pytest.raises(BSFError, match="same length.*a.vts: 10, b.vts: 2"):
        load_dataset(tmp_path)
    (tmp_path / "corres" / "b.vts").write_text("1\n2\nthree\n")
    with pytest.raises(BSFError, match=r"b\.vts: not a \.vts file"):
        load_dataset(tmp_path)
    (tmp_path / "corres" / "b.vts").write_text("\n".join(map(str, range(200, 210))))
    with pytest.raises(BSFError, match=r"b\.vts: indices must be in 1\.\.162"):
        load_dataset(tmp_path)
    (tmp_path / "corres" / "b.vts").write_text("\n".join(["0"] * 10))
    with pytest.raises(BSFError, match=r"b\.vts: indices must be in"):
        load_dataset(tmp_path)


def test_unreadable_mesh_names_file(tmp_path):
    _save(tmp_path / "a.off", 1)
    (tmp_path / "broken.off").write_text("OFF\n3 1 0\n0 0 0\n")
    with pytest.raises(BSFError, match=r"broken\.off"):
        load_dataset(tmp_path)


def test_single_shape_has_no_pair(tmp_path):
    _save(tmp_path / "a.off", 1)
    ds = load_dataset(tmp_path)
    with pytest.raises(BSFError, match="at least two shapes"):
        ds.pairs(1)
