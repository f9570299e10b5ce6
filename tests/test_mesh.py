"""Mesh container, reading and atomic writing."""

from __future__ import annotations

import os
import re
import warnings

import numpy as np
import pytest

import bsfjax
from bsfjax import Mesh, MeshError, load_mesh, save_mesh

from .conftest import data_path, icosphere


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


TET = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"


def test_load_real_off():
    m = load_mesh(data_path("faust", "tr_reg_000.off"))
    assert (m.n_vertices, m.n_faces) == (6890, 13776)
    assert m.vertices.dtype == np.float64 and m.faces.dtype == np.int64
    assert 1.5 < m.area < 2.1  # a human body in metres


def test_mesh_is_immutable(sphere_mesh):
    with pytest.raises(ValueError):
        sphere_mesh.vertices[0, 0] = 1.0
    with pytest.raises(AttributeError):
        sphere_mesh.vertices = np.zeros((3, 3))


def test_mesh_copies_input():
    v, f = icosphere(1)
    m = Mesh(v, f)
    v[0] = 99.0
    assert not np.any(m.vertices == 99.0)


@pytest.mark.parametrize("ext", [".off", ".ply", ".obj", ".stl"])
def test_roundtrip_formats(tmp_path, sphere_mesh, ext):
    p = tmp_path / f"s{ext}"
    save_mesh(p, sphere_mesh)
    back = load_mesh(p)
    assert back.n_faces == sphere_mesh.n_faces
    # STL stores float32 and duplicates vertices per face; meshio merges them back
    assert back.n_vertices == sphere_mesh.n_vertices
    np.testing.assert_allclose(np.sort(back.vertices, axis=0), np.sort(sphere_mesh.vertices, axis=0),
                               atol=1e-6)
    assert abs(back.area - sphere_mesh.area) < 1e-5 * sphere_mesh.area


def test_polygons_are_triangulated(tmp_path):
    cube = ("OFF\n8 6 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n"
            "4 0 3 2 1\n4 4 5 6 7\n4 0 1 5 4\n4 1 2 6 5\n4 2 3 7 6\n4 3 0 4 7\n")
    m = load_mesh(_write(tmp_path, "cube.off", cube))
    assert m.n_faces == 12
    assert m.area == pytest.approx(6.0)
    obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\nf 1 2 3 5 4\n"
    m = load_mesh(_write(tmp_path, "penta.obj", obj))
    assert m.n_faces == 3
    assert m.area == pytest.approx(1.25)


def test_unreferenced_vertices_warn_and_map(tmp_path):
    text = "OFF\n6 4 0\n0 0 0\n1 0 0\n9 9 9\n0 1 0\n0 0 1\n8 8 8\n3 0 3 1\n3 0 1 4\n3 0 4 3\n3 1 3 4\n"
    with pytest.warns(UserWarning, match="removed 2 unreferenced vertices"):
        m = load_mesh(_write(tmp_path, "u.off", text))
    assert m.n_vertices == 4
    np.testing.assert_array_equal(m.vertex_ids, [0, 1, 3, 4])
    assert not np.any(m.vertices == 9.0)


def test_zero_area_faces_warn(tmp_path):
    text = TET.replace("4 4 0", "5 6 0").replace("0 0 1\n", "0 0 1\n2 0 0\n", 1)
    text += "3 0 1 4\n3 0 0 2\n"  # collinear (0,0,0),(1,0,0),(2,0,0) and a repeated index
    with pytest.warns(UserWarning) as rec:
        m = load_mesh(_write(tmp_path, "z.off", text))
    msgs = " ".join(str(r.message) for r in rec)
    assert "removed 2 zero-area faces" in msgs and "removed 1 unreferenced" in msgs
    assert m.n_faces == 4 and m.n_vertices == 4


