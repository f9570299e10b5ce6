"""Cotangent stiffness and mass against libigl (float64) and closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import bsfjax
from bsfjax import Mesh, MeshError
from bsfjax.internal import cotangent_stiffness, mass_matrix

from .conftest import data_path, icosphere

igl = pytest.importorskip("igl", reason="libigl is the float64 reference for the Laplacian")


@pytest.fixture(scope="module")
def cat10k():
    return bsfjax.load_mesh(data_path("tosca_10k", "cat", "cat0.off"))  # open: has boundary edges


@pytest.mark.parametrize("which", ["faust", "cat"])
def test_matches_libigl(which, faust_mesh, cat10k):
    m = faust_mesh if which == "faust" else cat10k
    W, A = bsfjax.laplacian(m)
    L = igl.cotmatrix(m.vertices, m.faces)
    M = igl.massmatrix(m.vertices, m.faces, igl.MASSMATRIX_TYPE_VORONOI)
    scale = abs(L).max()
    assert abs(W + L).max() <= 1e-12 * scale  # igl's cotmatrix is negative semidefinite
    np.testing.assert_allclose(A.diagonal(), M.diagonal(), rtol=1e-12)
    Ab = mass_matrix(m, "barycentric")
    Mb = igl.massmatrix(m.vertices, m.faces, igl.MASSMATRIX_TYPE_BARYCENTRIC)
    np.testing.assert_allclose(Ab.diagonal(), Mb.diagonal(), rtol=1e-12)


def test_structure_and_psd(sphere_mesh):
    W, A = bsfjax.laplacian(sphere_mesh)
    assert sp.issparse(W) and sp.issparse(A)
    assert abs(W - W.T).max() == 0
    np.testing.assert_allclose(W @ np.ones(sphere_mesh.n_vertices), 0, atol=1e-12)
    assert np.linalg.eigvalsh(W.toarray()).min() > -1e-10
    off = W - sp.diags(W.diagonal())
    assert off.max() <= 0  # Delaunay sphere: all cotangent weights positive
    assert A.nnz == sphere_mesh.n_vertices  # diagonal
    for kind in ("mixed", "barycentric"):
        assert mass_matrix(sphere_mesh, kind).diagonal().sum() == pytest.approx(sphere_mesh.area, rel=1e-12)


def test_single_triangle_closed_form():
    # right isosceles triangle: angles 90, 45, 45 degrees
    m = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))
    W = cotangent_stiffness(m).toarray()
    # edge (1,2) is opposite the right angle: cot 90 = 0; edges (0,1),(0,2) opposite 45°: cot = 1
    expected = np.array([[1.0, -0.5, -0.5], [-0.5, 0.5, 0.0], [-0.5, 0.0, 0.5]])
    np.testing.assert_allclose(W, expected, atol=1e-15)
    # obtuse-free (right angle counts as non-obtuse): Voronoi areas 1/4, 1/8, 1/8
    np.testing.assert_allclose(mass_matrix(m, "mixed").diagonal(), [0.25, 0.125, 0.125], atol=1e-15)
    np.testing.assert_allclose(mass_matrix(m, "barycentric").diagonal(), [1 / 6] * 3)


def test_obtuse_triangle_mixed_area():
    m = Mesh(np.array([[0, 0, 0], [4, 0, 0], [2, 0.5, 0]], float), np.array([[0, 1, 2]]))
    a = 0.5 * 4 * 0.5
    np.testing.assert_allclose(mass_matrix(m, "mixed").diagonal(), [a / 4, a / 4, a / 2])


def test_scaling(sphere_mesh):
    W, A = bsfjax.laplacian(sphere_mesh)
    big = Mesh(sphere_mesh.vertices * 7.0, sphere_mesh.faces)
    W2, A2 = bsfjax.laplacian(big)
    assert abs(W2 - W).max() < 1e-12  # cotangents are scale invariant
    np.testing.assert_allclose(A2.diagonal(), 49.0 * A.diagonal(), rtol=1e-12)


def test_robust_option(sphere_mesh):
    pytest.importorskip("robust_laplacian")
    W, A = bsfjax.laplacian(sphere_mesh, robust=True)
    W0, A0 = bsfjax.laplacian(sphere_mesh)
    # on a Delaunay mesh the intrinsic Delaunay Laplacian is the cotangent Laplacian
    assert abs(W - W0).max() < 1e-8
    assert A.diagonal().sum() == pytest.approx(sphere_mesh.area, rel=1e-8)


def test_errors(sphere_mesh):
    with pytest.raises(ValueError, match="mass must be one of"):
        bsfjax.laplacian(sphere_mesh, mass="voronoi-ish")
    with pytest.raises(bsfjax.MeshError, match="bsfjax.Mesh"):
        bsfjax.laplacian(np.zeros((3, 3)))
    v, f = icosphere(1)
    lonely = Mesh(np.concatenate([v, [[5.0, 5, 5]]]), f)  # vertex 12 in no face
    with pytest.raises(MeshError, match="1 vertices have zero mass"):
        bsfjax.laplacian(lonely)
