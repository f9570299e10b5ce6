"""Segmentations given per triangle (bsfjax._pipeline._face_labels): shares, decision, transfer."""

from __future__ import annotations

import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError, Mesh, transfer_face_labels
from bsfjax.internal import face_label_shares, face_scores
from bsfjax import REGIMES

from .conftest import data_path, icosphere


def _kite() -> Mesh:
    """Two triangles on the edge 1–2: (0, 1, 2) of area ½ and (1, 3, 2) of area 3/2, and a
    zero-area triangle (0, 4, 1) whose vertex 4 is in nothing else."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 0], [0.5, 0, 0]], float)
    return Mesh(v, np.array([[0, 1, 2], [1, 3, 2], [0, 4, 1]]))


def test_shares_are_the_area_shares_of_each_star():
    ids, shares = face_label_shares(_kite(), [5, 2, 7])
    np.testing.assert_array_equal(ids, [2, 5, 7])
    expected = np.array([  # vertex: 0, 1, 2, 3, 4
        [0.0, 0.75, 0.75, 1.0, 0.0],   # label 2: the triangle of area 3/2
        [1.0, 0.25, 0.25, 0.0, 0.0],   # label 5: area 1/2 (the flat triangle adds no area)
        [0.0, 0.0, 0.0, 0.0, 1.0],     # label 7: vertex 4's star is flat, so triangles count
    ])
    np.testing.assert_allclose(shares, expected, rtol=0, atol=1e-15)


def test_triangles_take_the_majority_of_their_corners():
    mesh = _kite()  # triangles (0, 1, 2), (1, 3, 2), (0, 4, 1)
    got = bsfjax.face_labels_from_vertices(mesh, np.array([0, 1, 1, 2, 3]))
    np.testing.assert_array_equal(got, [1, 1, 0])  # corners 0 1 1, 1 2 1; 0 3 1 all differ
    with pytest.raises(BSFError, match="one entry per vertex"):
        bsfjax.face_labels_from_vertices(mesh, np.zeros(3, int))


def test_face_scores_average_the_corners():
    mesh = _kite()
    s = np.arange(10.0).reshape(2, 5)
    np.testing.assert_allclose(face_scores(mesh, s), s[:, mesh.faces].mean(axis=2))
    with pytest.raises(BSFError, match=r"shape \(L, 5\)"):
        face_scores(mesh, s[:, :4])


def _brute_force(source: Mesh, target: Mesh, face_labels, p2p):
    """Face labels pulled back through a point map, vertex by vertex and face by face."""
    ids = np.unique(face_labels)
    area = source.face_areas()
    share = np.zeros((source.n_vertices, ids.size))
    for f, tri in enumerate(source.faces):
        for v in tri:
            share[v, np.searchsorted(ids, face_labels[f])] += area[f]
    share /= share.sum(axis=1, keepdims=True)
    out = np.empty(target.n_faces, np.int64)
    for f, tri in enumerate(target.faces):
        out[f] = ids[np.argmax(sum(share[p2p[y]] for y in tri) / 3)]
    return out


@pytest.fixture(scope="module")
def spheres():
    v, f = icosphere(2)
    source = Mesh(v, f)
    rng = np.random.default_rng(0)
    target = Mesh(v * [1.0, 1.3, 0.8] + 0.01 * rng.standard_normal(v.shape), f)
    return source, target, bsfjax.spectrum(source, 12), bsfjax.spectrum(target, 12)


@pytest.mark.parametrize("x64", [False, True])
def test_pull_back_matches_a_brute_force_loop(spheres, x64):
    source, target, sm, sn = spheres
    rng = np.random.default_rng(1)
    # a labelling with regions (by height) and some single-triangle islands
    height = source.vertices[source.faces].mean(axis=1)[:, 2]
    labels = np.digitize(height, [-0.5, 0.0, 0.5]) * 3
    labels[rng.choice(source.n_faces, 15, replace=False)] = 10
    p2p = rng.integers(0, source.n_vertices, target.n_vertices)
    import jax

    with jax.enable_x64(x64):
        res = transfer_face_labels(sm, sn, labels, source_mesh=source, target_mesh=target,
                                   method="p2p", p2p=p2p)
    np.testing.assert_array_equal(res.labels, _brute_force(source, target, labels, p2p))
    assert res.scores.shape == (5, target.n_faces)  # labels 0, 3, 6, 9 and the islands
    assert res.unassigned_share == 0 and res.agreement == 1.0 and res.regime is None
    np.testing.assert_allclose(res.scores.sum(axis=0), 1.0, atol=1e-5)


def test_identity_gives_back_a_labelling_of_regions(spheres):
    source, _, sm, _ = spheres
    height = source.vertices[source.faces].mean(axis=1)[:, 2]
    labels = np.digitize(height, [-0.3, 0.4])
    res = transfer_face_labels(sm, sm, labels, source_mesh=source, target_mesh=source,
                               method="p2p", p2p=np.arange(source.n_vertices))
    np.testing.assert_array_equal(res.labels, labels)


def test_refined_votes_and_reports_its_regime(spheres):
    # an ellipsoid source: a round sphere's eigenspaces are degenerate (its basis inside them
    # is arbitrary), and ZoomOut from 6 eigenpairs would cut through one
    _, target, _, sn = spheres
    v, f = icosphere(2)
    source = Mesh(v * [1.0, 1.1, 0.9], f)
    sm = bsfjax.spectrum(source, 12)
    height = source.vertices[source.faces].mean(axis=1)[:, 2]
    labels = np.digitize(height, [-0.3, 0.4])
    p2p = np.arange(source.n_vertices)
    res = transfer_face_labels(sm, sn, labels, source_mesh=source, target_mesh=target,
                               method="refined", p2p=p2p, k_start=6, k_max=12, step=3)
    assert res.labels.shape == (target.n_faces,) and res.regime in REGIMES
    area = target.face_areas()
    assert np.sum(area * (res.labels == labels)) / area.sum() > 0.9
    assert res.confidence is None  # the scores are area shares, not votes


def test_a_fine_segmentation_is_not_called_unreliable(spheres):
    """With many small parts almost every triangle is at a border, so its winning share is
    far below 1 whatever the map: the regime comes from the agreement, not from the scores."""
    source, _, sm, _ = spheres
    labels = np.arange(source.n_faces) // 4  # 80 parts of about 4 triangles
    res = transfer_face_labels(sm, sm, labels, source_mesh=source, target_mesh=source,
                               method="refined", p2p=np.arange(source.n_vertices),
                               k_start=6, k_max=12, step=3)
    area = source.face_areas()
    assert np.sum(area * res.scores.max(axis=0)) / area.sum() < 0.8  # a vote would say so
    assert res.regime != "unreliable" and res.confidence is None


def test_bad_input_is_named(spheres):
    source, target, sm, sn = spheres
    kw = dict(source_mesh=source, target_mesh=target, method="p2p",
              p2p=np.arange(target.n_vertices))
    with pytest.raises(BSFError, match="one entry per face"):
        transfer_face_labels(sm, sn, np.zeros(source.n_vertices, int), **kw)
    with pytest.raises(BSFError, match=">= 0"):
        transfer_face_labels(sm, sn, -np.ones(source.n_faces, int), **kw)
    with pytest.raises(BSFError, match="integers"):
        transfer_face_labels(sm, sn, np.full(source.n_faces, 0.5), **kw)
    with pytest.raises(BSFError, match="target_mesh has total area .* the target spectrum"):
        transfer_face_labels(sm, sn, np.zeros(source.n_faces, int),
                             **{**kw, "target_mesh": source})  # same count, another shape
    with pytest.raises(BSFError, match="target_mesh has 5 vertices"):
        transfer_face_labels(sm, sn, np.zeros(source.n_faces, int),
                             **{**kw, "target_mesh": _kite()})
    with pytest.raises(BSFError, match="do not give mesh="):
        transfer_face_labels(sm, sn, np.zeros(source.n_faces, int), mesh=source, **kw)


def test_smpl_parts_of_faust_by_triangle():
    """The SMPL parts as triangle labels (majority of the corners) carried through the exact
    map of two registrations: the shares keep the parts to within the triangles that stick
    out of them."""
    seg = data_path("segmentations", "smpl_vert_segmentation.json")
    source = bsfjax.load_mesh(data_path("faust", "tr_reg_000.off"))
    target = bsfjax.load_mesh(data_path("faust", "tr_reg_001.off"))
    vertex_labels, _ = bsfjax.load_labels(seg)
    labels = bsfjax.face_labels_from_vertices(source, vertex_labels)
    sm, sn = bsfjax.spectrum(source, 4), bsfjax.spectrum(target, 4)
    res = transfer_face_labels(sm, sn, labels, source_mesh=source, target_mesh=target,
                               method="p2p", p2p=np.arange(target.n_vertices))
    area = target.face_areas()
    accuracy = np.sum(area * (res.labels == labels)) / area.sum()
    assert 0.999 < accuracy < 1.0  # 99.95 %: a few triangles stick out of their part
