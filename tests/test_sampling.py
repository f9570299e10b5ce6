"""Farthest point sampling against plain numpy / scipy references."""

from __future__ import annotations

import jax
import numpy as np
import pytest
import scipy.sparse.csgraph

import bsfjax
from bsfjax import BSFError, farthest_point_sampling
from bsfjax.internal import edge_graph

from .conftest import icosphere


def fps_reference(dist_from, n_points: int, n: int, seed: int) -> np.ndarray:
    """Textbook FPS: ``dist_from(i)`` is the full (N,) distance field of point i."""
    idx = [int(np.random.default_rng(seed).integers(n_points))]
    mind = dist_from(idx[0])
    for _ in range(1, n):
        idx.append(int(np.argmax(mind)))
        mind = np.minimum(mind, dist_from(idx[-1]))
    return np.array(idx)


def euclid(points):
    return lambda i: np.linalg.norm(points - points[i], axis=1)


@pytest.fixture(scope="module")
def bumpy_sphere():
    """An icosphere with jittered vertices: no symmetric ties between distances."""
    v, f = icosphere(3)
    rng = np.random.default_rng(7)
    v = v * (1 + 0.05 * rng.standard_normal((len(v), 1)))
    return bsfjax.Mesh(v, f, name="bumpy-sphere")


@pytest.fixture(scope="module")
def cloud():
    return np.random.default_rng(3).standard_normal((400, 3)) * [3.0, 1.0, 0.5]


def _covering_radius_and_separation(points, idx):
    d = np.linalg.norm(points[:, None, :] - points[None, idx, :], axis=-1)  # (N, n)
    cover = d.min(axis=1).max()
    pair = d[idx]
    pair[np.arange(len(idx)), np.arange(len(idx))] = np.inf
    return cover, pair.min()


@pytest.mark.parametrize("seed,n", [(0, 1), (0, 25), (5, 60), (11, 400)])
def test_euclidean_matches_numpy_x64(cloud, seed, n):
    with jax.enable_x64(True):
        got = farthest_point_sampling(cloud, n, seed=seed)
    want = fps_reference(euclid(cloud), len(cloud), n, seed)
    assert got.dtype == np.int64 and got.shape == (n,)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed,n", [(0, 2), (5, 60), (11, 400)])
def test_pruned_euclidean_matches_numpy(cloud, monkeypatch, seed, n):
    """Above PRUNED_FPS_MIN_POINTS the k-d-tree pruned loop runs (float64 in any mode): the
    textbook picks, all the way to n = N."""
    import bsfjax._sampling._fps as sampling

    calls = []
    orig = sampling._fps_pruned
    monkeypatch.setattr(sampling, "_fps_pruned", lambda *a: calls.append(1) or orig(*a))
    monkeypatch.setattr(sampling, "PRUNED_FPS_MIN_POINTS", 100)
    got = farthest_point_sampling(cloud, n, seed=seed)
    assert calls and got.dtype == np.int64 and got.shape == (n,)
    np.testing.assert_array_equal(got, fps_reference(euclid(cloud), len(cloud), n, seed))


