"""The refined pull-back's options on a pair with a point cloud (`method_for_shapes`).

The refined pull-back's ZoomOut continuation (`bsfjax._maps._refine`) matches, besides the
spectral embeddings, the first ``descriptor_dims`` WKS descriptors of the two shapes.  A point
cloud's descriptors come from another discretization (the point-cloud Laplacian of Sharp &
Crane 2020) than a mesh's (cotangent Laplacian), and they differ most at the high energies;
on a pair with a cloud the continuation is run on the spectral embeddings alone.

And the labels are the majority vote of every map of the continuation (60 to 100 eigenpairs
in steps of 10: five maps) instead of its last map alone.  A cloud's labels are wrong mostly
at the parts' borders, where successive maps of the continuation disagree by a point or two;
the vote places a border point where most of them do.  On the 12 noisy 15K clouds of FAUST
000→010, 001→011, 002→012 (sampling seeds 0–3; ``bsfjax transfer`` with 5 landmarks) the
mean accuracy per seed went 93.36 → 93.68, 93.45 → 93.76, 93.40 → 93.56, 93.80 → 94.06 % (the
vote of the last 3 maps in steps of 20: 93.62, 93.59 %), for 0.6 s more per 15K cloud.  Not
on meshes: there the vote of the last three maps was as accurate as the last map alone
(94.81 against 94.95 %, docs/results/segmentation.md).
"""

from __future__ import annotations

from ._refined import RefinedPullBack

__all__ = ["method_for_shapes", "CLOUD_DESCRIPTOR_WEIGHT", "CLOUD_REFINE_STEP", "CLOUD_VOTES"]

#: The refined pull-back's ``descriptor_weight`` on a pair with a point cloud.
CLOUD_DESCRIPTOR_WEIGHT = 0.0
#: Its continuation's step and the maps that vote, on such a pair (the module doc).
CLOUD_REFINE_STEP, CLOUD_VOTES = 10, 5


def method_for_shapes(method, *shapes):
    """``method`` for a pair of ``shapes`` ([`Mesh`][bsfjax.Mesh] es): the name ``"refined"``
    (its default options) becomes a [`RefinedPullBack`][bsfjax.RefinedPullBack] with
    ``descriptor_weight = CLOUD_DESCRIPTOR_WEIGHT``, ``step = CLOUD_REFINE_STEP`` and
    ``n_vote = CLOUD_VOTES`` when one of them is a point cloud; any other method, or a method
    object with options chosen by the caller, is returned as given."""
    if isinstance(method, str) and method == "refined" and any(getattr(s, "is_point_cloud", False) for s in shapes):
        return RefinedPullBack(descriptor_weight=CLOUD_DESCRIPTOR_WEIGHT,
                               step=CLOUD_REFINE_STEP, n_vote=CLOUD_VOTES)
    return method
