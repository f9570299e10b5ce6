"""The descriptor-guided ZoomOut continuation (``_refine.py``) and the ``"refined"`` method."""

import jax
import numpy as np
import pytest

import bsfjax as bj
from bsfjax.internal import refinement_sizes

K = 40


@pytest.fixture(scope="module")
def pair():
    ex = bj.example_pair(levels=2)  # ~2000 vertices, identity ground truth, six parts
    return ex, bj.spectrum(ex.source, K), bj.spectrum(ex.target, K)


def _corrupt(n, share, seed=0):
    rng = np.random.default_rng(seed)
    p = np.arange(n)
    bad = rng.random(n) < share
    p[bad] = rng.integers(0, n, bad.sum())
    return p


def _acc(labels, truth, mass):
    mass = np.asarray(mass)
    return float(np.sum(mass * (labels == truth)) / mass.sum())


def test_sizes():
    assert refinement_sizes(60, 100, 20) == (60, 80, 100)
    assert refinement_sizes(60, 100, 30) == (60, 90, 100)  # last step clipped
    assert refinement_sizes(60, 40, 20) == (40,)  # start clipped to k_max


def test_without_descriptors_is_zoomout(pair):
    """w = 0: the last map is ZoomOut's (an independent, tested route) from the same start."""
    ex, sm, sn = pair
    p0 = _corrupt(sn.n_vertices, 0.2)
    maps = np.asarray(bj.refine_point_maps(sm, sn, p0, k_start=20, step=10, n_keep=3,
                                           descriptor_weight=0.0))
    assert maps.shape == (3, sn.n_vertices)
    C0 = bj.fmap_from_p2p(sm.truncate(20), sn.truncate(20), p0)
    C = bj.zoomout(C0, sm, sn, K, step=10)
    np.testing.assert_array_equal(maps[-1], np.asarray(bj.fmap_to_p2p(C, sm, sn)))
    C30 = bj.zoomout(C0, sm.truncate(30), sn.truncate(30), 30, step=10)
    np.testing.assert_array_equal(maps[-2], np.asarray(bj.fmap_to_p2p(C30, sm.truncate(30),
                                                                       sn.truncate(30))))


def test_repairs_a_corrupted_map(pair):
    """30 % of the point map replaced by random vertices: the refined labels are right on
    almost all the area, far above the corrupted map's pull-back."""
    ex, sm, sn = pair
    p0 = _corrupt(sn.n_vertices, 0.3, seed=1)
    before = _acc(ex.labels[p0], ex.labels, sn.mass)
    res = bj.transfer_labels(sm, sn, ex.labels, p2p=p0, method=bj.RefinedPullBack(k_start=20,
                                                                                  step=10))
    after = _acc(res.labels, ex.labels, sn.mass)
    assert before < 0.8 and after > 0.97, (before, after)
    assert res.regime == "corrected" and res.unassigned_share == 0.0
    assert res.agreement == pytest.approx(_acc(res.labels, ex.labels[p0], sn.mass))


def test_engine_is_the_weighted_vote(pair):
    """transfer_values = Σ_t w_t f ∘ T_t over refine_point_maps' maps (w ∝ 1 + 10⁻³ t)."""
    ex, sm, sn = pair
    p0 = _corrupt(sn.n_vertices, 0.1, seed=2)
    opts = dict(k_start=20, step=10)
    maps = np.asarray(bj.refine_point_maps(sm, sn, p0, n_keep=3, **opts))
    f = np.random.default_rng(0).random((2, sm.n_vertices))
    w = 1 + 1e-3 * np.arange(3)
    want = np.einsum("t,mtn->mn", w / w.sum(), f[:, maps])
    got = bj.transfer_values(sm, sn, f, p2p=p0, method="refined", n_vote=3, **opts)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    # the default: the pull-back through the last map alone
    np.testing.assert_allclose(bj.transfer_values(sm, sn, f, p2p=p0, method="refined", **opts),
                               f[:, maps[-1]], rtol=1e-6)
    # starting from C instead of a point map: the same as from C's nearest-neighbour point map
    C = np.asarray(bj.fmap_from_p2p(sm.truncate(20), sn.truncate(20), p0))
    pC = np.asarray(bj.fmap_to_p2p(C, sm.truncate(20), sn.truncate(20)))
    np.testing.assert_allclose(bj.transfer_values(sm, sn, f, C=C, method="refined", **opts),
                               bj.transfer_values(sm, sn, f, p2p=pC, method="refined", **opts),
                               rtol=1e-5, atol=1e-6)


