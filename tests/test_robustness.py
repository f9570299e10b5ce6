"""Every bad input gets a clear error; every handled degenerate input gives a defined, NaN-free
result.  ``docs/robustness.md`` is the table of these cases; a test checks that it
lists every case id below.

``BAD_INPUTS``: (id, call, exception type, message regex).  Each call must raise that type (a
``ValueError`` subclass), with a message naming the argument and value.

``HANDLED_INPUTS``: (id, call, warning regex or ``None``).  Each call must succeed, emit the
warning (with its count) if one is given, and return only finite numbers.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import bsfjax
import bsfjax.internal
from bsfjax import BSFError, MeshError
from bsfjax import mesh_report
from bsfjax.internal import clean_mesh

from .conftest import icosphere

DOC = Path(__file__).resolve().parents[1] / "docs" / "robustness.md"


@pytest.fixture(scope="module")
def ns():
    """A small shape and everything built on it (42 vertices: fast)."""
    v, f = icosphere(1)
    mesh = bsfjax.Mesh(v, f, name="ico1")
    spec = bsfjax.spectrum(mesh, 10)
    centers = bsfjax.farthest_point_sampling(mesh, 8)
    frame = bsfjax.build_frame(spec, centers)
    F = bsfjax.random_indicators(mesh, 3, seed=1)
    n = mesh.n_vertices
    rng = np.random.default_rng(0)
    return SimpleNamespace(v=v, f=f, mesh=mesh, spec=spec, centers=centers, frame=frame, F=F,
                           n=n, C=np.eye(10), descr=rng.random((n, 4)))


def _two_components():
    v, f = icosphere(1)
    return np.concatenate([v, v + [5.0, 0, 0]]), np.concatenate([f, f + len(v)])


def _nan_spectrum(s):
    return bsfjax.Spectrum(s.evals, np.full_like(s.evecs, np.nan), s.mass)


BAD_INPUTS = [
    # --- mesh construction and files
    ("mesh-nan-vertices", lambda s: bsfjax.Mesh(np.full((3, 3), np.nan), [[0, 1, 2]]),
     MeshError, r"3 vertices have NaN or infinite coordinates"),
    ("mesh-ragged-vertices", lambda s: bsfjax.Mesh([[0, 0, 0], [1, 0]], [[0, 1, 1]]),
     MeshError, r"vertices must be an \(n, 3\) array"),
    ("mesh-complex-vertices", lambda s: bsfjax.Mesh(s.v.astype(complex), s.f),
     MeshError, r"vertices must be real numbers, got dtype complex128"),
    ("mesh-2d-vertices", lambda s: bsfjax.Mesh(s.v[:, :2], s.f),
     MeshError, r"vertices must have shape \(n, 3\), got \(42, 2\)"),
    ("mesh-no-vertices", lambda s: bsfjax.Mesh(np.zeros((0, 3)), [[0, 1, 2]]),
     MeshError, r"mesh is empty \(0 vertices\)"),
    ("mesh-no-faces", lambda s: bsfjax.Mesh(s.v, np.zeros((0, 3), int)),
     MeshError, r"mesh has no faces"),
    ("mesh-fractional-faces", lambda s: bsfjax.Mesh(s.v, s.f + 0.5),
     MeshError, r"faces must be integer indices, got dtype float64"),
    ("mesh-face-index-too-large", lambda s: bsfjax.Mesh(s.v, s.f + 1),
     MeshError, r"face indices out of range: found \[1, 42\] for 42 vertices"),
    ("mesh-negative-face-index", lambda s: bsfjax.Mesh(s.v, s.f - 1),
     MeshError, r"face indices out of range: found \[-1, 40\]"),
    ("mesh-huge-coordinates", lambda s: bsfjax.Mesh(s.v * 1e200, s.f),
     MeshError, r"coordinates up to 1e\+200 overflow"),
    ("mesh-all-faces-zero-area", lambda s: clean_mesh(np.zeros((3, 3)), [[0, 1, 2]]),
     MeshError, r"every face has zero area"),
    ("load-missing-file", lambda s: bsfjax.load_mesh("/nonexistent/shape.off"),
     MeshError, r"/nonexistent/shape.off: no such file"),
    ("load-directory", lambda s: bsfjax.load_mesh(Path(__file__).parent),
     MeshError, r"is a directory, not a mesh file"),
    ("save-unknown-format", lambda s: bsfjax.save_mesh("/tmp/x.notaformat", s.mesh),
     MeshError, r"unknown format '\.notaformat'"),
    ("save-point-data-length", lambda s: bsfjax.save_mesh("/tmp/x.ply", s.mesh,
                                                          point_data={"a": np.ones(3)}),
     MeshError, r"point_data\['a'\] has 3 rows, mesh has 42 vertices"),
    ("mesh-report-not-a-mesh", lambda s: mesh_report(s.v), MeshError, r"must be a bsfjax.Mesh"),
    ("mesh-float-vertex-ids", lambda s: bsfjax.Mesh(s.v, s.f, vertex_ids=np.zeros(42) + 0.5),
     MeshError, r"vertex_ids must be integer row indices, got dtype float64"),
    ("load-path-not-a-path", lambda s: bsfjax.load_mesh(None), MeshError,
     r"path must be a str or os.PathLike, got NoneType"),
    # --- Laplacian and spectrum
    ("laplacian-zero-area-mesh", lambda s: bsfjax.laplacian(bsfjax.Mesh(np.zeros((3, 3)),
                                                                        [[0, 1, 2]])),
     MeshError, r"3 vertices have zero mass"),
    ("laplacian-isolated-vertex", lambda s: bsfjax.laplacian(bsfjax.Mesh(
        np.vstack([s.v, [9.0, 9, 9]]), s.f)), MeshError, r"1 vertices have zero mass"),
    ("laplacian-unknown-mass", lambda s: bsfjax.laplacian(s.mesh, mass="voronoi"),
     BSFError, r"mass must be one of \('mixed', 'barycentric'\), got 'voronoi'"),
    ("laplacian-not-a-mesh", lambda s: bsfjax.laplacian(s.v), MeshError,
     r"mesh must be a bsfjax.Mesh, got ndarray"),
    ("spectrum-k-above-n-vertices", lambda s: bsfjax.spectrum(s.mesh, 43),
     BSFError, r"k must be an integer in \[1, n_vertices=42\], got 43 \(mesh ico1\)"),
    ("spectrum-k-not-int", lambda s: bsfjax.spectrum(s.mesh, 3.0),
     BSFError, r"k must be an integer in \[1, n_vertices=42\], got 3.0"),
    ("spectrum-unknown-mass", lambda s: bsfjax.spectrum(s.mesh, 3, mass="x"),
     BSFError, r"mass must be one of"),
    ("spectrum-cache-dir-is-a-file", lambda s: bsfjax.spectrum(s.mesh, 3, cache_dir=__file__),
     BSFError, r"cache_dir must be a folder path, got '.*test_robustness.py'"),
    ("operators-not-symmetric", lambda s: bsfjax.spectrum_from_operators(
        np.array([[1.0, 2.0], [0.0, 1.0]]), np.ones(2), 1), BSFError, r"W must be symmetric"),
    ("operators-nan", lambda s: bsfjax.spectrum_from_operators(
        np.array([[np.nan, 0], [0, 1.0]]), np.ones(2), 1), BSFError, r"must be finite"),
    ("operators-zero-mass", lambda s: bsfjax.spectrum_from_operators(np.eye(2), [1.0, 0.0], 1),
     BSFError, r"A must have a positive diagonal; 1 entries are <= 0"),
    ("operators-not-square", lambda s: bsfjax.spectrum_from_operators(np.ones((2, 3)),
                                                                       np.ones(2), 1),
     BSFError, r"W must be a non-empty square matrix, got shape \(2, 3\)"),
    ("operators-sigma-nan", lambda s: bsfjax.spectrum_from_operators(np.eye(2), np.ones(2), 1,
                                                                      sigma=float("nan")),
     BSFError, r"sigma must be a finite number or None, got nan"),
    ("spectrum-nan-evecs", lambda s: _nan_spectrum(s.spec), BSFError,
     r"Spectrum.evecs contains 420 NaN or infinite values"),
    ("spectrum-negative-mass", lambda s: bsfjax.Spectrum(s.spec.evals, s.spec.evecs,
                                                         -s.spec.mass),
     BSFError, r"Spectrum.mass \(vertex areas\) must be >= 0, found 42 negative"),
    ("spectrum-shape-mismatch", lambda s: bsfjax.Spectrum(s.spec.evals[:5], s.spec.evecs,
                                                          s.spec.mass),
     BSFError, r"Spectrum needs evals \(\.\.\., k\), evecs \(\.\.\., n, k\)"),
    ("spectrum-truncate-zero", lambda s: s.spec.truncate(0), BSFError,
     r"k must be an integer in \[1, 10\], got 0"),
    ("interval-one-node", lambda s: bsfjax.interval_spectrum(1, 1), BSFError,
     r"n must be an integer >= 2, got 1"),
    ("interval-negative-length", lambda s: bsfjax.interval_spectrum(5, 2, length=-1.0),
     BSFError, r"length must be positive and finite, got -1.0"),
    # --- sampling and frames
    ("fps-more-samples-than-points", lambda s: bsfjax.farthest_point_sampling(s.mesh, 43),
     BSFError, r"n must be in \[1, 42\] \(the number of points\), got 43"),
    ("fps-negative-seed", lambda s: bsfjax.farthest_point_sampling(s.mesh, 3, seed=-1),
     BSFError, r"seed must be a non-negative int, got -1"),
    ("fps-nan-points", lambda s: bsfjax.farthest_point_sampling(np.full((4, 3), np.nan), 2),
     BSFError, r"mesh points contain NaN or inf"),
    ("frame-negative-tau", lambda s: bsfjax.build_frame(s.spec, s.centers, taus=(-1e-3,)),
     BSFError, r"taus must be positive and finite, got \[-0.001\]"),
    ("frame-gamma-one", lambda s: bsfjax.build_frame(s.spec, s.centers, gamma=1.0),
     BSFError, r"gamma must be in the open interval \(0, 1\)"),
    ("frame-center-out-of-range", lambda s: bsfjax.build_frame(s.spec, [0, 42]),
     BSFError, r"centers must index the 42 vertices \(0\.\.41\), found values in \[0, 42\]"),
    ("frame-float-centers", lambda s: bsfjax.build_frame(s.spec, [1.5]),
     BSFError, r"centers must be integer vertex indices, got dtype float64"),
    ("frame-empty-centers", lambda s: bsfjax.build_frame(s.spec, []),
     BSFError, r"centers is empty"),
    ("transfer-frame-nan-map", lambda s: bsfjax.transfer_frame(s.frame, np.full((10, 10), np.nan),
                                                               s.spec),
     BSFError, r"C contains NaN or inf"),
    ("transfer-frame-map-too-large", lambda s: bsfjax.transfer_frame(s.frame, np.eye(11), s.spec),
     BSFError, r"C has k_M = 11 columns but frame has only 10 coefficient rows"),
    # --- coding
    ("encode-nan-function", lambda s: bsfjax.encode(s.frame, np.where(s.F[0] > 0, np.nan, 0)),
     BSFError, r"f contains \d+ NaN or infinite values"),
    ("encode-wrong-length", lambda s: bsfjax.encode(s.frame, np.ones(5)),
     BSFError, r"f has length 5 along its last axis, but the frame has n = 42 vertices"),
    ("decode-overflowing-codes", lambda s: bsfjax.decode(s.frame, np.full(24, 3e38, np.float32)),
     BSFError, r"alpha decodes to values up to .*, beyond the float32 range"),
    ("encode-sparsity-zero", lambda s: bsfjax.encode(s.frame, s.F, sparsity=0),
     BSFError, r"sparsity must be an integer >= 1, got 0"),
    ("encode-unknown-option", lambda s: bsfjax.encode(s.frame, s.F, "omp", lam=0.1),
     BSFError, r"unknown option\(s\) \['lam'\] for method='omp'"),
    ("encode-negative-weights", lambda s: bsfjax.encode(s.frame, s.F, weights=-np.ones(s.n)),
     BSFError, r"weights must be finite, >= 0 and not all zero"),
    ("encode-unknown-method", lambda s: bsfjax.encode(s.frame, s.F, "ksvd"),
     BSFError, r"method must be one of .*, got 'ksvd'"),
    ("decode-nan-coefficients", lambda s: bsfjax.decode(s.frame, np.full(24, np.nan)),
     BSFError, r"alpha contains 24 NaN or infinite values"),
    ("decode-wrong-length", lambda s: bsfjax.decode(s.frame, np.ones(3)),
     BSFError, r"alpha must have shape \(\.\.\., q\) with q = 24 atoms, got \(3,\)"),
    # --- metrics, test functions
    ("relative-error-nan", lambda s: bsfjax.relative_error(s.F * np.nan, s.F, s.spec.mass),
     BSFError, r"reference contains NaN or infinite values"),
    ("relative-error-length-mismatch", lambda s: bsfjax.relative_error(s.F, s.F[:, :5],
                                                                       s.spec.mass),
     BSFError, r"must share the last axis"),
    ("relative-error-zero-mass", lambda s: bsfjax.relative_error(s.F, s.F, np.zeros(s.n)),
     BSFError, r"mass must be >= 0 with at least one positive vertex area"),
    ("indicators-zero-count", lambda s: bsfjax.random_indicators(s.mesh, 0),
     BSFError, r"count must be a positive int, got 0"),
    ("indicators-bad-area-fraction", lambda s: bsfjax.random_indicators(
        s.mesh, 2, area_fraction=(0.5, 0.1)), BSFError, r"0 < lo <= hi <= 1, got \(0.5, 0.1\)"),
    ("labels-negative", lambda s: bsfjax.labels_to_indicators([-1, 0]), BSFError,
     r"labels must be >= 0, got min -1"),
    ("labels-nan-indicators", lambda s: bsfjax.indicators_to_labels(np.full((2, 3), np.nan)),
     BSFError, r"indicators contain NaN or infinite values"),
    # --- descriptors and maps
    ("hks-constant-spectrum", lambda s: bsfjax.hks(s.spec.truncate(1)), BSFError,
     r"needs at least 2 eigenpairs"),
    ("wks-zero-eigenvalues", lambda s: bsfjax.wks(bsfjax.Spectrum(
        np.zeros(3), s.spec.evecs[:, :3], s.spec.mass)), BSFError,
     r"wks needs a non-zero eigenvalue among the first k=3"),
    ("wks-variance-not-a-number", lambda s: bsfjax.wks(s.spec, variance="7"), BSFError,
     r"variance must be a positive finite number, got '7'"),
    ("p2p-index-out-of-range", lambda s: bsfjax.fmap_from_p2p(s.spec, s.spec,
                                                              np.full(s.n, 50)),
     BSFError, r"p2p indices must be in \[0, 42\) \(source vertices\), found range \[50, 50\]"),
    ("fmap-to-p2p-nan-map", lambda s: bsfjax.fmap_to_p2p(np.full((5, 5), np.nan), s.spec, s.spec),
     BSFError, r"C contains 25 NaN or infinite values"),
    ("zoomout-nan-map", lambda s: bsfjax.zoomout(np.full((5, 5), np.nan), s.spec, s.spec, 8),
     BSFError, r"C contains 25 NaN or infinite values"),
    ("icp-negative-iterations", lambda s: bsfjax.icp_refine(np.eye(5), s.spec, s.spec,
                                                            n_iter=-1),
     BSFError, r"n_iter must be a non-negative integer, got -1"),
    ("nearest-neighbors-nan", lambda s: bsfjax.internal.nearest_neighbors(np.full((3, 2), np.nan),
                                                                 np.ones((2, 2))),
     BSFError, r"reference contains 6 NaN or infinite values"),
    ("estimate-nan-descriptors", lambda s: bsfjax.estimate_fmap(
        s.spec, s.spec, np.full((s.n, 3), np.nan), s.descr[:, :3], k=5),
     BSFError, r"source_descr must be finite numbers"),
    ("estimate-nan-descriptors-jax", lambda s: bsfjax.estimate_fmap(  # (checked in JAX)
        s.spec, s.spec, s.descr[:, :3], jnp.asarray(s.descr[:, :3]).at[4, 1].set(jnp.inf), k=5),
     BSFError, r"target_descr must be finite numbers"),
    ("estimate-k-too-large", lambda s: bsfjax.estimate_fmap(s.spec, s.spec, s.descr, s.descr,
                                                            k=50),
     BSFError, r"k=\(k_source=50, k_target=50\) must be in \[2, available\]"),
    ("energy-nan-map", lambda s: bsfjax.fmap_energy(np.full((5, 5), np.nan), s.spec, s.spec,
                                                    s.descr, s.descr),
     BSFError, r"C contains 25 NaN or infinite values"),
    ("geodesic-source-out-of-range", lambda s: bsfjax.geodesic_distances(s.mesh, [0, 99]),
     BSFError, r"sources must be vertex indices in \[0, 42\), found range \[0, 99\]"),
    # --- pipeline
    ("transfer-pairs-nan-map", lambda s: bsfjax.transfer_pairs(
        "omp", [bsfjax.Pair(s.spec, s.spec, np.full((10, 10), np.nan), centers=s.centers)],
        s.F[None]),
     BSFError, r"pair.C contains 100 NaN or infinite values"),
    ("decode-mismatched-frames", lambda s: bsfjax.decode(
        bsfjax.build_frame(s.spec, s.centers[:2]), bsfjax.encode(s.frame, s.F)),
     BSFError, r"alpha must have shape \(\.\.\., q\) with q = 6 atoms"),
    ("stack-no-spectra", lambda s: bsfjax.stack_spectra([]), BSFError,
     r"spectra must be a non-empty sequence of bsfjax.Spectrum"),
    ("example-bad-levels", lambda s: bsfjax.example_mesh(levels=0), BSFError,
     r"levels must be an integer in \[1, 5\]"),
    # --- one validation layer for every path
    ("labels-huge-id-indicators", lambda s: bsfjax.labels_to_indicators(
        np.r_[np.zeros(s.n - 1, int), 10**12]), BSFError,
     r"labels has max 1000000000000: .* GiB; compact the labels first"),
    ("p2p-negative-index", lambda s: bsfjax.transfer_values(
        s.spec, s.spec, s.F, method="p2p", p2p=np.full(s.n, -1)), BSFError,
     r"p2p must be source vertex indices in \[0, 42\), found 42 outside \(first: p2p\[0\] = -1"),
    ("p2p-float-index", lambda s: bsfjax.transfer_values(
        s.spec, s.spec, s.F, method="p2p", p2p=np.full(s.n, 1.0)), BSFError,
     r"p2p must be integer source vertex indices, got dtype float64 \(first: 1.0\)"),
    ("p2p-uint64-index", lambda s: bsfjax.transfer_values(
        s.spec, s.spec, s.F, method="p2p", p2p=np.full(s.n, 2**64 - 1, np.uint64)), BSFError,
     r"p2p\[0\] = 18446744073709551615"),
    ("landmarks-float", lambda s: bsfjax.estimate_map(s.spec, s.spec, k=5,
                                                      landmarks=([1.0, 2.0], [1, 2])),
     BSFError, r"source landmarks must be integer vertex indices, got dtype float64"),
    ("landmarks-negative", lambda s: bsfjax.estimate_map(s.spec, s.spec, k=5,
                                                         landmarks=([1, 2], [-3, 2])),
     BSFError, r"target landmarks must be vertex indices in \[0, 42\).*= -3"),
    ("mesh-not-the-source-count", lambda s: bsfjax.transfer_values(
        s.spec, s.spec, s.F, C=s.C, mesh=bsfjax.example_mesh(levels=1)), BSFError,
     r"mesh has 506 vertices but the source spectrum has 42: mesh= must be the source mesh"),
    ("mesh-not-the-source-area", lambda s: bsfjax.transfer_values(
        s.spec, s.spec, s.F, C=s.C, mesh=bsfjax.Mesh(s.v * 2, s.f)), BSFError,
     r"mesh has total area .* but the source spectrum's areas sum to"),
    ("descriptors-zero-columns", lambda s: bsfjax.estimate_fmap(
        s.spec, s.spec, np.zeros((s.n, 0)), np.zeros((s.n, 0)), k=5), BSFError,
     r"source_descr has zero columns"),
    ("sparse-frame-decode-nan", lambda s: bsfjax.decode(_sparse(s), np.full(24, np.nan)),
     BSFError, r"alpha contains 24 NaN or infinite values"),
    ("sparse-frame-encode-nan", lambda s: bsfjax.encode(_sparse(s), s.F * np.nan),
     BSFError, r"f contains 126 NaN or infinite values"),
    ("sparse-frame-decode-overflow", lambda s: bsfjax.decode(
        _sparse(s), np.full(24, 3e38, np.float32)), BSFError,
     r"alpha decodes to values up to .*, beyond the float32 range"),
    ("save-mesh-unwritable", lambda s: bsfjax.save_mesh(Path(__file__) / "x.ply", s.mesh),
     MeshError, r"test_robustness.py/x.ply: cannot write \(.*test_robustness.py is not a folder\)"),
]


def _sparse(s):
    return bsfjax.build_frame(s.spec, s.centers, sparse=True)


def _finite_leaves(out) -> bool:
    leaves = jax.tree.leaves(out)
    return all(np.isfinite(np.asarray(x, dtype=np.float64)).all() for x in leaves
               if hasattr(x, "dtype") and (np.issubdtype(x.dtype, np.number)))


@pytest.mark.parametrize("case", BAD_INPUTS, ids=[c[0] for c in BAD_INPUTS])
def test_bad_input_raises_clear_error(ns, case):
    _, call, exc, match = case
    assert issubclass(exc, ValueError)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(exc, match=match):
            call(ns)


# --------------------------------------------------------------------------- handled inputs


def _load_text(tmp, name, text):
    p = Path(tmp) / name
    p.write_text(text)
    return bsfjax.load_mesh(p)


_SQUARE = "OFF\n5 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n1 1 0\n"


def _zero_encode_all(s, f):
    return [bsfjax.encode(s.frame, f, m, return_info=True)
            for m in ("lstsq", "omp", "omp_error", "lasso")]


def _empty_atom_frame(s):
    atoms = np.asarray(s.frame.atoms).copy()
    atoms[:, :4] = 0.0
    return [bsfjax.encode(atoms, s.F, m, return_info=True)
            for m in ("lstsq", "omp", "omp_error", "lasso")]


def _zero_map_transfer(s):
    tf = bsfjax.transfer_frame(s.frame, np.zeros((10, 10)), s.spec)
    assert float(np.abs(np.asarray(tf.atoms)).sum()) == 0.0  # vanished columns: empty atoms
    return tf.atoms, bsfjax.decode(tf, bsfjax.encode(s.frame, s.F))


def _unwritable_cache(s, tmp):
    blocker = Path(tmp) / "a_file"
    blocker.write_text("not a folder")
    spec = bsfjax.spectrum(s.mesh, 4, cache_dir=blocker / "cache")  # mkdir fails: OSError
    np.testing.assert_array_equal(spec.evecs, bsfjax.spectrum(s.mesh, 4).evecs)  # not lost
    return spec.evals, spec.evecs


def _same_codes(s, scale):
    a = np.asarray(bsfjax.encode(s.frame, s.F * scale), np.float64) / scale
    np.testing.assert_allclose(a, np.asarray(bsfjax.encode(s.frame, s.F)), rtol=1e-4, atol=1e-6)
    return a


def _huge_label_transfer(s):
    lab = np.where(s.F[0] > 0, 10**12, 7)  # two labels, ids far apart: no 10^12 rows
    res = bsfjax.transfer_labels(s.spec, s.spec, lab, C=s.C, method="std")
    assert res.scores.shape == (2, s.n) and set(np.unique(res.labels)) <= {-1, 7, 10**12}
    assert np.mean(res.labels == lab) > 0.9
    return res.scores


def _scaled_mesh_transfer(s, scale):
    # a bumpy sphere: no symmetric ties that rounding could break either way
    v = s.v * (1 + 0.2 * np.random.default_rng(0).random((s.n, 1)))
    out, ref = (bsfjax.transfer_values(spec, spec, s.F, C=np.eye(10), mesh=mesh)
                for mesh in (bsfjax.Mesh(v * scale, s.f), bsfjax.Mesh(v, s.f))
                for spec in [bsfjax.spectrum(mesh, 10)])
    np.testing.assert_allclose(out, ref, atol=1e-3)  # the unit-scale transfer, not zeros
    assert np.abs(ref).max() > 0.5
    return out


def _tiny_reference(s):
    """f = 1e-30·F against f̃ = F: an error of ~1e30 (each norm on its own scale)."""
    e = float(bsfjax.relative_error(1e-30 * s.F[0], s.F[0], s.spec.mass))
    np.testing.assert_allclose(e, (1 - 1e-30) * 1e30, rtol=1e-4)
    return e


def _pair_in_units(s, scale):
    """The point map of a pair's functional map, the target ×scale: the same as in one unit."""
    v = s.v * (1 + 0.2 * np.random.default_rng(0).random((s.n, 1)))
    src = bsfjax.spectrum(bsfjax.Mesh(s.v, s.f), 10)
    out = []
    for sc in (1.0, scale):
        tgt = bsfjax.spectrum(bsfjax.Mesh(v * sc, s.f), 10)
        C = bsfjax.fmap_from_p2p(src, tgt, np.arange(s.n))
        out.append(np.asarray(bsfjax.fmap_to_p2p(C, src, tgt)))
    np.testing.assert_array_equal(out[1], out[0])
    return out[1]


