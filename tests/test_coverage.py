"""map_coverage (bsfjax._maps._coverage) against a dense float64 reference and closed forms,
and choose_map with the coverage errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import bsfjax
from bsfjax import choose_map, map_coverage
from bsfjax._maps._coverage import coverage_errors
from bsfjax._mesh import vertex_areas

from .conftest import icosphere


@pytest.fixture(scope="module")
def sphere():
    v, f = icosphere(3)  # symmetric under x → −x, connectivity included
    mesh = bsfjax.Mesh(v, f)
    mirror = cKDTree(v).query(v * [-1, 1, 1])[1]
    return mesh, mirror


def reference_coverage(src, p2p, a_n, a_m, steps):
    """The module doc's formula with dense matrices and explicit loops: the pushed area, the
    one-ring averaging from the faces' corners, ``(Wᵀ)^s``, half the L1 norm."""
    n = src.n_vertices
    adj = np.zeros((n, n))
    for f in src.faces:
        for a in range(3):
            i, j = f[a], f[(a + 1) % 3]
            adj[i, j] = adj[j, i] = 1.0
    W = adj / adj.sum(axis=1, keepdims=True)
    pushed = np.zeros(n)
    for j, i in enumerate(p2p):
        pushed[i] += a_n[j] / a_n.sum()
    d = pushed - a_m / a_m.sum()
    for _ in range(steps):
        d = W.T @ d
    return 0.5 * np.abs(d).sum()


def test_coverage_matches_the_dense_reference(sphere):
    """Random maps, barycentric and given masses, 0, 1 and 10 steps: the float64 reference."""
    mesh, _ = sphere
    rng = np.random.default_rng(0)
    n = mesh.n_vertices
    maps = rng.integers(0, n, size=(3, n))
    bary = vertex_areas(mesh)
    given = rng.uniform(0.5, 2.0, size=n)
    for steps in (0, 1, 10):
        got = map_coverage(mesh, mesh, maps, smoothing=steps)
        want = [reference_coverage(mesh, m, bary, bary, steps) for m in maps]
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
        got = map_coverage(mesh, mesh, maps, source_mass=given, target_mass=bary[::-1].copy(),
                           smoothing=steps)
        want = [reference_coverage(mesh, m, bary[::-1], given, steps) for m in maps]
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    assert map_coverage(mesh, mesh, maps[0]) == pytest.approx(
        reference_coverage(mesh, maps[0], bary, bary, 10))  # one map: a float


def test_coverage_closed_forms(sphere):
    """The identity 0 (with any spreading); everything onto vertex i: ``1 − a_M(i)`` without
    spreading; the mirror image of the symmetric sphere (a bijection that keeps areas) 0; a
    fold of one half onto the other about ½ vertex by vertex, and well above a small slide."""
    mesh, mirror = sphere
    n = mesh.n_vertices
    a = vertex_areas(mesh)
    a = a / a.sum()
    ident = np.arange(n)
    for steps in (0, 10):
        assert map_coverage(mesh, mesh, ident, smoothing=steps) == pytest.approx(0, abs=1e-12)
    assert map_coverage(mesh, mesh, mirror) == pytest.approx(0, abs=1e-12)
    for i in (0, 17, n - 1):
        assert map_coverage(mesh, mesh, np.full(n, i), smoothing=0) == pytest.approx(1 - a[i])
    x = mesh.vertices[:, 0]
    fold = np.where(x < 0, mirror, ident)  # the x < 0 half onto the x > 0 one
    # vertex by vertex: the half's area moves, less the band at x = 0 that stays
    assert 0.45 < map_coverage(mesh, mesh, fold, smoothing=0) <= 0.5
    c = map_coverage(mesh, mesh, fold)  # spread over 10 rings of a 642-vertex sphere: less
    nearby = cKDTree(mesh.vertices).query(mesh.vertices + [0.02, 0, 0])[1]
    assert map_coverage(mesh, mesh, nearby) < 0.1 < 0.3 < c


