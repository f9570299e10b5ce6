"""estimate_fmap against a dense float64 least-squares reference, and on real FAUST pairs."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import bsfjax
import bsfjax.internal
from bsfjax import (BSFError, FmapWeights, estimate_fmap, fmap_energy, fmap_from_p2p, fmap_to_p2p,
                    geodesic_error, wks, zoomout)

from .conftest import data_path, icosphere

#: FAUST template vertex used as the single landmark: a fingertip of the hand on the +x side of
#: tr_reg_000 (the farthest vertex along +x of tr_reg_010).  GT is the identity, so it is the
#: same index on every FAUST registration.
FAUST_LANDMARK = 2446


def bumpy_sphere(seed=0, scale=(1.0, 0.8, 1.2)):
    """A closed, asymmetric surface (no repeated eigenvalues): 642 vertices."""
    v, f = icosphere(3)
    rng = np.random.default_rng(seed)
    bumps = sum(0.08 * np.exp(-8 * np.sum((v - c) ** 2, 1)) for c in rng.standard_normal((4, 3)))
    return bsfjax.Mesh(v * np.array(scale) * (1 + bumps)[:, None], f)


def descriptors(s, lm):
    return np.concatenate([np.asarray(wks(s, 12)), np.asarray(wks(s, 6, landmarks=lm))], axis=1)


@pytest.fixture(scope="module")
def small():
    """Source shape, a vertex-permuted copy (GT known) and a deformed shape, with spectra."""
    src = bumpy_sphere()
    perm = np.random.default_rng(1).permutation(src.n_vertices)
    # copy vertex i is source vertex perm[i]
    copy = bsfjax.Mesh(src.vertices[perm], np.argsort(perm)[src.faces])
    other = bumpy_sphere(scale=(1.1, 0.75, 1.25))
    spectra = [bsfjax.spectrum(m, 30) for m in (src, copy, other)]
    return (src, copy, other), spectra, perm


def ref_orientation_op(mesh, f):
    """(n, n) matrix of g ↦ per-vertex Σ_faces (|t|/3) ⟨n_t × ∇f, ∇g⟩_t, assembled face by face."""
    v, faces = mesh.vertices, mesh.faces
    W = np.zeros((mesh.n_vertices, mesh.n_vertices))
    for tri in faces:  # tiny meshes only
        p = v[tri]
        nrm = np.cross(p[1] - p[0], p[2] - p[0])
        area = np.linalg.norm(nrm) / 2
        nrm /= 2 * area
        # ∇ of the hat function of corner c: n × (edge opposite c) / 2|t|
        gb = [np.cross(nrm, p[(c + 2) % 3] - p[(c + 1) % 3]) / (2 * area) for c in range(3)]
        rot = np.cross(nrm, sum(f[tri[c]] * gb[c] for c in range(3)))
        for i in range(3):
            for j in range(3):
                W[tri[i], tri[j]] += area / 3 * rot @ gb[j]
    return W


def ref_estimate(sm, sn, dm, dn, k, w, lap="resolvent", gamma=0.5, normalize_weights=True,
                 meshes=None, sign=1.0):
    """Dense least squares: every term's stacked residual built with np.kron, solved by lstsq."""
    pm, pn = sm.evecs[:, :k], sn.evecs[:, :k]
    am, an = sm.mass, sn.mass
    dm = dm / np.sqrt(am @ dm**2)
    dn = dn / np.sqrt(an @ dn**2)
    Fm, Fn = pm.T @ (am[:, None] * dm), pn.T @ (an[:, None] * dn)
    Dm = np.stack([pm.T @ np.diag(am * d) @ pm for d in dm.T])
    Dn = np.stack([pn.T @ np.diag(an * d) @ pn for d in dn.T])
    w = np.asarray(w, float)
    if meshes is not None:
        Om = np.stack([pm.T @ ref_orientation_op(meshes[0], d) @ pm for d in dm.T])
        On = sign * np.stack([pn.T @ ref_orientation_op(meshes[1], d) @ pn for d in dn.T])
    else:
        w = w[:3]
    lm_, ln_ = sm.evals[:k], sn.evals[:k]
    if lap == "plain":
        mask = (lm_[None, :] - ln_[:, None]) ** 2
    else:
        sc = max(lm_.max(), ln_.max())
        a, b = (lm_ / sc) ** gamma, (ln_ / sc) ** gamma
        mask = ((a / (a**2 + 1))[None] - (b / (b**2 + 1))[:, None]) ** 2 \
            + ((1 / (a**2 + 1))[None] - (1 / (b**2 + 1))[:, None]) ** 2
    w = w / np.sum(w)
    if normalize_weights:  # pyFM's canonical scales, written out
        peff = np.mean([np.trace(F[1:].T @ F[1:]) ** 2 / np.sum((F[1:].T @ F[1:]) ** 2)
                        for F in (Fm, Fn)])
        tau_d = k * np.sum(Fm[1:] ** 2) / k / peff
        tau_l = k * mask.sum() / k**2
        tau_c = sum(k * np.sum(a**2) + k * np.sum(b**2) - 2 * np.trace(a) * np.trace(b)
                    for a, b in zip(Dm, Dn)) * k / k**2 / peff
        taus = [tau_d, tau_l, tau_c]
        if meshes is not None:
            taus.append(sum(k * np.sum(a**2) + k * np.sum(b**2) for a, b in zip(Om, On)) / k / peff)
        w = w / np.array(taus)
    eye = np.eye(k)
    blocks = [np.sqrt(w[0]) * np.kron(eye, Fm.T), np.sqrt(w[1]) * np.diag(np.sqrt(mask.ravel()))]
    blocks += [np.sqrt(w[2]) * (np.kron(eye, a.T) - np.kron(b, eye)) for a, b in zip(Dm, Dn)]
    if meshes is not None:
        blocks += [np.sqrt(w[3]) * (np.kron(eye, a.T) - np.kron(b, eye)) for a, b in zip(Om, On)]
    J = np.concatenate(blocks)
    rhs = np.concatenate([np.sqrt(w[0]) * Fn.ravel(), np.zeros(J.shape[0] - Fn.size)])
    c00 = np.sign(pm[0, 0] * pn[0, 0]) * np.sqrt(an.sum() / am.sum())
    fixed = np.arange(k) * k  # vec index of C[i, 0] (row-major); only C[0, 0] is non-zero
    free = np.setdiff1d(np.arange(k * k), fixed)
    y = np.linalg.lstsq(J[:, free], rhs - J[:, 0] * c00, rcond=None)[0]
    C = np.zeros(k * k)
    C[free], C[0] = y, c00
    return C.reshape(k, k)


