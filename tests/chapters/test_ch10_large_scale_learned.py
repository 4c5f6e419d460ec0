"""Chapter 10, part B graders (10.4-10.5, 10.9-10.10, 10.12-10.13, 10.17): the reference and the stand-ins pass;
every mutant fails and its hint fires.

Seeds are fixed; 10.9 uses two seeds per mutant (each grade runs two Adam alignments, ~2-5 s on the
loaded machine).
"""
from __future__ import annotations

import pytest

from graders.core.chapters import READY

if 10 not in {c.number for c in READY}:   # a planned chapter: its graders are work in progress, not yet held to the tests
    pytest.skip("chapter 10 is planned (ready=False in graders/core/chapters.py)", allow_module_level=True)

import grader_checks as checks
import numpy as np
from graders import ch10_large_scale as ch10
from graders import get
from mutants.ch10_large_scale_learned import MUTANTS
from solutions import ch10_large_scale as ref

IDS = ("10.4", "10.5", "10.9", "10.10", "10.12", "10.13", "10.17")
EXERCISES = {i: get(i) for i in IDS}
REFERENCE = {"10.9": ref.global_alignment, "10.10": ref.run_pipeline, "10.12": ref.choose_pipelines,
             "10.13": ref.chunked_poses, "10.17": ref.focal_from_pointmap,
             "10.4": [2 * 4 * 512 * 384, 50 * 49, 500, 4.0],
             "10.5": ["learned", "classical", "learned", "hybrid", "classical", "classical"]}
SEEDS = {"10.9": [0, 1], "10.10": [0, 1, 2], "10.12": [0, 1, 2], "10.13": [0, 1, 2], "10.17": [0, 1, 2]}
CODED = ("10.9", "10.10", "10.12", "10.13", "10.17")


@pytest.mark.parametrize("exercise_id", CODED)
def test_reference_gets_full_marks(exercise_id):
    for seed in SEEDS[exercise_id]:
        checks.assert_full_marks(EXERCISES[exercise_id], REFERENCE[exercise_id], seed)


@pytest.mark.parametrize("exercise_id", CODED)
def test_fallback_passes(exercise_id):
    checks.assert_fallback_passes(EXERCISES[exercise_id])


@pytest.mark.parametrize("exercise_id", ["10.4", "10.5"])
def test_value_hints_are_quiet_on_the_answer(exercise_id):
    checks.assert_value_hints_quiet(EXERCISES[exercise_id], REFERENCE[exercise_id])


@pytest.mark.parametrize("exercise_id, name, mutant, hint", MUTANTS, ids=[f"{m[0]}-{m[1]}" for m in MUTANTS])
def test_mutant_is_caught(exercise_id, name, mutant, hint):
    checks.assert_mutant_caught(EXERCISES[exercise_id], name, mutant, hint, SEEDS[exercise_id])


def test_every_code_exercise_has_mutants():
    checks.assert_enough_mutants({i: EXERCISES[i] for i in CODED}, MUTANTS)


def test_the_value_answers_are_the_solutions_package_s():
    assert REFERENCE["10.4"] == ref.pointmap_costs and REFERENCE["10.5"] == ref.pipeline_choices


def test_the_pose_model_refuses_more_views_than_it_holds():
    case = ch10.debug_case("10.13", seed=3)
    with pytest.raises(MemoryError):
        case["model"](list(range(case["max_views"] + 1)))
    out = case["model"](list(range(case["max_views"])))
    assert out["Rs"].shape == (case["max_views"], 3, 3)
    assert np.allclose(out["Rs"][0], np.eye(3)) and np.allclose(out["ts"][0], 0)   # the first view's frame


def test_out_of_domain_scenes_show_low_confidence_and_textureless_ones_lose_views():
    # The diagnosis 10.12 teaches rests on this: each failure is visible in the case, not only in the truth.
    for seed in range(5):
        case = ch10.debug_case("10.12", seed=seed)
        ratios = [np.median(s["learned"]["confidence"]) / case["indoor_confidence"] for s in case["scenes"]]
        lost = [not np.isfinite(s["classical"]["Rs"]).all() for s in case["scenes"]]
        assert min(ratios) < 0.3 and max(ratios) > 0.5 and any(lost)


def test_the_race_scores_both_routes_on_one_scene():
    # The experiment's two rows: with 120 keypoints a view classical SfM registers every view and is the more
    # accurate route; with 30 (textureless) too few are shared between views and it registers none, while the
    # pointmaps (the grader's alignment) place all six within 1 degree either way.
    for keypoints, registered in ((120, 6), (30, 0)):
        sc = ch10.race_scene(np.random.default_rng(7), n_views=6, keypoints=keypoints)
        res = ch10.race(sc, ch10.gt_global_alignment)
        assert res["classical"]["registered"] == registered and res["pointmaps"]["registered"] == 6
        assert res["pointmaps"]["rot_deg"] < 1.0
    sc = ch10.race_scene(np.random.default_rng(7), n_views=6, keypoints=120)
    res = ch10.race(sc, ch10.gt_global_alignment)
    assert res["classical"]["rot_deg"] < res["pointmaps"]["rot_deg"]