def test_clean_mesh_loads_without_warning(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = load_mesh(_write(tmp_path, "tet.off", TET))
    assert m.n_faces == 4


@pytest.mark.parametrize(
    "name,text,match",
    [
        ("nan.off", TET.replace("1 0 0\n", "nan 0 0\n", 1), "NaN or infinite"),
        ("inf.off", TET.replace("0 1 0\n", "0 inf 0\n", 1), "NaN or infinite"),
        ("range.off", TET.replace("3 1 2 3", "3 1 2 7"), "out of range|cannot read"),
        ("empty.off", "OFF\n0 0 0\n", "empty|no faces|cannot read"),
        ("garbage.off", "this is not a mesh at all\n\x00\x01", "cannot read"),
        ("truncated.ply", "ply\nformat ascii 1.0\nelement vertex 3\n", "cannot read"),
        ("mesh.unknownext", TET, "cannot read"),
    ],
)
def test_bad_files_raise_mesh_error(tmp_path, name, text, match):
    p = _write(tmp_path, name, text)
    with pytest.raises(MeshError, match=match) as info:
        load_mesh(p)
    assert str(p) in str(info.value)  # the message names the file
    assert isinstance(info.value, ValueError)


def _strict_off(path):
    """The line-by-line reader alone (the fast path switched off)."""
    from unittest import mock

    import bsfjax._mesh._readers as _readers
    with mock.patch.object(_readers, "_read_plain_off", lambda raw: None):
        return _readers._read_off(path)


def _plain_off(v, f, newline="\n", fmt=repr):
    rows = ["OFF", f"{len(v)} {len(f)} 0"] + [" ".join(fmt(float(x)) for x in r) for r in v]
    return newline.join(rows + [f"3 {a} {b} {c}" for a, b, c in f]) + newline


@pytest.mark.parametrize("newline,fmt", [("\n", repr), ("\r\n", lambda x: f"{x:.6e}"),
                                         ("\n", lambda x: f"  {x:g}\t")])
def test_plain_off_fast_path_equals_strict_reader(tmp_path, newline, fmt):
    from bsfjax._mesh._readers import _read_off, _read_plain_off

    v, f = icosphere(2)
    v = v * np.random.default_rng(0).uniform(0.5, 2.0, v.shape)  # digits in every coordinate
    p = tmp_path / "plain.off"
    p.write_bytes(_plain_off(v, f, newline, fmt).encode())
    assert _read_plain_off(p.read_bytes()) is not None  # the fast path took it
    fast, strict = _read_off(p), _strict_off(p)
    assert fast[1].dtype == strict[1].dtype == np.int64
    np.testing.assert_array_equal(fast[0], strict[0])
    np.testing.assert_array_equal(fast[1], strict[1])


@pytest.mark.parametrize("edit", [
    lambda t: t.replace("OFF\n", "OFF # comment\n", 1),
    lambda t: t.replace("OFF\n4 4 0\n", "OFF 4 4 0\n", 1),
    lambda t: t.replace("OFF", "COFF", 1),
    lambda t: t.replace("\n", "\r"),
    lambda t: t.replace("3 1 2 3", "4 1 2 3 0"),
    lambda t: t.replace("0 0 0\n1 0 0\n", "0 0 0 1\n0 0\n", 1),  # 3 + 3 tokens, wrong rows
    lambda t: t.replace("3 0 2 1", "3 0 2 1.5"),
])
def test_other_off_layouts_take_the_strict_reader(tmp_path, edit):
    from bsfjax._mesh._readers import _read_plain_off

    text = edit(TET)
    assert _read_plain_off(text.encode()) is None
    p = _write(tmp_path, "odd.off", text)
    try:
        expected = _strict_off(p)
    except MeshError as exc:
        with pytest.raises(MeshError, match=re.escape(str(exc).split(": ", 1)[1][:30])):
            load_mesh(p)
    else:
        got = load_mesh(p)  # every layout here keeps all its vertices
        np.testing.assert_array_equal(got.vertices, expected[0])
        np.testing.assert_array_equal(got.faces, expected[1])


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(MeshError, match="no such file") as info:
        load_mesh(tmp_path / "nope.off")
    assert "nope.off" in str(info.value)
    with pytest.raises(MeshError, match="directory"):
        load_mesh(tmp_path)


@pytest.mark.parametrize(
    "v,f,match",
    [
        (np.zeros((0, 3)), np.zeros((0, 3), int), "empty"),
        (np.zeros((4, 2)), np.zeros((1, 3), int), r"shape \(n, 3\)"),
        (np.eye(3), np.array([[0, 1]]), r"shape \(m, 3\)"),
        (np.eye(3), np.array([[0, 1, -1]]), "out of range"),
        (np.eye(3), np.array([[0.5, 1, 2]]), "integer"),
        (np.eye(3), np.zeros((0, 3), int), "no faces"),
    ],
)
def test_mesh_constructor_validates(v, f, match):
    with pytest.raises(MeshError, match=match):
        Mesh(v, f)


def test_save_point_data_and_atomicity(tmp_path, sphere_mesh):
    p = tmp_path / "out.ply"
    labels = np.arange(sphere_mesh.n_vertices) % 5
    err = np.linspace(0, 1, sphere_mesh.n_vertices)
    save_mesh(p, sphere_mesh, point_data={"label": labels, "error": err})
    import meshio

    back = meshio.read(p)
    np.testing.assert_array_equal(back.point_data["label"], labels)
    np.testing.assert_allclose(back.point_data["error"], err)
    assert [q.name for q in tmp_path.iterdir()] == ["out.ply"]  # no temp file left behind
    before = p.read_bytes()
    with pytest.raises(MeshError, match="point_data"):
        save_mesh(p, sphere_mesh, point_data={"bad": np.zeros(3)})
    assert p.read_bytes() == before  # the old file survives a failed write
    with pytest.raises((MeshError, ValueError)):
        save_mesh(tmp_path / "x.notaformat", sphere_mesh)
    assert sorted(q.name for q in tmp_path.iterdir()) == ["out.ply"]


def test_save_triangle_data_to_ply(tmp_path, sphere_mesh):
    """Per-triangle arrays (a segmentation of the triangles and its colours) go to PLY face
    properties that meshio and load_mesh read back; other formats and wrong lengths are named
    errors that leave nothing behind."""
    p = tmp_path / "faces.ply"
    m = sphere_mesh.n_faces
    label = np.arange(m) % 7
    rgb = np.stack([label * 30, 255 - label * 30, np.full(m, 9)], axis=1).astype(np.uint8)
    err = np.linspace(0, 1, sphere_mesh.n_vertices)
    save_mesh(p, sphere_mesh, point_data={"error": err},
              cell_data={"label": label, "red": rgb[:, 0], "green": rgb[:, 1], "blue": rgb[:, 2],
                         "normal": np.ones((m, 3))})
    import meshio

    back = meshio.read(p)
    np.testing.assert_array_equal(back.cells[0].data, sphere_mesh.faces)
    np.testing.assert_array_equal(back.points, sphere_mesh.vertices)  # exact: 17 digits
    np.testing.assert_array_equal(back.point_data["error"], err)
    np.testing.assert_array_equal(back.cell_data["label"][0], label)
    np.testing.assert_array_equal(back.cell_data["green"][0], rgb[:, 1])
    np.testing.assert_array_equal(back.cell_data["normal_2"][0], np.ones(m))
    assert back.cell_data["red"][0].dtype == np.uint8
    assert load_mesh(p).n_faces == m
    with pytest.raises(MeshError, match=r"cell_data\['label'\] has 3 rows, mesh has \d+ triangles"):
        save_mesh(tmp_path / "short.ply", sphere_mesh, cell_data={"label": label[:3]})
    with pytest.raises(MeshError, match=".ply files only"):
        save_mesh(tmp_path / "faces.off", sphere_mesh, cell_data={"label": label})
    with pytest.raises(MeshError, match="no property type"):
        save_mesh(tmp_path / "c.ply", sphere_mesh, cell_data={"z": label.astype(complex)})
    assert sorted(q.name for q in tmp_path.iterdir()) == ["faces.ply"]


def test_public_names():
    for name in ["Mesh", "MeshError", "load_mesh", "save_mesh", "laplacian", "Spectrum", "spectrum",
                 "spectrum_from_operators", "interval_spectrum"]:
        assert hasattr(bsfjax, name), name
    assert issubclass(bsfjax.MeshError, ValueError)
    assert os.path.basename(bsfjax.__file__) == "__init__.py"
