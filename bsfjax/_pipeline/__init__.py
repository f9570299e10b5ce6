"""Mesh-level entry points: values and labels from one mesh to another, per vertex or per triangle, and collections of targets."""

from ._collection import TargetTransfer, process_share, size_bucket, transfer_collection
from ._face_labels import (
    FaceShares, decide_face_labels, face_label_shares, face_labels_from_vertices,
    face_scores, transfer_face_labels,
)
from ._mesh_level import LabelTransfer, REGIMES, transfer_labels, transfer_values

__all__ = [
    "FaceShares", "LabelTransfer", "REGIMES", "TargetTransfer", "decide_face_labels",
    "face_label_shares", "face_labels_from_vertices", "face_scores", "process_share",
    "size_bucket", "transfer_collection", "transfer_face_labels", "transfer_labels",
    "transfer_values",
]
