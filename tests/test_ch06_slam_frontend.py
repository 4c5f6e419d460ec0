"""Chapter 6 graders, front-end (6.12-6.17, 6.20): the reference, the evo/gtsam-backed versions and the
stand-ins pass; every mutant fails and names its hint. Core's exercises: tests/test_ch06_slam.py.

Seeds are fixed so a failure here is reproducible; the graders themselves draw fresh seeds for learners.
"""
from __future__ import annotations

import numpy as np
import pytest

import grader_checks as checks
from graders import chapter, datasets
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


def test_imu_truth_is_physical_and_schemes_converge_to_it():
    # The truth is the continuous motion's (not Forster's discrete model): its rotation is converged in the
    # number of substeps, and Forster's O(dt) scheme, as gtsam runs it, approaches it as dt shrinks.
    from graders.ch06_slam.imu import _delta_error

    w = ch6.imu_window(np.random.default_rng(3), noise=False)
    w_fine = ch6.imu_window(np.random.default_rng(3), noise=False, substeps=128)
    assert _delta_error(ch6.true_deltas(w_fine), ch6.true_deltas(w)) < 1e-7   # 1.1e-8 measured
    errors = []
    for n, dt in [(100, 0.005), (800, 0.000625)]:    # the same motion (same draws), sampled 8x faster
        w = ch6.imu_window(np.random.default_rng(3), n=n, dt=dt, noise=False)
        out = ch6.gtsam_deltas(w["omega_m"], w["acc_m"], w["dt"], w["b_g"], w["b_a"])
        errors.append(_delta_error(out, ch6.true_deltas(w)))
    assert errors[0] > 1e-3 and 5 < errors[0] / errors[1] < 12   # first order: ~8x smaller


def test_imu_truth_case_accepts_a_midpoint_scheme():
    # VINS-Mono's midpoint integration (Qin et al. 2018) is a legitimate scheme: it must score the truth case.
    from graders.ch06_slam.imu import _delta_error, cases_preintegrate
    from graders.geometry import so3_exp

    def midpoint(omega_m, acc_m, dt, b_g, b_a):
        dR, dv, dp = np.eye(3), np.zeros(3), np.zeros(3)
        for k in range(len(omega_m)):
            k1 = min(k + 1, len(omega_m) - 1)
            R1 = dR @ so3_exp(0.5 * (omega_m[k] + omega_m[k1] - 2 * b_g) * dt)
            a = 0.5 * (dR @ (acc_m[k] - b_a) + R1 @ (acc_m[k1] - b_a))
            dp, dv, dR = dp + dv * dt + 0.5 * a * dt ** 2, dv + a * dt, R1
        return dR, dv, dp

    for seed in SEEDS:
        case = next(iter(cases_preintegrate(np.random.default_rng(seed))))
        assert "truth" in case.tags
        assert _delta_error(midpoint(*case.args), case.expected) < case.tol / 100


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
