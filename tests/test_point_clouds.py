"""Point clouds (files with points and no faces): reading, their Laplacian, a transfer from a
mesh to a cloud, the clear refusals of what needs triangles, and the command line."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp

import bsfjax
from bsfjax.cli import main
from bsfjax.internal import edge_graph, example_landmarks, mass_matrix, sample_surface


def _fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` evenly spread points on the unit sphere (the Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r, phi = np.sqrt(1 - z * z), np.pi * (1 + 5 ** 0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _sphere_points(n: int, seed: int = 0) -> np.ndarray:
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


# reading ------------------------------------------------------------------------------------

def test_point_files_read_as_point_clouds_in_row_order(tmp_path):
    pts = np.random.default_rng(1).normal(size=(50, 3))
    pts[7] = pts[3]  # a duplicate point keeps its own row
    rows = pts.tolist()  # Python floats: repr round-trips exactly
    (tmp_path / "c.xyz").write_text("# a scan\n" + "".join(
        f"{x!r} {y!r} {z!r} 0 0 1\n" if i % 2 else f"{x!r}, {y!r}, {z!r}\n\n"
        for i, (x, y, z) in enumerate(rows)))
    (tmp_path / "c.obj").write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in rows))
    bsfjax.save_mesh(tmp_path / "c.ply", bsfjax.PointCloud(pts))
    (tmp_path / "c.off").write_text(f"OFF\n{len(pts)} 0 0\n" + "".join(
        f"{x!r} {y!r} {z!r}\n" for x, y, z in rows))
    for name in ("c.xyz", "c.obj", "c.ply", "c.off"):
        cloud = bsfjax.load_mesh(tmp_path / name)
        assert isinstance(cloud, bsfjax.PointCloud) and cloud.is_point_cloud, name
        assert cloud.n_faces == 0 and cloud.vertex_ids is None
        np.testing.assert_array_equal(cloud.points, pts, err_msg=name)


def test_meshes_are_not_point_clouds_and_a_mesh_still_needs_faces(sphere_mesh):
    assert not sphere_mesh.is_point_cloud
    with pytest.raises(bsfjax.MeshError, match="no faces.*PointCloud"):
        bsfjax.Mesh(np.eye(3), np.zeros((0, 3), int))
    with pytest.raises(bsfjax.MeshError, match="has no faces"):
        bsfjax.PointCloud(sphere_mesh.vertices, sphere_mesh.faces)


@pytest.mark.parametrize("text, match", [
    ("1 2\n", "every row needs x y z"),
    ("1 2 x\n", "bad number"),
    ("# nothing\n", "empty"),
    ("1 2 nan\n3 4 5\n", "NaN"),
])
def test_bad_xyz_files_are_one_clear_error(tmp_path, text, match):
    (tmp_path / "bad.xyz").write_text(text)
    with pytest.raises(bsfjax.MeshError, match=match):
        bsfjax.load_mesh(tmp_path / "bad.xyz")


# the Laplacian -----------------------------------------------------------------------------

def test_laplacian_is_robust_laplacians_point_cloud_laplacian():
    import robust_laplacian

    pts = _sphere_points(400)
    W, A = bsfjax.laplacian(bsfjax.PointCloud(pts))
    W0, A0 = robust_laplacian.point_cloud_laplacian(pts, n_neighbors=30)
    assert W.dtype == np.float64 and A.dtype == np.float64
    assert abs(W - sp.csr_matrix(W0)).max() == 0 and abs(A - sp.csr_matrix(A0)).max() == 0
    np.testing.assert_allclose(np.asarray(W.sum(axis=1)).ravel(), 0, atol=1e-9)
    np.testing.assert_allclose(mass_matrix(bsfjax.PointCloud(pts)).diagonal(), A.diagonal())


def test_spectrum_of_a_sampled_sphere_is_close_to_the_closed_form():
    """Unit sphere: λ = l(l + 1) with multiplicity 2l + 1; the lumped areas sum to 4π.
    (Evenly spread points: 3000 random ones give eigenvalues ~6 % low.)"""
    cloud = bsfjax.PointCloud(_fibonacci_sphere(3000))
    s = bsfjax.spectrum(cloud, 16)
    exact = np.repeat([0.0, 2.0, 6.0, 12.0], [1, 3, 5, 7])
    np.testing.assert_allclose(s.evals, exact, rtol=0.01, atol=1e-8)
    assert abs(np.sum(s.mass) - 4 * np.pi) < 1e-3 * 4 * np.pi
    assert abs(cloud.area - np.sum(s.mass)) < 1e-9


def test_duplicate_points_keep_their_rows_and_add_no_zero_eigenvalue():
    pts = _sphere_points(600)
    dup = np.concatenate([pts, pts[:20]])
    s = bsfjax.spectrum(bsfjax.PointCloud(dup), 8)
    assert s.evecs.shape == (620, 8) and np.all(np.asarray(s.mass) > 0)
    assert s.evals[1] > 1.0  # one zero eigenvalue: the copies are tied to their originals
    ev = np.asarray(s.evecs)
    np.testing.assert_allclose(ev[600:], ev[:20], atol=1e-3 * np.abs(ev).max())


def test_geodesics_and_sampling_work_on_the_knn_graph():
    pts = _sphere_points(2000)
    cloud = bsfjax.PointCloud(pts)
    d = bsfjax.geodesic_distances(cloud, [0])[0]
    great = np.arccos(np.clip(pts @ pts[0], -1, 1))
    assert np.all(np.isfinite(d)) and np.all(d >= 2 * np.sin(great / 2) - 1e-6)  # ≥ the chord
    assert np.median(d[great > 0.5] / great[great > 0.5]) < 1.25  # graph paths: a bit longer
    g = edge_graph(cloud)
    assert g.shape == (2000, 2000) and (g != g.T).nnz == 0
    for metric in ("euclidean", "geodesic"):
        idx = bsfjax.farthest_point_sampling(cloud, 30, metric=metric)
        assert len(np.unique(idx)) == 30
    report = bsfjax.mesh_report(bsfjax.PointCloud(np.concatenate([pts, pts[:3]])))
    assert report.duplicate_vertices == 3 and report.components == 1
    assert report.n_faces == report.boundary_edges == report.isolated_vertices == 0


# a transfer mesh -> point cloud ----------------------------------------------------------

def test_transfer_from_a_faust_mesh_to_a_cloud_sampled_from_another_pose():
    from scipy.spatial import cKDTree

    from tests.conftest import data_path

    src = bsfjax.load_mesh(data_path("faust", "tr_reg_000.off"))
    tgt = bsfjax.load_mesh(data_path("faust", "tr_reg_010.off"))
    parts = bsfjax.load_labels(data_path("segmentations", "smpl_vert_segmentation.json"))
    pts, _, _ = sample_surface(tgt, 6000, seed=0)
    cloud = bsfjax.PointCloud(pts)
    truth = parts.labels[cKDTree(tgt.vertices).query(pts)[1]]
    lm = [412, 3216, 5907, 6296, 2445]
    lm_cloud = cKDTree(pts).query(tgt.vertices[lm])[1]
    sm, sn = bsfjax.spectrum(src, 100), bsfjax.spectrum(cloud, 100)
    est = bsfjax.estimate_map(sm, sn, landmarks=(lm, lm_cloud), source_mesh=src,
                              target_mesh=cloud)
    seg = bsfjax.transfer_labels(sm, sn, parts.labels, C=est.C, p2p=est.p2p,
                                 samples=est.samples, mesh=src)
    a = np.asarray(sn.mass)
    assert seg.labels.shape == (6000,)
    assert np.sum(a * (seg.labels == truth)) / a.sum() > 0.85


# refusals ----------------------------------------------------------------------------------

def test_what_needs_triangles_refuses_with_one_line_naming_the_reason(sphere_mesh):
    cloud = bsfjax.PointCloud(_sphere_points(300), name="scan.ply")
    s = bsfjax.spectrum(cloud, 40)
    with pytest.raises(bsfjax.BSFError,
                       match=r"point cloud target needs landmarks: the landmark-free map's "
                             r"orientation term needs triangles.*\(scan.ply\)"):
        bsfjax.estimate_map(s, s, source_mesh=sphere_mesh, target_mesh=cloud)
    with pytest.raises(bsfjax.BSFError, match=r"point cloud source needs landmarks"):
        bsfjax.estimate_map(s, s, source_mesh=cloud, target_mesh=sphere_mesh)
    with pytest.raises(bsfjax.BSFError, match="heat method"):
        bsfjax.geodesic_distances(cloud, [0], method="heat")
    with pytest.raises(bsfjax.BSFError, match="orientation agreement needs triangles"):
        bsfjax.orientation_agreement(cloud, cloud, np.arange(300))
    with pytest.raises(bsfjax.BSFError, match="per-triangle labels need a triangle source"):
        bsfjax.transfer_face_labels(s, s, np.zeros(0, int), source_mesh=cloud, target_mesh=cloud,
                                    p2p=np.arange(300), method="p2p")
    with pytest.raises(bsfjax.BSFError, match="cannot be subdivided"):
        bsfjax.internal.subdivide(cloud)
    with pytest.raises(bsfjax.MeshError, match="at least 4 points"):
        bsfjax.laplacian(bsfjax.PointCloud(np.eye(3)))


# the command line --------------------------------------------------------------------------

def test_cli_transfers_labels_to_a_point_cloud_in_file_order(tmp_path, capsys):
    import meshio

    pair = bsfjax.example_pair(levels=1)
    bsfjax.save_mesh(tmp_path / "src.off", pair.source)
    order = np.random.default_rng(0).permutation(pair.target.n_vertices)  # rows shuffled
    pts = pair.target.vertices[order]
    np.savetxt(tmp_path / "cloud.xyz", pts)
    np.savetxt(tmp_path / "labels.txt", pair.labels, fmt="%d")
    lm = example_landmarks(pair)
    lm_cloud = np.argsort(order)[lm]
    out, ply = tmp_path / "out.txt", tmp_path / "coloured.ply"
    landmarks = f"{','.join(map(str, lm))}:{','.join(map(str, lm_cloud))}"
    rc = main(["transfer", str(tmp_path / "src.off"), str(tmp_path / "cloud.xyz"), "--labels",
               str(tmp_path / "labels.txt"), "--landmarks", landmarks, "-k", "20",
               "--out", str(out), "--mesh-out", str(ply)])
    assert rc == 0
    got = np.loadtxt(out, dtype=int)
    assert got.shape == (len(pts),) and np.mean(got == pair.labels[order]) > 0.8
    written = meshio.read(ply)
    assert len(written.cells) == 0 or all(len(c.data) == 0 for c in written.cells)
    np.testing.assert_array_equal(written.points, pts)
    np.testing.assert_array_equal(written.point_data["label"], got)


# the stand-in surface: oriented normals and tangent-plane fans ------------------------------

def _mesh_vertex_normals(mesh) -> np.ndarray:
    v, f = mesh.vertices, mesh.faces
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    vn = np.zeros_like(v)
    for c in range(3):
        np.add.at(vn, f[:, c], fn)
    return vn / np.linalg.norm(vn, axis=1, keepdims=True)


def test_cloud_normals_are_outward_and_agree_with_the_mesh_normals():
    pts = _sphere_points(1500, seed=3)
    n = bsfjax.cloud_normals(pts)
    assert n.shape == (1500, 3)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-12)
    assert np.min(np.einsum("ij,ij->i", n, pts)) > 0.97  # the sphere's normal is the point
    # a non-convex body (the example's humanoid): the mesh's area-weighted vertex normals
    target = bsfjax.example_pair(levels=2).target
    order = np.random.default_rng(0).permutation(target.n_vertices)
    agree = np.einsum("ij,ij->i", bsfjax.cloud_normals(target.vertices[order]),
                      _mesh_vertex_normals(target)[order])
    assert np.mean(agree > 0.5) > 0.99


def test_cloud_surface_keeps_the_points_and_its_triangles_turn_outward():
    pts = _fibonacci_sphere(2000)[::-1]  # (any order)
    cloud = bsfjax.PointCloud(pts, name="sphere.xyz")
    s = bsfjax.cloud_surface(cloud)
    assert isinstance(s, bsfjax.Mesh) and not s.is_point_cloud and s.name == "sphere.xyz"
    np.testing.assert_array_equal(s.vertices, pts)
    assert np.array_equal(np.unique(s.faces), np.arange(2000))  # every point in a triangle
    assert len(np.unique(np.sort(s.faces, axis=1), axis=0)) == s.n_faces  # each triangle once
    v, f = s.vertices, s.faces
    normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert np.all(np.einsum("ij,ij->i", normal, v[f].mean(axis=1)) > 0)  # outward, every one
    # Delaunay fans of evenly spread points: close to a triangulation (2n − 4 triangles, 4π)
    assert 2 * 2000 - 4 <= s.n_faces < 1.1 * (2 * 2000 - 4)
    assert 4 * np.pi * 0.99 < s.face_areas().sum() < 4 * np.pi * 1.1
    # mirrored points: the triangles still turn outward (the orientation is not inherited)
    m = bsfjax.cloud_surface(pts * [-1, 1, 1])
    v, f = m.vertices, m.faces
    normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert np.all(np.einsum("ij,ij->i", normal, v[f].mean(axis=1)) > 0)


def test_cloud_surface_joins_duplicate_points_and_refuses_tiny_clouds():
    pts = _fibonacci_sphere(500)
    s = bsfjax.cloud_surface(np.concatenate([pts, pts[:5]]))
    assert np.array_equal(np.unique(s.faces), np.arange(505))
    with pytest.raises(bsfjax.BSFError, match="at least 4 points"):
        bsfjax.cloud_surface(np.eye(3))
    with pytest.raises(bsfjax.BSFError, match=r"\(n, 3\) points"):
        bsfjax.cloud_surface(np.zeros((10, 2)))


# noisy clouds --------------------------------------------------------------------------------

def test_cloud_noise_level_matches_the_mesh_level_and_denoise_smooths_a_cloud():
    """The level of a mesh's vertices read as a cloud is the mesh's (same one-ring size); noise
    raises it, and `denoise` with a strength brings the points back towards the surface (the
    unit sphere: the radial error in closed form) in their order."""
    from tests.conftest import icosphere

    v, f = icosphere(4)
    rng = np.random.default_rng(0)
    h = np.mean(np.linalg.norm(v[f[:, 0]] - v[f[:, 1]], axis=1))
    for sigma in (0.0, 0.3):
        noisy = v + rng.normal(scale=sigma * h, size=v.shape)
        mesh_level = bsfjax.noise_level(bsfjax.Mesh(noisy, f))
        cloud_level = bsfjax.noise_level(bsfjax.PointCloud(noisy))
        assert abs(cloud_level - mesh_level) < 0.25 * max(mesh_level, 0.04), (sigma, mesh_level,
                                                                               cloud_level)
    pts = _fibonacci_sphere(3000)
    spacing = np.sqrt(4 * np.pi / 3000)
    cloud = bsfjax.PointCloud(pts + rng.normal(scale=0.3 * spacing, size=pts.shape), name="n")
    assert bsfjax.noise_level(cloud) > 3 * bsfjax.noise_level(bsfjax.PointCloud(pts))
    # "auto" leaves a cloud as it is (its Laplacian tolerates the noise); a strength smooths
    assert bsfjax.denoise_iterations(cloud) == 0 and bsfjax.denoise(cloud) is cloud
    assert bsfjax.denoise_iterations(cloud, 10) == 10
    smooth = bsfjax.denoise(cloud, 10)
    assert isinstance(smooth, bsfjax.PointCloud) and smooth.name == "n"
    radial = lambda p: np.sqrt(np.mean((np.linalg.norm(p, axis=1) - 1) ** 2))  # noqa: E731
    assert radial(smooth.points) < 0.5 * radial(cloud.points)
    assert np.max(np.linalg.norm(smooth.points - cloud.points, axis=1)) < 2 * spacing
    assert bsfjax.denoise(cloud, 0) is cloud


# without landmarks, and a cloud as the source --------------------------------------------

def test_landmark_free_map_to_a_point_cloud_through_its_stand_in_surface():
    """One start without landmarks: the orientation term on the cloud's stand-in surface gives
    the right map, not the mirror image, and the surface's triangles turn as the source's do
    (the right map keeps them, the map composed with the left-right mirror turns them over)."""
    pair = bsfjax.example_pair(levels=2)
    order = np.random.default_rng(1).permutation(pair.target.n_vertices)
    cloud = bsfjax.PointCloud(pair.target.vertices[order])
    surface = bsfjax.cloud_surface(cloud)
    sm, sn = bsfjax.spectrum(pair.source, 40), bsfjax.spectrum(cloud, 40)
    est = bsfjax.estimate_map(sm, sn, k=20, starts=((20, 7.0),), source_mesh=pair.source,
                              target_mesh=surface)
    a = np.asarray(sn.mass)
    assert np.sum(a * (pair.labels[est.p2p] == pair.labels[order])) / a.sum() > 0.9
    truth = order  # (the example's source and target share their vertex numbering)
    from scipy.spatial import cKDTree

    mirror = cKDTree(pair.source.vertices * [-1, 1, 1]).query(pair.source.vertices)[1]
    keep = bsfjax.orientation_agreement(pair.source, surface, truth)
    flip = bsfjax.orientation_agreement(pair.source, surface, mirror[truth])
    assert keep > 0.95 and flip < 0.05, (keep, flip)


def _cli_case(tmp_path, capsys, src, tgt, landmarks: bool):
    """``bsfjax transfer`` on the example pair (levels 2) with the source and / or the target
    written as a cloud of shuffled points: the share of the target's area labelled right."""
    pair = bsfjax.example_pair(levels=2)
    rng = np.random.default_rng(2)
    so, to = rng.permutation(pair.source.n_vertices), rng.permutation(pair.target.n_vertices)
    so, to = (so if src == "xyz" else np.arange(pair.source.n_vertices),
              to if tgt == "xyz" else np.arange(pair.target.n_vertices))
    for name, mesh, order in (("src", pair.source, so), ("tgt", pair.target, to)):
        kind = src if name == "src" else tgt
        if kind == "xyz":
            np.savetxt(tmp_path / "src.xyz" if name == "src" else tmp_path / "tgt.xyz",
                       mesh.vertices[order])
        else:
            bsfjax.save_mesh(tmp_path / f"{name}.off", mesh)
    np.savetxt(tmp_path / "labels.txt", pair.labels[so], fmt="%d")
    lm = example_landmarks(pair)
    args = ["transfer", str(tmp_path / f"src.{src}"), str(tmp_path / f"tgt.{tgt}"), "--labels",
            str(tmp_path / "labels.txt"), "-k", "20", "--out", str(tmp_path / "out.txt")]
    if landmarks:
        args += ["--landmarks", f"{','.join(map(str, np.argsort(so)[lm]))}:"
                                f"{','.join(map(str, np.argsort(to)[lm]))}"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(args)
    err = capsys.readouterr().err
    assert rc == 0, err
    assert ("no landmarks: kept start" in err) == (not landmarks)
    got = np.loadtxt(tmp_path / "out.txt", dtype=int)
    assert got.shape == (len(to),)
    area = np.asarray(bsfjax.spectrum(pair.target, 2).mass)[to]
    return np.sum(area * (got == pair.labels[to])) / area.sum()


def test_cli_without_landmarks_to_a_cloud(tmp_path, capsys):
    """No landmarks: a cloud target is matched through its stand-in surface (the refusal is
    gone).  (The choice among starts may keep the left-right swap on a cloud,
    docs/how-to/scans.md: the swapped labels still agree on the torso and head.)"""
    assert _cli_case(tmp_path, capsys, "off", "xyz", landmarks=False) > 0.35


def test_cli_with_a_cloud_source(tmp_path, capsys):
    """A cloud source (one label per point, in its file order) is carried to a mesh without
    landmarks (its mirror symmetry on its stand-in surface) and to another cloud with them."""
    assert _cli_case(tmp_path, capsys, "xyz", "off", landmarks=False) > 0.35
    assert _cli_case(tmp_path, capsys, "xyz", "xyz", landmarks=True) > 0.85


def test_the_refined_pull_back_drops_the_descriptors_on_a_pair_with_a_cloud(sphere_mesh):
    from bsfjax.internal import method_for_shapes

    cloud = bsfjax.PointCloud(_sphere_points(100))
    got = method_for_shapes("refined", sphere_mesh, cloud)
    assert isinstance(got, bsfjax.RefinedPullBack) and got.descriptor_weight == 0
    assert (got.step, got.n_vote) == (10, 5) and bsfjax.RefinedPullBack().n_vote == 1
    assert bsfjax.RefinedPullBack().descriptor_weight > 0
    assert method_for_shapes("refined", sphere_mesh, sphere_mesh) == "refined"
    mine = bsfjax.RefinedPullBack(descriptor_weight=0.3)
    assert method_for_shapes(mine, cloud, cloud) is mine
    assert method_for_shapes("p2p", cloud, cloud) == "p2p"


def test_collection_matches_clouds_without_landmarks():
    """`transfer_collection` without landmarks carries labels to a cloud (one start: the
    batched stages' orientation term on the stand-in surface, padded to its own face count)
    and from a cloud source (the choice among starts, the turn check on its surface)."""
    pair = bsfjax.example_pair(levels=2)
    to = np.random.default_rng(1).permutation(pair.target.n_vertices)
    so = np.random.default_rng(3).permutation(pair.source.n_vertices)
    runs = [(pair.source, pair.labels, bsfjax.PointCloud(pair.target.vertices[to]),
             pair.labels[to], ((20, 7.0),)),
            (bsfjax.PointCloud(pair.source.vertices[so]), pair.labels[so], pair.target,
             pair.labels, None)]  # (from a cloud: the start (20, 7) alone is the mirror image)
    for source, labels, target, truth, starts in runs:
        (i, res), = bsfjax.transfer_collection(source, labels, [target], k=20, starts=starts)
        m = np.asarray(res.mass)
        assert i == 0 and res.labels.shape == truth.shape
        assert np.sum(m * (res.labels == truth)) / m.sum() > 0.9


def test_collection_zooms_out_in_larger_steps_on_a_cloud_alone(monkeypatch):
    """With landmarks, the batched stages of a cloud target run ZoomOut at
    ``CLOUD_ZOOMOUT_STEP`` eigenpairs per iteration with pairs read off a first map beside
    the given ones, and a mesh target's at the estimator's own step with the given pairs,
    and the cloud's refined pull-back votes, as ``bsfjax transfer`` (``for_point_clouds``,
    ``method_for_shapes``); both still label the body."""
    import bsfjax._pipeline._collection as col
    from bsfjax._maps import CLOUD_ZOOMOUT_STEP
    from bsfjax._maps._guide import CLOUD_ADDED_LANDMARKS
    from bsfjax.internal import example_landmarks

    pair = bsfjax.example_pair(levels=2)
    lm = example_landmarks(pair)
    to = np.random.default_rng(1).permutation(pair.target.n_vertices)
    cloud = bsfjax.PointCloud(pair.target.vertices[to])
    steps, votes, counts, read = [], [], [], []  # per group (mesh guided, cloud not: two)
    real, real_read = col.dispatch_stages, col.with_read_pairs

    def spy(cfg, *args):
        steps.append(cfg.zoomout_step)
        votes.append(cfg.method.n_vote)
        counts.append(cfg.n_landmarks)
        return real(cfg, *args)

    monkeypatch.setattr(col, "dispatch_stages", spy)
    monkeypatch.setattr(col, "with_read_pairs", lambda *a: read.append(a) or real_read(*a))
    landmarks = {0: (lm, lm), 1: (lm, np.argsort(to)[lm])}
    got = dict(bsfjax.transfer_collection(pair.source, pair.labels, [pair.target, cloud], k=20,
                                          landmarks=landmarks.get))
    assert sorted(steps) == [2, CLOUD_ZOOMOUT_STEP]
    assert sorted(zip(steps, votes)) == [(2, 1), (CLOUD_ZOOMOUT_STEP, 5)]  # (method_for_shapes)
    # the cloud's map: estimated with the given pairs and CLOUD_ADDED_LANDMARKS read off a
    # first map (MapEstimator.added_landmarks), the mesh's with the given pairs alone
    assert sorted(zip(steps, counts)) == [(2, len(lm)),
                                          (CLOUD_ZOOMOUT_STEP, len(lm) + CLOUD_ADDED_LANDMARKS)]
    (given, mesh, p2p, n), = read
    np.testing.assert_array_equal(given[1], landmarks[1][1])
    assert mesh.n_vertices == pair.source.n_vertices and n == CLOUD_ADDED_LANDMARKS
    for i, truth in ((0, pair.labels), (1, pair.labels[to])):
        m = np.asarray(got[i].mass)
        assert np.sum(m * (got[i].labels == truth)) / m.sum() > 0.9