HANDLED_INPUTS = [
    ("load-zero-area-face", lambda s, tmp: _load_text(
        tmp, "deg.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n2 0 0\n3 0 1 2\n3 0 1 3\n").vertices,
     r"removed 1 zero-area faces"),
    ("load-unreferenced-vertex", lambda s, tmp: _load_text(
        tmp, "iso.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n5 5 5\n3 0 1 2\n").vertex_ids,
     r"removed 1 unreferenced vertices"),
    ("load-duplicate-vertices", lambda s, tmp: _load_text(
        tmp, "dup.off", _SQUARE + "3 0 1 2\n3 0 4 3\n").vertices,
     r"1 duplicate vertices"),
    ("load-non-manifold-edge", lambda s, tmp: _load_text(
        tmp, "nm.off", "OFF\n5 3 0\n0 0 0\n1 0 0\n0 1 0\n0 -1 0\n0 0 1\n"
        "3 0 1 2\n3 1 0 3\n3 0 1 4\n").vertices, r"1 non-manifold edges"),
    ("spectrum-several-components", lambda s, tmp: bsfjax.spectrum(
        bsfjax.Mesh(*_two_components()), 4), r"mesh has 2 connected components"),
    ("encode-zero-function", lambda s, tmp: _zero_encode_all(s, np.zeros(s.n)), None),
    ("encode-empty-atoms", lambda s, tmp: _empty_atom_frame(s), None),
    ("transfer-with-zero-map", lambda s, tmp: _zero_map_transfer(s), None),
    ("encode-huge-values", lambda s, tmp: bsfjax.encode(s.frame, s.F * 1e30, weights=None),
     None),
    ("encode-tiny-values", lambda s, tmp: _same_codes(s, 1e-30), None),
    ("labels-huge-ids-transfer", lambda s, tmp: _huge_label_transfer(s), None),
    ("wks-two-eigenpairs", lambda s, tmp: bsfjax.wks(s.spec, k=2), None),
    ("transfer-mesh-scaled-1e20", lambda s, tmp: _scaled_mesh_transfer(s, 1e20), None),
    ("transfer-mesh-scaled-1e-20", lambda s, tmp: _scaled_mesh_transfer(s, 1e-20), None),
    ("relative-error-float64-beyond-float32", lambda s, tmp: bsfjax.relative_error(
        1e300 * s.F, 1e300 * np.roll(s.F, 1, 1), s.spec.mass), None),
    ("relative-error-zero-reference", lambda s, tmp: bsfjax.relative_error(
        np.zeros(s.n), s.F[0], s.spec.mass), None),
    ("relative-error-huge-values", lambda s, tmp: bsfjax.relative_error(
        np.float32(1e30) * s.F.astype(np.float32), np.float32(1e30) * np.roll(s.F, 1, 1)
        .astype(np.float32), s.spec.mass.astype(np.float32)), None),
    ("relative-error-tiny-reference", lambda s, tmp: _tiny_reference(s), None),
    ("pair-in-different-units", lambda s, tmp: _pair_in_units(s, 1e3), None),
    ("relative-error-tiny-values", lambda s, tmp: bsfjax.relative_error(
        np.float32(1e-30) * s.F.astype(np.float32), np.zeros(s.n, np.float32),
        s.spec.mass.astype(np.float32)), None),
    ("wks-energies-far-from-spectrum", lambda s, tmp: bsfjax.wks(s.spec, energies=[200.0],
                                                                 sigma=0.1), None),
    ("estimate-zero-descriptors", lambda s, tmp: bsfjax.estimate_fmap(
        s.spec, s.spec, np.zeros((s.n, 3)), np.zeros((s.n, 3)), k=5), None),
    ("fps-more-samples-than-distinct-points", lambda s, tmp: bsfjax.farthest_point_sampling(
        np.zeros((5, 3)), 3), None),
    ("spectrum-cache-not-writable", lambda s, tmp: _unwritable_cache(s, tmp),
     r"could not write spectrum cache file .*; continuing without caching it"),
    ("frame-on-several-components", lambda s, tmp: bsfjax.build_frame(
        bsfjax.spectrum(bsfjax.Mesh(*_two_components()), 6), [0, 50]).atoms,
     r"mesh has 2 connected components"),
]


