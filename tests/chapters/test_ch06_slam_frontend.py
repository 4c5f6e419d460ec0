"""Chapter 6 graders, front-end (6.12-6.17, 6.20): the reference, the evo/gtsam-backed versions and the
stand-ins pass; every mutant fails and names its hint. Core's exercises: tests/test_ch06_slam.py.

Seeds are fixed so a failure here is reproducible; the graders themselves draw fresh seeds for learners.
"""
from __future__ import annotations

import numpy as np
import pytest

import grader_checks as checks
from graders import chapter
from graders.kit import datasets
from graders import ch06_slam as ch6
from mutants.ch06_slam import MUTANTS
from solutions import ch06_slam as slam

SEEDS = [0, 1, 2]
FRONT_END = {"6.12", "6.13", "6.14", "6.15", "6.16", "6.17", "6.20"}
EXERCISES = {ex.id: ex for ex in chapter(6) if ex.id in FRONT_END}
FE_MUTANTS = [m for m in MUTANTS if m[0] in FRONT_END]

# Library-backed implementations: exercise id -> (function, cases it cannot answer and why).
LIBRARY = {
    "6.12": (ch6.evo_trajectory_errors, {}),
    "6.14": (ch6.scipy_bow_scores, {}),
    "6.17": (ch6.gtsam_preintegrate, {}),
}

needs_tum = pytest.mark.skipif(not datasets.available("trajectories"),
                               reason="TUM trajectories not available (python -m graders.datasets fetch trajectories)")


def reference(ex) -> object:
    return checks.reference(ex, (slam,))


@needs_tum
def test_evo_ape_figure_on_the_tum_pair():
    # `evo_ape tum freiburg1_xyz-groundtruth.txt freiburg1_xyz-rgbdslam.txt -a` (evo 1.38.1) prints
    # rmse 0.013470 m; the oracle and the reference both reproduce it.
    pair = ch6.load_tum_pair()
    assert abs(ch6.evo_trajectory_errors(**pair)[0] - 0.013470) < 5e-7
    assert abs(slam.trajectory_errors(**pair)[0] - 0.013470) < 5e-7


def test_association_matches_evo_on_a_gap():
    # evo's association keeps an estimate pose only if a ground-truth stamp lies within 0.01 s.
    from evo.core import sync

    pair = ch6.synthetic_pair(np.random.default_rng(5))
    ia, ib = slam.associate(pair["stamps_est"], pair["stamps_gt"])
    ea, eb = sync.matching_time_indices(pair["stamps_est"], pair["stamps_gt"], 0.01)
    assert list(ia) == list(ea) and list(ib) == list(eb)
    assert len(ia) < len(pair["stamps_est"])   # the planted gap drops some poses


def test_imu_truth_is_exact_for_zero_order_hold_data():
    # The synthetic windows are built so that Forster's discrete scheme is exact (the truth case's premise).
    w = ch6.imu_window(np.random.default_rng(3), noise=False)
    dR, dv, dp = ch6.gtsam_deltas(w["omega_m"], w["acc_m"], w["dt"], w["b_g"], w["b_a"])
    tR, tv, tp = ch6.true_deltas(w)
    assert np.abs(dR - tR).max() < 1e-12 and np.abs(dv - tv).max() < 1e-10 and np.abs(dp - tp).max() < 1e-10


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(EXERCISES))
def test_reference_gets_full_marks(exercise_id, seed):
    checks.assert_full_marks(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]), seed)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(LIBRARY))
def test_library_backed_implementation_passes(exercise_id, seed):
    fn, cannot = LIBRARY[exercise_id]
    checks.assert_library_passes(EXERCISES[exercise_id], fn, seed, cannot)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.fallback is not None])
def test_fallback_passes(exercise_id):
    checks.assert_fallback_passes(EXERCISES[exercise_id])


@pytest.mark.parametrize("exercise_id, name, mutant, hint", FE_MUTANTS, ids=[f"{m[0]}-{m[1]}" for m in FE_MUTANTS])
def test_mutant_is_caught(exercise_id, name, mutant, hint):
    checks.assert_mutant_caught(EXERCISES[exercise_id], name, mutant, hint, SEEDS)


def test_every_code_and_debug_exercise_has_mutants():
    checks.assert_enough_mutants(EXERCISES, FE_MUTANTS)
