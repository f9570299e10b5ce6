"""Sampling on a mesh: farthest point sampling (the frame centres, ZoomOut samples) and geodesic distances."""

from ._fps import Subsample, farthest_point_sampling, subsample
from ._geodesics import geodesic_distances, geodesic_error

__all__ = [
    "Subsample", "farthest_point_sampling", "geodesic_distances", "geodesic_error", "subsample",
]
