"""Test functions of the experiments: random connected regions and segmentations (paper Eq. 2).

A *step function* on a shape is ``f = Σ_r a_r χ_{R_r}`` (paper Eq. 2): pieces ``R_r`` with
constant values ``a_r``.  Two kinds are used:

* [`random_indicators`][bsfjax.random_indicators] — indicators ``χ_R`` of random **connected** regions covering a
  random share of the surface area, the test functions of the paper's Tables 1–5.
* [`labels_to_indicators`][bsfjax.labels_to_indicators] / [`indicators_to_labels`][bsfjax.indicators_to_labels] — a segmentation (one label per
  vertex) as a stack of piece indicators and back.  A step function with values ``a`` is
  ``a @ labels_to_indicators(labels)`` (= ``a[labels]``); after transferring every indicator,
  [`indicators_to_labels`][bsfjax.indicators_to_labels] (arg-max over pieces) gives the transferred segmentation.

Region growing.  Each region is the sub-level set of the shortest-path distance from a random
seed vertex in the edge graph, with every edge length multiplied by a random factor
``exp(irregularity · z)``, ``z ~ N(0, 1)``, so that regions are irregular blobs, not geodesic
discs.  Vertices join in order of distance until their areas reach the target share: a
sub-level set of a shortest-path distance with positive weights is connected (every vertex's
shortest path runs through vertices with strictly smaller distance), so every region is
connected.  All ``count`` regions come from one multi-source Dijkstra call and one vectorised
sort — no Python loop over functions.
"""

from __future__ import annotations

import numbers

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph

from .._util import BSFError
from .._spectral import laplacian
from .._mesh import Mesh, graph_from_edges, mesh_edges
from .._mesh import as_mesh

__all__ = ["random_indicators", "labels_to_indicators", "indicators_to_labels"]

#: Largest indicator stack [`labels_to_indicators`][bsfjax.labels_to_indicators] builds from the label values alone.
_INDICATOR_BUDGET_BYTES = 2**31


def _random_edge_graph(mesh: Mesh, rng: np.random.Generator, irregularity: float) -> sp.csr_matrix:
    """Edge graph with lengths scaled by log-normal noise, so regions grow irregularly."""
    e, _ = mesh_edges(mesh.faces)
    w = np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    return graph_from_edges(mesh.n_vertices, e, w * np.exp(irregularity * rng.standard_normal(len(e))))


