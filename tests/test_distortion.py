"""Point-map quality without ground truth: geodesic distortion, orientation, the choice."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

import bsfjax
from bsfjax import choose_map, map_distortion, orientation_agreement

from .conftest import icosphere


@pytest.fixture(scope="module")
def sphere():
    v, f = icosphere(3)  # symmetric under x → −x, connectivity included
    mesh = bsfjax.Mesh(v, f)
    mirror = cKDTree(v).query(v * [-1, 1, 1])[1]  # the vertex at the reflected position
    np.testing.assert_allclose(v[mirror], v * [-1, 1, 1], atol=1e-12)
    return mesh, mirror


def reference_distortion(src, tgt, p2p, samples, radius=None, fit_scale=False):
    """float64 reference: scipy's Dijkstra on edge graphs built here, unit areas; with a
    ``radius``, the relative error over the pairs closer than it on the target."""
    def dist(mesh, idx):
        v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        w = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
        g = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(v),) * 2).tocsr()
        d = dijkstra(g, directed=False, indices=idx)[:, idx]
        area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                    axis=1).sum()
        return d / np.sqrt(area)
    dn, dm = dist(tgt, samples), dist(src, p2p[samples])
    s = len(samples)
    if radius is not None:
        near = (dn > 0) & (dn < radius)
        return (np.abs(dm - dn)[near] / dn[near]).mean()
    a, b = dm[~np.eye(s, dtype=bool)], dn[~np.eye(s, dtype=bool)]
    scale = np.clip(a @ b / (b @ b), 1 / 1.2, 1.2) if fit_scale else 1.0
    return np.abs(a - scale * b).mean()


def test_local_distortion_against_a_reference(sphere):
    """With a radius: 0 for the isometries, the float64 reference's relative error over the
    near pairs for a scrambled map (batched too), and a clear error for a radius that keeps no
    pair or is not a positive number."""
    mesh, mirror = sphere
    n = mesh.n_vertices
    ident = np.arange(n)
    assert map_distortion(mesh, mesh, mirror, radius=0.3) == pytest.approx(0, abs=1e-12)
    rng = np.random.default_rng(1)
    noisy = np.where(rng.random(n) < 0.1, rng.integers(0, n, n), ident)
    samples = np.asarray(bsfjax.farthest_point_sampling(mesh, 60))
    ref = reference_distortion(mesh, mesh, noisy, samples, radius=0.3)
    full = reference_distortion(mesh, mesh, noisy, samples)
    assert ref > 0.1 and ref != pytest.approx(full, rel=0.1)  # another average
    got = map_distortion(mesh, mesh, np.stack([ident, noisy]), n_samples=60, radius=0.3)
    np.testing.assert_allclose(got, [0, ref], rtol=1e-12, atol=1e-15)
    with pytest.raises(bsfjax.BSFError, match="closer than radius"):
        map_distortion(mesh, mesh, noisy, n_samples=10, radius=1e-3)
    for bad in (0, -0.1, float("nan"), True):
        with pytest.raises(bsfjax.BSFError, match="radius must be"):
            map_distortion(mesh, mesh, noisy, radius=bad)


def test_distortion_of_isometries_and_against_a_reference(sphere):
    """0 for the identity, for the mirror symmetry (an automorphism of the edge graph) and for
    a copy in other units; a scrambled map against the float64 reference, also batched."""
    mesh, mirror = sphere
    n = mesh.n_vertices
    ident = np.arange(n)
    assert map_distortion(mesh, mesh, ident) == 0
    assert map_distortion(mesh, mesh, mirror) == pytest.approx(0, abs=1e-12)
    big = bsfjax.Mesh(np.asarray(mesh.vertices) * 1000, mesh.faces)
    assert map_distortion(mesh, big, ident) == pytest.approx(0, abs=1e-12)
    rng = np.random.default_rng(0)
    noisy = np.where(rng.random(n) < 0.3, rng.integers(0, n, n), ident)
    samples = np.asarray(bsfjax.farthest_point_sampling(mesh, 40))
    ref = reference_distortion(mesh, mesh, noisy, samples)
    assert ref > 0.05  # a scrambled map is far from isometric
    assert map_distortion(mesh, mesh, noisy, n_samples=40) == pytest.approx(ref, rel=1e-12)
    both = map_distortion(mesh, mesh, np.stack([ident, noisy]), n_samples=40)
    np.testing.assert_allclose(both, [0, ref], rtol=1e-12, atol=1e-15)


def test_distortion_up_to_a_scale(sphere):
    """``fit_scale``: the float64 reference with its least-squares scale on a sphere stretched
    along one axis (other proportions), another value than without; a map onto one vertex is
    bounded by the clipped scale, not 0."""
    mesh, _ = sphere
    n = mesh.n_vertices
    ident = np.arange(n)
    tall = bsfjax.Mesh(np.asarray(mesh.vertices) * [1, 1.6, 1], mesh.faces)
    samples = np.asarray(bsfjax.farthest_point_sampling(tall, 50))
    plain = reference_distortion(mesh, tall, ident, samples)
    fitted = reference_distortion(mesh, tall, ident, samples, fit_scale=True)
    assert fitted != pytest.approx(plain, rel=1e-3)
    assert map_distortion(mesh, tall, ident, n_samples=50, fit_scale=True) == \
        pytest.approx(fitted, rel=1e-12)
    assert map_distortion(mesh, tall, ident, n_samples=50) == pytest.approx(plain, rel=1e-12)
    point = np.zeros(n, np.int64)  # every target vertex onto vertex 0: d_M = 0
    dn = reference_distortion(tall, tall, ident, samples)  # (0: the identity)
    assert dn == 0
    d0 = map_distortion(mesh, tall, point, n_samples=50, fit_scale=True)
    assert d0 == pytest.approx(reference_distortion(mesh, tall, point, samples) / 1.2,
                               rel=1e-12)


def test_distortion_of_a_mesh_in_two_pieces(sphere):
    """Two spheres apart: finite values; 0 for the identity and for swapping the two equal
    spheres; a map that sends one sphere's points across counts each torn pair as the largest
    sampled distance apart, against the reference with that rule."""
    mesh, _ = sphere
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    n = len(v)
    two = bsfjax.Mesh(np.concatenate([v, v + [5, 0, 0]]), np.concatenate([f, f + n]))
    ident = np.arange(2 * n)
    swap = np.concatenate([ident[n:], ident[:n]])
    assert map_distortion(two, two, ident) == 0
    assert map_distortion(two, two, swap) == pytest.approx(0, abs=1e-12)
    torn = np.concatenate([ident[:n // 2], ident[n + n // 2:], ident[n:]])  # half of piece 1
    got = map_distortion(two, two, torn, n_samples=30)
    assert np.isfinite(got) and got > 0.1
    samples = np.asarray(bsfjax.farthest_point_sampling(two, 30))

    def dist(idx):  # the reference: the same rule, written out
        g = bsfjax.geodesic_distances(two, idx)[:, idx]
        return np.where(np.isfinite(g), g, g[np.isfinite(g)].max()) / np.sqrt(two.area)
    ref = np.abs(dist(torn[samples]) - dist(samples))[~np.eye(30, dtype=bool)].mean()
    assert got == pytest.approx(ref, rel=1e-12)


def test_orientation_of_a_map_its_mirror_and_half_of_each(sphere):
    """1 for the identity, 0 for the mirror image, about the mirrored area share for a map
    mirrored on one half; a reflected target with reversed faces is matched by the identity
    as a mirror image."""
    mesh, mirror = sphere
    n = mesh.n_vertices
    ident = np.arange(n)
    assert orientation_agreement(mesh, mesh, ident) == 1
    assert orientation_agreement(mesh, mesh, mirror) == 0
    v = np.asarray(mesh.vertices)
    half = np.where(v[:, 0] > 0.3, mirror, ident)  # mirrored on the cap x > 0.3
    share = orientation_agreement(mesh, mesh, half)
    f = np.asarray(mesh.faces)
    inside = (v[f, 0] > 0.3).sum(axis=1)  # vertices of each face on the mirrored cap
    cap = mesh.face_areas()[inside == 3].sum() / mesh.area
    seam = mesh.face_areas()[(inside > 0) & (inside < 3)].sum() / mesh.area  # either way
    assert 0.05 < cap < 0.45 and seam < 0.1
    assert 1 - cap - seam <= share <= 1 - cap
    np.testing.assert_array_equal(
        orientation_agreement(mesh, mesh, np.stack([ident, mirror, half])), [1, 0, share])
    reflected = bsfjax.Mesh(v * [-1, 1, 1], f[:, ::-1])  # a consistently oriented mirror copy
    assert orientation_agreement(mesh, reflected, ident) == 0
    assert orientation_agreement(mesh, reflected, mirror) == 1


def test_choose_map():
    d, o = [0.10, 0.05, 0.02, 0.05], [0.90, 0.85, 0.50, 0.88]
    assert choose_map(d, o) == 1  # 0.02 is too far below the best orientation
    assert choose_map(d, o, slack=1.0) == 2
    assert choose_map(d, o, slack=0.0) == 0
    assert choose_map([0.05, 0.05], [0.9, 0.9]) == 0  # ties: the first
    for args, kw, msg in (((d, o[:3]), {}, "non-empty 1-D arrays of one length"),
                          (([], []), {}, "non-empty 1-D"),
                          (([np.nan, 0.1], [0.9, 0.9]), {}, "must be finite"),
                          ((d, o), {"slack": 1.5}, r"slack must be in \[0, 1\]")):
        with pytest.raises(ValueError, match=msg):
            choose_map(*args, **kw)


def test_bad_inputs_are_named(sphere):
    mesh, _ = sphere
    n = mesh.n_vertices
    for fn in (map_distortion, orientation_agreement):
        with pytest.raises(ValueError, match=r"p2p must have shape \(642,\) or \(B, 642\)"):
            fn(mesh, mesh, np.arange(n - 1))
        with pytest.raises(ValueError, match="p2p"):
            fn(mesh, mesh, np.full(n, n))
        with pytest.raises(ValueError, match="target_mesh must be a bsfjax.Mesh"):
            fn(mesh, np.zeros((3, 3)), np.arange(n))
    with pytest.raises(ValueError, match="n_samples must be an integer >= 2"):
        map_distortion(mesh, mesh, np.arange(n), n_samples=1)


def test_shared_geodesics_equal_fresh_dijkstra_and_run_each_vertex_once(sphere, monkeypatch):
    """_Geodesics (estimate_map's distortions share one per shape) answers overlapping,
    unordered, repeated vertex sets as Dijkstra from scratch does, running it from each vertex
    once; and a distortion through it equals map_distortion's."""
    import bsfjax._maps._distortion as _distortion
    mesh, mirror = sphere
    runs = []
    real = _distortion.geodesic_distances
    monkeypatch.setattr(_distortion, "geodesic_distances",
                        lambda m, src, **kw: runs.append(len(src)) or real(m, src, **kw))
    geo = _distortion._Geodesics(mesh)
    rng = np.random.default_rng(0)
    first = rng.choice(mesh.n_vertices, 30, replace=False)
    second = np.concatenate([first[10:], rng.choice(mesh.n_vertices, 25, replace=False),
                             first[:3]])  # overlaps the first, other order, a repeat
    for vs in (first, second, first[::-1]):
        np.testing.assert_allclose(geo.among(vs), real(mesh, vs)[:, vs], rtol=1e-12, atol=0)
    assert sum(runs) == len(np.union1d(first, second)) == len(geo.seen)
    p2p = np.stack([mirror, rng.permutation(mesh.n_vertices)])  # an isometry, a scramble
    shared = _distortion._distortions(mesh, mesh, p2p, 40, None, (geo, _distortion._Geodesics(
        mesh)))
    np.testing.assert_allclose(shared, map_distortion(mesh, mesh, p2p, n_samples=40),
                               rtol=1e-12, atol=1e-15)
    assert shared[0] < 1e-15 < 0.1 < shared[1]
