r"""How evenly a point map covers its source: the third measure of a map without ground truth,
beside [`map_distortion`][bsfjax.map_distortion] and
[`orientation_agreement`][bsfjax.orientation_agreement].

A point map ``T: N → M`` (``p2p[j]`` the source vertex of target vertex ``j``) between two
near-isometric shapes carries the target's area onto the source's as it lies there: every
region of ``M`` receives the share of the area it has.  A map that folds (two limbs onto one,
one side of the torso onto the other) piles area on one region and leaves another bare.  With
``a_N`` the target's vertex areas and ``a_M`` the source's, each normalized to sum 1, the
pushed area ``p = Tₓ a_N`` (``p_i = Σ_{j: T(j) = i} a_N(j)``) and the source's own ``a_M``
are both spread by ``s`` steps of the source's one-ring averaging (``W`` the row-stochastic
averaging matrix; ``Wᵀ`` keeps the total, and it forgives a vertex-to-vertex map the vertices
it skips between neighbours, which are not a fold); the **coverage error** is their total
variation

.. math::
    c(T) = \tfrac12 \big\| (W^⊤)^s (p − a_M) \big\|_1 \in [0, 1],

the share of the target's area that would have to move for the map to cover the source as
the source's own areas do: 0 for a bijection that keeps areas, 1 − a_M(i) (before the
spreading) for the map that sends everything to vertex ``i``, about ½ (before the spreading)
for a map that folds one half of a symmetric shape onto the other.

Where the distortion is noisy, it breaks ties the distortion cannot: on a noisy point cloud
the geodesic distortion runs on a stand-in surface whose Dijkstra distances the noise
lengthens unevenly, and among the landmark-free starts it kept a map of 85.6 % right labels
(FAUST 001→011, a noisy 15K cloud) where a start of nearly as little distortion and less
coverage error reached 91.5 %;
[`choose_map`][bsfjax.choose_map] weighs both where it is given the coverage
(``MapEstimator.choice_coverage``, on for point clouds).

Owner of `map_coverage` and `COVERAGE_SMOOTHING`.
"""

from __future__ import annotations

import numpy as np

from ._distortion import _check_pair
from .._mesh import Mesh, as_mesh, umbrella_operator, vertex_areas
from .._util import BSFError, check_finite, check_int, require_triangles

__all__ = ["map_coverage", "COVERAGE_SMOOTHING"]

#: One-ring averaging steps ``s`` on the source before the total variation (module doc): the
#: pushed area of a vertex-to-vertex map between meshes of 6890 and a 15K cloud is grainy
#: at one vertex; ten steps spread it over a few rings.
COVERAGE_SMOOTHING = 10


def coverage_errors(source_mesh: Mesh, maps: np.ndarray, target_mass, source_mass=None,
                    smoothing: int = COVERAGE_SMOOTHING) -> np.ndarray:
    """``(B,)`` coverage errors of ``maps`` ``(B, n_N)`` (entries ``-1``: target vertices not
    searched, left out with their area), ``target_mass`` ``(n_N,)``, ``source_mass`` ``(n_M,)``
    (default: the source's barycentric vertex areas); unchecked (`map_coverage` checks)."""
    n = source_mesh.n_vertices
    maps = np.atleast_2d(np.asarray(maps, np.int64))
    a_m = vertex_areas(source_mesh) if source_mass is None else np.asarray(source_mass, float)
    a_n = np.asarray(target_mass, np.float64)
    a_m = a_m / a_m.sum()
    # D[:, b] = pushed area of map b minus the source's: linear, so spread once for all maps
    D = np.empty((n, maps.shape[0]))
    for b, m in enumerate(maps):
        keep = m >= 0
        w = a_n[keep]
        D[:, b] = np.bincount(m[keep], weights=w / w.sum(), minlength=n) - a_m
    Wt = umbrella_operator(source_mesh).T.tocsr()  # (Wᵀ keeps the total)
    for _ in range(smoothing):
        D = Wt @ D
    return 0.5 * np.abs(D).sum(axis=0)


def _check_mass(mass, n: int, name: str) -> np.ndarray:
    check_finite(mass, name)  # (real numbers first: a string or NaN is named as such)
    a = np.asarray(mass, np.float64)
    if a.shape != (n,) or np.any(a < 0) or a.sum() <= 0:
        raise BSFError(f"{name} must be {n} finite non-negative vertex areas (not all 0), got "
                       f"shape {np.shape(mass)}")
    return a


def map_coverage(source_mesh: Mesh, target_mesh: Mesh, p2p, *, source_mass=None,
                 target_mass=None, smoothing: int = COVERAGE_SMOOTHING):
    """The coverage error of point map(s) ``T: N → M`` (module doc).

    **Arguments:**

    - ``source_mesh``, ``target_mesh``: the meshes ``M`` and ``N``.
    - `p2p`: ``(n_N,)`` source vertex of each target vertex, or ``(B, n_N)`` for ``B`` maps.
    - ``source_mass``, ``target_mass``: ``(n_M,)``, ``(n_N,)`` positive vertex areas (a
      [`Spectrum`][bsfjax.Spectrum]'s ``mass``, as `MapEstimator` uses); default: the
      meshes' barycentric vertex areas.  The source needs triangles (it is spread along
      them); the target only with its default areas: a point cloud target takes its
      spectrum's ``mass``.
    - `smoothing`: one-ring averaging steps on the source (``COVERAGE_SMOOTHING``, 10; 0:
      vertex by vertex).

    **Returns:**

    a float (or ``(B,)`` floats) in ``[0, 1]``: the share of the target's area that is not
    where the source's is.
    """
    source_mesh, target_mesh = (as_mesh(source_mesh, "source_mesh"),
                                as_mesh(target_mesh, "target_mesh"))
    # the source is spread along its triangles; the target only gives areas, its own or given
    # (a point cloud target with its Laplacian's masses)
    for m, mass in ((source_mesh, None), (target_mesh, target_mass)):
        if mass is None:
            require_triangles(m, "the coverage error needs triangles on the source (and on a "
                              "target without target_mass): a point cloud has none "
                              "(bsfjax.cloud_surface gives a cloud a stand-in surface)")
    maps, single = _check_pair(source_mesh, target_mesh, p2p)
    smoothing = check_int(smoothing, "smoothing", 0)
    masses = [vertex_areas(m) if a is None else _check_mass(a, m.n_vertices, name)
              for a, m, name in ((source_mass, source_mesh, "source_mass"),
                                 (target_mass, target_mesh, "target_mass"))]
    out = coverage_errors(source_mesh, maps, masses[1], masses[0], smoothing=smoothing)
    return float(out[0]) if single else out