def _check_fraction(area_fraction) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in area_fraction)
    except (TypeError, ValueError):
        raise BSFError(f"area_fraction must be a pair (lo, hi), got {area_fraction!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi <= 1):
        raise BSFError(f"area_fraction must satisfy 0 < lo <= hi <= 1, got {area_fraction!r}")
    return lo, hi


def random_indicators(mesh: Mesh, count: int, seed: int = 0, area_fraction=(0.05, 0.25), *,
                      mass=None, irregularity: float = 0.5) -> np.ndarray:
    """Indicators of ``count`` random connected regions, ``(count, n)`` of 0.0 / 1.0.

    Region ``r`` grows from a seed vertex drawn uniformly (distinct seeds while ``count ≤ n``)
    to a target share ``s_r ~ U(lo, hi)`` of the total area ``Σ_i A_i``: it is the smallest
    set of the vertices closest to the seed (randomly weighted edge-graph distance, see the
    module doc) whose area reaches ``s_r · Σ A``.  So each region is connected and its area
    share lies in ``[s_r, s_r + max_i A_i / Σ A]``.

    **Arguments:**

    - `mesh`: the shape ([`Mesh`][bsfjax.Mesh]); must be connected for regions to reach large
      shares (growth stops at the seed's component).
    - `count`: number of regions (≥ 1).
    - `seed`: non-negative int; same seed, same regions.
    - `area_fraction`: ``(lo, hi)`` with ``0 < lo ≤ hi ≤ 1`` (paper: 5–25 %).
    - `mass`: ``(n,)`` vertex areas (default: the mixed-Voronoi mass of
      [`bsfjax.laplacian`][bsfjax.laplacian], the same as ``bsfjax.spectrum(mesh, k).mass``).
    - `irregularity`: log-normal spread of the random edge-length factors; ``0`` grows
      graph-geodesic discs.

    **Returns:**

    ``(count, n)`` float64 numpy array.
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    if not isinstance(mesh, Mesh):
        raise BSFError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    if isinstance(count, (bool, np.bool_)) or not isinstance(count, numbers.Integral) or count < 1:
        raise BSFError(f"count must be a positive int, got {count!r}")
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise BSFError(f"seed must be a non-negative int, got {seed!r}")
    lo, hi = _check_fraction(area_fraction)
    if not (isinstance(irregularity, numbers.Real) and np.isfinite(irregularity)
            and irregularity >= 0):
        raise BSFError(f"irregularity must be a finite number >= 0, got {irregularity!r}")
    n = mesh.n_vertices
    if mass is None:
        mass = laplacian(mesh)[1].diagonal()
    mass = np.asarray(mass, dtype=np.float64)
    if mass.shape != (n,) or not np.all(np.isfinite(mass)) or np.any(mass < 0) \
            or mass.sum() <= 0:
        raise BSFError(f"mass must be ({n},) finite, >= 0 and not all zero, got shape "
                       f"{mass.shape}")
    rng = np.random.default_rng(int(seed))
    graph = _random_edge_graph(mesh, rng, float(irregularity))
    seeds = rng.choice(n, size=count, replace=count > n)
    target = rng.uniform(lo, hi, size=count) * mass.sum()
    dist = scipy.sparse.csgraph.dijkstra(graph, directed=False, indices=seeds)  # (count, n)
    order = np.argsort(dist, axis=1, kind="stable")
    cum = np.cumsum(mass[order], axis=1)
    # first vertex at which the cumulated area reaches the target joins too
    size = np.minimum((cum < target[:, None]).sum(axis=1) + 1, n)
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(n)[None, :].repeat(count, axis=0), axis=1)
    inside = (rank < size[:, None]) & np.isfinite(dist)
    return inside.astype(np.float64)


def labels_to_indicators(labels, n_labels: int | None = None) -> jax.Array:
    """One indicator per label: ``(..., n)`` int labels → ``(..., L, n)`` of 0/1.

    Row ``l`` is ``χ_{labels = l}``, so a step function with piece values ``a`` ``(L,)`` is
    ``a @ labels_to_indicators(labels)`` (paper Eq. 2).

    **Arguments:**

    - `labels`: ``(..., n)`` non-negative integer labels.
    - `n_labels`: ``L`` (static); default ``max(labels) + 1`` (needs concrete labels).

    **Returns:**

    ``(..., L, n)`` in JAX's default float dtype; works under ``jit`` given ``n_labels``.
    """
    traced = isinstance(labels, jax.core.Tracer)
    if not traced:
        labels = np.asarray(labels)
        if labels.ndim < 1 or labels.size == 0:
            raise BSFError(f"labels must be a non-empty (..., n) array, got shape {labels.shape}")
        if not np.issubdtype(labels.dtype, np.integer) or labels.dtype == np.bool_:
            raise BSFError(f"labels must be integers, got dtype {labels.dtype}")
        if labels.min() < 0:
            raise BSFError(f"labels must be >= 0, got min {labels.min()}")
    elif n_labels is None:
        raise BSFError("n_labels must be given when labels are traced (under jit/vmap)")
    if n_labels is None:
        n_labels = int(labels.max()) + 1
        # memory must not follow the label values: refuse what cannot fit, never crash
        need = n_labels * int(labels.size) * jnp.dtype(jnp.result_type(float)).itemsize
        if need > _INDICATOR_BUDGET_BYTES:
            raise BSFError(f"labels has max {labels.max()}: {n_labels} indicators of "
                           f"{labels.size} entries would take {need / 2**30:.3g} GiB; compact "
                           "the labels first (numpy.unique(labels, return_inverse=True)) or "
                           "use transfer_labels, which does")
    if isinstance(n_labels, (bool, np.bool_)) or not isinstance(n_labels, numbers.Integral) \
            or n_labels < 1:
        raise BSFError(f"n_labels must be a positive int, got {n_labels!r}")
    if not traced and labels.max() >= n_labels:
        raise BSFError(f"labels must be < n_labels={n_labels}, got max {labels.max()}")
    lab = jnp.asarray(labels)
    ids = jnp.arange(int(n_labels), dtype=lab.dtype)[:, None]
    return (lab[..., None, :] == ids).astype(jnp.result_type(float))


def indicators_to_labels(indicators) -> jax.Array:
    """Labels from (possibly soft, transferred) indicators: arg-max over pieces.

    **Arguments:**

    - `indicators`: ``(..., L, n)``, row ``l`` the (approximate) indicator of piece ``l``.

    **Returns:**

    ``(..., n)`` int32, ``argmax_l indicators[..., l, i]`` (ties: the smallest label).
    Inverse of [`labels_to_indicators`][bsfjax.labels_to_indicators] on exact indicators.
    """
    if not isinstance(indicators, jax.core.Tracer):
        if not hasattr(indicators, "shape"):
            indicators = np.asarray(indicators)
        if indicators.ndim < 2 or indicators.shape[-2] == 0:
            raise BSFError(f"indicators must have shape (..., L, n) with L >= 1, got "
                           f"{tuple(indicators.shape)}")
        if not np.all(np.isfinite(np.asarray(indicators))):
            raise BSFError("indicators contain NaN or infinite values")
    return jnp.argmax(jnp.asarray(indicators), axis=-2).astype(jnp.int32)
