"""Random connected indicators and segmentation <-> indicator conversions."""

from __future__ import annotations

import jax
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.csgraph

import bsfjax
from bsfjax import BSFError, indicators_to_labels, labels_to_indicators, random_indicators


@pytest.fixture(scope="module")
def pair():
    return bsfjax.example_pair(levels=2)


@pytest.fixture(scope="module")
def mass(pair):
    return bsfjax.laplacian(pair.source)[1].diagonal()


def _adjacency(mesh):
    f = mesh.faces
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    n = mesh.n_vertices
    return sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))


def test_shape_binary_connected_and_area_share(pair, mass):
    mesh = pair.source
    F = random_indicators(mesh, 40, seed=3, area_fraction=(0.05, 0.25))
    assert F.shape == (40, mesh.n_vertices) and F.dtype == np.float64
    assert set(np.unique(F)) <= {0.0, 1.0}
    adj = _adjacency(mesh)
    for row in F:  # connectivity is checked per region (test only)
        idx = np.flatnonzero(row)
        n_comp, _ = scipy.sparse.csgraph.connected_components(adj[idx][:, idx], directed=False)
        assert n_comp == 1
    share = F @ mass / mass.sum()
    assert share.min() >= 0.05 - 1e-12
    assert share.max() <= 0.25 + mass.max() / mass.sum() + 1e-12
    assert share.max() - share.min() > 0.1  # shares are spread over the range, not constant


def test_regions_are_not_discs_and_irregularity_zero_gives_graph_balls(pair):
    mesh = pair.source
    F = random_indicators(mesh, 5, seed=1, irregularity=0.0)
    # with irregularity 0 every region is a sub-level set of the edge-length graph distance from
    # one of its vertices (a graph-geodesic ball)
    graph = bsfjax._mesh._graph.edge_graph(mesh)
    for row in F:
        idx = np.flatnonzero(row)
        d = scipy.sparse.csgraph.dijkstra(graph, directed=False, indices=idx)
        radius = d[:, idx].max(axis=1)
        outside = np.flatnonzero(row == 0)
        is_ball = (d[:, outside] >= radius[:, None] - 1e-12).all(axis=1)
        assert is_ball.any()


def test_seed_determinism(pair, mass):
    a = random_indicators(pair.source, 6, seed=7, mass=mass)
    b = random_indicators(pair.source, 6, seed=7)
    c = random_indicators(pair.source, 6, seed=8)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("kwargs, match", [
    ({"count": 0}, "count"),
    ({"count": 2, "seed": -1}, "seed"),
    ({"count": 2, "area_fraction": (0.3, 0.1)}, "area_fraction"),
    ({"count": 2, "area_fraction": (0.0, 0.1)}, "area_fraction"),
    ({"count": 2, "area_fraction": 0.1}, "area_fraction"),
    ({"count": 2, "mass": np.ones(3)}, "mass"),
    ({"count": 2, "irregularity": -1.0}, "irregularity"),
])
def test_bad_arguments(pair, kwargs, match):
    with pytest.raises(BSFError, match=match):
        random_indicators(pair.source, **kwargs)
    with pytest.raises(BSFError, match="Mesh"):
        random_indicators(np.zeros((4, 3)), 2)


def test_labels_round_trip_and_step_function(pair):
    labels = np.asarray(pair.labels)
    ind = labels_to_indicators(labels)
    L = labels.max() + 1
    assert ind.shape == (L, labels.size)
    np.testing.assert_array_equal(np.asarray(ind).sum(axis=0), 1.0)
    np.testing.assert_array_equal(np.asarray(indicators_to_labels(ind)), labels)
    values = np.linspace(-2.0, 3.0, L)  # Eq. 2 with arbitrary piece values
    np.testing.assert_allclose(values @ np.asarray(ind), values[labels], rtol=1e-6)
    # soft (transferred) indicators: arg-max wins
    noisy = np.asarray(ind) * 0.6 + 0.3 * np.random.default_rng(0).uniform(size=ind.shape)
    np.testing.assert_array_equal(np.asarray(indicators_to_labels(noisy)), labels)


def test_labels_batched_jit_and_extra_labels():
    labels = np.array([[0, 2, 2], [1, 1, 0]])
    ind = labels_to_indicators(labels, n_labels=4)
    assert ind.shape == (2, 4, 3)
    np.testing.assert_array_equal(np.asarray(ind)[:, 3], 0.0)
    jitted = jax.jit(lambda x: labels_to_indicators(x, n_labels=4))
    np.testing.assert_array_equal(np.asarray(jitted(labels)), np.asarray(ind))
    np.testing.assert_array_equal(np.asarray(indicators_to_labels(ind)), labels)


@pytest.mark.parametrize("labels, n, match", [
    (np.array([0, -1]), None, ">= 0"),
    (np.array([0.0, 1.0]), None, "integers"),
    (np.array([0, 3]), 2, "< n_labels"),
    (np.array([], dtype=int), None, "non-empty"),
])
def test_labels_bad_input(labels, n, match):
    with pytest.raises(BSFError, match=match):
        labels_to_indicators(labels, n)


def test_indicators_bad_input():
    with pytest.raises(BSFError, match="L, n"):
        indicators_to_labels(np.ones(5))
    with pytest.raises(BSFError, match="NaN"):
        indicators_to_labels(np.array([[np.nan, 1.0]]))
