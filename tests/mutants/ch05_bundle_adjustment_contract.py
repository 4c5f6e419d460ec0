"""Chapter 5's contract data (tests/chapters/test_contract.py): the mutant catalogue and the implementations backed
by scipy, torch and pycolmap that must pass."""
from __future__ import annotations

from grader_checks import Library
from graders import ch05_bundle_adjustment as ch5
from graders.oracles.bundle_adjust import cv_bal_project
from mutants.ch05_bundle_adjustment import MUTANTS  # noqa: F401 (the contract's catalogue)

SEEDS = [0, 1, 2]

# `cannot`: documented limitations (case display name -> why), which may pass or fail.
LIBRARY = [
    Library("5.5", "gt_read_bal", ch5.gt_read_bal),
    Library("5.6", "gt_project", ch5.gt_project),
    Library("5.6", "OpenCV projectPoints", cv_bal_project),    # the release's stand-in (standins.TWINS)
    Library("5.7", "OpenCV projectPoints in an autograd Function", ch5.cv_torch_cost),   # standins.TWINS
    Library("5.8", "torch autograd", ch5.torch_jacobians),
    Library("5.8", "OpenCV projectPoints", ch5.cv_jacobians),    # the release's stand-in (standins.TWINS)
    Library("5.11", "scipy sparse LU", ch5.gt_schur_solve,
            {"30 cameras, 4,000 points (residual of the full system)":
             "a sparse LU of the full 12,000-unknown system is too slow to be useful"}),
    Library("5.12", "scipy cg", ch5.scipy_pcg),
    Library("5.14", "pycolmap", ch5.colmap_bundle_adjust,
            {"fix_gauge=True: camera 0 and the scale held, cost vs scipy":
             "COLMAP fixes the scale its own way (TWO_CAMS_FROM_WORLD)"}),
]
