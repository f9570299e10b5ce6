"""Meshes from other libraries (bsfjax.as_mesh): trimesh, pyFM, open3d's attribute layout,
(V, F) pairs.  Each gives the same arrays, bit-identical spectra and labels as the same mesh
read from a file by bsfjax.load_mesh; Mesh.to_trimesh round-trips."""

from __future__ import annotations

import numpy as np
import pytest

import bsfjax


class _Vector:
    """open3d's Vector3dVector / Vector3iVector: a sequence numpy converts (no .shape)."""

    def __init__(self, a):
        self._a = [tuple(r) for r in np.asarray(a).tolist()]

    def __len__(self):
        return len(self._a)

    def __getitem__(self, i):
        return self._a[i]

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self._a, dtype=dtype)


class O3DTriangleMesh:  # open3d.geometry.TriangleMesh's attribute layout
    def __init__(self, v, f):
        self.vertices, self.triangles = _Vector(v), _Vector(f)
        self.vertex_normals = _Vector(np.zeros((0, 3)))


class O3DPointCloud:  # open3d.geometry.PointCloud's attribute layout
    def __init__(self, p):
        self.points = _Vector(p)
        self.normals = _Vector(np.zeros((0, 3)))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The built-in example pair written to OFF files (read back by every library)."""
    pair = bsfjax.example_pair(levels=1)
    d = tmp_path_factory.mktemp("interop")
    paths = d / "source.off", d / "target.off"
    for p, m in zip(paths, (pair.source, pair.target)):  # plain OFF, as every reader takes it
        rows = [f"{x!r} {y!r} {z!r}" for x, y, z in m.vertices.tolist()]
        rows += [f"3 {a} {b} {c}" for a, b, c in m.faces.tolist()]
        p.write_text(f"OFF\n{m.n_vertices} {m.n_faces} 0\n" + "\n".join(rows) + "\n")
    return pair, paths


def _holders(path):
    """The mesh of ``path`` as each library holds it."""
    out = {}
    trimesh = pytest.importorskip("trimesh")
    tm = trimesh.load(str(path), process=False)
    out["trimesh"] = tm
    from pyFM.mesh import TriMesh

    out["pyFM"] = TriMesh.load(str(path)) if hasattr(TriMesh, "load") else TriMesh(str(path))
    out["open3d layout"] = O3DTriangleMesh(np.asarray(tm.vertices), np.asarray(tm.faces))
    out["(V, F)"] = (np.asarray(tm.vertices), np.asarray(tm.faces))
    try:
        import open3d  # noqa: F401 (large: only where installed)

        out["open3d"] = open3d.io.read_triangle_mesh(str(path))
    except ImportError:
        pass
    return out


def test_every_holder_gives_the_file_mesh_and_bit_identical_spectra(files):
    pytest.importorskip("pyFM")
    _, (path, _) = files
    ref = bsfjax.load_mesh(path)
    sref = bsfjax.spectrum(ref, 12)
    for kind, obj in _holders(path).items():
        m = bsfjax.as_mesh(obj)
        assert type(m) is bsfjax.Mesh, kind
        assert np.array_equal(m.vertices, ref.vertices) and np.array_equal(m.faces, ref.faces), kind
        s = bsfjax.spectrum(obj, 12)  # the public function takes the object itself
        for a, b in ((s.evals, sref.evals), (s.evecs, sref.evecs), (s.mass, sref.mass)):
            assert np.array_equal(np.asarray(a), np.asarray(b)), kind


def test_every_holder_gives_bit_identical_labels(files):
    pytest.importorskip("pyFM")
    pair, (spath, tpath) = files
    src, tgt = bsfjax.load_mesh(spath), bsfjax.load_mesh(tpath)
    sm, sn = bsfjax.spectrum(src, 20), bsfjax.spectrum(tgt, 20)
    C = bsfjax.fmap_from_p2p(sm, sn, pair.p2p)
    # omp samples its frame centres on the mesh (farthest points): the mesh matters here
    ref = bsfjax.transfer_labels(sm, sn, pair.labels, C=C, method="omp", mesh=src).labels
    assert (ref == pair.labels[pair.p2p]).mean() > 0.7  # a real transfer, not a constant
    for kind, obj in _holders(spath).items():
        got = bsfjax.transfer_labels(sm, sn, pair.labels, C=C, method="omp", mesh=obj).labels
        assert np.array_equal(np.asarray(got), np.asarray(ref)), kind
        fps = bsfjax.farthest_point_sampling(obj, 20, metric="geodesic")
        assert np.array_equal(fps, bsfjax.farthest_point_sampling(src, 20, metric="geodesic"))


def test_point_clouds_and_to_trimesh():
    trimesh = pytest.importorskip("trimesh")
    rng = np.random.default_rng(0)
    p = rng.normal(size=(50, 3))
    for obj in (O3DPointCloud(p), trimesh.PointCloud(p), (p, None), (p, np.zeros((0, 3), int))):
        m = bsfjax.as_mesh(obj)
        assert m.is_point_cloud and np.array_equal(m.vertices, p)
    mesh = bsfjax.example_mesh(levels=1) if "levels" in bsfjax.example_mesh.__code__.co_varnames \
        else bsfjax.example_pair(levels=1).source
    tm = mesh.to_trimesh()
    assert isinstance(tm, trimesh.Trimesh)
    assert np.array_equal(tm.vertices, mesh.vertices) and np.array_equal(tm.faces, mesh.faces)
    back = bsfjax.as_mesh(tm)
    assert np.isclose(back.area, mesh.area, rtol=1e-12, atol=0)
    assert isinstance(bsfjax.PointCloud(p).to_trimesh(), trimesh.PointCloud)


def test_unknown_objects_are_one_clear_error():
    with pytest.raises(bsfjax.MeshError, match=r"mesh must be a bsfjax.Mesh, got int"):
        bsfjax.spectrum(3, 5)
    with pytest.raises(bsfjax.MeshError, match="source_mesh must be a bsfjax.Mesh"):
        bsfjax.map_distortion(object(), object(), np.zeros(3, int))
    with pytest.raises(bsfjax.MeshError, match="face indices out of range"):
        bsfjax.as_mesh((np.zeros((3, 3)), np.array([[0, 1, 5]])))


def test_the_pyfm_how_to_runs_on_pyfm_trimesh_objects(files):
    pytest.importorskip("polyscope")
    from pathlib import Path
    import re

    from pyFM.mesh import TriMesh

    pair, (spath, tpath) = files
    load = TriMesh.load if hasattr(TriMesh, "load") else TriMesh
    ns = {"mesh1": load(str(spath)), "mesh2": load(str(tpath)), "p2p_21": pair.p2p,
          "labels": pair.labels}
    page = (Path(__file__).resolve().parents[1] / "docs" / "how-to" / "from-pyfm.md").read_text()
    code = re.search(r"```python\n(.*?)```", page, re.S).group(1)
    assert len(code.strip().splitlines()) == 5
    exec(code.replace("bsfjax.view(mesh1, mesh2,", "bsfjax.view(mesh1, mesh2, backend='mock',"),
         ns)
    assert (ns["seg"].labels == pair.labels[pair.p2p]).mean() > 0.95
