"""Chapter 10 beyond the contract suite (tests/chapters/test_contract.py, data in
tests/mutants/ch10_large_scale_contract.py): the vocabulary tree's words and baseline, Sim(3) moving cameras with
the world, the broken capture of 10.11, the value answers, the pose model's memory limit, the domain gap of 10.12
and the classical-vs-pointmap race.
"""
from __future__ import annotations

import numpy as np
import pytest

from graders.core.chapters import READY

if 10 not in {c.number for c in READY}:   # a planned chapter: its graders are work in progress, not yet held to the tests
    pytest.skip("chapter 10 is planned (ready=False in graders/core/chapters.py)", allow_module_level=True)

from graders import ch10_large_scale as ch10
from solutions import ch10_large_scale as ref


def test_structured_words_are_recovered_by_hierarchical_kmeans():
    # The exact-score cases rest on this: the reference's tree finds the generator's words (up to labels).
    from solutions.ch10_large_scale.retrieval import _Tree

    P = ch10.structured_problem(np.random.default_rng(7), branching=3, depth=2)
    tree = _Tree.__new__(_Tree)
    tree.depth = 2
    tree.__init__(np.concatenate(P["db_descriptors"]), 3, 2, 0)
    found = np.concatenate([tree.quantise(D) for D in P["db_descriptors"]])
    true = np.concatenate(P["db_words"])
    pairs = set(zip(found.tolist(), true.tolist()))
    assert len(pairs) == len(set(found.tolist())) == len(set(true.tolist())) == 9


def test_the_vocabulary_tree_beats_nothing_and_brute_force_is_a_fair_baseline():
    # On the places renders brute-force matching reaches a useful mAP, and random scores do not.
    P = ch10.place_problem(np.random.default_rng(3))
    bf = ch10.mean_ap(ch10.brute_force_scores(P["db_descriptors"], P["query_descriptors"]), P["db_labels"],
                      P["query_labels"])
    rnd = ch10.mean_ap(np.random.default_rng(0).random((10, 30)), P["db_labels"], P["query_labels"])
    assert bf > 0.6 and rnd < 0.45


def test_apply_sim3_moves_cameras_with_the_world():
    # A camera's projection of a point is unchanged when both are mapped by the same similarity.
    from graders.kit.geometry import project
    P = ch10.merge_problem(np.random.default_rng(1), n_shared=8)
    rec = P["rec_b"]
    sim = P["sim_ba"]
    moved = ch10.apply_sim3(sim, rec)
    i, p = min(rec["cameras"]), min(rec["points"])
    c, cm = rec["cameras"][i], moved["cameras"][i]
    uv, _ = project(rec["points"][p][None], c["K"], c["R"], c["t"])
    uvm, _ = project(moved["points"][p][None], cm["K"], cm["R"], cm["t"])
    assert np.allclose(uv, uvm, atol=1e-9)


def test_broken_capture_falls_apart_and_the_fallback_joins_it():
    case = ch10.debug_case("10.11", seed=4)
    assert case["components_before"] > 10
    assert ch10.components_after(4, ch10.cv_fix_components(case)) <= 2


def test_the_value_answers_are_the_solutions_package_s():
    # the answers as the questions state them, against the solutions package the contract suite grades
    assert ref.pointmap_costs == [2 * 4 * 512 * 384, 50 * 49, 500, 4.0]
    assert ref.pipeline_choices == ["learned", "classical", "learned", "hybrid", "classical", "classical"]


def test_the_pose_model_refuses_more_views_than_it_holds():
    case = ch10.debug_case("10.13", seed=3)
    with pytest.raises(MemoryError):
        case["model"](list(range(case["max_views"] + 1)))
    out = case["model"](list(range(case["max_views"])))
    assert out["Rs"].shape == (case["max_views"], 3, 3)
    assert np.allclose(out["Rs"][0], np.eye(3)) and np.allclose(out["ts"][0], 0)   # the first view's frame


def test_out_of_domain_scenes_stay_confident_and_textureless_ones_lose_views():
    # What 10.12 teaches rests on this: a learned model out of its domain stays confident (DUSt3R's confidence
    # comes from its confidence-weighted loss, not an out-of-domain detector), so the case cannot be diagnosed from
    # the confidence; the classical route's failure (views left unregistered) is visible in the case.
    for seed in range(5):
        case = ch10.debug_case("10.12", seed=seed)
        ratios = [np.median(s["learned"]["confidence"]) / case["indoor_confidence"] for s in case["scenes"]]
        lost = [not np.isfinite(s["classical"]["Rs"]).all() for s in case["scenes"]]
        assert min(ratios) > 0.5 and any(lost), (seed, ratios)     # the old "out of domain" signal was < 0.3


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


def test_pipeline_load_reads_only_the_judges_images_never_through_a_link(tmp_path):
    """10.10's `load` stage runs in the judge in graded mode on a path the learner's code passes: only the images the
    judge saved, opened without following a link the learner may have put in their place."""
    import os
    images, _ = ch10.pipeline_images(np.random.default_rng(0))
    paths = ch10.save_images(images[:2], str(tmp_path))
    stages = ch10.PipelineStages(paths=tuple(paths))
    assert np.array_equal(stages.load(paths[1]), images[1])
    (tmp_path / "secret").write_text("root's secret")
    with pytest.raises(ValueError, match="not one of the pipeline's images"):
        stages.load(str(tmp_path / "secret"))
    os.remove(paths[0])
    os.symlink(tmp_path / "secret", paths[0])
    with pytest.raises(OSError):
        stages.load(paths[0])
