"""Chapter 8 — dense reconstruction: exercise specifications, oracles and stand-ins, one module per section.

Oracles: the real Middlebury motorcycle pair with its ground-truth disparity (scikit-image's
`skimage.data.stereo_motorcycle()`), OpenCV's StereoBM / StereoSGBM on the same pairs, synthetic
rectified pairs with exact disparity, and multi-view scenes of textured planes rendered by
`graders.kit.scene` with exact depth (plane-sweep MVS and depth-map fusion are judged on it).

Geometry modules: `stereo` (8.8-8.9), `mvs` (8.10), `fusion` (8.11), `debug` (8.17), `questions` (8.1-8.3, 8.24); the
FRONTIER fit (8.25) in `fit3d`. Importing the package registers the
chapter; the names below are the API of the notebook, the tests and the benchmark.
"""
from __future__ import annotations

from . import debug, fusion, mvs, questions, stereo  # noqa: F401 (register 8.1-8.3, 8.8-8.11, 8.17, 8.24)
from .debug import CAUSES, broken_mvs, debug_case, debug_truth
from .fusion import fusion_problem, gt_fuse, on_surface
from .mvs import depth_accuracy, gt_plane_sweep, mvs_scene, sweep_costs, sweep_homography, sweep_region
from .stereo import (cost_volume, cv_block_matching, cv_sgbm, gt_block_matching, gt_sgm, judged_region, motorcycle,
                     motorcycle_crop, stereo_scores, synthetic_pair, wta_lr)

__all__: list[str] = ["CAUSES", "broken_mvs", "debug_case", "debug_truth", "fusion_problem", "gt_fuse", "on_surface", "depth_accuracy", "gt_plane_sweep", "mvs_scene", "sweep_costs", "sweep_homography",
                      "sweep_region", "cost_volume", "cv_block_matching", "cv_sgbm", "gt_block_matching", "gt_sgm", "judged_region",
                      "motorcycle", "motorcycle_crop", "stereo_scores", "synthetic_pair", "wta_lr"]

# neural (8.4-8.7, 8.12-8.16, 8.18-8.23)
from . import nerf  # noqa: F401,E402 (register 8.12)
from .nerf import analytic_render, gt_volume_render, ray_batch  # noqa: E402
__all__ += ["analytic_render", "gt_volume_render", "ray_batch"]
from . import splat  # noqa: F401,E402 (register 8.14)
from .splat import gaussian_scene, gt_project, gt_project_gaussians  # noqa: E402
__all__ += ["gaussian_scene", "gt_project", "gt_project_gaussians"]
from . import raster  # noqa: F401,E402 (register 8.15)
from .raster import brute_force_weights, gt_rasterize, splat_batch  # noqa: E402
__all__ += ["brute_force_weights", "gt_rasterize", "splat_batch"]
from . import fit2d  # noqa: F401,E402 (register 8.16)
from .fit2d import gt_fit_splats, initial_gaussians, psnr, render_splats, target_image  # noqa: E402
__all__ += ["gt_fit_splats", "initial_gaussians", "psnr", "render_splats", "target_image"]
from . import tiny_nerf  # noqa: F401,E402 (register 8.13)
from .tiny_nerf import gt_train_tiny_nerf, nerf_scene, render_field  # noqa: E402
__all__ += ["gt_train_tiny_nerf", "nerf_scene", "render_field"]
from . import neural_questions  # noqa: F401,E402 (register 8.4-8.7, 8.22-8.23)
from . import floaters  # noqa: F401,E402 (register 8.19)
from .floaters import debug_floaters, render_gaussians  # noqa: E402
from . import diverge, neural_debug  # noqa: F401,E402 (register 8.20, 8.21)
from .diverge import debug_diverging  # noqa: E402
from .neural_debug import debug_blurry, neural_debug_case  # noqa: E402
from . import reflect  # noqa: F401,E402 (register 8.18)
from .reflect import reflect_case, reflect_scene  # noqa: E402
__all__ += ["debug_blurry", "debug_diverging", "debug_floaters", "neural_debug_case", "render_gaussians", "reflect_case", "reflect_scene"]
from . import fit3d  # noqa: F401,E402 (register 8.25, the FRONTIER fit)
from .fit3d import render_gaussians_at, splat_fit_scene  # noqa: E402
__all__ += ["render_gaussians_at", "splat_fit_scene"]