def at_one_area(sm, sn):
    """The pair as estimate_fmap solves it (bsfjax.unit_area_pair, written out): the source
    scaled by a_M = the power of 4 nearest its area, the target by a_M·S_N/S_M (one area)."""
    S_m, S_n = float(np.sum(sm.mass)), float(np.sum(sn.mass))
    a_m = 4.0 ** np.round(np.log2(S_m) / 2)
    scale = lambda s, a: bsfjax.Spectrum(np.asarray(s.evals) * a,  # noqa: E731
                                         np.asarray(s.evecs) * np.sqrt(a), np.asarray(s.mass) / a)
    return scale(sm, a_m), scale(sn, a_m * S_n / S_m), np.sqrt(S_n / S_m)


def ref_in_given_bases(sm, sn, *args, **kwargs):
    """ref_estimate at one area, its map brought back to the given bases (×√(S_N/S_M))."""
    um, un, back = at_one_area(sm, sn)
    return ref_estimate(um, un, *args, **kwargs) * back


# --------------------------------------------------------------------------- exactness


@pytest.mark.parametrize("options", [dict(), dict(laplacian="plain", normalize_weights=False,
                                                  weights=(1.0, 1e-2, 0.5))])
def test_matches_dense_least_squares(small, options):
    _, (s0, _, s2), _ = small
    d0, d2 = descriptors(s0, [5, 77]), descriptors(s2, [5, 77])
    k = 9
    with jax.enable_x64(True):
        C = np.asarray(estimate_fmap(s0, s2, d0, d2, k=k, **options))
    assert abs(np.sum(s2.mass) / np.sum(s0.mass) - 1) > 0.01  # the areas differ
    ref = ref_in_given_bases(s0, s2, d0, d2, k, options.get("weights", FmapWeights()),
                       lap=options.get("laplacian", "resolvent"),
                       normalize_weights=options.get("normalize_weights", True))
    assert C.shape == (k, k)
    np.testing.assert_allclose(C, ref, atol=1e-8 * np.abs(ref).max())
    with jax.enable_x64(True):  # and it is the minimum of the energy: zero gradient in C[:, 1:]
        grad = jax.grad(lambda c: fmap_energy(c, s0, s2, d0, d2, **options))(jnp.asarray(C))
        e0 = fmap_energy(C, s0, s2, d0, d2, **options)
        nudged = C + 1e-3 * np.random.default_rng(0).standard_normal(C.shape) * (np.arange(k) > 0)
        assert fmap_energy(nudged, s0, s2, d0, d2, **options) > e0
    assert np.abs(np.asarray(grad)[:, 1:]).max() < 1e-9