def _samples(ex, n):
    return bj.subsample(ex.source, n), bj.subsample(ex.target, n)


def test_samples_covering_every_vertex_are_the_exact_computation(pair):
    """Each vertex its own sample (unit cells): the quadrature is Φ_Nᵀ A_N Π Φ_M and the
    searches are over every vertex, so the maps equal those without samples."""
    ex, sm, sn = pair
    p0 = _corrupt(sn.n_vertices, 0.2, seed=8)
    opts = dict(k_start=20, step=10, n_keep=1)
    every = _samples(ex, 10 ** 6)
    np.testing.assert_array_equal(np.asarray(bj.refine_point_maps(sm, sn, p0, samples=every,
                                                                  **opts)),
                                  np.asarray(bj.refine_point_maps(sm, sn, p0, **opts)))


def test_kept_steps_run_on_every_vertex(pair):
    """Samples only replace the steps whose maps are not kept: with every step kept they
    change nothing; with one kept, the earlier steps are ZoomOut on the samples."""
    ex, sm, sn = pair
    p0 = _corrupt(sn.n_vertices, 0.2, seed=9)
    S = _samples(ex, 500)
    opts = dict(k_start=20, step=10, descriptor_weight=0.0)
    np.testing.assert_array_equal(
        np.asarray(bj.refine_point_maps(sm, sn, p0, n_keep=3, samples=S, **opts)),
        np.asarray(bj.refine_point_maps(sm, sn, p0, n_keep=3, **opts)))
    # w = 0, one map kept: sizes 20 → 30 on the samples (bsfjax.zoomout with samples, a tested
    # route), then the 40-eigenpair search over every vertex
    last = np.asarray(bj.refine_point_maps(sm, sn, p0, n_keep=1, samples=S, **opts))[-1]
    C0 = bj.fmap_from_p2p(sm.truncate(20), sn.truncate(20), p0)
    C = bj.zoomout(C0, sm, sn, K, step=10, samples=S)
    np.testing.assert_array_equal(last, np.asarray(bj.fmap_to_p2p(C, sm, sn)))


def test_samples_repair_a_corrupted_map(pair):
    """The sampled continuation keeps the full one's repair (30 % random matches)."""
    ex, sm, sn = pair
    p0 = _corrupt(sn.n_vertices, 0.3, seed=1)
    method = bj.RefinedPullBack(k_start=20, step=10)
    res = bj.transfer_labels(sm, sn, ex.labels, p2p=p0, method=method, samples=_samples(ex, 500))
    assert _acc(res.labels, ex.labels, sn.mass) > 0.97
    assert res.confidence == pytest.approx(1.0)  # one map: 0/1 scores


def test_bad_samples(pair):
    ex, sm, sn = pair
    p = np.arange(sn.n_vertices)
    S = _samples(ex, 300)
    with pytest.raises(bj.BSFError, match="samples"):
        bj.refine_point_maps(sm, sn, p, samples=S[::-1][:1])
    bad = (S[0], bj.Subsample(S[1].indices, S[1].cells[:-1]))
    with pytest.raises(bj.BSFError, match="target samples"):
        bj.refine_point_maps(sm, sn, p, samples=bad)
    with pytest.raises(bj.BSFError, match="target samples"):
        bj.transfer_labels(sm, sn, ex.labels, p2p=p, samples=bad)