@pytest.mark.parametrize("case", HANDLED_INPUTS, ids=[c[0] for c in HANDLED_INPUTS])
def test_handled_input_is_defined_and_finite(ns, tmp_path, case):
    _, call, warning = case
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        out = call(ns, tmp_path)
    msgs = [str(w.message) for w in rec]
    if warning is not None:
        assert any(re.search(warning, m) for m in msgs), msgs
    assert _finite_leaves(out), f"NaN or inf escaped: {out}"


def test_zero_norm_and_overflow_rules(ns):
    """The documented values, not just finiteness."""
    m = ns.spec.mass
    # ‖f‖_A = 0: the absolute error ‖f̃‖_A
    want = np.sqrt(np.sum(m * ns.F[0] ** 2))
    np.testing.assert_allclose(bsfjax.relative_error(np.zeros(ns.n), ns.F[0], m), want,
                               rtol=1e-5)
    # huge / tiny values: the same ratio as at unit scale (scale invariance survives float32)
    ref = np.asarray(bsfjax.relative_error(ns.F, np.roll(ns.F, 1, 1), m))
    for s in (1e30, 1e-30):
        got = bsfjax.relative_error((s * ns.F).astype(np.float32),
                                    (s * np.roll(ns.F, 1, 1)).astype(np.float32),
                                    m.astype(np.float32))
        np.testing.assert_allclose(got, ref, rtol=1e-5)
    # an all-zero function codes to exactly zero, with zero residual
    for alpha, info in _zero_encode_all(ns, np.zeros(ns.n)):
        assert float(np.abs(alpha).max()) == 0.0 and float(info.residual) == 0.0
    # empty atoms are never used
    for alpha, _ in _empty_atom_frame(ns):
        assert float(np.abs(np.asarray(alpha)[..., :4]).max()) == 0.0