@pytest.mark.parametrize("orientation", ["preserving", "reversing"])
def test_orientation_term_matches_dense_least_squares(orientation):
    v, f = icosphere(1)  # 42 vertices: the face-by-face reference is slow
    rng = np.random.default_rng(3)
    meshes = [bsfjax.Mesh(v * (1 + 0.1 * rng.random((len(v), 1))), f) for _ in range(2)]
    s0, s1 = (bsfjax.spectrum(m, 10) for m in meshes)
    d0 = np.stack([s0.evecs[:, 1] ** 2, s0.evecs[:, 3] + 0.2 * s0.evecs[:, 2], v[:, 0]], 1)
    d1 = np.stack([s1.evecs[:, 1] ** 2, s1.evecs[:, 3] + 0.2 * s1.evecs[:, 2], v[:, 0]], 1)
    w = FmapWeights(descr=1.0, lap=1e-2, comm=0.5, orient=2.0)
    with jax.enable_x64(True):
        C = np.asarray(estimate_fmap(s0, s1, d0, d1, k=6, weights=w, source_mesh=meshes[0],
                                     target_mesh=meshes[1], orientation=orientation))
        C0 = np.asarray(estimate_fmap(s0, s1, d0, d1, k=6, weights=w._replace(orient=0.0)))
    sign = 1.0 if orientation == "preserving" else -1.0
    ref = ref_in_given_bases(s0, s1, d0, d1, 6, w, meshes=meshes, sign=sign)
    np.testing.assert_allclose(C, ref, atol=1e-8 * np.abs(ref).max())
    assert np.abs(C - C0).max() > 1e-3  # the term does something


def test_orientation_operator(small):
    """O^f = Φᵀ W_f Φ; ⟨n × ∇f, ∇f⟩ = 0 on every face, so O^f kills f's own coefficients."""
    (m0, _, _), (s0, _, _), _ = small
    from bsfjax._maps._orientation import face_geometry, _orient_ops

    coef = np.random.default_rng(0).standard_normal((30, 2))
    f, g = (s0.evecs @ coef).T  # band-limited: exactly represented by their coefficients
    with jax.enable_x64(True):
        ops = np.asarray(_orient_ops(jnp.asarray(s0.evecs), jax.tree.map(jnp.asarray,
                                     face_geometry(m0)), jnp.asarray(np.stack([f, g], 1))))
    assert ops.shape == (2, 30, 30)
    np.testing.assert_allclose(ops[0] @ coef[:, 0], 0.0, atol=1e-10 * np.abs(ops[0]).max())
    assert np.abs(ops[0] @ coef[:, 1]).max() > 1e-2 * np.abs(ops[0]).max()
    ref = s0.evecs.T @ ref_orientation_op(m0, f) @ s0.evecs
    np.testing.assert_allclose(ops[0], ref, atol=1e-10 * np.abs(ref).max())


def test_float32_close_to_float64(small):
    _, (s0, _, s2), _ = small
    d0, d2 = descriptors(s0, [5]), descriptors(s2, [5])
    with jax.enable_x64(True):
        C64 = np.asarray(estimate_fmap(s0, s2, d0, d2, k=20))
    C32 = np.asarray(estimate_fmap(s0, s2, d0, d2, k=20))
    assert C32.dtype == np.float32
    np.testing.assert_allclose(C32, C64, atol=2e-3 * np.abs(C64).max())


def test_first_column_is_the_constant_map(small):
    (m0, _, m2), (s0, _, s2), _ = small
    C = np.asarray(estimate_fmap(s0, s2, descriptors(s0, [3]), descriptors(s2, [3]), k=(12, 10)))
    assert C.shape == (10, 12)  # (k_target, k_source)
    expect = np.zeros(10)
    expect[0] = np.sqrt(m2.area / m0.area)  # both constant eigenvectors are positive
    np.testing.assert_allclose(C[:, 0], expect, rtol=1e-5)


def test_recovers_a_vertex_permutation(small):
    """Same surface, shuffled vertices: the estimated map is the ground truth."""
    _, (s0, s1, _), perm = small
    gt = perm  # copy vertex i sits where source vertex perm[i] is
    lm = [5, 200]
    d0, d1 = descriptors(s0, lm), descriptors(s1, np.argsort(perm)[lm])
    C = estimate_fmap(s0, s1, d0, d1, k=20)
    C_gt = np.asarray(fmap_from_p2p(s0.truncate(20), s1.truncate(20), gt))
    np.testing.assert_allclose(C_gt, np.eye(20), atol=1e-5)  # sanity: same shape, same basis
    np.testing.assert_allclose(np.asarray(C), C_gt, atol=1e-3)
    p2p = np.asarray(fmap_to_p2p(C, s0, s1))
    assert np.mean(p2p == gt) > 0.95


