"""Functional maps: descriptors, the descriptor-commutativity estimate, ZoomOut, point-map conversion and refinement, and the map estimator."""

from ._batched import (
    StageConfig, map_stage, point_map_stage, problem_stage, source_ops_stage, spectra,
)
from ._descriptors import hks, hks_times, wks, wks_energies
from ._distortion import choose_map, map_distortion, orientation_agreement
from ._estimation import FmapWeights, estimate_fmap, fmap_energy
from ._estimator import (
    LANDMARK_FREE_STARTS, MapEstimate, ORIENTATION_SLACK, ORIENT_WEIGHT, TURN_RADIUS,
    TURN_SAMPLES, WKS_VARIANCE, ZOOMOUT_SAMPLES, check_landmark_pairs, check_starts,
    estimate_map, mirror_symmetry,
)
from ._fmap import (
    check_samples, chunk_for, default_chunk, fmap_from_p2p, fmap_to_p2p, icp_refine,
    nearest_neighbors, zoomout,
)
from ._orientation import OrientationBasis, face_geometry, orientation_bases
from ._refine import (
    REFINE_EIGENPAIRS, check_options, refine_core, refine_point_maps, refinement_sizes,
    sizes_for, start_point_map,
)

__all__ = [
    "FmapWeights", "LANDMARK_FREE_STARTS", "MapEstimate", "ORIENTATION_SLACK", "ORIENT_WEIGHT",
    "OrientationBasis", "REFINE_EIGENPAIRS", "StageConfig", "TURN_RADIUS", "TURN_SAMPLES",
    "WKS_VARIANCE", "ZOOMOUT_SAMPLES", "check_landmark_pairs", "check_options", "check_samples",
    "check_starts", "choose_map", "chunk_for", "default_chunk", "estimate_fmap", "estimate_map",
    "face_geometry", "fmap_energy", "fmap_from_p2p", "fmap_to_p2p", "hks", "hks_times",
    "icp_refine", "map_distortion", "map_stage", "mirror_symmetry", "nearest_neighbors",
    "orientation_agreement", "orientation_bases", "point_map_stage", "problem_stage",
    "refine_core", "refine_point_maps", "refinement_sizes", "sizes_for", "source_ops_stage",
    "spectra", "start_point_map", "wks", "wks_energies", "zoomout",
]
