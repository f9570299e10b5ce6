"""Property-based tests (hypothesis) of the public API on random valid meshes and functions.

Invariants:

* ``decode(encode(f))`` error never increases when the OMP sparsity S grows;
* transferring a frame with the identity map onto the same shape reproduces it exactly, and so
  transferring a function that way equals approximating it;
* the relative error is invariant to scaling the functions and the areas;
* results are invariant to re-ordering the vertices when the map is re-ordered the same way
  (Laplacian, spectrum, frame, codes, functional map, transfer, error).

Meshes are random star-shaped deformations of an icosphere (smooth radial bumps, anisotropic
scaling, rotation), so they are valid, closed and without symmetries; all have 162 vertices so
that jitted stages compile once.  ``max_examples`` is small and ``deadline=None``: the file
runs in a few seconds.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import bsfjax

from .conftest import icosphere

SETTINGS = settings(max_examples=6, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])
K = 12
N_CENTERS = 10
_BASE = icosphere(2)


def random_mesh(seed: int, bump: float, stretch: tuple[float, float, float]) -> bsfjax.Mesh:
    """A random smooth deformation of the 162-vertex icosphere."""
    rng = np.random.default_rng(seed)
    v, f = _BASE
    dirs = rng.normal(size=(4, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    radial = 1.0 + bump * np.tanh(np.sin(3.0 * v @ dirs.T + rng.uniform(0, 6, 4)).sum(axis=1))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return bsfjax.Mesh((v * radial[:, None] * np.asarray(stretch)) @ q, f)


# bump > 0: an exactly symmetric shape (the sphere) has eigenvectors whose largest |entry| is
# attained with both signs, so their sign (and any degenerate eigenspace) depends on vertex order
meshes = st.builds(random_mesh, st.integers(0, 2**31 - 1), st.floats(0.05, 0.25),
                   st.tuples(*[st.floats(0.6, 1.6)] * 3))
seeds = st.integers(0, 2**31 - 1)


def _setup(mesh: bsfjax.Mesh, seed: int):
    spec = bsfjax.spectrum(mesh, K)
    centers = bsfjax.farthest_point_sampling(mesh, N_CENTERS, seed=seed % mesh.n_vertices)
    return spec, centers, bsfjax.build_frame(spec, centers)


def _step_functions(mesh, seed, count=3):
    """Step functions Σ a_r χ_R (paper Eq. 2) with random values on random regions."""
    chi = bsfjax.random_indicators(mesh, count, seed=seed)
    vals = np.random.default_rng(seed).uniform(-2, 2, size=(count, 1))
    return chi * vals


@SETTINGS
@given(mesh=meshes, seed=seeds)
def test_omp_error_never_increases_with_sparsity(mesh, seed):
    spec, centers, frame = _setup(mesh, seed)
    F = _step_functions(mesh, seed)
    residuals = []
    for S in (1, 2, 4, 8, 16):
        alpha, info = bsfjax.encode(frame, F, "omp", sparsity=S, weights="area",
                                    return_info=True)
        # the residual is the area-weighted error of decode(encode(f)), computed independently
        err = np.sqrt(np.sum(spec.mass * (F - np.asarray(bsfjax.decode(frame, alpha))) ** 2, 1))
        np.testing.assert_allclose(err, info.residual, rtol=1e-3, atol=1e-5)
        residuals.append(err)
    residuals = np.asarray(residuals)
    scale = np.sqrt(np.sum(spec.mass * F**2, axis=1))
    assert np.all(np.diff(residuals, axis=0) <= 1e-4 * scale), residuals / scale


@SETTINGS
@given(mesh=meshes, seed=seeds)
def test_identity_map_transfer_is_exact(mesh, seed):
    spec, centers, frame = _setup(mesh, seed)
    same = bsfjax.transfer_frame(frame, np.eye(K), spec)
    np.testing.assert_array_equal(np.asarray(same.atoms), np.asarray(frame.atoms))
    np.testing.assert_array_equal(np.asarray(same.coeffs), np.asarray(frame.coeffs))
    F = _step_functions(mesh, seed)
    for method in ("omp", "lstsq"):
        alpha = bsfjax.encode(frame, F, method)
        np.testing.assert_array_equal(np.asarray(bsfjax.decode(same, alpha)),
                                      np.asarray(bsfjax.decode(frame, alpha)))


@settings(max_examples=40, deadline=None, database=None)
@given(data=st.data(), n=st.integers(1, 60), s=st.floats(1e-6, 1e6), w=st.floats(1e-6, 1e6))
def test_relative_error_is_scale_invariant(data, n, s, w):
    arrays = st.lists(st.floats(-10, 10), min_size=n, max_size=n).map(np.asarray)
    f, g = data.draw(arrays), data.draw(arrays)
    mass = data.draw(st.lists(st.floats(0.01, 5), min_size=n, max_size=n).map(np.asarray))
    base = float(bsfjax.relative_error(f, g, mass))
    scaled = float(bsfjax.relative_error(s * f, s * g, w * mass))
    assert np.isfinite(base) and np.isfinite(scaled)
    # float64 reference.  In float32 a reference below ~1e-38 of the estimate's magnitude is
    # zero (f = 1e-205 against f̃ = 1 now and then in these draws): the zero-norm rule, an
    # absolute error; else the ratio, each norm on its own scale (f = 1e-30 against f̃ = 1 is
    # 1e30), at most float32's largest value
    top = max(np.max(np.abs(f)), np.max(np.abs(g)))
    top = np.ldexp(1.0, np.frexp(top)[1]) if top > 0 else 1.0  # as the library: a power of 2
    zero = not np.any(np.abs(f / top) >= np.finfo(np.float32).tiny)  # (subnormals: zero)
    num = np.sqrt(np.sum(mass * (f - g) ** 2))
    if zero:
        assert base == pytest.approx(num, rel=1e-4, abs=1e-6)
        return
    assert scaled == pytest.approx(base, rel=1e-4, abs=1e-6)  # the ratio is scale invariant
    m = np.ldexp(1.0, -np.frexp(np.max(np.abs(f)))[1])  # exact: f·m in [0.5, 1)
    ratio = np.sqrt(np.sum(mass * (m * f - m * g) ** 2)) / np.sqrt(np.sum(mass * (m * f) ** 2))
    assert base == pytest.approx(min(ratio, np.finfo(np.float32).max), rel=1e-4, abs=1e-6)


def _permuted_mesh(mesh, perm):
    """``mesh`` with vertex ``perm[i]`` moved to row ``i`` (faces renumbered)."""
    inv = np.argsort(perm)
    return bsfjax.Mesh(mesh.vertices[perm], inv[mesh.faces])


@SETTINGS
@given(mesh=meshes, seed=seeds)
def test_vertex_reordering_invariance(mesh, seed):
    rng = np.random.default_rng(seed)
    n = mesh.n_vertices
    perm = rng.permutation(n)
    inv = np.argsort(perm)
    mesh_p = _permuted_mesh(mesh, perm)
    # operators: W' = P W Pᵀ, A' = P A Pᵀ
    W, A = bsfjax.laplacian(mesh)
    Wp, Ap = bsfjax.laplacian(mesh_p)
    P = sp.csr_matrix((np.ones(n), (np.arange(n), perm)), shape=(n, n))
    assert abs(Wp - P @ W @ P.T).max() <= 1e-12 * abs(W).max()
    np.testing.assert_allclose(Ap.diagonal(), A.diagonal()[perm], rtol=1e-13)
    # spectrum: same eigenvalues; eigenvectors permuted (the sign rule is order independent)
    spec, centers, frame = _setup(mesh, seed)
    spec_p = bsfjax.spectrum(mesh_p, K)
    np.testing.assert_allclose(spec_p.evals, spec.evals, rtol=1e-7, atol=1e-9)
    gaps = np.diff(spec.evals)
    good = np.flatnonzero((np.r_[np.inf, gaps] > 1e-3) & (np.r_[gaps, np.inf] > 1e-3))
    np.testing.assert_allclose(spec_p.evecs[:, good], spec.evecs[perm][:, good], atol=1e-6)
    # frame, codes and errors on the exactly permuted spectrum: vertices permute, atoms do not
    exact = bsfjax.Spectrum(spec.evals, spec.evecs[perm], spec.mass[perm])
    frame_p = bsfjax.build_frame(exact, inv[centers])
    np.testing.assert_array_equal(np.asarray(frame_p.atoms), np.asarray(frame.atoms)[perm])
    F = _step_functions(mesh, seed)
    for method in ("lstsq", "omp"):
        a = np.asarray(bsfjax.encode(frame, F, method, weights="area"))
        a_p = np.asarray(bsfjax.encode(frame_p, F[:, perm], method, weights="area"))
        np.testing.assert_allclose(a_p, a, rtol=1e-4, atol=1e-4)
    # transfer M → N and M → N' (N re-ordered, the map re-ordered the same way)
    target = random_mesh(seed + 1, 0.1, (1.0, 1.2, 0.9))
    spec_n = bsfjax.spectrum(target, K)
    spec_n_p = bsfjax.Spectrum(spec_n.evals, spec_n.evecs[perm], spec_n.mass[perm])
    p2p = rng.integers(0, n, n)  # target vertex i → source vertex p2p[i]
    C = np.asarray(bsfjax.fmap_from_p2p(spec, spec_n, p2p))
    C_p = np.asarray(bsfjax.fmap_from_p2p(spec, spec_n_p, p2p[perm]))
    np.testing.assert_allclose(C_p, C, rtol=1e-5, atol=1e-6)
    alpha = bsfjax.encode(frame, F, "lstsq")
    out = np.asarray(bsfjax.decode(bsfjax.transfer_frame(frame, C, spec_n), alpha))
    out_p = np.asarray(bsfjax.decode(bsfjax.transfer_frame(frame, C, spec_n_p), alpha))
    np.testing.assert_allclose(out_p, out[:, perm], rtol=1e-5, atol=1e-5)
    ref = F[:, p2p]
    err = np.asarray(bsfjax.relative_error(ref, out, spec_n.mass))
    err_p = np.asarray(bsfjax.relative_error(ref[:, perm], out_p, spec_n_p.mass))
    np.testing.assert_allclose(err_p, err, rtol=1e-5, atol=1e-6)
