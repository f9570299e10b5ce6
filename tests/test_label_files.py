"""Segmentation files (``_label_files.py``): SMPL's ``.json`` and one label per vertex."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bsfjax import BSFError, load_labels, save_labels
from bsfjax.internal import is_face_file

from .conftest import data_path


def test_json_first_name_wins_and_every_vertex_is_listed(tmp_path):
    f = tmp_path / "parts.json"
    f.write_text(json.dumps({"b": [0, 1, 2], "a": [2, 3], "c": [4]}))
    lab, names = load_labels(f)
    assert names == ("a", "b", "c")
    np.testing.assert_array_equal(lab, [1, 1, 0, 0, 2])  # vertex 2 in a and b: "a"
    f.write_text(json.dumps({"a": [0, 2]}))
    with pytest.raises(BSFError, match="1 vertices are in no part"):
        load_labels(f)
    g = tmp_path / "labels.txt"
    np.savetxt(g, [0, 2, 1])
    lab, names = load_labels(g)
    np.testing.assert_array_equal(lab, [0, 2, 1])
    assert names is None  # integer labels are their own names
    np.savetxt(g, [0, 10**12])
    np.testing.assert_array_equal(load_labels(g).labels, [0, 10**12])  # no allocation by id


@pytest.mark.parametrize("suffix", [".json", ".txt", ".npy", ".seg"])
def test_save_then_load_round_trip(tmp_path, suffix):
    lab = np.random.default_rng(0).integers(0, 5, 300)
    lab[7] = 6  # label 5 has no vertex: its name is written all the same (.json)
    names = ("head", "arm", "leg", "torso", "hand", "foot", "neck")
    path = tmp_path / f"out{suffix}"
    save_labels(path, lab, names)
    got, got_names = load_labels(path)
    if suffix == ".json":  # names in sorted order: map them back
        parts = json.loads(path.read_text())
        assert parts["foot"] == [] and sorted(parts) == sorted(names)
        np.testing.assert_array_equal(np.asarray(got_names)[got], np.asarray(names)[lab])
    else:
        np.testing.assert_array_equal(got, lab)
    assert is_face_file(path) == (suffix == ".seg")  # one label per triangle, by the suffix


def test_unassigned_vertices_are_listed_apart(tmp_path):
    path = tmp_path / "t.json"
    save_labels(path, np.array([0, -1, 1, -1]), ("a", "b"))
    assert json.loads(path.read_text()) == {"a": [0], "b": [2], "unassigned": [1, 3]}


def test_bad_files_and_arguments_are_named(tmp_path):
    with pytest.raises(BSFError, match="no such file"):
        load_labels(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2]")
    with pytest.raises(BSFError, match=r"expected \{part name: \[vertex indices\]\}"):
        load_labels(bad)
    bad.write_text(json.dumps({"a": [-1, 0]}))
    with pytest.raises(BSFError, match="negative vertex indices"):
        load_labels(bad)
    txt = tmp_path / "bad.txt"
    txt.write_text("0\n1.5\n")
    with pytest.raises(BSFError, match=r"one non-negative integer label per vertex, found 1.5 "
                                       r"\(entry 1\)"):
        load_labels(txt)
    txt.write_text("0\n-2\n")
    with pytest.raises(BSFError, match=r"found -2.0 \(entry 1\)"):
        load_labels(txt)
    txt.write_text("")
    with pytest.raises(BSFError, match="per vertex, got no data"):
        load_labels(txt)
    txt.write_text("0\n1.5\n")
    txt.rename(seg := tmp_path / "bad.seg")
    with pytest.raises(BSFError, match="one non-negative integer label per triangle"):
        load_labels(seg)
    with pytest.raises(BSFError, match="use a .json, .txt, .npy or .seg"):
        save_labels(tmp_path / "x.csv", np.zeros(3, int))
    with pytest.raises(BSFError, match="3 or more distinct part names"):
        save_labels(tmp_path / "x.json", np.array([0, 1, 2]), ("a", "b"))
    save_labels(tmp_path / "x.json", np.array([0, 1]), ("a", "unassigned"))  # no -1: a name
    with pytest.raises(BSFError, match="a part is named 'unassigned'"):
        save_labels(tmp_path / "x.json", np.array([0, -1]), ("a", "unassigned"))
    with pytest.raises(BSFError, match="integers >= -1"):
        save_labels(tmp_path / "x.json", np.array([0.5, 1.0]))
    existing = tmp_path / "keep.json"
    existing.write_text("{}")
    with pytest.raises(BSFError):
        save_labels(existing, np.array([0, -2]))
    assert existing.read_text() == "{}"  # a refused write leaves the file as it was


def test_smpl_segmentation_of_the_data():
    seg = data_path("segmentations", "smpl_vert_segmentation.json")
    lab, names = load_labels(seg)
    assert lab.shape == (6890,) and len(names) == 24 and "hips" in names
    assert np.bincount(lab).min() > 0
    parts = json.loads(seg.read_text())
    for i, name in enumerate(names):  # each vertex labelled with a part that lists it
        assert set(np.flatnonzero(lab == i)) <= set(parts[name])