def test_vmapped_pairs_equal_single(pair):
    ex, sm, sn = pair
    p0, p1 = _corrupt(sn.n_vertices, 0.1, seed=3), _corrupt(sn.n_vertices, 0.2, seed=4)
    f = np.asarray(bj.labels_to_indicators(ex.labels), np.float32)
    method = bj.RefinedPullBack(k_start=20, step=10)
    S = _samples(ex, 500)
    pairs = [bj.Pair(source=sm, target=sn, p2p=p, samples=S) for p in (p0, p1)]
    both = bj.transfer_pairs(method, pairs, np.stack([f, f])).transferred
    for i, p in enumerate((p0, p1)):
        one = bj.transfer(method, bj.Pair(source=sm, target=sn, p2p=p, samples=S), f).transferred
        np.testing.assert_allclose(np.asarray(both[i]), np.asarray(one), atol=1e-6)


def test_label_permutation_equivariance(pair):
    ex, sm, sn = pair
    p0 = _corrupt(sn.n_vertices, 0.15, seed=5)
    perm = np.random.default_rng(0).permutation(ex.labels.max() + 1)
    method = bj.RefinedPullBack(k_start=20, step=10)
    a = bj.transfer_labels(sm, sn, ex.labels, p2p=p0, method=method).labels
    b = bj.transfer_labels(sm, sn, perm[ex.labels], p2p=p0, method=method).labels
    np.testing.assert_array_equal(perm[a], b)


def test_float64_same_maps(pair):
    ex, sm, sn = pair
    p0 = _corrupt(sn.n_vertices, 0.1, seed=6)
    m32 = np.asarray(bj.refine_point_maps(sm, sn, p0, k_start=20, step=10))
    with jax.enable_x64(True):
        m64 = np.asarray(bj.refine_point_maps(sm, sn, p0, k_start=20, step=10))
    assert np.mean(m32 == m64) > 0.99  # float32 ties and near-ties may differ


@pytest.mark.parametrize("kwargs, match", [
    (dict(k_start=0), "k_start"),
    (dict(step=0), "step"),
    (dict(n_keep=0), "n_vote"),
    (dict(descriptor_weight=-1.0), "descriptor_weight"),
    (dict(descriptor_weight=float("nan")), "descriptor_weight"),
    (dict(descriptor_dims=200), "descriptor_dims"),
    (dict(k_max=K + 1), "k_max"),
])
def test_bad_options(pair, kwargs, match):
    ex, sm, sn = pair
    with pytest.raises(bj.BSFError, match=match):
        bj.refine_point_maps(sm, sn, np.arange(sn.n_vertices), **kwargs)


def test_bad_point_maps(pair):
    ex, sm, sn = pair
    p = np.arange(sn.n_vertices)
    with pytest.raises(bj.BSFError, match=r"p2p indices must be in \[0, "):
        bj.refine_point_maps(sm, sn, np.where(p == 3, -1, p))
    with pytest.raises(bj.BSFError, match="one source vertex per target vertex"):
        bj.refine_point_maps(sm, sn, p[:-1])
    with pytest.raises(bj.BSFError, match="integer"):
        bj.refine_point_maps(sm, sn, p.astype(float))
    with pytest.raises(bj.BSFError, match="needs a functional map C or a point map"):
        bj.transfer_labels(sm, sn, ex.labels)


@pytest.mark.parametrize("c", [2.0 ** -40, 2.0 ** 40])
def test_pair_scaled_by_a_common_factor(pair, c):
    """Both meshes scaled by c (λ/c², Φ/c, A·c²): the same labels; the pair is rescaled on the
    host by one common power of 4 before the float32 cast (areas of 1e±24 would not survive)."""
    ex, sm, sn = pair
    scale = lambda s: bj.Spectrum(np.asarray(s.evals) / c ** 2, np.asarray(s.evecs) / c,  # noqa
                                  np.asarray(s.mass) * c ** 2)
    p0 = _corrupt(sn.n_vertices, 0.2, seed=7)
    method = bj.RefinedPullBack(k_start=20, step=10)
    want = bj.transfer_labels(sm, sn, ex.labels, p2p=p0, method=method).labels
    got = bj.transfer_labels(scale(sm), scale(sn), ex.labels, p2p=p0, method=method).labels
    np.testing.assert_array_equal(got, want)
    maps = np.asarray(bj.refine_point_maps(scale(sm), scale(sn), p0, k_start=20, step=10))
    np.testing.assert_array_equal(maps, np.asarray(bj.refine_point_maps(sm, sn, p0, k_start=20,
                                                                        step=10)))