def test_mesh_report_counts(tmp_path):
    v, f = _two_components()
    v = np.vstack([v, v[:1], [[7.0, 7, 7]]])  # one duplicate vertex, one isolated vertex
    f = np.vstack([f, [[0, 1, 1]], f[:1]])  # one degenerate face, one duplicate face
    rep = mesh_report(bsfjax.Mesh(v, f))
    assert rep.n_vertices == 86 and rep.n_faces == 162
    assert rep.degenerate_faces == 1 and rep.duplicate_faces == 1
    assert rep.duplicate_vertices == 1 and rep.isolated_vertices == 2
    assert rep.components == 4  # two spheres, the isolated vertex and the duplicate vertex
    # the duplicated face doubles its 3 edges, and the degenerate face [0, 1, 1] adds two more
    # faces to edge 0-1 and a self-edge 1-1 of a single face (a "boundary" edge)
    assert rep.non_manifold_edges == 3 and rep.boundary_edges == 1


@pytest.mark.parametrize("target,call", [
    ("bsfjax._frame._build._build_core", lambda s: bsfjax.build_frame(s.spec, [99])),
    ("bsfjax._coding._encode._encode_batch", lambda s: bsfjax.encode(s.frame, s.F * np.nan)),
    ("bsfjax._metrics._relative_error._relative_error", lambda s: bsfjax.relative_error(s.F, s.F, -s.spec.mass)),
    ("bsfjax._maps._fmap._fmap_to_p2p_jit", lambda s: bsfjax.fmap_to_p2p(np.eye(5) * np.inf, s.spec,
                                                                 s.spec)),
])
def test_errors_come_before_tracing(ns, monkeypatch, target, call):
    """Validation runs in Python first: the jitted kernel is never reached."""
    mod, name = target.rsplit(".", 1)

    def boom(*a, **k):
        raise AssertionError(f"{target} was called with bad input")

    import importlib

    monkeypatch.setattr(importlib.import_module(mod), name, boom)
    with pytest.raises(BSFError):
        call(ns)


