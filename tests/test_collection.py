"""transfer_collection: size buckets, padding, and equality with the one-pair path."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import bsfjax
from bsfjax import BSFError, transfer_collection
from bsfjax.internal import size_bucket
from bsfjax.internal import BUCKET_FACTORS


def test_size_bucket_is_a_small_bounded_set():
    prev = 0
    for n in range(1, 70_000, 37):
        b = size_bucket(n)
        assert b >= n and b >= prev  # covers n, monotone
        assert any(b == c << j for c in BUCKET_FACTORS for j in range(20))  # c · 2^j
        if n > 64:
            assert b <= 1.5 * n  # at most 50 % padding
        prev = b
    # a 3.4K–6.9K collection meets at most three sizes: few compilations
    assert len({size_bucket(n) for n in range(3400, 6900)}) <= 3


def test_merge_buckets_trades_padding_for_compilations():
    from bsfjax.internal import MERGE_PADDING, merge_buckets

    six = [size_bucket(n) for n in (6890, 6201, 5512, 4823, 4134, 3446)]
    assert set(merge_buckets(six).values()) == {8192}  # six FAUST-like targets: one size
    many = [4096] * 30 + [8192] * 50  # 30 · 4096 padded vertices > MERGE_PADDING: kept apart
    assert merge_buckets(many) == {4096: 4096, 8192: 8192}
    # exactly at the bound merges, one vertex over does not
    assert merge_buckets([100, 100, 100 + MERGE_PADDING // 2]) == {100: 100 + MERGE_PADDING // 2,
                                                                   100 + MERGE_PADDING // 2:
                                                                   100 + MERGE_PADDING // 2}
    assert merge_buckets([100, 100, 101 + MERGE_PADDING // 2])[100] == 100
    # a chain: what moved up moves on with its new bucket, never down
    into = merge_buckets([512, 1024, 1024, 3072])
    assert into == {512: 3072, 1024: 3072, 3072: 3072}


def test_merged_buckets_give_the_unpadded_results():
    """Two targets in two buckets (512, 2048) of a small collection are computed in one
    (2048 vertices, the larger face bucket): the same point maps and labels as unpadded."""
    from bsfjax._pipeline._collection import _merged_sizes

    small, large = bsfjax.example_pair(levels=1), bsfjax.example_pair(levels=2)
    targets = [small.target, large.target]
    sizes = _merged_sizes(targets, lambda i, mesh: None)
    assert sizes[0] == sizes[1] == (2048, size_bucket(large.target.n_faces))
    # one start: the maps from the padded stages (several: estimate_map's, never padded)
    runs = [dict(transfer_collection(small.source, small.labels, targets, method="p2p", k=10,
                                     zoomout_samples=300, pad=pad, starts=((10, 7.0),)))
            for pad in (True, False)]
    for i in range(2):
        np.testing.assert_array_equal(runs[0][i].p2p, runs[1][i].p2p)
        np.testing.assert_array_equal(runs[0][i].labels, runs[1][i].labels)


def test_each_target_file_is_read_once(tmp_path, monkeypatch):
    """The size scan's meshes serve the run: one read per target file, the same results as
    targets given as meshes."""
    import bsfjax._pipeline._collection as _collection
    small, large = bsfjax.example_pair(levels=1), bsfjax.example_pair(levels=2)
    paths = [tmp_path / "a.off", tmp_path / "b.off"]
    for path, mesh in zip(paths, (small.target, large.target)):
        bsfjax.save_mesh(path, mesh)
    reads = []

    def counting(path):
        reads.append(str(path))
        return bsfjax.load_mesh(path)

    monkeypatch.setattr(_collection, "load_mesh", counting)
    kw = dict(method="p2p", k=10, zoomout_samples=300, starts=((10, 7.0),))
    from_files = dict(transfer_collection(small.source, small.labels, paths, **kw))
    assert sorted(reads) == sorted(map(str, paths))
    from_meshes = dict(transfer_collection(small.source, small.labels,
                                           [bsfjax.load_mesh(q) for q in paths], **kw))
    for i in range(2):
        np.testing.assert_array_equal(from_files[i].labels, from_meshes[i].labels)


@pytest.fixture(scope="module")
def collection():
    """Source: the example source (506 V); targets: the example target at two resolutions
    (506 and 2018 V: padded to the buckets 512 and 2048), the second with landmarks (its own
    bucket key), in one call."""
    small = bsfjax.example_pair(levels=1)
    large = bsfjax.example_pair(levels=2)
    lm_src = [0, 100, 200, 300]
    lm = {1: (lm_src, lm_src)}  # levels keep the coarse vertices first: vertex i ↔ vertex i
    targets = [small.target, large.target]
    # ZoomOut on 300 samples of each shape: the samples are padded with the vertices
    res = dict(transfer_collection(small.source, small.labels, targets, method="refined", k=10,
                                   landmarks=lambda i: lm.get(i), zoomout_samples=300))
    return small, targets, lm, res


def _one_pair_maps(small, targets, lm):
    """``(i, target, source spectrum, target spectrum, estimate_map)`` of the one-pair path
    for each target of the ``collection`` fixture (its options)."""
    sm = bsfjax.spectrum(small.source, 100)
    for i, t in enumerate(targets):
        sn = bsfjax.spectrum(t, 100)
        # ZoomOut to 2k = 20, where landmarks guide it to the spectra's 100 (guided_to)
        yield i, t, sm, sn, bsfjax.estimate_map(
            sm, sn, k=10, refine_to=20, landmarks=lm.get(i), source_mesh=small.source,
            target_mesh=t, zoomout_samples=300)


def test_padded_targets_equal_the_one_pair_path(collection):
    """Each target's result, computed padded to its size bucket, is the one of the unpadded
    one-pair path, estimate_map then transfer_labels (what ``bsfjax transfer --out`` runs):
    the same point map and labels, bit for bit (``"refined"`` continuing on ZoomOut's samples)."""
    small, targets, lm, padded = collection
    assert all(size_bucket(t.n_vertices) > t.n_vertices for t in targets)  # really padded
    for i, t, sm, sn, est in _one_pair_maps(small, targets, lm):
        res = bsfjax.transfer_labels(sm, sn, small.labels, C=est.C, p2p=est.p2p,
                                     mesh=small.source, samples=est.samples)
        assert padded[i].labels.shape == padded[i].p2p.shape == (t.n_vertices,)
        np.testing.assert_array_equal(padded[i].p2p, est.p2p)
        np.testing.assert_allclose(padded[i].C, est.C, atol=1e-4)
        np.testing.assert_array_equal(padded[i].labels, res.labels)
        assert padded[i].regime == res.regime
        assert padded[i].unassigned_share == pytest.approx(res.unassigned_share, abs=1e-6)
        assert padded[i].agreement == pytest.approx(res.agreement, abs=1e-6)
        assert np.isfinite(padded[i].map_energy) and padded[i].map_energy > 0
    # the pair is the same shape in another pose: the transfer is nearly right
    truth = small.labels[small.p2p]
    mass = np.asarray(bsfjax.spectrum(targets[0], 2).mass)
    assert np.sum(mass * (padded[0].labels == truth)) / mass.sum() > 0.9


def test_labels_of_triangles_equal_the_one_pair_path(collection):
    """faces=True: each target's triangles labelled as estimate_map then transfer_face_labels
    label them (padded targets: the padding adds no triangle)."""
    small, targets, lm, _ = collection
    faces = bsfjax.face_labels_from_vertices(small.source, small.labels)
    got = dict(transfer_collection(small.source, faces, targets, method="refined", k=10,
                                   landmarks=lambda i: lm.get(i), zoomout_samples=300,
                                   faces=True))
    for i, t, sm, sn, est in _one_pair_maps(small, targets, lm):
        res = bsfjax.transfer_face_labels(sm, sn, faces, source_mesh=small.source,
                                          target_mesh=t, C=est.C, p2p=est.p2p,
                                          samples=est.samples)
        assert got[i].labels.shape == (t.n_faces,)
        np.testing.assert_array_equal(got[i].labels, res.labels)
        assert got[i].regime == res.regime
        assert got[i].agreement == pytest.approx(res.agreement, abs=1e-6)
    with pytest.raises(BSFError, match="one entry per face"):
        list(transfer_collection(small.source, small.labels, targets, faces=True))
    with pytest.raises(BSFError, match="labels must be True"):
        list(transfer_collection(small.source, faces, targets, faces=True, labels=False))


def test_one_start_runs_targets_without_landmarks_through_the_batched_stages(collection):
    """``starts=((k, wks_variance),)``: a target without landmarks gets the single start's
    map from the padded stages, equal to estimate_map with that start (and not the default's
    choice among starts, which is another map here)."""
    small, targets, _, default = collection
    one = dict(transfer_collection(small.source, small.labels, targets[:1], method="refined",
                                   k=10, zoomout_samples=300, starts=((10, 7.0),)))[0]
    sm, sn = bsfjax.spectrum(small.source, 100), bsfjax.spectrum(targets[0], 100)
    kw = dict(k=10, refine_to=20, source_mesh=small.source, target_mesh=targets[0],
              zoomout_samples=300)
    est = bsfjax.estimate_map(sm.truncate(20), sn.truncate(20), starts=((10, 7.0),), **kw)
    np.testing.assert_array_equal(one.p2p, est.p2p)
    np.testing.assert_allclose(one.C, est.C, atol=1e-4)
    chosen = bsfjax.estimate_map(sm.truncate(20), sn.truncate(20), **kw)
    assert chosen.start is not None and not np.array_equal(chosen.p2p, est.p2p)
    np.testing.assert_array_equal(default[0].p2p, chosen.p2p)
    # the turn check's doubt comes with the chosen map; one start and landmarks have none
    assert isinstance(chosen.turn_doubtful, bool)
    assert default[0].turn_doubtful is chosen.turn_doubtful
    assert one.turn_doubtful is None and default[1].turn_doubtful is None
    with pytest.raises(ValueError, match="k0 must be an integer"):
        next(transfer_collection(small.source, small.labels, targets[:1], k=10,
                                 starts=((0, 7.0),)))


def test_the_collection_follows_its_estimators_fields(collection):
    """A given [`MapEstimator`]: the batched stages follow its ZoomOut step and its single
    start's WKS variance (the estimator's own map at ``k`` and ``2k``, not the default's), and a
    target without landmarks gets the estimator's choice among its starts; the map options
    are not given beside it."""
    import dataclasses
    small, targets, _, _ = collection
    target = targets[0]
    sm, sn = bsfjax.spectrum(small.source, 20), bsfjax.spectrum(target, 20)
    meshes = dict(source_mesh=small.source, target_mesh=target)
    kw = dict(method="p2p", k=10)

    def run(estimator):
        return dict(transfer_collection(small.source, small.labels, [target], **kw,
                                        estimator=estimator))[0]

    default = dict(transfer_collection(small.source, small.labels, [target], **kw,
                                       zoomout_samples=300, starts=((10, 7.0),)))[0]
    # ZoomOut's step: the estimator's own map, bit for bit (not the default step's)
    step = bsfjax.MapEstimator(k=99, zoomout_samples=300, starts=((10, 7.0),), zoomout_step=1)
    got = run(step)
    own = dataclasses.replace(step, k=10, refine_to=20)(sm, sn, **meshes)
    np.testing.assert_array_equal(got.p2p, own.p2p)
    np.testing.assert_allclose(got.C, own.C, atol=1e-4)
    assert np.sum(default.p2p != own.p2p) > 50
    # the single start's WKS variance: the estimator's own map up to the solver's tolerance
    # (11 of 506 vertices differ; 373 from the default variance's map)
    wider = bsfjax.MapEstimator(zoomout_samples=300, starts=((10, 3.5),), wks_variance=3.5)
    got = run(wider)
    own = dataclasses.replace(wider, k=10, refine_to=20)(sm, sn, **meshes)
    assert np.mean(got.p2p == own.p2p) > 0.95 and np.mean(default.p2p == own.p2p) < 0.5
    np.testing.assert_allclose(got.C, own.C, atol=1e-2)
    several = bsfjax.MapEstimator(zoomout_samples=300, starts=((10, 3.5), (20, 7.0)),
                                  derived_landmarks=0, turn_check=False)
    got = run(several)
    own = dataclasses.replace(several, k=10, refine_to=20)(sm, sn, **meshes)
    np.testing.assert_array_equal(got.p2p, own.p2p)
    assert own.start is not None and got.turn_doubtful is None  # (no turn check)
    with pytest.raises(BSFError, match="give n_energies, zoomout_samples and starts as its"):
        next(transfer_collection(small.source, small.labels, [target], k=10, estimator=step,
                                 starts=((10, 7.0),)))
    with pytest.raises(BSFError, match="estimator must be a bsfjax.MapEstimator"):
        next(transfer_collection(small.source, small.labels, [target], k=10, estimator="one"))


def test_source_operators_follow_each_targets_landmarks():
    """The source's share of the estimation problem is computed once per set of source
    landmarks and reused: a target whose source landmarks differ from
    the previous target's gets its own, so each result equals the target's run alone."""
    small = bsfjax.example_pair(levels=1)
    lms = [([0, 100, 200, 300],) * 2, ([5, 150, 250, 400],) * 2, ([0, 100, 200, 300],) * 2]
    targets = [small.target] * 3
    kw = dict(method="p2p", k=10, zoomout_samples=300, starts=((10, 7.0),))
    together = dict(transfer_collection(small.source, small.labels, targets, landmarks=lms, **kw))
    for i in (1, 2):
        alone = dict(transfer_collection(small.source, small.labels, [small.target],
                                         landmarks=[lms[i]], **kw))[0]
        np.testing.assert_array_equal(together[i].p2p, alone.p2p)
        np.testing.assert_allclose(together[i].C, alone.C, atol=1e-6)
    assert not np.array_equal(together[0].C, together[1].C)  # the landmarks matter


def test_targets_in_other_units():
    """A target in millimetres (×1000) or in kilometres: the point map and labels of the same
    target in the source's units, ``C`` ×s (the one-pair path's invariance)."""
    small = bsfjax.example_pair(levels=1)
    lm = ([0, 100, 200, 300],) * 2
    targets = [bsfjax.Mesh(small.target.vertices * s, small.target.faces)
               for s in (1.0, 1e3, 1e-3)]
    res = dict(transfer_collection(small.source, small.labels, targets, landmarks=[lm] * 3,
                                   method="refined", k=10, zoomout_samples=300))
    for i, s in ((1, 1e3), (2, 1e-3)):
        # float32 near-ties aside (with landmarks ZoomOut runs to all 100 eigenpairs of this
        # 506-vertex mesh on 300 samples: 92-98 % of the point map equal, the labels all)
        assert np.mean(res[i].p2p == res[0].p2p) > 0.9, s
        assert np.mean(res[i].labels == res[0].labels) > 0.98, s
        np.testing.assert_allclose(res[i].C / s, res[0].C, atol=5e-3)
    assert np.mean(res[0].labels == small.labels) > 0.9  # (vertex i ↔ vertex i)


@pytest.mark.parametrize("x64", [False, True])
def test_batched_targets_equal_one_at_a_time(x64):
    """``batch=2``: the targets of a bucket run two at a time under ``vmap``, the last group
    short of one (filled with a copy): the same point maps and labels as ``batch=1``, the maps
    and scores to float round-off, each target's result in its own slot (float32 and 64)."""
    small = bsfjax.example_pair(levels=1)
    large = bsfjax.example_pair(levels=2)
    targets = [small.target, large.target, small.target, large.target, small.target]
    # one start: every map through the batched stages (several: estimate_map's, on the host)
    kw = dict(method="refined", k=10, zoomout_samples=300, starts=((10, 7.0),))
    with jax.enable_x64(x64):
        one = dict(transfer_collection(small.source, small.labels, targets, **kw))
        two = dict(transfer_collection(small.source, small.labels, targets, batch=2, **kw))
    assert sorted(two) == list(range(5))
    for i, t in enumerate(targets):
        assert two[i].p2p.shape == (t.n_vertices,)
        np.testing.assert_array_equal(two[i].p2p, one[i].p2p)
        np.testing.assert_array_equal(two[i].labels, one[i].labels)
        np.testing.assert_allclose(two[i].C, one[i].C, atol=1e-5)
        np.testing.assert_allclose(two[i].values, one[i].values, atol=1e-5)
    with pytest.raises(BSFError, match="batch must be an integer >= 1"):
        next(transfer_collection(small.source, small.labels, targets, batch=0))


def test_errors_are_reported_per_target_or_raised(tmp_path):
    small = bsfjax.example_pair(levels=1)
    bad = tmp_path / "bad.off"
    bad.write_text("not a mesh\n")
    out = list(transfer_collection(small.source, small.labels, [bad], method="p2p", k=10,
                                   errors="report"))
    assert len(out) == 1 and out[0][0] == 0 and isinstance(out[0][1], ValueError)
    assert "bad.off" in str(out[0][1])
    with pytest.raises(ValueError, match="bad.off"):
        list(transfer_collection(small.source, small.labels, [bad], method="p2p", k=10))
    # invalid landmarks for one target: reported for it (not a crash of the size scan), the
    # other target finishes
    out = dict(transfer_collection(small.source, small.labels, [small.target, small.target],
                                   method="p2p", k=10, landmarks=[(5,), None],
                                   errors="report"))
    assert isinstance(out[0], (BSFError, ValueError))
    assert out[1].labels.shape == (small.target.n_vertices,)


@pytest.mark.parametrize("kwargs, match", [
    (dict(method="std2"), "std2"),
    (dict(k=1), "k"),
    (dict(errors="ignore"), "errors"),
    (dict(threshold=1.5), r"threshold must be in \[0, 1\)"),
])
def test_bad_options(kwargs, match):
    small = bsfjax.example_pair(levels=1)
    with pytest.raises(BSFError, match=match):
        list(transfer_collection(small.source, small.labels, [small.target], **kwargs))


def test_bad_values_and_landmarks():
    small = bsfjax.example_pair(levels=1)
    with pytest.raises(BSFError, match="one entry per source vertex"):
        list(transfer_collection(small.source, small.labels[:-1], [small.target]))
    out = list(transfer_collection(small.source, small.labels, [small.target], k=10,
                                   landmarks=[([0, 1], [0])], errors="report"))
    assert isinstance(out[0][1], BSFError) and "equal" in str(out[0][1])
    out = list(transfer_collection(small.source, small.labels, [small.target], k=10,
                                   landmarks=[([0], [10**6])], errors="report"))
    assert isinstance(out[0][1], BSFError) and "target landmarks" in str(out[0][1])


def test_host_work_overlaps_the_stages_on_one_blas_thread(monkeypatch):
    """On a CPU the next target's eigensolve runs while the group before it computes, with
    one BLAS thread (``_threads``); a target from ``ONE_THREAD_BELOW`` vertices on waits for
    the group instead and keeps the default threads.  Either way the results are the same."""
    from threadpoolctl import threadpool_info

    import bsfjax._pipeline._collection as _collection
    import bsfjax._util._threads as _threads

    small, large = bsfjax.example_pair(levels=1), bsfjax.example_pair(levels=2)
    targets = [small.target, large.target, small.target]
    seen, solve = [], _collection.spectrum

    def recording(mesh, k, **kw):
        if mesh is not small.source:
            seen.append(max(lib["num_threads"] for lib in threadpool_info()
                            if lib["user_api"] == "blas"))
        return solve(mesh, k, **kw)

    monkeypatch.setattr(_collection, "spectrum", recording)
    kw = dict(method="p2p", k=10, zoomout_samples=300, starts=((10, 7.0),))
    overlapped = dict(transfer_collection(small.source, small.labels, targets, **kw))
    default = max(lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas")
    # (one device: each target is dispatched once prepared, so the next one overlaps it)
    assert len(jax.local_devices()) > 1 or seen == [default, 1, 1]
    seen.clear()
    monkeypatch.setattr(_threads, "ONE_THREAD_BELOW", 0)
    waited = dict(transfer_collection(small.source, small.labels, targets, **kw))
    assert seen == [default] * 3
    for i in range(3):
        np.testing.assert_array_equal(overlapped[i].p2p, waited[i].p2p)
        np.testing.assert_array_equal(overlapped[i].labels, waited[i].labels)


def test_a_target_missing_parts_is_estimated_again(collection, monkeypatch):
    """A target whose labels miss source parts has its map estimated again with
    ``derived_guidance`` (as ``bsfjax transfer``; with landmarks: phases 3 and 4 after their
    map), and that result is the one yielded: equal to the collection run with such an
    estimator from the start; with ``estimate_again=False`` it is estimated once."""
    import bsfjax._pipeline._collection as col
    small, targets, lm, _ = collection
    used = []
    real = col.for_point_clouds

    def spy(est, *meshes):
        used.append(est.derived_guidance)
        return real(est, *meshes)

    real_missing = col.missing_parts
    monkeypatch.setattr(col, "for_point_clouds", spy)
    monkeypatch.setattr(col, "missing_parts",  # (every target misses a part)
                        lambda *a: tuple(real_missing(*a)) or (int(small.labels[0]),))
    kw = dict(method="refined", k=10, zoomout_samples=300, landmarks=lambda i: lm.get(i))
    chosen = []  # the choices among starts (phase 2): the second estimate resumes the first's
    real_choose = bsfjax.MapEstimator._choose_start
    monkeypatch.setattr(bsfjax.MapEstimator, "_choose_start",
                        lambda self, *a: chosen.append(1) or real_choose(self, *a))
    got = dict(transfer_collection(small.source, small.labels, targets, **kw))
    assert used == [False, False, True, True]  # (target 1 with its landmarks too)
    assert len(chosen) == 1  # (target 0's: with landmarks there is no choice among starts)
    assert got[0].estimated_again and got[1].estimated_again
    used.clear()
    partial = bsfjax.MapEstimator(zoomout_samples=300, derived_guidance=True)
    direct = dict(transfer_collection(small.source, small.labels, targets, method="refined",
                                      k=10, estimator=partial, landmarks=lambda i: lm.get(i)))
    assert used == [True, True] and not direct[0].estimated_again
    for i in range(2):
        np.testing.assert_array_equal(got[i].p2p, direct[i].p2p)
        np.testing.assert_array_equal(got[i].labels, direct[i].labels)
    assert got[0].seconds > direct[0].seconds * 0.5  # (both estimates counted)
    used.clear()
    once = dict(transfer_collection(small.source, small.labels, targets[:1], **kw,
                                    estimate_again=False))[0]
    assert used == [False] and not once.estimated_again and once.missing
