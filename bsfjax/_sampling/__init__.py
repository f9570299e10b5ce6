"""Sampling on a mesh: well-spread points and distances between them.

Farthest point sampling (Euclidean, geodesic by Dijkstra, or biharmonic) gives the frame's
centres (paper: 5 % of the vertices) and ZoomOut's samples with their Voronoi cells
(`subsample`); `geodesic_distances` and `geodesic_error` measure maps.
"""

from ._fps import Subsample, farthest_point_sampling, subsample
from ._geodesics import geodesic_distances, geodesic_error

__all__ = [
    "Subsample", "farthest_point_sampling", "geodesic_distances", "geodesic_error", "subsample",
]