def test_vmap_over_pairs_equals_separate_calls(small):
    _, (s0, s1, s2), perm = small
    pairs = [(s0, s2, [5]), (s2, s0, [9]), (s0, s1, [7])]
    stack = lambda xs: jax.tree.map(lambda *a: np.stack(a), *xs)  # noqa: E731
    src = stack([p[0] for p in pairs])
    tgt = stack([p[1] for p in pairs])
    dsrc = np.stack([descriptors(p[0], p[2]) for p in pairs])
    dtgt = np.stack([descriptors(p[1], p[2]) for p in pairs])
    with jax.enable_x64(True):
        batched = np.asarray(estimate_fmap(src, tgt, dsrc, dtgt, k=15))
        single = [np.asarray(estimate_fmap(p[0], p[1], a, b, k=15))
                  for p, a, b in zip(pairs, dsrc, dtgt)]
    assert batched.shape == (3, 15, 15)
    np.testing.assert_allclose(batched, np.stack(single), atol=1e-10)
    # With the orientation term, the meshes come as sequences (stacked per-face geometry).
    (m0, m1, m2), w = small[0], FmapWeights(orient=0.5)
    src_m, tgt_m = [m0, m2, m0], [m2, m0, m1]
    with jax.enable_x64(True):
        batched = np.asarray(estimate_fmap(src, tgt, dsrc, dtgt, k=8, weights=w,
                                           source_mesh=src_m, target_mesh=tgt_m))
        single = [np.asarray(estimate_fmap(p[0], p[1], a, b, k=8, weights=w, source_mesh=ms,
                                           target_mesh=mt))
                  for p, a, b, ms, mt in zip(pairs, dsrc, dtgt, src_m, tgt_m)]
    np.testing.assert_allclose(batched, np.stack(single), atol=1e-10)


# --------------------------------------------------------------------------- FAUST (paper setting)


@pytest.fixture(scope="module")
def faust(request):
    meshes = [bsfjax.load_mesh(data_path("faust", f"tr_reg_{i}.off")) for i in ("000", "001")]
    try:
        cache = request.config.cache.mkdir("bsfjax_spectra")  # shared with test_fmap
    except AttributeError:
        cache = None
    return meshes, [bsfjax.spectrum(m, 100, cache_dir=cache) for m in meshes]


def test_faust_wks_one_landmark_30x30_then_zoomout(faust):
    """WKS (100 energies) + WKS at one landmark, 30×30 map, then ZoomOut to 100."""
    meshes, (sm, sn) = faust
    lm = [FAUST_LANDMARK]
    dm = np.concatenate([np.asarray(wks(sm, 100)), np.asarray(wks(sm, 100, landmarks=lm))], 1)
    dn = np.concatenate([np.asarray(wks(sn, 100)), np.asarray(wks(sn, 100, landmarks=lm))], 1)
    C = estimate_fmap(sm, sn, dm, dn, k=30)
    p2p = np.asarray(fmap_to_p2p(C, sm, sn))
    p2p_zo = np.asarray(fmap_to_p2p(zoomout(C, sm, sn, 100, step=5), sm, sn))
    gt = np.arange(sn.n_vertices)
    sub = np.random.default_rng(0).choice(gt.size, 1000, replace=False)  # speed: 1000 targets
    err, err_zo = geodesic_error(meshes[0], np.stack([p2p[sub], p2p_zo[sub]]), gt[sub])
    assert err < 0.05, err  # measured 0.035 (pyFM's fit on the same input: 0.035)
    assert err_zo < 0.5 * err, (err, err_zo)  # measured 0.008


# --------------------------------------------------------------------------- bad input


