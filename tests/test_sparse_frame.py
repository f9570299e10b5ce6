"""Sparse frames (per-vertex atom lists): same atoms, codes and transfers as the dense path."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp

import bsfjax
from bsfjax import BSFError, SparseFrame, build_frame, decode, encode, transfer_frame
import bsfjax._frame._build as frame_mod
from bsfjax.internal import ell_matmul, ell_rmatmul, sparse_atoms, sparse_gram

from .conftest import data_path, icosphere

TAUS = (1e-3, 5e-3, 1e-2)


def _shape(seed, k=30):
    v, f = icosphere(3)
    bump = 1 + 0.15 * np.sin(v @ np.random.default_rng(seed).normal(size=3) * 2.0)
    return bsfjax.spectrum(bsfjax.Mesh(v * bump[:, None], f), k)


@pytest.fixture(scope="module")
def pair():
    src, tgt = _shape(0), _shape(1)
    n = src.n_vertices
    centers = np.arange(0, n, 7)
    dense = build_frame(src, centers, TAUS, (0.7, 0.75, 0.8))
    sparse = build_frame(src, centers, TAUS, (0.7, 0.75, 0.8), sparse=True)
    C = np.asarray(bsfjax.fmap_from_p2p(src, tgt, np.arange(n)))
    return src, tgt, centers, dense, sparse, C


def _near_threshold(evecs, coeffs, gammas, tol=1e-4):
    """Entries whose float64 |g|/max|g| lies within ``tol`` of γ (float32 may round either way)."""
    g = np.abs(np.asarray(evecs, np.float64) @ np.asarray(coeffs, np.float64))
    m = g.max(axis=0)
    return np.abs(g / np.where(m > 0, m, 1) - np.asarray(gammas)) < tol


def test_sparse_build_has_the_dense_atoms(pair):
    src, _, centers, dense, sparse, _ = pair
    assert isinstance(sparse, SparseFrame) and isinstance(dense, bsfjax.Frame)
    B = np.asarray(dense.atoms)
    diff = np.asarray(sparse.todense()) != B
    assert not np.any(diff & ~_near_threshold(src.evecs, dense.coeffs, dense.gammas))
    assert diff.sum() <= 2
    np.testing.assert_array_equal(np.asarray(sparse.coeffs), np.asarray(dense.coeffs))
    for name in ("taus", "centers", "gammas", "mass"):
        np.testing.assert_array_equal(np.asarray(getattr(sparse, name)),
                                      np.asarray(getattr(dense, name)))
    assert sparse.n_atoms == dense.n_atoms and sparse.n_vertices == dense.n_vertices
    assert sparse.nnz == int(np.asarray(sparse.todense()).sum())
    lists = np.asarray(sparse.atom_lists)  # sorted, padded with q, width = max row count
    assert lists.shape[1] == int(np.asarray(sparse.todense()).sum(axis=1).max())
    assert np.all((np.diff(lists, axis=1) > 0) | (lists[:, 1:] == sparse.n_atoms))


def test_sparse_transfer_matches_dense(pair):
    _, tgt, _, dense, sparse, C = pair
    td = transfer_frame(dense, C, tgt)
    ts = transfer_frame(sparse, C, tgt)
    assert isinstance(ts, SparseFrame) and isinstance(transfer_frame(sparse, C, tgt, sparse=False),
                                                      bsfjax.Frame)
    diff = np.asarray(ts.todense()) != np.asarray(td.atoms)
    assert not np.any(diff & ~_near_threshold(tgt.evecs, td.coeffs, td.gammas))
    np.testing.assert_allclose(np.asarray(ts.coeffs), np.asarray(td.coeffs), rtol=1e-6, atol=1e-7)
    # a map that kills every kernel gives empty atoms (no NaN), as in the dense path
    zero = transfer_frame(sparse, np.zeros_like(C), tgt)
    assert zero.nnz == 0 and zero.atom_lists.shape[1] == 1


def test_products_match_float64():
    rng = np.random.default_rng(0)
    n, q = 57, 23
    B = rng.random((n, q)) < 0.2
    B[:, 3] = False  # an empty atom
    B[5] = False  # a vertex in no atom
    width = int(B.sum(axis=1).max())
    lists = np.stack([np.concatenate([np.flatnonzero(r), np.full(width - r.sum(), q)]) for r in B])
    fr = SparseFrame(atom_lists=jnp.asarray(lists, jnp.int32), coeffs=jnp.zeros((4, q)),
                     taus=jnp.ones(q), centers=jnp.zeros(q, jnp.int32), mass=jnp.ones(n))
    X, Y = rng.normal(size=(q, 3)), rng.normal(size=(n, 3))
    np.testing.assert_allclose(np.asarray(ell_matmul(fr.atom_lists, jnp.asarray(X, jnp.float32))),
                               B @ X, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(np.asarray(ell_rmatmul(fr.atom_lists, jnp.asarray(Y, jnp.float32), q)),
                               B.T @ Y, rtol=1e-5, atol=1e-5)
    w = rng.random(n)
    np.testing.assert_array_equal(sparse_gram(fr).toarray(), B.T.astype(float) @ B)
    np.testing.assert_allclose(sparse_gram(fr, w).toarray(), B.T @ (w[:, None] * B), rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(fr.todense()), B)
    np.testing.assert_array_equal(fr.to_scipy().toarray(), B)
    np.testing.assert_array_equal(fr.atom_columns([3, 0, 7]), B[:, [3, 0, 7]])


@pytest.mark.parametrize("method,opts,weights", [("omp", {"sparsity": 8}, None),
                                                 ("omp_error", {}, "area"),
                                                 ("lstsq", {}, "area"),
                                                 ("lasso", {"lam": 0.02}, None)])
def test_encode_matches_dense_path(pair, method, opts, weights):
    _, _, _, _, sparse, _ = pair
    dense = bsfjax.Frame(atoms=sparse.todense(jnp.float32), coeffs=sparse.coeffs, taus=sparse.taus,
                         centers=sparse.centers, mass=sparse.mass, gammas=sparse.gammas)
    n = sparse.n_vertices
    F = (np.random.default_rng(2).random((2, 3, n)) < 0.4).astype(np.float32)
    a_d, i_d = encode(dense, F, method, weights=weights, return_info=True, **opts)
    a_s, i_s = encode(sparse, F, method, weights=weights, return_info=True, **opts)
    assert a_s.shape == (2, 3, sparse.n_atoms)
    if method == "lstsq":  # the minimum-norm solution of a rank-deficient B: compare in float64
        with jax.enable_x64(True):
            d64 = bsfjax.Frame(atoms=jnp.asarray(np.asarray(dense.atoms), jnp.float64),
                               coeffs=dense.coeffs, taus=dense.taus, centers=dense.centers,
                               mass=jnp.asarray(np.asarray(dense.mass), jnp.float64))
            s64 = jax.tree.map(lambda x: jnp.asarray(np.asarray(x)), sparse)
            F64 = F.astype(np.float64)
            np.testing.assert_allclose(np.asarray(encode(s64, F64, method, weights=weights)),
                                       np.asarray(encode(d64, F64, method, weights=weights)),
                                       rtol=1e-8, atol=1e-9)
    if method == "lasso":  # FISTA stops at tol: iterates differ a little
        np.testing.assert_allclose(np.asarray(a_s), np.asarray(a_d), rtol=1e-4, atol=1e-3)
    else:  # OMP: binary frames have duplicate atoms, and rounding may pick the other twin
        np.testing.assert_array_equal(np.asarray(i_s.n_atoms), np.asarray(i_d.n_atoms))
        np.testing.assert_array_equal(np.asarray(i_s.converged), np.asarray(i_d.converged))
    np.testing.assert_allclose(np.asarray(decode(sparse, a_s)), np.asarray(decode(dense, a_d)),
                               rtol=1e-4, atol=2e-4)
    np.testing.assert_allclose(np.asarray(i_s.residual), np.asarray(i_d.residual), rtol=1e-4,
                               atol=1e-4)
    np.testing.assert_allclose(np.asarray(decode(sparse, a_d)), np.asarray(decode(dense, a_d)),
                               rtol=1e-5, atol=1e-5)


def test_transfer_through_sparse_frames_equals_dense(pair):
    """The manual route (encode on M, decode on the carried frame) on list and dense frames."""
    src, tgt, _, dense, sparse, C = pair
    F = (np.random.default_rng(3).random((4, src.n_vertices)) < 0.3).astype(np.float32)
    ts, td = transfer_frame(sparse, C, tgt), transfer_frame(dense, C, tgt)
    a_s, a_d = encode(sparse, F, sparsity=6), encode(dense, F, sparsity=6)
    np.testing.assert_allclose(np.asarray(decode(ts, a_s)), np.asarray(decode(td, a_d)),
                               rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(np.asarray(decode(sparse, a_s)), np.asarray(decode(dense, a_d)),
                               rtol=1e-4, atol=1e-4)
    assert encode(sparse, np.zeros((0, src.n_vertices))).shape == (0, sparse.n_atoms)


def test_automatic_choice_and_errors(pair, monkeypatch):
    src, tgt, centers, _, sparse, C = pair
    with pytest.raises(BSFError, match="sparse must be"):
        build_frame(src, centers, sparse="yes")
    monkeypatch.setattr(frame_mod, "DENSE_BUDGET_BYTES", 4 * src.n_vertices * 3 * len(centers) - 1)
    assert isinstance(build_frame(src, centers), SparseFrame)
    assert isinstance(build_frame(src, centers, sparse=False), bsfjax.Frame)
    monkeypatch.setattr(frame_mod, "DENSE_BUDGET_BYTES", 4 * src.n_vertices * 3 * len(centers))
    assert isinstance(build_frame(src, centers), bsfjax.Frame)
    import bsfjax._frame._operator as operator_mod

    monkeypatch.setattr(operator_mod, "DENSE_BUDGET_BYTES", 8)
    F = np.ones((1, src.n_vertices))
    with pytest.raises(BSFError, match="dense q × q Gram"):
        encode(sparse, F, "lstsq")
    encode(sparse, F, "omp")  # OMP never needs it dense
    with pytest.raises(BSFError, match="concrete"):
        jax.jit(lambda ev: build_frame(bsfjax.Spectrum(src.evals, ev, src.mass), centers,
                                       sparse=True).coeffs)(src.evecs)
    with pytest.raises(BSFError, match="has length"):
        encode(sparse, np.ones(src.n_vertices + 1))
    with pytest.raises(BSFError, match="alpha must have shape"):
        decode(sparse, np.ones(sparse.n_atoms + 1))
    with pytest.raises(BSFError, match="unknown option"):
        encode(sparse, F, "omp", sparsityy=3)


def test_faust_sparse_build_matches_dense():
    """A real mesh (FAUST, 6890 V, k = 40, 5 % centres × 3 scales): atom entries agree except
    at the threshold."""
    mesh = bsfjax.load_mesh(data_path("faust", "tr_reg_000.off"))
    spec = bsfjax.spectrum(mesh, 40)
    centers = bsfjax.farthest_point_sampling(mesh, 0.05)
    dense = build_frame(spec, centers)
    lists = sparse_atoms(spec.evecs, dense.coeffs, dense.gammas)
    got = np.zeros(dense.atoms.shape, bool)
    rows = np.repeat(np.arange(mesh.n_vertices), lists.shape[1])
    ok = np.asarray(lists).ravel() < dense.n_atoms
    got[rows[ok], np.asarray(lists).ravel()[ok]] = True
    diff = got != (np.asarray(dense.atoms) > 0)
    assert diff.sum() <= 1e-6 * diff.size + 2
    assert not np.any(diff & ~_near_threshold(spec.evecs, dense.coeffs, dense.gammas))


def test_dense_omp_host_gram_rows_match_the_gemm(pair, monkeypatch):
    """A concrete binary frame coding a large batch takes its Gram rows from a host CSR copy
    (precompute="auto"); the codes equal the full-Gram GEMM path."""
    import bsfjax._frame._gram_rows as coding

    _, _, _, dense, _, _ = pair
    F = (np.random.default_rng(4).random((40, dense.n_vertices)) < 0.4).astype(np.float32)
    registered = []
    orig = coding.HostGramRows.register
    monkeypatch.setattr(coding.HostGramRows, "register",
                        classmethod(lambda cls, *a: registered.append(1) or orig(*a)))
    for w in (None, "area"):
        a_host, i_host = encode(dense, F, "omp", sparsity=6, weights=w, return_info=True)
        a_gemm, i_gemm = encode(dense, F, "omp", sparsity=6, weights=w, precompute=True,
                                return_info=True)
        np.testing.assert_allclose(np.asarray(decode(dense, a_host)),
                                   np.asarray(decode(dense, a_gemm)), rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(np.asarray(i_host.residual), np.asarray(i_gemm.residual),
                                   rtol=1e-5, atol=1e-5)
    assert len(registered) == 2 and not coding.HostGramRows._live  # released after use


def test_host_gram_rows_are_computed_once_per_atom(pair, monkeypatch):
    """Within one encode call each selected atom's Gram row is computed on the host once, however
    many functions select it; with the row budget exhausted (nothing kept) the codes are the
    same."""
    import bsfjax._frame._gram_rows as coding

    _, _, _, dense, sparse, _ = pair
    F = (np.random.default_rng(5).random((30, dense.n_vertices)) < 0.3).astype(np.float32)
    F = np.concatenate([F, F])  # every atom is selected by at least two functions
    computed = []
    orig = coding.HostGramRows.rows.__func__

    def counting(cls, token, k):
        before = sum(len(v.cache) for v in cls._live.values())
        out = orig(cls, token, k)
        computed.append(sum(len(v.cache) for v in cls._live.values()) - before)
        return out

    monkeypatch.setattr(coding.HostGramRows, "rows", classmethod(counting))
    for frame in (dense, sparse):
        computed.clear()
        a = np.asarray(encode(frame, F, "omp", sparsity=6))
        # host rows were used, and fewer were computed than atoms selected (shared atoms)
        assert computed and 0 < sum(computed) < np.count_nonzero(a)
        monkeypatch.setattr(coding, "ROW_CACHE_BYTES", 0)
        b = np.asarray(encode(frame, F, "omp", sparsity=6))
        monkeypatch.setattr(coding, "ROW_CACHE_BYTES", 2**28)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a[:30], a[30:])


def test_build_in_many_column_blocks(pair, monkeypatch):
    """Blocks of 7 atoms (the last one padded), lists in 5 vertex chunks grown one slot at a
    time: the same lists as one block."""
    import bsfjax._frame._sparse_frame as sf_mod

    src, _, _, dense, sparse, _ = pair
    monkeypatch.setattr(sf_mod, "_BUILD_ELEMS", 7 * src.n_vertices)
    monkeypatch.setattr(sf_mod, "_BUILD_CHUNKS", 5)
    monkeypatch.setattr(sf_mod, "_GROW_SLOTS", 1)
    assert dense.n_atoms % 7 != 0
    lists = sparse_atoms(src.evecs, dense.coeffs, dense.gammas)
    np.testing.assert_array_equal(np.asarray(lists), np.asarray(sparse.atom_lists))
    assert lists.shape[1] > 16


def _random_lists(rng, n, q, density):
    """Random 0/1 ``B`` ``(n, q)`` (with an empty atom and an empty vertex) and its lists."""
    B = rng.random((n, q)) < density
    B[:, 3] = False
    B[5] = False
    width = max(1, int(B.sum(axis=1).max()))
    lists = np.stack([np.concatenate([np.flatnonzero(r), np.full(width - r.sum(), q)])
                      for r in B]).astype(np.int32)
    return B, lists


def test_list_builder_appends_in_chunks(monkeypatch):
    """Appending atoms block by block into vertex chunks (uneven last chunk, growth by one slot,
    vertices with no atoms) gives the sorted padded lists, 64-byte aligned."""
    import bsfjax._frame._sparse_frame as sf_mod

    rng = np.random.default_rng(1)
    n, q = 83, 41
    B, lists = _random_lists(rng, n, q, 0.3)
    for chunks, grow in ((4, 1), (1, 64), (200, 3)):
        monkeypatch.setattr(sf_mod, "_BUILD_CHUNKS", chunks)
        monkeypatch.setattr(sf_mod, "_GROW_SLOTS", grow)
        builder = sf_mod._ListBuilder(n, q)
        for lo in range(0, q, 6):  # atoms arrive in increasing blocks, as in sparse_atoms
            r, c = np.nonzero(B[:, lo:lo + 6])
            builder.append(r, (c + lo).astype(np.int32))
        out = builder.finish()
        np.testing.assert_array_equal(out, lists)
        assert out.dtype == np.int32 and out.ctypes.data % 64 == 0
    empty = sf_mod._ListBuilder(4, 9).finish()
    np.testing.assert_array_equal(empty, np.full((4, 1), 9))


def test_products_in_overlapping_blocks(monkeypatch):
    """Blocks that do not divide n (the last one moved back over its predecessor): every row is
    counted once in B X, Bᵀ Y and nnz; integer data, so the sums are exact."""
    import bsfjax._frame._ell as ell_mod

    rng = np.random.default_rng(2)
    n, q, m = 61, 29, 3
    B, lists = _random_lists(rng, n, q, 0.25)
    X = rng.integers(-4, 5, size=(q, m)).astype(np.float32)
    Y = rng.integers(-4, 5, size=(n, m)).astype(np.float32)
    width = lists.shape[1]
    for rows in (1, 7, 60, n):
        monkeypatch.setattr(ell_mod, "_PRODUCT_ELEMS", rows * width * m)
        # new lambdas: retraced with the patched block size (jit caches by function)
        matmul = jax.jit(lambda a, x: ell_mod.ell_matmul.__wrapped__(a, x))
        rmatmul = jax.jit(lambda a, y: ell_mod.ell_rmatmul.__wrapped__(a, y, q))
        counts = jax.jit(lambda a: ell_mod._block_counts.__wrapped__(a, q))
        np.testing.assert_array_equal(np.asarray(matmul(jnp.asarray(lists), jnp.asarray(X))),
                                      B.astype(np.float32) @ X)
        np.testing.assert_array_equal(np.asarray(rmatmul(jnp.asarray(lists), jnp.asarray(Y))),
                                      B.T.astype(np.float32) @ Y)
        assert int(np.asarray(counts(jnp.asarray(lists))).sum()) == B.sum()


def test_atom_vertices_is_the_scipy_transpose(monkeypatch):
    """The chunked counting-sort transpose equals scipy's CSC of B (indptr and sorted vertex
    indices), for one chunk, for chunks of a few rows, and with panels of 8 vertices."""
    import bsfjax._frame._ell as ell_mod

    rng = np.random.default_rng(3)
    n, q = 70, 37
    B, lists = _random_lists(rng, n, q, 0.2)
    ref = sp.csc_matrix(B)
    for elems, bits in ((2**23, 16), (3 * lists.shape[1], 16), (1, 16), (2 * lists.shape[1], 3)):
        monkeypatch.setattr(ell_mod, "_HOST_CHUNK_ELEMS", elems)
        monkeypatch.setattr(ell_mod, "_PANEL_BITS", bits)
        av = ell_mod.atom_vertices(jnp.asarray(lists), q)
        assert av.lo.dtype == np.uint16 and av.starts.shape == (q, -(-n // 2**bits) + 1)
        np.testing.assert_array_equal(av.indptr, ref.indptr)
        got = [av.vertices(j) for j in range(q)]
        assert all(g.dtype == np.int64 for g in got)
        np.testing.assert_array_equal(np.concatenate(got), ref.indices)


def test_ell_gram_rows_equal_the_csr_product(monkeypatch):
    """Gram rows from the lists and their transpose equal scipy's ``(√w B)ᵀ (√w B)`` rows and
    column norms: bitwise (same products, same order) in one chunk; counts exactly and weighted
    rows to rounding when an atom's vertices are split over chunks."""
    import bsfjax._frame._ell as ell_mod

    rng = np.random.default_rng(4)
    n, q = 90, 33
    B, lists = _random_lists(rng, n, q, 0.3)
    w = rng.random(n) + 0.1
    sw = np.sqrt(w)
    Bw = sp.csr_matrix(B * sw[:, None])
    ks = np.array([0, 3, 7, 7, q - 1])  # an empty atom, a repeated one
    monkeypatch.setattr(ell_mod, "_PANEL_BITS", 4)  # several panels
    av = ell_mod.atom_vertices(lists, q)
    ref_counts = (sp.csr_matrix(B.astype(float)).T[ks] @ sp.csr_matrix(B.astype(float))).toarray()
    ref_w = (Bw.T.tocsr()[ks] @ Bw).toarray()
    for elems, exact in ((2**23, True), (2 * lists.shape[1], False)):
        monkeypatch.setattr(ell_mod, "_HOST_CHUNK_ELEMS", elems)
        np.testing.assert_array_equal(ell_mod.ell_gram_rows(lists, av, ks), ref_counts)
        got = ell_mod.ell_gram_rows(lists, av, ks, sw * sw)
        if exact:
            np.testing.assert_array_equal(got, ref_w)
        else:
            np.testing.assert_allclose(got, ref_w, rtol=1e-14)
        # column norms are summed per whole atom, so chunking never changes them
        np.testing.assert_array_equal(ell_mod.atom_sums(av, sw * sw),
                                      np.asarray(Bw.multiply(Bw).sum(axis=0)).ravel())


