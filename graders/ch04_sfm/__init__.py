"""Chapter 4 — structure from motion: exercise specifications, oracles and stand-ins, by topic.

    triangulation.py       4.4-4.6   normalised DLT, midpoint, triangulation angles
    pnp.py                 4.7-4.10  PnP by DLT, P3P, EPnP, PnP inside RANSAC
    tracks.py              4.11      tracks by union-find
    initial_pair.py        4.12-4.13 two-view initialisation, ranking initial pairs
    sfm_scenes.py, incremental.py, photos.py
                           4.14      incremental SfM: synthetic scenes (K known and unknown), real photos
    rotation_averaging.py  4.15      chordal L2
    colmap_io.py           4.16-4.17 COLMAP text models
    debug.py               4.18, 4.20 DEBUG: components, scale drift (and debug_case for all four)
    repairs.py             4.19, 4.21 DEBUG, diagnosed repairs: failed registrations, a degenerate initial pair
    standin_ba.py          bundle_adjust: chapter 5's scipy adjuster on a 4.14 reconstruction (a stand-in)
    alignment.py           4.25      FRONTIER: Umeyama on pointmaps
    questions.py           4.1-4.3, 4.22-4.24

Shared oracles: graders.oracles.sfm_standin (the OpenCV stand-in for 4.14, PnP RANSAC, union-find tracks)
and graders.oracles.colmap (COLMAP text model and database). Reconstructions are judged up to their gauge:
camera positions after a Sim(3) (Umeyama) alignment, rotations after a global rotation, tracks as sets of
(image, keypoint) sets, P3P solutions regardless of order. Conventions: docs/CONVENTIONS.md; poses
world-to-camera `x_c = R X + t`. The learner's interface is stated in each stub of notebooks/04_sfm.ipynb
and in each topic module's `Exercise(...)` rows. The names below are the notebook's API.
"""
from __future__ import annotations

from graders.core.compare import rotation_angle_deg
from graders.kit.geometry import camera_centre, project
from ..oracles.colmap import colmap_log, colmap_read_text, gt_write_colmap_text
from ..oracles.sfm_standin import IncrementalSfM, cv_incremental_sfm, cv_pnp_ransac, union_find_tracks
from graders.kit.scene import two_view
from . import questions  # noqa: F401  (registers 4.1-4.3, 4.22-4.24)
from .alignment import cv_umeyama, pointmap_pair
from .colmap_io import colmap_recon
from .debug import (broken_components, broken_trajectory, debug_case, debug_components, debug_drift, gt_components,
                    gt_fix_drift)
from .repairs import (INITIAL_PAIR_CAUSES, REGISTRATION_CAUSES, broken_initial_pair, broken_initial_run,
                      broken_registration, cv_fix_initial_pair, cv_fix_registration, cv_pair_stats, debug_initial_pair,
                      debug_registration, registration_status)
from .standin_ba import bundle_adjust
from .incremental import focal_error, low_angle_fraction, recon_errors
from .initial_pair import colmap_two_view, cv_two_view_init, gt_rank_initial_pairs
from .photos import (PHOTO_SETS, SACRE_COEUR_FEATURES, SACRE_COEUR_MAX_SIDE, colmap_photos, colmap_sacre_coeur,
                     photo_problem, real_focal_error, real_reprojection_px, recon_reprojection_px,
                     relative_rotation_errors, sacre_coeur_problem)
from .pnp import colmap_pnp, cv_epnp, cv_p3p, cv_sqpnp, gt_pnp_dlt, held_out_px, pnp_scene, pose_error
from .questions import sigma_z
from .rotation_averaging import align_rotations, gt_rotation_averaging, rotation_graph
from .sfm_scenes import sfm_scene, strip_scene, uncalibrated_sfm_scene
from .tracks import gt_build_tracks, track_problem
from .triangulation import colmap_triangulation_angles, cv_triangulate, gt_midpoint, gt_triangulation_angles

__all__ = [
    # geometry and scenes the notebook uses
    "camera_centre", "project", "rotation_angle_deg", "two_view", "pnp_scene", "sfm_scene", "strip_scene",
    "uncalibrated_sfm_scene", "track_problem", "rotation_graph", "pointmap_pair", "colmap_recon",
    # oracles and stand-ins
    "cv_triangulate", "gt_midpoint", "gt_triangulation_angles", "colmap_triangulation_angles", "gt_pnp_dlt",
    "cv_p3p", "cv_epnp", "cv_sqpnp", "cv_pnp_ransac", "colmap_pnp", "gt_build_tracks", "union_find_tracks",
    "cv_two_view_init", "colmap_two_view", "gt_rank_initial_pairs", "cv_incremental_sfm", "IncrementalSfM",
    "gt_rotation_averaging", "gt_write_colmap_text", "colmap_read_text", "cv_umeyama",
    # metrics
    "pose_error", "held_out_px", "recon_errors", "low_angle_fraction", "focal_error", "align_rotations",
    "real_reprojection_px", "recon_reprojection_px", "relative_rotation_errors",
    # the Sacré-Cœur photos
    "sacre_coeur_problem", "colmap_sacre_coeur", "SACRE_COEUR_MAX_SIDE", "SACRE_COEUR_FEATURES",
    "photo_problem", "colmap_photos", "PHOTO_SETS", "real_focal_error",   # every real set (Sceaux Castle: K known)
    # DEBUG (section 3)
    "debug_case", "debug_components", "debug_registration", "debug_drift", "debug_initial_pair",
    "broken_components", "broken_initial_pair", "broken_initial_run", "broken_registration", "broken_trajectory",
    "REGISTRATION_CAUSES", "INITIAL_PAIR_CAUSES", "registration_status",
    "cv_pair_stats", "cv_fix_initial_pair", "cv_fix_registration", "gt_components", "gt_fix_drift",
    # stand-ins a learner may call in self-study: chapter 5's scipy bundle adjuster; pycolmap's C++ log switch
    "bundle_adjust", "colmap_log",
    # questions
    "sigma_z",
]
