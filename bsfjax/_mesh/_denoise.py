"""Denoising a triangle mesh before its spectrum: a noise estimate from the mesh itself and
Taubin's λ/μ smoothing (Taubin 1995) on the same connectivity.

Vertex noise (a scan's) makes the cotangent Laplacian's eigenfunctions and the WKS descriptors
follow the noise; smoothing the coordinates first gives them back.  Owner of `noise_level`
(the roughness of the vertex positions relative to the mean edge length) and `denoise` (a
new `Mesh` with smoothed vertices and everything else unchanged: faces, vertex order,
`vertex_ids`, `file_rows`, so per-vertex results belong to the original file rows).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from .._util import BSFError
from ._graph import mesh_edges
from ._cloud_denoise import cloud_noise_level, cloud_smooth
from ._cloud_surface import cloud_surface
from ._mesh import Mesh, PointCloud
from ._interop import as_mesh

__all__ = ["umbrella_operator", "denoise", "noise_level", "denoise_iterations", "as_strength", "auto_iterations", "NOISE_THRESHOLD", "TAUBIN_LAMBDA",
           "TAUBIN_MU", "MAX_ITERATIONS", "CLOUD_NOISE_THRESHOLD", "mesh_threshold",
           "surface_for_map"]

#: Taubin's pass band: a shrinking step ``λ`` then an inflating step ``μ < −λ``
#: (pass-band frequency ``1/λ + 1/μ ≈ 0.1``).
TAUBIN_LAMBDA = 0.5
TAUBIN_MU = -0.53
#: Below this noise level a mesh is left as it is (clean meshes: registrations, the example
#: pair, measure well under it; see `noise_level`).
NOISE_THRESHOLD = 0.1
#: A point cloud's threshold: none is smoothed automatically.  Its Laplacian (Sharp & Crane's,
#: local triangulations of 30 neighbours) tolerates the noise: on FAUST clouds of 5K–40K points
#: with Gaussian noise of σ = 0.25–0.5 % of the height, Taubin smoothing over the k-NN graph
#: at the mesh rule's strength lost 0.6 points of accuracy on average (5 landmarks, 6 draws;
#: CHANGELOG).  An explicit strength still smooths a cloud.
CLOUD_NOISE_THRESHOLD = float("inf")
#: The most Taubin iterations the automatic strength chooses.
MAX_ITERATIONS = 40


def umbrella_operator(mesh: Mesh) -> sp.csr_matrix:
    """The uniform (umbrella) averaging operator ``W`` (sparse, row-stochastic): row ``i``
    averages vertex ``i``'s one-ring neighbours (an isolated vertex averages to itself); also
    the coverage error's spreading (`bsfjax._maps._coverage`)."""
    n = mesh.n_vertices
    edges, _ = mesh_edges(mesh.faces)
    i = np.concatenate([edges[:, 0], edges[:, 1]])
    j = np.concatenate([edges[:, 1], edges[:, 0]])
    A = sp.csr_matrix((np.ones(i.size), (i, j)), shape=(n, n))
    deg = np.asarray(A.sum(axis=1)).ravel()
    lone = deg == 0
    A = A + sp.diags(lone.astype(float))
    return sp.diags(1.0 / np.maximum(deg, 1)) @ A


def _mean_edge(mesh: Mesh) -> float:
    edges, _ = mesh_edges(mesh.faces)
    v = np.asarray(mesh.vertices)
    return float(np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1).mean())


def _vertex_normals(mesh: Mesh) -> np.ndarray:
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # area-weighted
    vn = np.zeros_like(v)
    for c in range(3):
        np.add.at(vn, f[:, c], fn)
    norm = np.linalg.norm(vn, axis=1, keepdims=True)
    return vn / np.where(norm > 0, norm, 1)


