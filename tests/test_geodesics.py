"""Geodesic distances (Dijkstra, heat method) and the geodesic error of point maps."""

from __future__ import annotations

import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError, geodesic_distances, geodesic_error

from .conftest import icosphere


@pytest.fixture(scope="module")
def sphere():
    v, f = icosphere(4)  # 2562 vertices, unit radius: geodesics are great-circle arcs
    return bsfjax.Mesh(v, f)


def flat_grid(n=21, size=2.0):
    x = np.linspace(-size / 2, size / 2, n)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    v = np.stack([xx.ravel(), yy.ravel(), np.zeros(n * n)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return bsfjax.Mesh(v, f)


def floyd_warshall(mesh):
    """All-pairs shortest paths on the edge graph, the textbook O(n³) way (tiny meshes only)."""
    n = mesh.n_vertices
    d = np.full((n, n), np.inf)
    np.fill_diagonal(d, 0.0)
    f = mesh.faces
    for a, b in np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]):
        w = np.linalg.norm(mesh.vertices[a] - mesh.vertices[b])
        d[a, b] = d[b, a] = min(d[a, b], w)
    for k in range(n):
        d = np.minimum(d, d[:, [k]] + d[[k], :])
    return d


def test_dijkstra_equals_floyd_warshall():
    v, f = icosphere(1)  # 42 vertices
    v = v * np.array([1.0, 2.0, 0.5])
    mesh = bsfjax.Mesh(v, f)
    got = geodesic_distances(mesh, np.arange(mesh.n_vertices), chunk_size=5)
    fw = floyd_warshall(mesh)
    np.testing.assert_allclose(got, fw, rtol=1e-12)
    # to some vertices only (repeated, unsorted): those columns
    targets = np.array([7, 3, 7, 41, 0])
    part = geodesic_distances(mesh, np.arange(mesh.n_vertices), chunk_size=5, targets=targets)
    np.testing.assert_allclose(part, fw[:, targets], rtol=1e-12)


def test_sphere_against_great_circles(sphere):
    v = sphere.vertices
    src = np.array([0, 7, 1000])
    true = np.arccos(np.clip(v[src] @ v.T, -1.0, 1.0))
    dij = geodesic_distances(sphere, src)
    heat = geodesic_distances(sphere, src, method="heat")
    rel = lambda d: np.abs(d - true).mean() / true.mean()  # noqa: E731
    assert rel(dij) < 0.1  # paths along edges: a few percent off
    assert rel(heat) < 0.015  # measured 0.8 %
    assert rel(heat) < 0.3 * rel(dij)
    np.testing.assert_allclose(heat[np.arange(3), src], 0.0, atol=1e-12)


def test_heat_method_on_flat_grid_is_euclidean():
    mesh = flat_grid()
    centre = mesh.n_vertices // 2
    true = np.linalg.norm(mesh.vertices - mesh.vertices[centre], axis=1)
    heat = geodesic_distances(mesh, [centre], method="heat")[0]
    far = true > 0.3  # away from the source (and its smoothing) the heat method is accurate
    dij = geodesic_distances(mesh, [centre])[0]
    rel = lambda d: np.abs(d[far] - true[far]).mean() / true[far].mean()  # noqa: E731
    assert rel(heat) < 0.03  # measured 2.1 % (boundary effects included)
    assert rel(heat) < 0.2 * rel(dij)  # edge paths on this grid: 18 % too long
    assert np.all(dij >= true - 1e-12)  # edge paths are never shorter than the straight line


def test_geodesic_error_definition(sphere):
    rng = np.random.default_rng(0)
    n = sphere.n_vertices
    gt = rng.permutation(n)[: n // 2]  # 1281 targets, arbitrary ground truth, repeats allowed
    gt[::7] = gt[0]
    p2p = rng.integers(0, n, gt.shape[0])
    d = geodesic_distances(sphere, gt)  # row i: distances from gt[i]
    expect = d[np.arange(len(gt)), p2p] / np.sqrt(sphere.area)
    mean, per = geodesic_error(sphere, p2p, gt, per_vertex=True, chunk_size=100)
    np.testing.assert_allclose(per, expect, rtol=1e-12)
    assert mean == pytest.approx(expect.mean(), rel=1e-12)
    assert geodesic_error(sphere, gt, gt) == 0.0
    # Several maps at once, distances computed once.
    both = geodesic_error(sphere, np.stack([p2p, gt]), gt)
    np.testing.assert_allclose(both, [expect.mean(), 0.0], rtol=1e-12)


def test_geodesic_error_is_scale_invariant(sphere):
    big = bsfjax.Mesh(5.0 * sphere.vertices, sphere.faces)
    rng = np.random.default_rng(1)
    gt = np.arange(sphere.n_vertices)
    p2p = np.where(rng.random(gt.size) < 0.3, rng.integers(0, gt.size, gt.size), gt)
    for method in ("dijkstra", "heat"):
        a = geodesic_error(sphere, p2p, gt, method=method)
        b = geodesic_error(big, p2p, gt, method=method)
        assert a == pytest.approx(b, rel=1e-8)
        assert 0.1 < a < 0.3  # random images on a sphere: mean arc π/2 over √(4π) ≈ 0.44, ×0.3


def test_bad_input_raises(sphere):
    n = sphere.n_vertices
    gt = np.arange(n)
    with pytest.raises(ValueError, match="method"):
        geodesic_error(sphere, gt, gt, method="fmm")
    with pytest.raises(ValueError, match=rf"\[0, {n}\)"):
        geodesic_error(sphere, gt + 1, gt)
    with pytest.raises(ValueError, match="match gt_p2p"):
        geodesic_error(sphere, gt[:-1], gt)
    with pytest.raises(ValueError, match="integer"):
        geodesic_error(sphere, gt.astype(float), gt)
    with pytest.raises(BSFError, match="Mesh"):
        geodesic_distances(sphere.vertices, [0])
    with pytest.raises(BSFError, match="chunk_size"):
        geodesic_distances(sphere, [0], chunk_size=0)
    with pytest.raises(BSFError, match=rf"targets must be vertex indices in \[0, {n}\)"):
        geodesic_distances(sphere, [0], targets=[n])
    with pytest.raises(BSFError, match="targets must be a 1-D array"):
        geodesic_distances(sphere, [0], targets=[[0, 1]])
