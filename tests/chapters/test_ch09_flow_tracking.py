"""Chapter 9 graders, part B (9.5-9.8, 9.14-9.16, 9.19-9.20, 9.24): the reference and the library-backed
versions pass; every mutant fails with its hint named.

Seeds are fixed so a failure here is reproducible; the graders draw fresh seeds for learners. Three seeds
per exercise: the hidden-case generators are random, and a grader that only works for a lucky draw is a bug.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

import grader_checks as checks
from graders import chapter, get
from graders import ch09_flow as ch9
from mutants.ch09_flow_tracking import MUTANTS
from solutions import ch09_flow as flow

SEEDS = [0, 1, 2]
PART_B = {"9.5", "9.6", "9.7", "9.8", "9.14", "9.15", "9.16", "9.19", "9.20", "9.24"}
EXERCISES = {ex.id: ex for ex in chapter(9) if ex.id in PART_B}


def reference(ex) -> object:
    return checks.reference(ex, (flow,))


def scipy_occlusion_mask(w_f, w_b, alpha=0.01, beta=0.5):
    """9.14 with scipy's bilinear interpolation (map_coordinates, order 1) in place of the course's."""
    H, W = w_f.shape[:2]
    y, x = np.mgrid[0:H, 0:W].astype(float)
    gx, gy = x + w_f[..., 0], y + w_f[..., 1]
    wb = np.stack([map_coordinates(w_b[..., c], [gy, gx], order=1, mode="nearest") for c in (0, 1)], -1)
    bad = np.sum((w_f + wb) ** 2, -1) >= alpha * (np.sum(w_f ** 2, -1) + np.sum(wb ** 2, -1)) + beta
    return bad | (gx < 0) | (gx > W - 1) | (gy < 0) | (gy > H - 1)


def scipy_scene_flow(D1, D2, flow, K):
    H, W = D1.shape
    y, x = np.mgrid[0:H, 0:W].astype(float)
    xs, ys = x + flow[..., 0], y + flow[..., 1]
    Z2 = map_coordinates(D2, [ys, xs], order=1, mode="nearest")
    Kinv = np.linalg.inv(K)
    P = lambda u, v, Z: Z[..., None] * (np.stack([u, v, np.ones_like(u)], -1) @ Kinv.T)
    return P(xs, ys, Z2) - P(x, y, D1)


def torch_grid_sample_lookup(corr, coords, radius):
    return ch9.gt_corr_lookup(corr, coords, radius)


# Library-backed implementations: exercise id -> (function, cases it cannot answer and why).
LIBRARY = {
    "9.14": (scipy_occlusion_mask, {}),
    "9.16": (scipy_scene_flow, {}),
    "9.24": (torch_grid_sample_lookup, {}),
}


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(EXERCISES))
def test_reference_gets_full_marks(exercise_id, seed):
    checks.assert_full_marks(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]), seed)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(LIBRARY))
def test_library_backed_implementation_passes(exercise_id, seed):
    fn, cannot = LIBRARY[exercise_id]
    checks.assert_library_passes(get(exercise_id), fn, seed, cannot)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.fallback is not None])
def test_fallback_passes(exercise_id):
    checks.assert_fallback_passes(EXERCISES[exercise_id])


@pytest.mark.parametrize("exercise_id, name, mutant, hint", MUTANTS, ids=[f"{m[0]}-{m[1]}" for m in MUTANTS])
def test_mutant_is_caught(exercise_id, name, mutant, hint):
    checks.assert_mutant_caught(EXERCISES[exercise_id], name, mutant, hint, SEEDS)


def test_every_code_and_debug_exercise_has_mutants():
    checks.assert_enough_mutants(EXERCISES, MUTANTS)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.value])
def test_value_hints_are_quiet_on_the_answer(exercise_id):
    checks.assert_value_hints_quiet(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]))


def test_joint_tracking_beats_independent_tracking():
    # 9.15's premise on fixed draws: carrying hidden points keeps them within a few px, the matcher alone does not.
    for seed in range(3):
        seq = ch9.tracking_sequence(np.random.default_rng(seed))
        args = (seq["query"], seq["obs"], seq["score"], seq["group"])
        joint = ch9.occluded_error(ch9.gt_joint_tracker(*args)[0], seq["tracks"], seq["visible"])
        alone = ch9.occluded_error(ch9.independent_tracker(*args)[0], seq["tracks"], seq["visible"])
        assert joint < 2.0 < 15.0 < alone


def test_true_occlusion_is_what_the_check_finds():
    # 9.14's mask on exact flows overlaps the exactly known occlusion (IoU > 0.8; only the 1-px bilinear band
    # along the patch's edge differs).
    for seed in range(3):
        d = ch9.occlusion_pair(np.random.default_rng(seed))
        m = ch9.gt_occlusion_mask(d["w_f"], d["w_b"])
        assert (m & d["occluded"]).sum() / (m | d["occluded"]).sum() > 0.8
