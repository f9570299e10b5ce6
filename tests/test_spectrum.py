"""Laplace–Beltrami spectrum: accuracy against a libigl + scipy float64 reference, 1D closed form,
sign convention, caching and pytree behaviour."""

from __future__ import annotations

import importlib
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse.linalg

import bsfjax
from bsfjax import Mesh, Spectrum

from .conftest import icosphere


@pytest.fixture(scope="module")
def faust_spec(faust_mesh):
    return bsfjax.spectrum(faust_mesh, 100)


def test_matches_libigl_reference(faust_mesh, faust_spec):
    igl = pytest.importorskip("igl")
    L = -igl.cotmatrix(faust_mesh.vertices, faust_mesh.faces)
    M = igl.massmatrix(faust_mesh.vertices, faust_mesh.faces, igl.MASSMATRIX_TYPE_VORONOI)
    ref = np.sort(scipy.sparse.linalg.eigsh(L.tocsc(), k=100, M=M.tocsc(), sigma=-1e-3,
                                            which="LM", tol=0)[0])
    s = faust_spec
    assert s.evals.shape == (100,) and s.evecs.shape == (6890, 100) and s.mass.shape == (6890,)
    assert s.evals.dtype == np.float64
    assert abs(s.evals[0]) < 1e-10
    np.testing.assert_allclose(s.evals[1:], ref[1:], rtol=1e-8)
    gram = s.evecs.T @ (s.mass[:, None] * s.evecs)
    assert abs(gram - np.eye(100)).max() < 1e-8
    W, A = bsfjax.laplacian(faust_mesh)
    resid = W @ s.evecs - (A @ s.evecs) * s.evals
    assert abs(resid).max() < 1e-8 * s.evals[-1] * abs(A @ s.evecs).max()


def test_sign_convention_and_determinism(faust_mesh, faust_spec):
    idx = np.argmax(np.abs(faust_spec.evecs), axis=0)
    assert np.all(faust_spec.evecs[idx, np.arange(100)] > 0)
    again = bsfjax.spectrum(faust_mesh, 100)
    np.testing.assert_array_equal(again.evecs, faust_spec.evecs)
    np.testing.assert_array_equal(again.evals, faust_spec.evals)


def test_dense_and_sparse_paths_agree(sphere_mesh, monkeypatch):
    spec_mod = importlib.import_module("bsfjax._spectral._spectrum")  # the module, not the function

    dense = bsfjax.spectrum(sphere_mesh, 20)
    monkeypatch.setattr(spec_mod, "DENSE_LIMIT", 0)
    sparse = bsfjax.spectrum(sphere_mesh, 20)
    np.testing.assert_allclose(sparse.evals, dense.evals, rtol=1e-9, atol=1e-10)
    # eigenvectors of simple eigenvalues agree up to the fixed sign; sphere eigenspaces are
    # degenerate (2l+1), so compare the subspaces through projectors instead
    # the first 16 eigenpairs close full eigenspaces l = 0..3 (1+3+5+7)
    P1 = dense.evecs[:, :16] @ (dense.evecs[:, :16].T * dense.mass)
    P2 = sparse.evecs[:, :16] @ (sparse.evecs[:, :16].T * sparse.mass)
    assert abs(P1 - P2).max() < 1e-8


def test_sphere_eigenvalues_closed_form():
    v, f = icosphere(4)
    s = bsfjax.spectrum(Mesh(v, f), 16)
    exact = np.repeat([l * (l + 1) for l in range(4)], [1, 3, 5, 7])  # l(l+1), multiplicity 2l+1
    np.testing.assert_allclose(s.evals[1:], exact[1:], rtol=2e-2)


def test_interval_spectrum_converges():
    L = 2.0
    errs = []
    for n in (50, 200, 800):
        s = bsfjax.interval_spectrum(n, 8, length=L)
        exact = (np.pi * np.arange(8) / L) ** 2
        errs.append(np.max(np.abs(s.evals[1:] - exact[1:]) / exact[1:]))
        assert s.mass.sum() == pytest.approx(L)
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 1e-3
    assert errs[0] / errs[1] > 10  # second-order convergence: 4x nodes, ~16x smaller error
    s = bsfjax.interval_spectrum(801, 4, length=L)
    x = np.linspace(0, L, 801)
    np.testing.assert_allclose(np.abs(s.evecs[:, 2]), np.abs(np.sqrt(2 / L) * np.cos(2 * np.pi * x / L)),
                               atol=1e-3)


def test_disconnected_mesh_warns():
    v, f = icosphere(2)
    two = Mesh(np.concatenate([v, v + [3.0, 0, 0]]), np.concatenate([f, f + len(v)]))
    with pytest.warns(UserWarning, match="2 connected components"):
        s = bsfjax.spectrum(two, 6)
    np.testing.assert_allclose(s.evals[:2], 0, atol=1e-9)
    assert s.evals[2] > 0.5


