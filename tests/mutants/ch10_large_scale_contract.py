"""Chapter 10's contract data (tests/chapters/test_contract.py): the whole chapter's mutant catalogue (part A's in
mutants/ch10_large_scale.py, part B's in mutants/ch10_large_scale_learned.py), its seeds, and the library-backed
implementations that must pass."""
from __future__ import annotations

from grader_checks import Library
from graders import ch10_large_scale as ch10
from mutants.ch10_large_scale import MUTANTS as _PART_A
from mutants.ch10_large_scale_learned import MUTANTS as _PART_B

SEEDS = [0, 1, 2]
SEEDS_FOR = {"10.9": [0, 1],     # each grade runs two Adam alignments (~2-5 s on a loaded machine): two seeds
             "10.10": [0, 1]}   # each grade runs the pipeline four times (each starts and stops a LocalCluster)
MUTANTS = _PART_A + _PART_B

# `cannot`: documented limitations (case display name -> why), which may pass or fail.
LIBRARY = [
    Library("10.6", "cv2.kmeans tree", ch10.cv_vocab_tree_retrieve),      # cv2.kmeans (k-means++) per node
    # pycolmap.estimate_sim3d_robust returns None on exactly coplanar landmarks (degenerate for its solver).
    Library("10.7", "pycolmap", ch10.cv_sim3_ransac, {"6 exact pairs on a façade: rotation": "pycolmap refuses coplanar sets",
                                                      "6 exact pairs on a façade: scale": "pycolmap refuses coplanar sets"}),
]
