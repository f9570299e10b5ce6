"""How good is a point map, without ground truth: its geodesic distortion and orientation.

A point map ``T: N → M`` (``p2p[j]`` the source vertex of target vertex ``j``) between two
near-isometric shapes keeps geodesic distances, and between two shapes of one orientation it
keeps the orientation of small triangles.  Two numbers measure this from the meshes alone:

* **geodesic distortion** ([`map_distortion`][bsfjax.map_distortion]): on ``s`` farthest-point samples ``x_i`` of
  the target, the mean over the pairs ``i ≠ j`` of

      | d_M(T x_i, T x_j) / √area(M) − d_N(x_i, x_j) / √area(N) |,

  with ``d`` the Dijkstra distance along mesh edges ([`bsfjax.geodesic_distances`][bsfjax.geodesic_distances]), each
  shape at unit area; two points in different components count as the shape's largest sampled
  distance apart (a map that tears a component apart is distorted, and the value stays
  finite).  A map that slides a whole part elsewhere (an arm onto a leg, a partly
  mirrored limb) tears distances apart where it jumps, so it scores high.  The mirror image of a
  symmetric shape keeps every distance, so it scores as low as the right map: that is what the
  second number is for.

  With a ``radius`` only the pairs closer than ``radius`` on the target count, each relative to
  its target distance: the **local distortion** ``|d_M(T x_i, T x_j) − d_N(x_i, x_j)| /
  d_N(x_i, x_j)``, both at unit area.  It sees what the mean over all pairs averages away: a
  limb twisted along its length (the front-to-back turn of [`bsfjax.estimate_map`][bsfjax.estimate_map])
  stretches distances between nearby points, while the long distances that dominate the
  global mean barely change.
* **orientation agreement** ([`orientation_agreement`][bsfjax.orientation_agreement]): the area-weighted share of the
  target's faces ``(a, b, c)`` whose images ``(T a, T b, T c)`` (three distinct source vertices)
  turn the same way as the source surface, ``(n_Ta + n_Tb + n_Tc) · ((x_Tb − x_Ta) × (x_Tc −
  x_Ta)) > 0`` with ``n`` the source's area-weighted vertex normals.  A mirror image has
  agreement near 0, a right map near 1 (0.90–0.97 on the FAUST pairs of
  docs/results/segmentation.md: a
  vertex-to-vertex map folds some small triangles), a partly mirrored map in between.  Both
  meshes must be consistently oriented.

[`choose_map`][bsfjax.choose_map] combines them: among maps within ``slack`` of the best orientation, the one
of least distortion.  [`bsfjax.estimate_map`][bsfjax.estimate_map] uses it to pick among its starts when it has
no landmarks (docs/results/segmentation.md, "Without landmarks").
"""

from __future__ import annotations

import numpy as np

from .._util import BSFError
from .._sampling import geodesic_distances
from .._mesh import Mesh
from .._sampling import farthest_point_sampling
from .._util import check_indices, check_int, check_real, require_triangles
from .._mesh import as_mesh

__all__ = ["map_distortion", "orientation_agreement", "choose_map", "DISTORTION_SAMPLES",
           "ORIENTATION_SLACK"]

#: Target samples over whose pairs [`map_distortion`][bsfjax.map_distortion] averages (100·99 distances).
DISTORTION_SAMPLES = 100

#: [`choose_map`][bsfjax.choose_map] keeps the maps whose orientation agreement is at most this far below the
#: best one's (on the FAUST pairs of docs/results/segmentation.md: right maps 0.90–0.97, partly
#: mirrored or
#: slid ones down to 0.34).
ORIENTATION_SLACK = 0.1

#: With ``fit_scale`` the global distortion compares ``d_M`` with ``s · d_N`` for the best scale
#: ``s`` in ``[1 / SCALE_RANGE, SCALE_RANGE]`` (bounded: a map that collapses the target onto a
#: small region would otherwise fit ``s → 0``).
SCALE_RANGE = 1.2


def _check_pair(source_mesh, target_mesh, p2p) -> tuple[np.ndarray, bool]:
    for name, m in (("source_mesh", source_mesh), ("target_mesh", target_mesh)):
        if not isinstance(m, Mesh):
            raise BSFError(f"{name} must be a bsfjax.Mesh, got {type(m).__name__}")
    maps = check_indices(p2p, "p2p", source_mesh.n_vertices, what="source vertex indices")
    single = maps.ndim == 1
    maps = maps[None] if single else maps
    if maps.ndim != 2 or maps.shape[1] != target_mesh.n_vertices:
        raise BSFError(f"p2p must have shape ({target_mesh.n_vertices},) or (B, "
                       f"{target_mesh.n_vertices}) (one source vertex per target vertex), got "
                       f"{np.shape(p2p)}")
    return maps.astype(np.int64), single