def test_bad_input_raises(small):
    _, (s0, _, s2), _ = small
    d0, d2 = descriptors(s0, [1]), descriptors(s2, [1])
    with pytest.raises(ValueError, match="same number of descriptors"):
        estimate_fmap(s0, s2, d0, d2[:, :-1])
    with pytest.raises(ValueError, match=r"source_descr must have shape \(642, 'p'\)"):
        estimate_fmap(s0, s2, d0[:-1], d2)
    with pytest.raises(ValueError, match="k=.*available"):
        estimate_fmap(s0, s2, d0, d2, k=31)
    with pytest.raises(BSFError, match="weights"):
        estimate_fmap(s0, s2, d0, d2, weights={"desc": 1.0})
    with pytest.raises(BSFError, match="weights"):
        estimate_fmap(s0, s2, d0, d2, weights=(1.0, -1.0, 1.0))
    with pytest.raises(BSFError, match="laplacian"):
        estimate_fmap(s0, s2, d0, d2, laplacian="cot")
    with pytest.raises(BSFError, match="NaN"):
        estimate_fmap(s0, s2, np.full_like(d0, np.nan), d2)
    stacked = jax.tree.map(lambda *a: np.stack(a), s0, s2)
    with pytest.raises(BSFError, match="stacked alike"):
        estimate_fmap(stacked, s2, d0, d2)
    with pytest.raises(BSFError, match="C must be"):
        fmap_energy(np.ones(3), s0, s2, d0, d2)
    with pytest.raises(BSFError, match="needs source_mesh and target_mesh"):
        estimate_fmap(s0, s2, d0, d2, weights=FmapWeights(orient=1.0))
    (m0, _, m2) = small[0]
    with pytest.raises(BSFError, match="has 42 vertices but its spectrum has 642"):
        estimate_fmap(s0, s2, d0, d2, weights=FmapWeights(orient=1.0), target_mesh=m2,
                      source_mesh=bsfjax.Mesh(*icosphere(1)))
    with pytest.raises(BSFError, match="orientation"):
        estimate_fmap(s0, s2, d0, d2, orientation="flip")


@pytest.mark.parametrize("x64", [False, True])
def test_shared_orientation_bases_equal_the_meshes(small, x64):
    """One face scan at k = 24 serves the estimates at 10 and 24 (top-left blocks), with the
    same maps as the meshes give, also for a target in other units (both put at one area)."""
    (m0, _, m2), (s0, _, _), _ = small
    big = bsfjax.Mesh(7.0 * m2.vertices, m2.faces)
    s2 = bsfjax.spectrum(big, 30)
    d0, d2 = descriptors(s0, [5]), descriptors(s2, [5])
    w = FmapWeights(orient=1.0)
    with jax.enable_x64(x64):
        bases = bsfjax.internal.orientation_bases(s0, s2, m0, big, 24)
        assert bases[0].Y.shape == (642, 24, 24)
        for k in (10, 24):
            C = np.asarray(estimate_fmap(s0, s2, d0, d2, k=k, weights=w, source_mesh=m0,
                                         target_mesh=big))
            C_shared = np.asarray(estimate_fmap(s0, s2, d0, d2, k=k, weights=w,
                                                orientation_bases=bases))
            tol = 1e-10 if x64 else 1e-5
            np.testing.assert_allclose(C_shared, C, atol=tol * np.abs(C).max())
        C_plain = np.asarray(estimate_fmap(s0, s2, d0, d2, k=10))
    assert np.abs(C_plain - np.asarray(estimate_fmap(
        s0, s2, d0, d2, k=10, weights=w, orientation_bases=bases))).max() > 1e-3


def test_orientation_bases_bad_input(small):
    (m0, _, m2), (s0, _, s2), _ = small
    d0, d2 = descriptors(s0, [1]), descriptors(s2, [1])
    bases = bsfjax.internal.orientation_bases(s0, s2, m0, m2, 8)
    w = FmapWeights(orient=1.0)
    with pytest.raises(BSFError, match="at least 10 eigenvectors"):
        estimate_fmap(s0, s2, d0, d2, k=10, weights=w, orientation_bases=bases)
    with pytest.raises(BSFError, match="not both"):
        estimate_fmap(s0, s2, d0, d2, k=8, weights=w, orientation_bases=bases, source_mesh=m0,
                      target_mesh=m2)
    with pytest.raises(BSFError, match="weights.orient must be > 0"):
        estimate_fmap(s0, s2, d0, d2, k=8, orientation_bases=bases)
    with pytest.raises(BSFError, match="orientation_bases must be the pair's"):
        estimate_fmap(s0, s2, d0, d2, k=8, weights=w, orientation_bases=(m0, m2))
    with pytest.raises(BSFError, match="k must be in"):
        bsfjax.internal.orientation_bases(s0, s2, m0, m2, 31)
    with pytest.raises(BSFError, match="has 42 vertices but its spectrum has 642"):
        bsfjax.internal.orientation_bases(s0, s2, m0, bsfjax.Mesh(*icosphere(1)), 8)
