"""Chapter 8 — dense reconstruction, from scratch: every learner name of the notebook (instructor release).

numpy (vectorised cost volumes) and scipy (filters) for the geometry half; torch on CPU for the neural
half. Conventions (docs/CONVENTIONS.md): rectified pairs, disparity d = x_left - x_right >= 0 in
pixels, NaN where no disparity is reported; poses world-to-camera X_c = R X + t; depth is the camera
frame's Z.
"""
from __future__ import annotations

from .questions import *  # noqa: F401,F403 (8.1-8.3, 8.24)
from .questions import __all__ as _questions
from .debug import fill_holes_with_planes, fix_textureless_holes
from .fusion import fuse_depth_maps
from .mvs import bilinear, plane_homography, plane_sweep, sweep_volume
from .stereo import block_matching, census_volume, filter_speckles, sad_volume, sgm, sgm_stereo

__all__ = list(_questions) + ["block_matching", "census_volume", "filter_speckles", "sad_volume", "sgm", "sgm_stereo",
                              "bilinear", "plane_homography", "plane_sweep", "sweep_volume", "fuse_depth_maps",
                              "fill_holes_with_planes", "fix_textureless_holes"]

# neural (8.4-8.7, 8.12-8.16, 8.18-8.23)
from .nerf import positional_encoding, train_tiny_nerf, volume_render  # noqa: E402
__all__ += ["volume_render", "positional_encoding", "train_tiny_nerf"]
from .splat import project_gaussians, quat_to_R, rasterize  # noqa: E402
__all__ += ["project_gaussians", "quat_to_R", "rasterize"]
from .fit2d import fit_splats, render_splats_torch  # noqa: E402
__all__ += ["fit_splats", "render_splats_torch"]
from .neural_questions import *  # noqa: F401,F403,E402 (8.4-8.7, 8.22-8.23)
from .neural_questions import __all__ as _neural_questions  # noqa: E402
__all__ += list(_neural_questions)
from .neural_debug import fix_blurry_splats, fix_diverging_splats, fix_floaters  # noqa: E402
__all__ += ["fix_blurry_splats", "fix_diverging_splats", "fix_floaters"]
from .reflect import fix_reflections  # noqa: E402
__all__ += ["fix_reflections"]
from .fit3d import fit_gaussians_3d  # noqa: E402
__all__ += ["fit_gaussians_3d"]
