"""Functional maps between two spectra, and the map estimator.

Descriptors (WKS, HKS), the descriptor-commutativity estimate of `C` (Nogneng & Ovsjanikov
2017, solved with optimistix) with an optional orientation term, ZoomOut, conversions between
functional and point maps, the refinement behind the `refined` method, the measures that
choose among landmark-free maps (geodesic distortion, orientation agreement, coverage), and
`estimate_map`, which runs them from two spectra (and meshes) to one map.  The map stages of the
batched collection path live here too.
"""

from ._batched import (
    StageConfig, map_stage, point_map_stage, problem_stage, source_ops_stage, spectra,
)
from ._coverage import COVERAGE_SMOOTHING, map_coverage
from ._descriptors import hks, hks_times, wks, wks_energies
from ._distortion import choose_map, map_distortion, orientation_agreement
from ._estimation import FmapWeights, check_fmap_memory, estimate_fmap, fmap_energy
from ._estimate import MapEstimate, check_landmark_pairs, check_starts
from ._estimator import MapEstimator
from ._functions import estimate_map, mirror_symmetry
from ._fmap import (
    check_samples, chunk_for, default_chunk, fmap_from_p2p, fmap_to_p2p, icp_refine,
    nearest_neighbors, zoomout,
)
from ._guide import (CLOUD_ZOOMOUT_STEP, DERIVED_GUIDANCE, GUIDE_WEIGHT, estimate_size,
                     estimates_again, follows_landmarks, for_point_clouds, guidable,
                     guided_zoomout,
                     landmark_geodesics, turn_mirror_size)
from ._orientation import OrientationBasis, face_geometry, orientation_bases
from ._turn import with_read_pairs
from ._refine import (
    REFINE_EIGENPAIRS, check_options, refine_core, refine_point_maps, refinement_sizes,
    sizes_for, start_point_map,
)

__all__ = [
    "CLOUD_ZOOMOUT_STEP", "COVERAGE_SMOOTHING", "DERIVED_GUIDANCE", "FmapWeights", "GUIDE_WEIGHT", "MapEstimate", "MapEstimator", "OrientationBasis", "REFINE_EIGENPAIRS",
    "StageConfig", "check_fmap_memory", "check_landmark_pairs", "check_options", "check_samples",
    "check_starts", "choose_map", "chunk_for", "default_chunk", "estimate_fmap", "estimate_map",
    "estimate_size", "estimates_again", "follows_landmarks", "guidable", "guided_zoomout",
    "landmark_geodesics",
    "face_geometry", "fmap_energy", "fmap_from_p2p", "fmap_to_p2p", "hks", "hks_times",
    "icp_refine", "map_coverage", "map_distortion", "map_stage", "mirror_symmetry", "nearest_neighbors",
    "orientation_agreement", "orientation_bases", "point_map_stage", "problem_stage",
    "refine_core", "refine_point_maps", "refinement_sizes", "sizes_for", "source_ops_stage",
    "turn_mirror_size", "for_point_clouds", "with_read_pairs",
    "spectra", "start_point_map", "wks", "wks_energies", "zoomout",
]
