"""Loop and midpoint subdivision."""

from __future__ import annotations

import numpy as np
import pytest

import bsfjax
from bsfjax import Mesh
from bsfjax.internal import mesh_edges
from bsfjax.internal import subdivide

from .conftest import icosphere


def torus(nu=12, nv=8, R=2.0, r=0.7):
    """A regular torus grid: every vertex has valence 6."""
    u, v = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = 2 * np.pi * u / nu, 2 * np.pi * v / nv
    verts = np.stack([(R + r * np.cos(b)) * np.cos(a), (R + r * np.cos(b)) * np.sin(a), r * np.sin(b)], -1)
    idx = lambda i, j: (i % nu) * nv + (j % nv)  # noqa: E731
    i, j = u.ravel(), v.ravel()
    faces = np.concatenate([np.stack([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)], 1),
                            np.stack([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)], 1)])
    return Mesh(verts.reshape(-1, 3), faces)


def test_counts_and_midpoint_geometry(sphere_mesh):
    edges, _ = mesh_edges(np.asarray(sphere_mesh.faces))
    s = subdivide(sphere_mesh, "midpoint")
    assert s.n_vertices == sphere_mesh.n_vertices + len(edges)
    assert s.n_faces == 4 * sphere_mesh.n_faces
    assert s.area == pytest.approx(sphere_mesh.area, rel=1e-12)  # planar split keeps area
    np.testing.assert_array_equal(s.vertices[: sphere_mesh.n_vertices], sphere_mesh.vertices)
    # Euler characteristic is preserved (closed genus 0)
    e2, _ = mesh_edges(np.asarray(s.faces))
    assert s.n_vertices - len(e2) + s.n_faces == 2


def test_loop_regular_stencils_closed_form():
    """On a valence-6 torus Loop's rules are: even 5/8 v + 1/16 Σ six neighbours,
    odd 3/8 (a + b) + 1/8 (c + d)."""
    m = torus()
    s = subdivide(m, "loop")
    v = m.vertices
    n = m.n_vertices
    edges, _ = mesh_edges(np.asarray(m.faces))
    nbrs = [[] for _ in range(n)]
    for a, b in edges:
        nbrs[a].append(b)
        nbrs[b].append(a)
    even = np.array([5 / 8 * v[i] + 1 / 16 * v[nbrs[i]].sum(0) for i in range(n)])
    np.testing.assert_allclose(s.vertices[:n], even, atol=1e-12)
    f = np.asarray(m.faces)
    e = 3  # check one edge against its two opposite vertices
    a, b = edges[e]
    opp = [int(set(t.tolist()).difference({a, b}).pop()) for t in f if a in t and b in t]
    np.testing.assert_allclose(s.vertices[n + e], 3 / 8 * (v[a] + v[b]) + 1 / 8 * (v[opp[0]] + v[opp[1]]),
                               atol=1e-12)


def test_loop_matches_libigl_on_regular_mesh():
    igl = pytest.importorskip("igl")
    m = torus()
    s = subdivide(m, "loop")
    V, F = igl.loop(np.asarray(m.vertices), np.asarray(m.faces))
    from scipy.spatial import cKDTree

    d, _ = cKDTree(V).query(s.vertices)
    assert d.max() < 1e-12  # same point set (libigl orders new vertices differently)


def test_loop_smooths_towards_sphere_and_keeps_boundary_flat():
    v, f = icosphere(1)
    s = subdivide(Mesh(v, f), "loop", levels=2)
    r = np.linalg.norm(s.vertices, axis=1)
    assert r.std() / r.mean() < 0.02  # the limit surface of an icosahedron is nearly round
    # an open flat square stays flat and its boundary straight
    sq = Mesh(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]))
    s = subdivide(sq, "loop", levels=2)
    assert np.allclose(s.vertices[:, 2], 0)
    assert s.vertices[:, :2].min() >= -1e-12 and s.vertices[:, :2].max() <= 1 + 1e-12


def test_errors(sphere_mesh):
    with pytest.raises(ValueError, match="scheme"):
        subdivide(sphere_mesh, "butterfly")
    with pytest.raises(ValueError, match="levels"):
        subdivide(sphere_mesh, levels=-1)
    fan = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]], float),
               np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]]))
    with pytest.raises(ValueError, match="manifold"):
        subdivide(fan, "loop")