def test_cache_roundtrip_and_corruption(tmp_path, sphere_mesh):
    s1 = bsfjax.spectrum(sphere_mesh, 12, cache_dir=tmp_path)
    files = list(tmp_path.glob("*.npz"))
    assert len(files) == 1
    s2 = bsfjax.spectrum(sphere_mesh, 12, cache_dir=tmp_path)
    np.testing.assert_array_equal(s1.evecs, s2.evecs)
    # a cache hit must not recompute: poison the solver and load again
    spec_mod = importlib.import_module("bsfjax._spectral._spectrum")

    orig = spec_mod.spectrum_from_operators
    spec_mod.spectrum_from_operators = None
    try:
        s3 = bsfjax.spectrum(sphere_mesh, 12, cache_dir=tmp_path)
    finally:
        spec_mod.spectrum_from_operators = orig
    np.testing.assert_array_equal(s3.evals, s1.evals)
    # flip bytes inside the stored eigenvectors: checksum must catch it
    raw = bytearray(files[0].read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    files[0].write_bytes(bytes(raw))
    with pytest.warns(UserWarning, match="corrupt"):
        s4 = bsfjax.spectrum(sphere_mesh, 12, cache_dir=tmp_path)
    np.testing.assert_array_equal(s4.evals, s1.evals)
    files[0].write_bytes(b"garbage")
    with pytest.warns(UserWarning, match="corrupt"):
        bsfjax.spectrum(sphere_mesh, 12, cache_dir=tmp_path)
    assert bsfjax.spectrum(sphere_mesh, 12, cache_dir=tmp_path).k == 12  # file was rewritten
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp.npz")] == []


def test_spectrum_is_a_pytree(sphere_mesh):
    s = bsfjax.spectrum(sphere_mesh, 10)
    leaves = jax.tree_util.tree_leaves(s)
    assert len(leaves) == 3

    @jax.jit
    def energy(sp: Spectrum):
        return jnp.sum(sp.evals) + jnp.sum(sp.mass)

    assert float(energy(s)) == pytest.approx(s.evals.sum() + s.mass.sum(), rel=1e-5)
    s2 = Mesh(sphere_mesh.vertices * 2.0, sphere_mesh.faces)
    stacked = jax.tree.map(lambda *x: jnp.stack(x), s, bsfjax.spectrum(s2, 10))
    out = jax.vmap(lambda sp: jnp.sum(sp.mass))(stacked)
    np.testing.assert_allclose(np.asarray(out), [s.area, 4 * s.area], rtol=1e-5)
    assert s.truncate(4).evecs.shape == (s.n_vertices, 4)


def test_spectrum_from_operators_validates():
    from bsfjax.internal import interval_operators

    W, a = interval_operators(10)
    with pytest.raises(ValueError, match="k must be"):
        bsfjax.spectrum_from_operators(W, a, 11)
    with pytest.raises(ValueError, match="k must be"):
        bsfjax.spectrum_from_operators(W, a, 0)
    with pytest.raises(ValueError, match="positive diagonal"):
        bsfjax.spectrum_from_operators(W, np.zeros(10), 3)
    with pytest.raises(ValueError, match="NaN"):
        bsfjax.spectrum_from_operators(W, np.full(10, np.nan), 3)
    with pytest.raises(ValueError, match="diagonal"):
        bsfjax.spectrum_from_operators(W, np.ones(9), 3)
    with pytest.raises(ValueError, match="n must be"):
        bsfjax.interval_spectrum(1, 1)


def test_spectrum_k_errors(sphere_mesh):
    with pytest.raises(ValueError, match=r"k must be an integer in \[1, n_vertices=642\]"):
        bsfjax.spectrum(sphere_mesh, 1000)
    with pytest.raises(ValueError, match="k must be"):
        bsfjax.spectrum(sphere_mesh, 2.5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bsfjax.spectrum(sphere_mesh, 5)  # a clean connected mesh warns about nothing


def test_signs_match_the_largest_magnitude_entry():
    # _signs reads each column's largest and smallest entries instead of |evecs|: the same
    # rule as the sign of argmax |x| (first index on a tie), +1 for a zero column
    from bsfjax._spectral._spectrum import _signs
    rng = np.random.default_rng(5)
    X = rng.standard_normal((200, 30))
    X[:, 3] = 0.0
    X[:4, 4], X[4:, 4] = [0.5, -0.5, 0.1, 0.0], 0.0   # tie, the positive entry first
    X[:4, 5], X[4:, 5] = [-0.5, 0.5, 0.1, 0.0], 0.0   # tie, the negative entry first
    X[:, 6] = -1.0                                     # constant negative column
    idx = np.argmax(np.abs(X), axis=0)
    want = np.sign(X[idx, np.arange(30)])
    want[want == 0] = 1.0
    np.testing.assert_array_equal(_signs(X), want)
    assert list(_signs(X)[3:7]) == [1.0, 1.0, -1.0, -1.0]
