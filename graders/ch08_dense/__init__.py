"""Chapter 8 — dense reconstruction: exercise specifications, oracles and stand-ins, one module per section.

Oracles: the real Middlebury motorcycle pair with its ground-truth disparity (scikit-image's
`skimage.data.stereo_motorcycle()`), OpenCV's StereoBM / StereoSGBM on the same pairs, synthetic
rectified pairs with exact disparity, and multi-view scenes of textured planes rendered by
`graders.scene` with exact depth (plane-sweep MVS and depth-map fusion are judged on it).

Geometry modules: `questions` (8.1-8.3, 8.24). Importing the package registers the chapter; the
names below are the API of the notebook, the tests and the benchmark.
"""
from __future__ import annotations

from . import questions  # noqa: F401 (register 8.1-8.3, 8.24)

__all__: list[str] = []

# neural (8.4-8.7, 8.12-8.16, 8.18-8.23, 8.25)
