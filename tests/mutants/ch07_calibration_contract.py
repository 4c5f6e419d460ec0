"""Chapter 7's contract data (tests/chapters/test_contract.py): the mutant catalogue and the OpenCV-backed
implementations (named by their functions in graders.ch07_calibration) that must pass every case, and
another published method (Fusiello's rectification) that must pass too."""
from __future__ import annotations

from grader_checks import Library
from graders import ch07_calibration as ch7
from mutants.ch07_calibration import MUTANTS  # noqa: F401 (the contract's catalogue)

SEEDS = [0, 1, 2]

LIBRARY = [Library("7.5", "gt_homography", ch7.gt_homography),
           Library("7.8", "cv_refine_calibration", ch7.cv_refine_calibration),
           Library("7.9", "cv_stereo_extrinsics", ch7.cv_stereo_extrinsics),
           Library("7.10", "cv_stereo_rectify", ch7.cv_stereo_rectify),
           # Fusiello, Trucco & Verri (MVA 2000): another valid rectification, 0.01-1.3° from OpenCV's R1.
           Library("7.10", "fusiello_rectify", ch7.fusiello_rectify),
           Library("7.21", "cv_fix_mount_shift", ch7.cv_fix_mount_shift)]