def test_unsearched_rows_are_left_out(sphere):
    """``coverage_errors`` (the estimator's route): ``-1`` entries leave the target vertex and
    its area out, as the map restricted to the searched vertices."""
    mesh, mirror = sphere
    n = mesh.n_vertices
    rng = np.random.default_rng(1)
    m = rng.integers(0, n, size=n)
    rows = np.sort(rng.choice(n, n // 3, replace=False))
    partial = np.full(n, -1)
    partial[rows] = m[rows]
    a = vertex_areas(mesh)
    got = coverage_errors(mesh, partial[None], a)[0]
    assert got == pytest.approx(reference_coverage(mesh, m[rows], a[rows], a, 10), rel=1e-12)


def test_bad_inputs_are_named(sphere):
    mesh, _ = sphere
    n = mesh.n_vertices
    cloud = bsfjax.PointCloud(mesh.vertices)
    for args, kw, msg in (((mesh, mesh, np.arange(n - 1)), {}, "p2p must have shape"),
                          ((mesh, mesh, np.full(n, n)), {}, "p2p"),
                          ((mesh, mesh, np.arange(n)), {"smoothing": -1}, "smoothing"),
                          ((mesh, mesh, np.arange(n)), {"source_mass": np.ones(3)},
                           "source_mass must be"),
                          ((mesh, mesh, np.arange(n)), {"target_mass": -np.ones(n)},
                           "target_mass must be"),
                          ((mesh, mesh, np.arange(n)), {"source_mass": "areas"},
                           "source_mass must hold real numbers"),
                          ((mesh, mesh, np.arange(n)), {"target_mass": np.full(n, np.nan)},
                           "target_mass contains"),
                          ((cloud, mesh, np.arange(n)), {}, "coverage error needs triangles"),
                          ((mesh, cloud, np.arange(n)), {}, "coverage error needs triangles"),
                          ((cloud, mesh, np.arange(n)), {"source_mass": np.ones(n),
                                                         "target_mass": np.ones(n)},
                           "coverage error needs triangles")):
        with pytest.raises(ValueError, match=msg):
            map_coverage(*args, **kw)


def test_a_point_cloud_target_takes_given_areas(sphere):
    """A point cloud target has no triangles, but with its areas given (its spectrum's mass)
    only the source's triangles are needed: the same value as the mesh with those areas."""
    mesh, mirror = sphere
    n = mesh.n_vertices
    cloud = bsfjax.PointCloud(mesh.vertices)
    mass = np.asarray(bsfjax.spectrum(cloud, 4).mass)
    maps = np.stack([np.arange(n), mirror, np.random.default_rng(2).integers(0, n, n)])
    got = map_coverage(mesh, cloud, maps, target_mass=mass)
    want = [reference_coverage(mesh, m, mass, vertex_areas(mesh), 10) for m in maps]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(got, map_coverage(mesh, mesh, maps, target_mass=mass),
                               rtol=1e-12)


def test_choose_map_with_coverage():
    """Each measure relative to its best among the kept maps: a map of slightly more
    distortion and much better coverage wins; the orientation slack still rules maps out;
    a coverage of 0 wins it; bad coverages are named."""
    d, o = [0.030, 0.031, 0.010], [0.90, 0.88, 0.50]
    assert choose_map(d, o) == 0
    assert choose_map(d, o, coverage=[0.30, 0.10, 0.0]) == 1  # 1 + 3 against 1.03 + 1
    assert choose_map(d, o, coverage=[0.30, 0.31, 0.0]) == 0  # 1 + 1 against 1.03 + 1.03
    assert choose_map(d, o, coverage=[0.0, 0.10, 0.0]) == 0
    assert choose_map(d, o, slack=1.0, coverage=[0.3, 0.1, 0.1]) == 2
    for cov, msg in (([0.1, 0.2], "non-empty 1-D arrays of one length"),
                     ([0.1, np.nan, 0.1], "must be finite"), ([0.1, -0.2, 0.1], ">= 0")):
        with pytest.raises(ValueError, match=msg):
            choose_map(d, o, coverage=cov)