def test_host_gram_rows_in_float64(pair):
    """Under jax_enable_x64 the host rows keep float64 accuracy (weighted Gram rows are not
    integers): sparse, dense-host and dense-GEMM OMP agree to 1e-10."""
    _, _, _, _, sparse, _ = pair
    with jax.enable_x64(True):
        s64 = jax.tree.map(lambda x: jnp.asarray(np.asarray(x)), sparse)
        d64 = bsfjax.Frame(atoms=s64.todense(jnp.float64), coeffs=s64.coeffs, taus=s64.taus,
                           centers=s64.centers, mass=jnp.asarray(np.asarray(sparse.mass), jnp.float64))
        F = (np.random.default_rng(6).random((40, sparse.n_vertices)) < 0.4).astype(np.float64)
        res = [np.asarray(encode(fr, F, "omp", sparsity=6, weights="area", return_info=True,
                                 **opts)[1].residual)
               for fr, opts in ((s64, {}), (d64, {}), (d64, {"precompute": True}))]
        assert res[0].dtype == np.float64
        np.testing.assert_allclose(res[0], res[2], rtol=1e-10)
        np.testing.assert_allclose(res[1], res[2], rtol=1e-10)


def test_sparse_frames_with_the_adaptive_and_hygiene_options(pair):
    """Adaptive scales build sparse too; pruning and p2p pull-back work on sparse frames (see
    test_prune_and_p2p_pull_back_on_sparse_frames); the lasso's target support gives the dense
    path's codes on a sparse frame."""
    src, tgt, centers, dense, sparse, C = pair
    ad_dense = build_frame(src, centers, "adaptive")
    ad_sparse = build_frame(src, centers, "adaptive", sparse=True)
    np.testing.assert_array_equal(np.asarray(ad_sparse.taus), np.asarray(ad_dense.taus))
    diff = np.asarray(ad_sparse.todense()) != np.asarray(ad_dense.atoms)
    assert diff.sum() <= 4
    F = (np.asarray(src.evecs[:, 1]) > 0).astype(np.float32)[None]
    a_d = encode(dense, F, "lasso", target_atoms=6)
    a_s = encode(sparse, F, "lasso", target_atoms=6)
    assert int(np.sum(np.asarray(a_s) != 0)) <= 6
    np.testing.assert_allclose(np.asarray(decode(sparse, a_s)), np.asarray(decode(dense, a_d)),
                               atol=2e-3)


