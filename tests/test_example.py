"""The built-in example pair: topology, ground truth, labels, near-isometry, spectrum."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

import bsfjax
from bsfjax import BSFError
from bsfjax import example_mesh, example_pair
from bsfjax.internal import JOINTS, LABEL_NAMES, POSES
from bsfjax import Mesh
from bsfjax.internal import clean_mesh


@pytest.fixture(scope="module")
def pair():
    return example_pair()


def _edges(faces: np.ndarray) -> np.ndarray:
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0)


def _adjacency(faces: np.ndarray, n: int) -> sp.csr_matrix:
    e = _edges(faces)
    a = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return (a + a.T).tocsr()


def _min_angles(mesh: Mesh) -> np.ndarray:
    v, f = mesh.vertices, mesh.faces
    angles = []
    for k in range(3):
        a = v[f[:, (k + 1) % 3]] - v[f[:, k]]
        b = v[f[:, (k + 2) % 3]] - v[f[:, k]]
        c = (a * b).sum(1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
        angles.append(np.degrees(np.arccos(np.clip(c, -1, 1))))
    return np.min(angles, axis=0)


def test_size_and_shared_connectivity(pair):
    n = pair.source.n_vertices
    assert n >= 5000
    assert n == 126 * 4**3 + 2  # the documented size formula
    assert pair.target.n_vertices == n
    np.testing.assert_array_equal(pair.source.faces, pair.target.faces)
    np.testing.assert_array_equal(pair.p2p, np.arange(n))
    assert pair.labels.shape == (n,) and pair.labels.dtype == np.int64
    assert pair.label_names == LABEL_NAMES and len(LABEL_NAMES) == 6
    for lv in (1, 2):
        assert example_pair(lv).source.n_vertices == 126 * 4**lv + 2


@pytest.mark.parametrize("which", ["source", "target"])
def test_closed_oriented_manifold_genus0(pair, which):
    mesh = getattr(pair, which)
    f, n = mesh.faces, mesh.n_vertices
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    # consistent orientation: each directed edge once, and its reverse present (closed)
    key = directed[:, 0] * n + directed[:, 1]
    assert np.unique(key).size == key.size
    assert np.isin(directed[:, 1] * n + directed[:, 0], key).all()
    # every undirected edge shared by exactly two faces
    _, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert set(counts.tolist()) == {2}
    E = counts.size
    assert n - E + len(f) == 2  # Euler characteristic of a sphere
    assert connected_components(_adjacency(f, n), directed=False)[0] == 1
    assert np.bincount(f.ravel(), minlength=n).min() >= 3  # no unreferenced/dangling vertex
    # outward orientation: positive signed volume
    v = mesh.vertices
    vol = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6
    assert vol > 0
    # well-shaped triangles (measured min angle: 22.7° source, 20.0° target)
    ang = _min_angles(mesh)
    assert ang.min() > 15.0
    assert np.median(ang) > 30.0


def _max_detour(mesh: Mesh) -> float:
    """Max over vertex pairs closer than 1.5 median edge lengths of graph / Euclidean distance.

    Where two parts touch or interpenetrate, vertices of both come within an edge length of
    each other while the path between them along the mesh is long (inf beyond 5 edges).
    """
    v, f, n = mesh.vertices, mesh.faces, mesh.n_vertices
    e = _edges(f)
    L = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    G = sp.coo_matrix((L, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    pairs = cKDTree(v).query_pairs(1.5 * np.median(L), output_type="ndarray")
    assert len(pairs) > n  # the radius is large enough to be a real check
    geo = np.empty(len(pairs))
    for lo in range(0, n, 1000):  # Dijkstra from 1000 sources at a time bounds the memory
        sel = (pairs[:, 0] >= lo) & (pairs[:, 0] < lo + 1000)
        src = np.unique(pairs[sel, 0])
        D = dijkstra(G, directed=False, indices=src, limit=5 * np.median(L))
        geo[sel] = D[np.searchsorted(src, pairs[sel, 0]), pairs[sel, 1]]
    eu = np.linalg.norm(v[pairs[:, 0]] - v[pairs[:, 1]], axis=1)
    return float(np.max(geo / eu))


@pytest.mark.parametrize("which", ["source", "target"])
def test_no_self_contact(pair, which):
    """Vertices close in space are close on the surface: no touching or crossing parts
    (measured max detour 1.57 source, 1.93 target)."""
    assert _max_detour(getattr(pair, which)) < 3.0


def test_self_contact_is_detected():
    # the check above can fail: an arm pressed against the torso, a knee folded shut
    assert _max_detour(example_mesh({"left_shoulder": (0, 0, -90)}, levels=2)) > 3.0
    assert _max_detour(example_mesh({"left_knee": (150, 0, 0)}, levels=2)) > 3.0
    assert _max_detour(example_mesh({"left_shoulder": (0, 0, -80)}, levels=2)) < 3.0


def test_valid_mesh_without_warnings(pair, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = Mesh(pair.source.vertices, pair.source.faces)
        clean_mesh(m.vertices, m.faces)  # would warn on zero-area faces / unused vertices
        bsfjax.save_mesh(tmp_path / "src.ply", pair.source)
        back = bsfjax.load_mesh(tmp_path / "src.ply")
    assert back.n_vertices == m.n_vertices and back.vertex_ids is None
    np.testing.assert_allclose(back.vertices, m.vertices, rtol=1e-6, atol=1e-6)
    assert m.face_areas().min() > 1e-3 * m.face_areas().mean()


def test_deterministic_and_fast():
    t0 = time.perf_counter()
    a = example_pair()
    elapsed = time.perf_counter() - t0  # measured: ~10 ms
    b = example_pair()
    assert elapsed < 1.0
    for x, y in ((a.source.vertices, b.source.vertices), (a.target.vertices, b.target.vertices),
                 (a.source.faces, b.source.faces), (a.labels, b.labels)):
        np.testing.assert_array_equal(x, y)
    assert not a.labels.flags.writeable and not a.p2p.flags.writeable


def test_example_mesh_matches_pair(pair):
    np.testing.assert_array_equal(example_mesh("source").vertices, pair.source.vertices)
    np.testing.assert_array_equal(example_mesh("target").vertices, pair.target.vertices)
    np.testing.assert_array_equal(example_mesh("rest").faces, pair.source.faces)
    # a pose given as a mapping: zero rotations are the rest pose, the named pose is itself
    zero = example_mesh({j: (0, 0, 0) for j in JOINTS}, levels=2)
    np.testing.assert_allclose(zero.vertices, example_mesh("rest", levels=2).vertices, atol=1e-12)
    np.testing.assert_allclose(example_mesh(POSES["target"], levels=2).vertices,
                               example_pair(2).target.vertices, atol=1e-12)


def test_labels_cover_parts_connected_and_placed(pair):
    n = pair.source.n_vertices
    lab = pair.labels
    assert set(np.unique(lab).tolist()) == set(range(len(LABEL_NAMES)))
    adj = _adjacency(pair.source.faces, n)
    for k in range(len(LABEL_NAMES)):
        idx = np.flatnonzero(lab == k)
        assert idx.size > 0.05 * n
        # spatially coherent: the part's vertices induce one connected subgraph
        assert connected_components(adj[idx][:, idx], directed=False)[0] == 1, LABEL_NAMES[k]
    # the names match the geometry (y up, body faces +z, left side at +x), in both poses
    for mesh in (pair.source, pair.target):
        c = np.stack([mesh.vertices[lab == k].mean(axis=0) for k in range(6)])
        name = dict(zip(LABEL_NAMES, c))
        assert name["head"][1] > name["torso"][1] > max(name["left_leg"][1], name["right_leg"][1])
        assert name["left_arm"][0] > name["torso"][0] > name["right_arm"][0]
        assert name["left_leg"][0] > name["right_leg"][0]
    # boundaries are few: a part touches the torso along one ring, not scattered islands
    e = _edges(pair.source.faces)
    cut = lab[e[:, 0]] != lab[e[:, 1]]
    assert cut.mean() < 0.03


def _edge_ratios(pair):
    e = _edges(pair.source.faces)
    ls = np.linalg.norm(np.subtract(*pair.source.vertices[e.T]), axis=1)
    lt = np.linalg.norm(np.subtract(*pair.target.vertices[e.T]), axis=1)
    return lt / ls


def test_near_isometric(pair):
    """Edge lengths barely change except near bent joints (measured quantiles of |r − 1|:
    50%: 0.006, 75%: 0.037, 90%: 0.096; area ratio 0.976).  FAUST tr_reg_000 → 001 measures
    0.031, 0.080, 0.162 for comparison."""
    r = _edge_ratios(pair)
    dev = np.abs(r - 1)
    assert abs(np.median(r) - 1) < 0.01
    q50, q75, q90 = np.quantile(dev, [0.5, 0.75, 0.9])
    assert q50 < 0.02 and q75 < 0.06 and q90 < 0.15
    assert abs(pair.target.area / pair.source.area - 1) < 0.05
    # a third of the edges keep their length to 0.1%: the rigid parts really are rigid
    assert np.mean(dev < 1e-3) > 0.3


def test_non_rigid(pair):
    """The best similarity transform (rotation, translation and scale) leaves a residual of
    ~9% of the shape's size (√area): the pose change is not a rigid motion or a scaling."""
    X = pair.source.vertices - pair.source.vertices.mean(0)
    Y = pair.target.vertices - pair.target.vertices.mean(0)
    U, s, Vt = np.linalg.svd(Y.T @ X)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    scale = np.trace(np.diag(s) @ D) / (X**2).sum()
    resid = np.sqrt(((scale * X @ R.T - Y) ** 2).sum(1).mean())
    size = np.sqrt(pair.source.area)
    assert resid > 0.05 * size
    # sanity of the Procrustes code: a rigidly moved copy aligns exactly
    Q, _ = np.linalg.qr(np.random.default_rng(0).standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    Z = X @ Q.T
    U, s, Vt = np.linalg.svd(Z.T @ X)
    np.testing.assert_allclose(X @ (U @ Vt).T, Z, atol=1e-9)
    # the displacement is large where the limbs moved
    disp = np.linalg.norm(scale * X @ R.T - Y, axis=1)
    assert disp.max() > 0.2 * size  # measured 0.28


def test_spectra_close(pair):
    """Near-isometric shapes have near-equal spectra: eigenvalues 2..21 within 10% (measured
    max deviation 6.7%, mostly the 2.4% area change plus the bent joints)."""
    a = bsfjax.spectrum(pair.source, 30)
    b = bsfjax.spectrum(pair.target, 30)
    assert a.evals.shape == (30,) and a.evecs.shape == (pair.source.n_vertices, 30)
    assert abs(a.evals[0]) < 1e-8 and a.evals[1] > 1e-3  # one component
    ratio = b.evals[1:21] / a.evals[1:21]
    assert np.all(np.abs(ratio - 1) < 0.10), ratio
    # and a genuinely different shape (the rest pose scaled by 1.5) is far off
    big = Mesh(example_mesh("rest", levels=2).vertices * 1.5, example_mesh("rest", levels=2).faces)
    c = bsfjax.spectrum(big, 6)
    assert np.all(c.evals[1:6] / a.evals[1:6] < 0.6)


def test_bad_arguments():
    with pytest.raises(BSFError, match="levels"):
        example_pair(0)
    with pytest.raises(BSFError, match="levels"):
        example_pair(2.5)
    with pytest.raises(BSFError, match="levels"):
        example_mesh(levels=True)
    with pytest.raises(BSFError, match="pose"):
        example_mesh("sitting")
    with pytest.raises(BSFError, match="unknown joint 'tail'"):
        example_mesh({"tail": (0, 0, 10)})
    with pytest.raises(BSFError, match="left_knee"):
        example_mesh({"left_knee": (0, 10)})
    with pytest.raises(BSFError, match="left_knee"):
        example_mesh({"left_knee": (0, np.nan, 0)})
    with pytest.raises(BSFError, match="target_pose"):
        example_pair(2, target_pose=3)