def map_distortion(source_mesh: Mesh, target_mesh: Mesh, p2p, *,
                   n_samples: int = DISTORTION_SAMPLES, radius: float | None = None,
                   fit_scale: bool = False):
    """Mean geodesic distortion of point map(s) ``T: N → M`` on target samples (module doc).

    **Arguments:**

    - ``source_mesh``, ``target_mesh``: the meshes ``M`` and ``N``.
    - `p2p`: ``(n_N,)`` source vertex of each target vertex, or ``(B, n_N)`` for ``B`` maps
      (the target's distances are computed once, the source's once per distinct image).
    - `n_samples`: farthest-point samples of the target (all vertices if fewer).
    - `radius`: ``None`` (every pair, absolute differences), or the local distortion over
      the pairs closer than ``radius`` (in units of √area of the target), relative to their
      distance on the target.
    - `fit_scale`: the global distortion up to a scale, ``mean |d_M − s d_N|`` with the
      least-squares ``s = Σ d_M d_N / Σ d_N²`` clipped to ``[1/1.2, 1.2]``: two bodies of
      different build (FAUST's subjects) at unit area keep distances only up to a few per
      cent (the ground-truth map of ``tr_reg_000 → 010``: ``s = 1.045``), which a map that
      slides the torso can fit better without the scale.

    **Returns:**

    a float (or ``(B,)`` floats), 0 for an isometry; in units of √area, or a
    ratio with a ``radius``.
    """
    source_mesh, target_mesh = as_mesh(source_mesh, "source_mesh"), as_mesh(target_mesh,
                                                                            "target_mesh")
    maps, single = _check_pair(source_mesh, target_mesh, p2p)
    n_samples = check_int(n_samples, "n_samples", 2)
    if radius is not None:
        radius = check_real(radius, "radius", positive=True)
    out = _distortions(source_mesh, target_mesh, maps, n_samples, radius,
                       fit_scale=bool(fit_scale))
    if out is None:
        raise BSFError(f"no two of the target's {min(n_samples, target_mesh.n_vertices)} "
                       f"samples are closer than radius = {radius} (in units of √area): give "
                       f"a larger radius or more samples")
    return float(out[0]) if single else out


def _distortions(source_mesh: Mesh, target_mesh: Mesh, maps: np.ndarray, n_samples: int,
                 radius: float | None, geodesics=None, *,
                 fit_scale: bool = False) -> np.ndarray | None:
    """[`map_distortion`][bsfjax.map_distortion] of checked ``(B, n_N)`` maps; ``None`` where a ``radius`` keeps
    no pair of samples (a coarse target: [`bsfjax.estimate_map`][bsfjax.estimate_map] then skips its turn
    check).  ``geodesics``: the pair's `_Geodesics` ``(source, target)`` when several
    calls on one pair share their Dijkstra runs."""
    geo_m, geo_n = geodesics or (_Geodesics(source_mesh), _Geodesics(target_mesh))
    s = np.asarray(farthest_point_sampling(target_mesh, min(n_samples, target_mesh.n_vertices)))
    d_n = _capped(geo_n.among(s)) / np.sqrt(target_mesh.area)
    images = maps[:, s]  # (B, s)
    uniq, inv = np.unique(images, return_inverse=True)
    inv = inv.reshape(images.shape)
    d_u = _capped(geo_m.among(uniq)) / np.sqrt(source_mesh.area)
    d_m = d_u[inv[:, :, None], inv[:, None, :]]  # (B, s, s)
    if radius is None:
        pairs = ~np.eye(len(s), dtype=bool)
        a, b = d_m[:, pairs], d_n[pairs]
        scale = 1.0
        if fit_scale:  # (per map, least squares, bounded)
            scale = np.clip(a @ b / max(float(b @ b), 1e-300), 1 / SCALE_RANGE,
                            SCALE_RANGE)[:, None]
        return np.abs(a - scale * b).mean(axis=1)
    pairs = (d_n > 0) & (d_n < radius)
    if not pairs.any():
        return None
    return (np.abs(d_m - d_n)[:, pairs] / d_n[pairs]).mean(axis=1)


class _Geodesics:
    """Dijkstra distances among the vertices of one mesh asked for so far.  A later call runs
    Dijkstra only from the vertices not seen before: their rows also hold their distances to
    the others (the edge graph is undirected).  Memory: the square of the vertices seen, never
    ``n × n``.  [`bsfjax.estimate_map`][bsfjax.estimate_map] shares one per shape across its distortions."""

    def __init__(self, mesh: Mesh):
        self.mesh = mesh
        self.seen = np.zeros(0, np.int64)  # the vertices run so far, in the order run
        self.d = np.zeros((0, 0))

    def among(self, vertices) -> np.ndarray:
        """``(len(vertices), len(vertices))`` distances between the given vertices."""
        v = np.asarray(vertices, np.int64)
        new = np.setdiff1d(v, self.seen)
        if new.size:
            old = len(self.seen)
            both = np.concatenate([self.seen, new])
            d = np.empty((len(both), len(both)))
            d[:old, :old] = self.d
            # only the columns asked for: never (new, n), 1.3 GB for 1500 sources at 111K
            d[old:] = geodesic_distances(self.mesh, new, targets=both)
            d[:old, old:] = d[old:, :old].T
            self.seen, self.d = both, d
        order = np.argsort(self.seen, kind="stable")
        pos = order[np.searchsorted(self.seen, v, sorter=order)]
        return self.d[np.ix_(pos, pos)]