def noise_level(mesh: Mesh) -> float:
    """How rough the vertex positions are, relative to the mean edge length.

    Each vertex's signed offset from its one-ring plane (along its vertex normal, from the
    average of its neighbours) is smooth on a clean surface: it follows the curvature, which
    changes slowly from vertex to vertex.  Noise makes it jump.  The level is the root mean
    square of what is left of the offsets after their own one-ring average is taken away,
    over the mean edge length.  Clean meshes (FAUST registrations, the example pair) measure
    0.005 (the example pair) to 0.06 (FAUST registrations); Gaussian vertex noise of σ adds about ``σ / h`` (in quadrature) with ``h`` the
    mean edge length.  A point cloud's (`cloud_noise_level`): the same with each point's 6
    nearest neighbours (symmetrized) as its one-ring, PCA normals, and the mean distance to
    those neighbours as the edge length; clean area-uniform samples of a FAUST body measure
    0.07–0.11 (40K–5K points), and with Gaussian noise of σ = 0.25 % of the height 0.26–0.37.

    **Arguments:**

    - `mesh`: a [`Mesh`][bsfjax.Mesh].
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    if mesh.is_point_cloud:
        return cloud_noise_level(mesh.vertices)
    if mesh.n_faces == 0:
        return 0.0
    W = umbrella_operator(mesh)
    v = np.asarray(mesh.vertices)
    d = np.einsum("ij,ij->i", v - W @ v, _vertex_normals(mesh))
    r = d - W @ d
    h = _mean_edge(mesh)
    return float(np.sqrt(np.mean(r**2)) / h) if h > 0 else 0.0


def auto_iterations(level: float, threshold: float = NOISE_THRESHOLD) -> int:
    """The Taubin iterations `denoise` chooses for a `noise_level`: none up to ``threshold``
    (`NOISE_THRESHOLD`; `CLOUD_NOISE_THRESHOLD` for a point cloud), then
    ``round(32 · level)`` (Gaussian noise of σ = 0.1 % of a FAUST body's height: 5 iterations;
    σ = 0.3 %: 10), at most `MAX_ITERATIONS`."""
    if not np.isfinite(level) or level <= threshold:
        return 0
    return int(min(MAX_ITERATIONS, max(1, round(32.0 * level))))


def denoise(mesh: Mesh, strength="auto") -> Mesh:
    """The mesh with smoothed vertex positions: Taubin's λ/μ smoothing (λ = 0.5, μ = −0.53,
    umbrella weights), which removes high-frequency vertex noise without shrinking the shape.

    The result has the same triangles, the same vertices in the same order, the same
    `vertex_ids` and `file_rows`, so labels computed on it belong to the original mesh's
    vertices (and file rows) as they are.  Use it before [`spectrum`][bsfjax.spectrum] on a
    noisy scan; `bsfjax transfer` and [`transfer_collection`][bsfjax.transfer_collection] do it
    by default.

    **Arguments:**

    - `mesh`: a [`Mesh`][bsfjax.Mesh], or a [`PointCloud`][bsfjax.PointCloud]: the same
      smoothing with each point's 6 nearest neighbours (symmetrized) as its one-ring, and a
      `PointCloud` with the same points in the same order comes back; ``"auto"`` leaves a
      cloud as it is (its Laplacian tolerates scanner noise: smoothing did not help, measured
      in docs/how-to/scans.md).
    - `strength`: ``"auto"`` (default) chooses the number of iterations from
      [`noise_level`][bsfjax.noise_level]: none on a clean mesh, more the noisier it is; an
      integer is that many iterations (``0``: the mesh itself).

    **Returns:** a [`Mesh`][bsfjax.Mesh] (``mesh`` itself when nothing is smoothed); the
    iterations it runs are [`denoise_iterations(mesh, strength)`][bsfjax.denoise_iterations].
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    n_iter = denoise_iterations(mesh, strength)
    if n_iter == 0:
        return mesh
    if mesh.is_point_cloud:
        smooth = PointCloud(cloud_smooth(mesh.vertices, n_iter, TAUBIN_LAMBDA, TAUBIN_MU),
                            vertex_ids=mesh.vertex_ids, name=mesh.name)
        object.__setattr__(smooth, "file_rows", mesh.file_rows)  # (frozen: as replace does)
        return smooth
    W = umbrella_operator(mesh)
    v = np.array(mesh.vertices, dtype=np.float64)
    for _ in range(n_iter):
        v = v + TAUBIN_LAMBDA * (W @ v - v)
        v = v + TAUBIN_MU * (W @ v - v)
    return dataclasses.replace(mesh, vertices=v)


def as_strength(denoise) -> object:
    """A ``denoise=`` argument (``True``, ``False``, ``"auto"`` or iterations) as a strength."""
    if denoise is True:
        return "auto"
    if denoise is False or denoise is None:
        return 0
    return denoise


def denoise_iterations(mesh: Mesh, strength="auto") -> int:
    """The Taubin iterations [`denoise`][bsfjax.denoise] runs on ``mesh`` for ``strength``:
    for ``"auto"`` none up to a [`noise_level`][bsfjax.noise_level] of 0.1 (clean meshes),
    then ``round(32 · level)``, at most 40 (a point cloud: none, `CLOUD_NOISE_THRESHOLD`).

    **Arguments:**

    - `mesh`: a [`Mesh`][bsfjax.Mesh].
    - `strength`: as for [`denoise`][bsfjax.denoise].
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    if not mesh.is_point_cloud and mesh.n_faces == 0:
        return 0
    if isinstance(strength, str):
        if strength != "auto":
            raise BSFError(f"denoise strength must be 'auto' or a number of iterations, got "
                           f"{strength!r}")
        return auto_iterations(noise_level(mesh), mesh_threshold(mesh))
    if isinstance(strength, bool) or int(strength) != strength or strength < 0:
        raise BSFError(f"denoise strength must be 'auto' or a number of iterations >= 0, got "
                       f"{strength!r}")
    return int(strength)


def mesh_threshold(mesh: Mesh) -> float:
    """The noise level above which ``"auto"`` smooths ``mesh``: `NOISE_THRESHOLD`, or
    `CLOUD_NOISE_THRESHOLD` for a point cloud."""
    return CLOUD_NOISE_THRESHOLD if mesh.is_point_cloud else NOISE_THRESHOLD


def surface_for_map(mesh: Mesh) -> Mesh:
    """What the landmark-free map estimator gets as a shape's mesh (its orientation term,
    geodesic distortions and orientation agreement): a point cloud's
    [`cloud_surface`][bsfjax.cloud_surface], any other mesh itself.

    The surface of a noisy cloud is built on its points smoothed by the mesh rule
    (`auto_iterations` of its `noise_level`, threshold `NOISE_THRESHOLD`): Dijkstra paths
    along its edges zig-zag with the noise and lengthen its geodesic distances, where the
    spectrum (left on the points as given) tolerates the noise.  The vertices stay in the
    cloud's order."""
    if not mesh.is_point_cloud:
        return mesh
    return cloud_surface(denoise(mesh, auto_iterations(noise_level(mesh))))
