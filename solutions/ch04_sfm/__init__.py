"""Chapter 4 — structure from motion: the reference answers (numpy/scipy only), one module per topic,
following the notebook's sections:

    triangulation       4.4 triangulate_dlt, 4.5 triangulate_midpoint, 4.6 triangulation_angles
                        (+ triangulate_multiview, reprojection_errors)
    pnp                 4.7 pnp_dlt, 4.8 p3p, 4.9 epnp, 4.10 pnp_ransac (+ refine_pose, pnp_ransac_focal)
    tracks              4.11 build_tracks
    initial_pair        4.12 two_view_init, 4.13 rank_initial_pairs (+ decompose_homography,
                        focal_from_fundamental)
    pipeline            4.14 incremental_sfm (+ reprojection_stats)
    model               the reconstruction's state for 4.14 (+ distort, undistort, default_intrinsics)
    folders             reconstruct_folder: the pipeline on photos (Chapter 3's features, Chapter 2's RANSAC)
    rotation_averaging  4.15 rotation_averaging
    colmap_io           4.16 write_colmap_text, 4.17 read_colmap_text
    debug               4.18-4.21 the four DEBUG fixes
    questions           4.1-4.3, 4.22-4.24 CONCEPT and DESIGN answers
    frontier            4.25 umeyama (+ pose_from_pointmaps)

Every learner name of the notebook is exported here (`from solutions.ch04_sfm import ...`). Shared
primitives (camera_centre, project_to_so3, rodrigues, hartley, umeyama) come from solutions.geometry.
Conventions: docs/CONVENTIONS.md; world-to-camera poses `X_c = R X + t`.
"""
from .colmap_io import read_colmap_text, write_colmap_text
from .debug import fix_components, fix_initial_pair, fix_registration, fix_scale_drift
from .folders import extract_features, load_image, match_and_verify, match_features, reconstruct_folder, verify_matches
from .frontier import pose_from_pointmaps, umeyama
from .initial_pair import decompose_homography, focal_from_fundamental, rank_initial_pairs, two_view_init
from .pipeline import default_intrinsics, distort, incremental_sfm, reprojection_stats, undistort
from .pnp import epnp, p3p, pnp_dlt, pnp_ransac, refine_pose
from .questions import colmap_thresholds, exhaustive_pairs, matching_hours, pair_reduction_1m, sfm_choice, sigma_z
from .rotation_averaging import rotation_averaging
from .tracks import build_tracks
from .triangulation import (reprojection_errors, triangulate_dlt, triangulate_midpoint, triangulate_multiview,
                            triangulation_angles)

__all__ = [
    # CODE
    "triangulate_dlt", "triangulate_midpoint", "triangulation_angles", "pnp_dlt", "p3p", "epnp", "pnp_ransac",
    "build_tracks", "two_view_init", "rank_initial_pairs", "incremental_sfm", "rotation_averaging",
    "write_colmap_text", "read_colmap_text",
    # DEBUG
    "fix_components", "fix_registration", "fix_scale_drift", "fix_initial_pair",
    # CONCEPT and DESIGN
    "sigma_z", "colmap_thresholds", "exhaustive_pairs", "matching_hours", "sfm_choice", "pair_reduction_1m",
    # FRONTIER
    "umeyama", "pose_from_pointmaps",
    # helpers the pipeline, the benchmark and the tests use
    "triangulate_multiview", "reprojection_errors", "refine_pose", "decompose_homography", "focal_from_fundamental",
    "default_intrinsics", "distort", "undistort", "reprojection_stats", "load_image", "extract_features",
    "match_features", "verify_matches", "match_and_verify", "reconstruct_folder",
]
