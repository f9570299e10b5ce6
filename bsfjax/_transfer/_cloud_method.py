"""The refined pull-back's options on a pair with a point cloud (`method_for_shapes`).

The refined pull-back's ZoomOut continuation (`bsfjax._maps._refine`) matches, besides the
spectral embeddings, the first ``descriptor_dims`` WKS descriptors of the two shapes.  A point
cloud's descriptors come from another discretization (the point-cloud Laplacian of Sharp &
Crane 2020) than a mesh's (cotangent Laplacian), and they differ most at the high energies;
on a pair with a cloud the continuation is run on the spectral embeddings alone.
"""

from __future__ import annotations

from ._refined import RefinedPullBack

__all__ = ["method_for_shapes", "CLOUD_DESCRIPTOR_WEIGHT"]

#: The refined pull-back's ``descriptor_weight`` on a pair with a point cloud.
CLOUD_DESCRIPTOR_WEIGHT = 0.0


def method_for_shapes(method, *shapes):
    """``method`` for a pair of ``shapes`` ([`Mesh`][bsfjax.Mesh] es): the name ``"refined"``
    (its default options) becomes a [`RefinedPullBack`][bsfjax.RefinedPullBack] with
    ``descriptor_weight = CLOUD_DESCRIPTOR_WEIGHT`` when one of them is a point cloud; any
    other method, or a method object with options chosen by the caller, is returned as
    given."""
    if isinstance(method, str) and method == "refined" and any(getattr(s, "is_point_cloud", False) for s in shapes):
        return RefinedPullBack(descriptor_weight=CLOUD_DESCRIPTOR_WEIGHT)
    return method