def _capped(d: np.ndarray) -> np.ndarray:
    """Distances between components (infinite) set to the largest finite one."""
    far = ~np.isfinite(d)
    if far.any():
        d = np.where(far, d[~far].max(initial=0.0), d)
    return d


def _vertex_normals(mesh: Mesh) -> np.ndarray:
    v, f = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # 2 × area × unit normal
    n = np.zeros_like(v)
    for c in range(3):
        np.add.at(n, f[:, c], fn)
    return n


def orientation_agreement(source_mesh: Mesh, target_mesh: Mesh, p2p):
    """Area share of the target's faces whose images keep their orientation (module doc).

    **Arguments:**

    - ``source_mesh``, ``target_mesh``: consistently oriented meshes ``M`` and ``N``.
    - `p2p`: ``(n_N,)`` or ``(B, n_N)`` point map(s) ``T: N → M``.

    **Returns:**

    a float (or ``(B,)``) in [0, 1]: 1 for a map that keeps every triangle's
    orientation, 0 for a mirror image; faces whose three images are not distinct do not count.
    """
    source_mesh, target_mesh = as_mesh(source_mesh, "source_mesh"), as_mesh(target_mesh,
                                                                            "target_mesh")
    maps, single = _check_pair(source_mesh, target_mesh, p2p)
    for m in (source_mesh, target_mesh):
        require_triangles(m, "the orientation agreement needs triangles: a point cloud has "
                          "none")
    out = _agreements(source_mesh, target_mesh, maps)
    return float(out[0]) if single else out


def _agreements(source_mesh: Mesh, target_mesh: Mesh, maps: np.ndarray,
                faces: np.ndarray | None = None) -> np.ndarray:
    """[`orientation_agreement`][bsfjax.orientation_agreement] of checked ``(B, n_N)`` maps over the target's faces, or
    over the faces ``faces`` (indices) only: then the maps need to be known (``≥ 0``) only at
    those faces' corners, and the result is the area-weighted share over them."""
    v = np.asarray(source_mesh.vertices, np.float64)
    normals = _vertex_normals(source_mesh)
    f = np.asarray(target_mesh.faces)
    w = target_mesh.face_areas()
    if faces is not None:
        f, w = f[faces], w[faces]
    out = np.empty(len(maps))
    for b, t in enumerate(maps):  # B maps, each one vectorized pass over the faces
        a, c1, c2 = t[f[:, 0]], t[f[:, 1]], t[f[:, 2]]
        distinct = (a != c1) & (c1 != c2) & (a != c2)
        turn = np.einsum("ij,ij->i", normals[a] + normals[c1] + normals[c2],
                         np.cross(v[c1] - v[a], v[c2] - v[a]))
        total = w[distinct].sum()
        out[b] = w[distinct & (turn > 0)].sum() / total if total > 0 else 0.0
    return out


def choose_map(distortion, orientation, *, slack: float = ORIENTATION_SLACK,
               coverage=None) -> int:
    """Index of the map of least distortion among those within ``slack`` of the best
    orientation agreement (ties: the first).  With ``coverage``, of least
    ``d / min d + c / min c`` among them: each measure relative to the best value it takes
    there, so neither needs a weight (`bsfjax._maps._coverage`).

    **Arguments:**

    - ``distortion``, ``orientation``: ``(B,)`` values of [`map_distortion`][bsfjax.map_distortion] and
      [`orientation_agreement`][bsfjax.orientation_agreement] for ``B`` candidate maps.
    - `slack`: in [0, 1].
    - `coverage`: ``None``, or their ``(B,)`` [`map_coverage`][bsfjax.map_coverage] errors.
    """
    d = np.asarray(distortion, np.float64)
    o = np.asarray(orientation, np.float64)
    c = np.zeros_like(d) if coverage is None else np.asarray(coverage, np.float64)
    if d.ndim != 1 or d.shape != o.shape or d.shape != c.shape or d.size == 0:
        raise BSFError(f"distortion, orientation (and coverage) must be non-empty 1-D arrays "
                       f"of one length, got shapes {d.shape}, {o.shape}"
                       + ("" if coverage is None else f" and {c.shape}"))
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(o)) and np.all(np.isfinite(c))):
        raise BSFError("distortion, orientation and coverage must be finite")
    if np.any(c < 0):
        raise BSFError("coverage must be >= 0")
    slack = check_real(slack, "slack")
    if not 0 <= slack <= 1:
        raise BSFError(f"slack must be in [0, 1], got {slack}")
    keep = np.flatnonzero(o >= o.max() - slack)
    score = d[keep]
    if coverage is not None:
        tiny = np.finfo(np.float64).tiny  # (a measure that is 0 somewhere: that map wins it)
        score = score / max(score.min(), tiny) + c[keep] / max(c[keep].min(), tiny)
    return int(keep[np.argmin(score)])
