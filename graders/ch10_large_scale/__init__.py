"""Chapter 10 — large-scale and learned 3D: exercise specifications, oracles and stand-ins, one module
per section.

Oracles: brute-force descriptor matching (retrieval), pycolmap (estimate_sim3d_robust,
align_reconstructions_via_points), the grader's own Umeyama (graders.kit.geometry) and exact synthetic
ground truth (textured-plane renders of known places, sub-reconstructions with known poses).

Modules (part A): `questions` (10.1-10.3, 10.14-10.16), `retrieval` (10.6), `sim3` (10.7),
`merge` (10.8), `debug` (10.11).
Modules (part B): `questions_learned` (10.4-10.5), `pointmaps` (10.9), `distributed` (10.10; its stages in `stages`),
`debug_learned` (10.12-10.13),
`frontier` (10.17 and the classical-vs-pointmaps race of the widget).
Importing the package registers the chapter; the names below are the API of the notebook, the tests
and the benchmark.
"""
from __future__ import annotations

from graders.core.engine import debug_practice

from . import questions  # noqa: F401 (registers 10.1-10.3, 10.14-10.16)

# ---- part A
from .retrieval import (average_precision, brute_force_scores, cv_vocab_tree_retrieve, mean_ap, place_images,
                        place_problem, recall_at_k, sift_descriptors, structured_problem, tfidf_scores)
from .debug import DEBUG_GENERATORS as _DEBUG_A
from .debug import components, components_after, cv_fix_components, top_k_pairs
from .merge import apply_sim3, gauge_errors, gt_merge_reconstructions, merge_problem
from .sim3 import cv_sim3_ransac, exact_planar_problem, gt_sim3_ransac, held_rms, sim3_problem

DEBUG_GENERATORS: dict = dict(_DEBUG_A)
__all__ = ["components", "components_after", "cv_fix_components", "top_k_pairs", "apply_sim3", "gauge_errors", "gt_merge_reconstructions", "merge_problem",
           "average_precision", "brute_force_scores", "cv_sim3_ransac", "cv_vocab_tree_retrieve", "debug_case", "exact_planar_problem", "gt_sim3_ransac",
           "held_rms", "mean_ap", "place_images", "place_problem", "recall_at_k", "sift_descriptors", "sim3_problem",
           "structured_problem", "tfidf_scores"]

# ---- part B (pointmaps, distributed, debug_learned, frontier, demo): add imports, DEBUG_GENERATORS entries
# and __all__ names below this line.
from . import questions_learned  # noqa: F401,E402 (registers 10.4-10.5)
from .distributed import gt_run_pipeline, gt_serial_pipeline, pipeline_images, save_images  # noqa: E402
from .stages import PermanentTaskError, PipelineStages, TransientTaskError, task_key  # noqa: E402
from .pointmaps import (alignment_errors, alignment_loss, gt_global_alignment, pair_graph,  # noqa: E402
                        pointmap_scene)

from .debug_learned import DEBUG_GENERATORS as _DEBUG_B  # noqa: E402
from .debug_learned import cv_choose_pipelines, cv_chunked_poses, pose_errors  # noqa: E402

from .frontier import gt_focal_from_pointmap, pointmap_view, race, race_scene  # noqa: E402

DEBUG_GENERATORS.update(_DEBUG_B)
__all__ += ["gt_focal_from_pointmap", "pointmap_view", "race", "race_scene", "cv_choose_pipelines", "cv_chunked_poses", "pose_errors", "PipelineStages", "TransientTaskError", "PermanentTaskError", "save_images", "gt_run_pipeline", "gt_serial_pipeline", "pipeline_images",
            "task_key", "alignment_errors", "alignment_loss", "gt_global_alignment", "pair_graph", "pointmap_scene"]

debug_case = debug_practice(DEBUG_GENERATORS)   # every DEBUG exercise's practice case (10.11-10.13)
