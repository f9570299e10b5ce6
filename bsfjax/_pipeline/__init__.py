"""Mesh-level entry points: from one mesh to another, or to many.

`transfer_values` and `transfer_labels` (per vertex: each label's indicator is transferred and
the target takes the arg-max), `transfer_face_labels` (labels given per triangle), and
`transfer_collection` (one source to many targets in size buckets, batched and sharded, with
the batched stages of map estimation and transfer).
"""

from ._collection import TargetTransfer, process_share, size_bucket, transfer_collection
from ._face_labels import (
    FaceShares, decide_face_labels, face_label_shares, face_labels_from_vertices,
    face_scores, transfer_face_labels,
)
from ._mesh_level import LabelTransfer, REGIMES, transfer_labels, transfer_values
from ._stages import capped_batch

__all__ = [
    "FaceShares", "LabelTransfer", "REGIMES", "TargetTransfer", "capped_batch",
    "decide_face_labels",
    "face_label_shares", "face_labels_from_vertices", "face_scores", "process_share",
    "size_bucket", "transfer_collection", "transfer_face_labels", "transfer_labels",
    "transfer_values",
]