def test_cli_reports_bad_input_in_one_line(tmp_path, capsys, ns):
    from bsfjax.cli import main

    src = tmp_path / "s.off"
    bsfjax.save_mesh(src, ns.mesh)
    fun = tmp_path / "f.txt"
    np.savetxt(fun, np.full(ns.n, np.nan))
    rc = main(["transfer", str(src), str(src), "--function", str(fun), "--out",
               str(tmp_path / "o.txt"), "--map", "fmap", str(tmp_path / "missing.txt")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err[-1].startswith("bsfjax transfer: error:")
    assert "Traceback" not in "\n".join(err)
    assert not (tmp_path / "o.txt").exists()
    rc = main(["spectrum", str(src), "-k", "5", "--out", str(tmp_path / "sp.dat")])
    assert rc == 2 and "use a .npz file name" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.txt", "s.off"]


# --------------------------------------------------------------------------- CLI


def _cli_files(tmp: Path, ns) -> dict:
    src = tmp / "s.off"
    bsfjax.save_mesh(src, ns.mesh)
    lab = tmp / "lab.txt"
    np.savetxt(lab, (ns.F[0] > 0).astype(int), fmt="%d")
    fp2p = tmp / "p2p_float.txt"
    np.savetxt(fp2p, np.full(ns.n, 1.5))
    up2p = tmp / "p2p_uint.npy"
    np.save(up2p, np.full(ns.n, 2**64 - 1, np.uint64))
    (tmp / "dir.txt").mkdir()
    (tmp / "dir.npz").mkdir()
    return dict(src=str(src), lab=str(lab), fp2p=str(fp2p), up2p=str(up2p), tmp=str(tmp))


def _transfer(f, *extra, out="o.txt"):
    return ["transfer", f["src"], f["src"], "--labels", f["lab"], "--out",
            str(Path(f["tmp"]) / out) if "/" not in out else out, *extra]


#: (id, argv from the files of _cli_files, regex of the one-line message).  Each must exit
#: with status 2, print that one line (no traceback) and write nothing.
CLI_BAD_INPUTS = [
    ("cli-out-equals-input", lambda f: _transfer(f, out=f["lab"]),
     r"--out '.*lab.txt' is the same path as the input --labels"),
    ("cli-out-is-a-folder", lambda f: _transfer(f, out="dir.txt"),
     r"--out '.*dir.txt': is a folder; give a file name"),
    ("cli-out-under-a-file", lambda f: _transfer(f, out=f["lab"] + "/o.txt"),
     r"--out '.*lab.txt/o.txt': '.*lab.txt' is not a folder"),
    ("cli-outputs-same-path", lambda f: _transfer(f, "--mesh-out", f["tmp"] + "/x.ply",
                                                  out=f["tmp"] + "/x.ply"),
     r"--out and --mesh-out are the same path"),
    ("cli-missing-map-file", lambda f: _transfer(f, "--map", "p2p", f["tmp"] + "/none.txt"),
     r"--map .*none.txt: no such file"),
    ("cli-negative-landmark", lambda f: _transfer(f, "--landmarks", "-1,2:3,4"),
     r"--landmarks \(source\) must be vertex indices in \[0, 42\).*= -1"),
    ("cli-float-p2p-file", lambda f: _transfer(f, "--map", "p2p", f["fp2p"]),
     r"p2p file .*p2p_float.txt: expected integers, found 1.5"),
    ("cli-uint64-p2p-file", lambda f: _transfer(f, "--map", "p2p", f["up2p"]),
     r"p2p file .*p2p_uint.npy: p2p must be .*p2p\[0\] = 18446744073709551615"),
    ("cli-negative-seed", lambda f: ["demo", "--seed", "-5", "--out", f["tmp"] + "/d"],
     r"--seed must be an integer >= 0, got -5"),
    ("cli-zero-functions", lambda f: ["demo", "--functions", "0", "--out", f["tmp"] + "/d"],
     r"--functions must be an integer >= 1, got 0"),
    ("cli-demo-out-is-a-file", lambda f: ["demo", "--out", f["lab"]],
     r"--out '.*lab.txt': exists and is not a folder"),
    ("cli-reproduce-out-is-data", lambda f: ["reproduce", "fig7", "--data", f["tmp"],
                                             "--out", f["tmp"]],
     r"--out '.*' is the same path as the input --data"),
    ("cli-spectrum-out-is-a-folder", lambda f: ["spectrum", f["src"], "--out",
                                                f["tmp"] + "/dir.npz"],
     r"--out '.*dir.npz': is a folder"),
]


@pytest.mark.parametrize("case", CLI_BAD_INPUTS, ids=[c[0] for c in CLI_BAD_INPUTS])
def test_cli_bad_input_one_line_status_2_nothing_written(tmp_path, capsys, ns, case):
    from bsfjax.cli import main

    _, argv, match = case
    files = _cli_files(tmp_path, ns)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    capsys.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main(argv(files))
    err = capsys.readouterr().err
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("bsfjax")]
    assert rc == 2 and "Traceback" not in err, err
    assert len(lines) == 1 and re.search(match, lines[0]), err
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_cli_outputs_all_or_none(tmp_path, capsys, ns, monkeypatch):
    """The second output fails after the first was written: neither is left, the message
    names the user's path (not the temporary file), and an existing file keeps its content."""
    import bsfjax._cli._transfer as cli_transfer
    from bsfjax import cli
    from bsfjax.internal import atomic_path

    files = _cli_files(tmp_path, ns)
    old = tmp_path / "m.ply"
    old.write_text("previous")

    def failing_write(path, arr, names=None):
        with atomic_path(path) as tmp:
            tmp.write_text("partial")
            raise OSError(28, "No space left on device", str(tmp))

    monkeypatch.setattr(cli_transfer, "_write_array", failing_write)
    argv = _transfer(files, "--map", "p2p", files["lab"].replace("lab", "p2p"),
                     "--mesh-out", str(old), "--method", "std")
    np.savetxt(files["lab"].replace("lab", "p2p"), np.arange(ns.n), fmt="%d")
    rc = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and err[-1].endswith("o.txt: cannot write (No space left on device)"), err
    assert ".tmp" not in err[-1]
    assert old.read_text() == "previous" and not (tmp_path / "o.txt").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_cli_huge_label_ids(tmp_path, capsys, ns):
    """A label id of 10^12 is a label like any other (no allocation by id)."""
    from bsfjax.cli import main

    files = _cli_files(tmp_path, ns)
    lab = np.where(ns.F[0] > 0, 10**12, 3)
    np.savetxt(files["lab"], lab, fmt="%d")
    np.savetxt(tmp_path / "p2p.txt", np.arange(ns.n), fmt="%d")
    rc = main(_transfer(files, "--map", "p2p", str(tmp_path / "p2p.txt"), "--method", "std"))
    assert rc == 0, capsys.readouterr().err
    got = np.loadtxt(tmp_path / "o.txt", dtype=np.int64)
    assert set(np.unique(got)) <= {-1, 3, 10**12} and np.mean(got == lab) > 0.9


def test_docs_table_lists_every_case():
    text = DOC.read_text()
    ids = [c[0] for c in BAD_INPUTS + HANDLED_INPUTS + CLI_BAD_INPUTS]
    from .test_fuzz_readers import READER_CASES

    ids += [c[0] for c in READER_CASES]
    missing = [i for i in ids if f"`{i}`" not in text]
    assert not missing, f"docs/robustness.md does not list {missing}"
    rows = [ln for ln in text.splitlines() if ln.startswith("| `")]
    assert len(rows) >= 30