def test_pruned_euclidean_ties_and_duplicates():
    """A grid (many equal distances) with every point twice: ties go to the smallest index, and
    once all distinct points are taken the picks repeat as the full-pass loop's do."""
    g = np.stack(np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij"), -1).reshape(-1, 2)
    pts = np.concatenate([g, g])
    import bsfjax._sampling._fps as sampling

    want = fps_reference(euclid(pts), len(pts), 45, seed=0)
    np.testing.assert_array_equal(sampling._fps_pruned(pts, int(want[0]), 45), want)
    with jax.enable_x64(True):
        full = np.asarray(sampling._fps_points_jit(jax.numpy.asarray(pts), int(want[0]), 45))
    np.testing.assert_array_equal(full, want)


def test_euclidean_float32_is_a_valid_fps(cloud):
    """In float32 each pick must be a farthest point up to float32 rounding (checked in f64)."""
    idx = farthest_point_sampling(cloud, 50, seed=2)
    assert idx[0] == np.random.default_rng(2).integers(len(cloud))
    mind = np.linalg.norm(cloud - cloud[idx[0]], axis=1)
    for s in idx[1:]:
        assert mind[s] >= mind.max() * (1 - 1e-5)
        mind = np.minimum(mind, np.linalg.norm(cloud - cloud[s], axis=1))
    assert len(set(idx.tolist())) == 50


@pytest.mark.parametrize("n", [2, 10, 40])
def test_covering_radius_property(cloud, n):
    """FPS samples are pairwise at least the final covering radius apart, and that radius
    never grows when more samples are added."""
    idx = farthest_point_sampling(cloud, n, seed=1)
    cover, sep = _covering_radius_and_separation(cloud, idx)
    assert sep >= cover * (1 - 1e-6)
    more = farthest_point_sampling(cloud, n + 5, seed=1)
    np.testing.assert_array_equal(more[:n], idx)  # greedy: a prefix of the longer run
    assert _covering_radius_and_separation(cloud, more)[0] <= cover * (1 + 1e-6)


def test_deterministic_and_seed_picks_first(bumpy_sphere):
    for metric in ("euclidean", "geodesic"):
        a = farthest_point_sampling(bumpy_sphere, 30, metric=metric, seed=4)
        b = farthest_point_sampling(bumpy_sphere, 30, metric=metric, seed=4)
        np.testing.assert_array_equal(a, b)
        assert a[0] == np.random.default_rng(4).integers(bumpy_sphere.n_vertices)
    firsts = {int(farthest_point_sampling(bumpy_sphere, 1, seed=s)[0]) for s in range(6)}
    assert len(firsts) > 1


def test_fraction(bumpy_sphere):
    n = bumpy_sphere.n_vertices  # 642
    assert len(farthest_point_sampling(bumpy_sphere, 0.05)) == round(0.05 * n)
    assert len(farthest_point_sampling(bumpy_sphere, 1e-9)) == 1
    full = farthest_point_sampling(bumpy_sphere, 1.0)
    np.testing.assert_array_equal(np.sort(full), np.arange(n))  # a permutation of all vertices


def test_interval_points():
    """1D: points are x[:, None] (irregular, so there are no exact distance ties)."""
    x = np.sort(np.random.default_rng(1).uniform(0.0, 2.0, 201))
    with jax.enable_x64(True):
        idx = farthest_point_sampling(x[:, None], 8, seed=0)
    np.testing.assert_array_equal(idx, fps_reference(lambda i: np.abs(x - x[i]), 201, 8, 0))
    assert idx[1] in (0, 200)  # on a segment the farthest point from anywhere is an end


@pytest.mark.parametrize("seed,n", [(0, 40), (9, 150)])
def test_geodesic_matches_full_dijkstra(bumpy_sphere, seed, n):
    graph = edge_graph(bumpy_sphere)
    full = lambda i: scipy.sparse.csgraph.dijkstra(graph, directed=False, indices=i)  # noqa: E731
    got = farthest_point_sampling(bumpy_sphere, n, metric="geodesic", seed=seed)
    np.testing.assert_array_equal(got, fps_reference(full, bumpy_sphere.n_vertices, n, seed))


def test_edge_graph_lengths(bumpy_sphere):
    g = edge_graph(bumpy_sphere)
    f, v = bumpy_sphere.faces, bumpy_sphere.vertices
    assert (g != g.T).nnz == 0
    assert g.nnz == 2 * (3 * len(f) // 2)  # closed manifold: E = 3F/2, both directions
    i, j = f[0, 0], f[0, 1]
    assert g[i, j] == pytest.approx(np.linalg.norm(v[i] - v[j]))


def test_geodesic_differs_from_euclidean_on_a_folded_strip():
    """A strip of length 3 folded in half: its two arms lie 0.1 apart in space."""
    nx, ny = 41, 3
    u, y = (a.ravel() for a in np.meshgrid(np.linspace(0, 3, nx), np.linspace(0, 0.2, ny)))
    lower = u <= 1.5
    pts = np.stack([np.where(lower, u, 3 - u), y, np.where(lower, 0.0, 0.1)], axis=1)
    q = (np.arange(ny - 1)[:, None] * nx + np.arange(nx - 1)[None, :]).ravel()
    faces = np.concatenate([np.stack([q, q + 1, q + nx], 1),
                            np.stack([q + 1, q + nx + 1, q + nx], 1)])
    mesh = bsfjax.Mesh(pts, faces)
    # a seed whose first sample sits near the u = 0 end: in space the farthest point is then the
    # fold (x = 1.5), along the surface it is the other end u = 3 (which is above the start)
    seed = next(s for s in range(200) if u[np.random.default_rng(s).integers(len(u))] < 0.4)
    geo = farthest_point_sampling(mesh, 2, metric="geodesic", seed=seed)
    euc = farthest_point_sampling(mesh, 2, metric="euclidean", seed=seed)
    assert geo[0] == euc[0]
    assert u[geo[1]] == 3.0
    assert abs(u[euc[1]] - 1.5) < 0.1


def test_biharmonic_matches_numpy(bumpy_sphere):
    spec = bsfjax.spectrum(bumpy_sphere, 30)
    emb = spec.evecs[:, 1:] / spec.evals[1:]
    assert spec.evals[0] < 1e-8 * spec.evals[-1]  # one zero eigenvalue, skipped
    with jax.enable_x64(True):
        got = farthest_point_sampling(bumpy_sphere, 40, metric="biharmonic", spectrum=spec, seed=3)
    np.testing.assert_array_equal(got, fps_reference(euclid(emb), len(emb), 40, 3))
    # also on bare points, where only the point count is used
    got_pts = farthest_point_sampling(bumpy_sphere.vertices, 40, metric="biharmonic",
                                      spectrum=spec, seed=3)
    assert got_pts[0] == got[0] and len(set(got_pts.tolist())) == 40


@pytest.mark.parametrize("n,match", [(0, "n must be in"), (643, "n must be in"),
                                     (1.5, r"\(0, 1\]"), (0.0, r"\(0, 1\]"),
                                     (-0.1, r"\(0, 1\]"), (float("nan"), r"\(0, 1\]"),
                                     (True, "n must be"), ("5", "n must be")])
def test_bad_n(bumpy_sphere, n, match):
    with pytest.raises(BSFError, match=match):
        farthest_point_sampling(bumpy_sphere, n)


def test_bad_inputs(bumpy_sphere, cloud):
    with pytest.raises(BSFError, match="metric must be one of"):
        farthest_point_sampling(bumpy_sphere, 5, metric="diffusion")
    with pytest.raises(BSFError, match="needs spectrum"):
        farthest_point_sampling(bumpy_sphere, 5, metric="biharmonic")
    with pytest.raises(BSFError, match="spectrum has 400 vertices but mesh has 642"):
        farthest_point_sampling(bumpy_sphere, 5, metric="biharmonic",
                                spectrum=bsfjax.interval_spectrum(400, 5))
    with pytest.raises(BSFError, match="needs a bsfjax.Mesh"):
        farthest_point_sampling(cloud, 5, metric="geodesic")
    with pytest.raises(BSFError, match="x\\[:, None\\]"):
        farthest_point_sampling(np.linspace(0, 1, 10), 3)
    with pytest.raises(BSFError, match="NaN"):
        farthest_point_sampling(np.array([[0.0], [np.nan]]), 1)
    with pytest.raises(BSFError, match="seed"):
        farthest_point_sampling(cloud, 3, seed=-1)
    with pytest.raises(BSFError, match="non-zero eigenvalue"):
        farthest_point_sampling(np.zeros((50, 1)), 3, metric="biharmonic",
                                spectrum=bsfjax.interval_spectrum(50, 1))


def test_subsample_cells_are_the_nearest_samples(cloud):
    sub = bsfjax.subsample(cloud, 37, seed=2)
    np.testing.assert_array_equal(sub.indices, farthest_point_sampling(cloud, 37, seed=2))
    d = np.linalg.norm(cloud[:, None] - cloud[None, sub.indices], axis=-1)
    np.testing.assert_array_equal(sub.cells, d.argmin(axis=1))  # float64 Voronoi cells
    np.testing.assert_array_equal(sub.cells[sub.indices], np.arange(37))
    w = np.asarray(sub.weights(np.ones(len(cloud))))
    np.testing.assert_array_equal(w, np.bincount(sub.cells, minlength=37))
    every = bsfjax.subsample(cloud, 10_000)  # more samples than points: every point
    np.testing.assert_array_equal(every.indices, np.arange(len(cloud)))
    np.testing.assert_array_equal(every.cells, np.arange(len(cloud)))
    for bad in (0, -3, 2.5, True):
        with pytest.raises(BSFError, match="positive int"):
            bsfjax.subsample(cloud, bad)