def test_packed_lists_beyond_16_bits(monkeypatch):
    """q ≥ 2¹⁶: 16-bit lists with per-vertex segment starts (bsfjax._frame._packed_lists) give the
    int32 lists' products, counts, transpose, Gram rows, columns and pull-back; the builder
    packs them as the atoms arrive (blocks straddling 2¹⁶ and 2·2¹⁶)."""
    import bsfjax._frame._ell as ell_mod
    import bsfjax._frame._sparse_frame as sf_mod
    from bsfjax.internal import decode_host, decode_traced, pack_lists

    rng = np.random.default_rng(7)
    n, q = 47, 140_000
    active = np.unique(np.concatenate([[0, 65_535, 65_536, 131_071, 131_072, q - 1],
                                       rng.integers(0, q, 60)]))
    B = np.zeros((n, q), bool)
    B[:, active] = rng.random((n, active.size)) < 0.4
    B[5] = False  # a vertex in no atom
    B[6, :65_536] = False  # a vertex with atoms above 2¹⁶ only
    width = int(B.sum(axis=1).max())
    lists = np.stack([np.concatenate([np.flatnonzero(r), np.full(width - r.sum(), q)])
                      for r in B]).astype(np.int32)
    lo, seg = pack_lists(lists, q, rows=10)
    assert lo.dtype == np.uint16 and seg.shape == (n, 2)
    np.testing.assert_array_equal(decode_host(lo, seg), lists)
    np.testing.assert_array_equal(np.asarray(decode_traced(jnp.asarray(lo), jnp.asarray(seg))),
                                  lists)
    for chunks, step in ((3, 20_000), (1, 70_000), (50, 1_000)):
        monkeypatch.setattr(sf_mod, "_BUILD_CHUNKS", chunks)
        builder = sf_mod._ListBuilder(n, q)
        for a in range(0, q, step):
            r, c = np.nonzero(B[:, a:a + step])
            builder.append(r, (c + a).astype(np.int32))
        got_lo, got_seg = builder.finish_packed()
        np.testing.assert_array_equal(got_lo, lo)
        np.testing.assert_array_equal(got_seg, seg)
    kw = dict(coeffs=jnp.zeros((4, q)), taus=jnp.ones(q), centers=jnp.zeros(q, jnp.int32),
              mass=jnp.ones(n), gammas=jnp.full(q, 0.5))
    packed = SparseFrame(atom_lists=jnp.asarray(lo), atom_segments=jnp.asarray(seg), **kw)
    plain = SparseFrame(atom_lists=jnp.asarray(lists), **kw)
    X = rng.integers(-4, 5, size=(3, q)).astype(np.float32)
    Y = rng.integers(-4, 5, size=(3, n)).astype(np.float32)
    np.testing.assert_array_equal(np.asarray(packed.apply(jnp.asarray(X))),
                                  X @ B.T.astype(np.float32))
    np.testing.assert_array_equal(np.asarray(packed.apply_transpose(jnp.asarray(Y))),
                                  Y @ B.astype(np.float32))
    assert packed.nnz == plain.nnz == B.sum()
    np.testing.assert_array_equal(packed.host_lists(), lists)
    np.testing.assert_array_equal(packed.to_scipy().toarray(), B)
    np.testing.assert_array_equal(packed.atom_columns(active[:5]), B[:, active[:5]])
    av, av_ref = (ell_mod.atom_vertices(f.atom_lists, q, f.atom_segments) for f in (packed, plain))
    for x, y in zip(av, av_ref):
        np.testing.assert_array_equal(x, y)
    ks = active[[0, 2, 3, -1]]
    np.testing.assert_array_equal(ell_mod.ell_gram_rows(lo, av, ks, segments=seg),
                                  ell_mod.ell_gram_rows(lists, av_ref, ks))
    p2p = rng.integers(0, n, n)
    np.testing.assert_array_equal(packed.pull_back(p2p, kw["coeffs"], kw["mass"]).host_lists(),
                                  lists[p2p])
    cols = np.sort(rng.choice(active, 20, replace=False))
    sel, sel_ref = (f.select_columns(cols) for f in (packed, plain))
    np.testing.assert_array_equal(sel.host_lists(), sel_ref.host_lists())
