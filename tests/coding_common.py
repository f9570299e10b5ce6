"""Shared frames, functions and references of the coder tests (test_lstsq, test_omp,
test_lasso, test_encode, test_coders).

Frames here are built independently of ``bsfjax.build_frame``: random binary matrices (with an
empty and a duplicated atom, as real binary frames have), and a small real frame on FAUST
tr_reg_000 made with numpy, ``atoms = |Φ(ĝ ⊙ Φ[x, :])| / max ≥ 0.75``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order
from sklearn.linear_model import orthogonal_mp, orthogonal_mp_gram

import bsfjax
from bsfjax import Frame

from .conftest import data_path

METHODS = ("lstsq", "omp", "omp_error", "lasso")


def random_frame(seed, n=120, q=60, density=0.25):
    """Random binary atoms with one empty column and one duplicated column (rank deficient)."""
    rng = np.random.default_rng(seed)
    B = (rng.random((n, q)) < density).astype(np.float64)
    B[:, 3] = 0.0
    B[:, 7] = B[:, 11]
    return B


def fold_duplicate(A):
    """Coefficients with the duplicated atom 11 folded into its copy 7: which of two identical
    atoms OMP picks is a tie (scikit-learn's column swapping and our lowest-index rule differ)."""
    A = np.array(A, dtype=np.float64)
    A[..., 7] += A[..., 11]
    A[..., 11] = 0.0
    return A


def random_functions(seed, m, n, density=0.3):
    """Random step functions plus a little noise: exact ties between atoms' correlations (which
    binary functions on binary atoms produce, and which any OMP breaks by rounding noise) do
    not occur, so the OMP path is determined.  Indicator functions are tested on FAUST."""
    rng = np.random.default_rng(seed)
    return (rng.random((m, n)) < density) + 0.1 * rng.random((m, n))


def as_frame(B, mass=None):
    n, q = B.shape
    return Frame(atoms=B, coeffs=np.zeros((1, q)), taus=np.ones(q), centers=np.zeros(q, int),
                 mass=np.ones(n) if mass is None else mass)


def sk_omp(B, F, S=None, tol=None, precompute=False):
    """orthogonal_mp on the ℓ2-normalised non-empty atoms, mapped back: α_j = β_j / ‖b_j‖.

    ``precompute=True`` is orthogonal_mp's Gram path; it is called here as what it runs,
    ``orthogonal_mp_gram(DᵀD, DᵀF)``, so that the Gram matrix is formed once for all calls."""
    norms = np.linalg.norm(B, axis=0)
    ok = norms > 0
    D = B[:, ok] / norms[ok]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # "ended prematurely"
        if precompute:
            G, Xy = D.T @ D, D.T @ F.T
            if tol is None:
                beta = orthogonal_mp_gram(G, Xy, n_nonzero_coefs=S)
            else:
                beta = np.stack([orthogonal_mp_gram(G, Xy[:, i:i + 1], tol=float(tol[i]),
                                                    norms_squared=[F[i] @ F[i]])
                                 for i in range(F.shape[0])], axis=1)
        elif tol is None:
            beta = orthogonal_mp(D, F.T, n_nonzero_coefs=S)
        else:
            beta = np.stack([orthogonal_mp(D, F[i], tol=float(tol[i]))
                             for i in range(F.shape[0])], axis=1)
    alpha = np.zeros((B.shape[1], F.shape[0]))
    alpha[ok] = beta.reshape(ok.sum(), -1) / norms[ok][:, None]
    return alpha.T


def lasso_objective(B, f, a, lam_abs):
    r = f - B @ a
    return 0.5 * r @ r + lam_abs * np.abs(a).sum()


@pytest.fixture(scope="module")
def faust():
    """A small real frame on FAUST tr_reg_000 (k = 30, 60 centres, 3 scales → q = 180) and 14
    indicator functions: 10 connected regions grown breadth-first from random vertices
    (3–20 % of the vertices) and 4 half-spaces ``y > t`` / ``x > t``."""
    mesh = bsfjax.load_mesh(data_path("faust", "tr_reg_000.off"))
    spec = bsfjax.spectrum(mesh, 30)
    V, n = mesh.vertices, mesh.n_vertices
    rng = np.random.default_rng(0)
    centers = rng.choice(n, 60, replace=False)
    lam = spec.evals * spec.mass.sum()  # scale-invariant τ (unit-area eigenvalues)
    cols = []
    for tau in (1e-3, 5e-3, 1e-2):
        g = spec.evecs @ (np.exp(-tau * (lam - lam[0]))[:, None] * spec.evecs[centers].T)
        cols.append(np.abs(g) / np.abs(g).max(axis=0) >= 0.75)
    B = np.concatenate(cols, axis=1).astype(np.float64)
    f = mesh.faces
    i, j = np.r_[f[:, 0], f[:, 1], f[:, 2]], np.r_[f[:, 1], f[:, 2], f[:, 0]]
    adj = sp.coo_matrix((np.ones(i.size), (i, j)), shape=(n, n)).tocsr()
    regions = []
    for _ in range(10):
        order = breadth_first_order(adj + adj.T, int(rng.integers(n)), directed=False,
                                    return_predecessors=False)
        x = np.zeros(n)
        x[order[: int(rng.uniform(0.03, 0.2) * n)]] = 1.0
        regions.append(x)
    for axis, qt in ((1, 0.3), (1, 0.6), (1, 0.9), (0, 0.5)):
        regions.append((V[:, axis] > np.quantile(V[:, axis], qt)).astype(np.float64))
    return {"B": B, "mass": spec.mass, "F": np.stack(regions),
            "frame": as_frame(B, spec.mass)}
