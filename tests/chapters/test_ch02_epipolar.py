"""Chapter 2 graders: the reference and the OpenCV/kornia/pycolmap-backed versions pass; every mutant fails.

Seeds are fixed so a failure here is reproducible; the graders themselves draw fresh seeds for
learners. Three seeds per exercise: the hidden-case generators are random, and a grader that only
works for a lucky draw is a bug. Also tests the two helpers this chapter added to graders.core.compare
(`sampson_rms_px`, `unordered`) and the engine's `Case.call` hook.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

import kornia.geometry.epipolar as KE
import kornia.geometry.homography as KH
import grader_checks as checks
import solutions.ch02_epipolar as ref
from graders import ch02_epipolar as ch2
from graders import chapter, get, grade
from graders.core.compare import rotation_angle_deg, sampson_rms_px, unordered, up_to_scale
from graders.core.engine import Case, Exercise
from mutants.ch02_epipolar import MUTANTS

SEEDS = [0, 1, 2]
EXERCISES = {ex.id: ex for ex in chapter(2)}


def reference(ex) -> object:
    return checks.reference(ex, (ref,))


# ----------------------------------------------------------------- library-backed implementations

def _t(a):
    return torch.as_tensor(np.asarray(a, float))[None]


def kornia_skew(v):
    return KE.cross_product_matrix(torch.as_tensor(np.asarray(v, float)))[None][0].numpy()


def kornia_essential(R, t):  # kornia takes two absolute poses; camera 1 = (I, 0)
    return KE.essential_from_Rt(_t(np.eye(3)), _t(np.zeros((3, 1))), _t(R), _t(np.reshape(t, (3, 1))))[0].numpy()


def kornia_fundamental(E, K1, K2):
    return KE.fundamental_from_essential(_t(E), _t(K1), _t(K2))[0].numpy()


def kornia_lines(F, x1):
    return KE.compute_correspond_epilines(_t(x1), _t(F))[0].numpy()


def kornia_sampson(F, x1, x2):
    return KE.sampson_epipolar_distance(_t(x1), _t(x2), _t(F), squared=False, eps=0.0)[0].numpy()


def kornia_eight_point(x1, x2):
    return KE.find_fundamental(_t(x1), _t(x2), method="8POINT")[0].numpy()


def kornia_seven_point(x1, x2):
    return [F for F in KE.find_fundamental(_t(x1), _t(x2), method="7POINT")[0].numpy() if np.abs(F).max() > 0]


def kornia_five_point(x1, x2):
    """kornia's find_essential pads to 10 candidates: keep the distinct real essential matrices
    through the five points."""
    keep = []
    for E in KE.find_essential(_t(x1), _t(x2))[0].numpy():
        if not np.isfinite(E).all() or np.linalg.norm(E) == 0:
            continue
        E = E / np.linalg.norm(E)
        if sampson_rms_px(E, x1, x2) > 1e-6 or any(up_to_scale(E, k) < 1e-6 for k in keep):
            continue
        keep.append(E)
    return keep


def kornia_decompose(E):
    R1, R2, t = (a[0].numpy() for a in KE.decompose_essential_matrix(_t(E)))
    t = t.ravel() / np.linalg.norm(t)
    return [(R1, t), (R1, -t), (R2, t), (R2, -t)]


def kornia_recover_pose(E, x1, x2):
    R, t, _, _ = KE.motion_from_essential_choose_solution(_t(E), _t(np.eye(3)), _t(np.eye(3)), _t(x1), _t(x2))
    t = t[0].numpy().ravel()
    return R[0].numpy(), t / np.linalg.norm(t)


def kornia_homography(x1, x2):
    return KH.find_homography_dlt(_t(x1), _t(x2))[0].numpy()


def kornia_weighted(x1, x2, w):
    return KE.find_fundamental(_t(x1), _t(x2), weights=_t(w), method="8POINT")[0].numpy()


def kornia_unweighted_normalisation(x1, x2, w):
    """The weighted 8-point as upstream kornia's `run_8point` builds it: Hartley's transform of all the
    matches (kornia's `normalize_points` without weights), only Aᵀ diag(w) A weighted, then rank 2."""
    (n1, T1), (n2, T2) = (tuple(a[0].numpy() for a in KE.normalize_points(_t(x))) for x in (x1, x2))
    h1, h2 = np.c_[n1, np.ones(len(n1))], np.c_[n2, np.ones(len(n2))]
    A = (h2[:, :, None] * h1[:, None, :]).reshape(-1, 9)
    F = np.linalg.eigh(A.T @ (np.asarray(w, float)[:, None] * A))[1][:, 0].reshape(3, 3)
    U, S, Vt = np.linalg.svd(F)
    return T2.T @ (U @ np.diag([S[0], S[1], 0.0]) @ Vt) @ T1


# exercise id -> [(name, function)]
LIBRARY = {
    "2.5": [("kornia", kornia_skew)],
    "2.6": [("kornia", kornia_essential)],
    "2.7": [("kornia", kornia_fundamental)],
    "2.8": [("kornia", kornia_lines)],
    "2.9": [("OpenCV", ch2.cv_sampson), ("kornia", kornia_sampson)],
    "2.10": [("OpenCV", ch2.cv_eight_point), ("kornia", kornia_eight_point)],
    "2.11": [("OpenCV", ch2.cv_seven_point), ("kornia", kornia_seven_point)],
    "2.12": [("OpenCV", ch2.cv_five_point), ("kornia", kornia_five_point)],
    "2.13": [("OpenCV", ch2.cv_decompose_essential), ("kornia", kornia_decompose)],
    "2.14": [("OpenCV", ch2.cv_recover_pose), ("kornia", kornia_recover_pose)],
    "2.15": [("OpenCV", ch2.cv_homography), ("kornia", kornia_homography)],
    "2.17": [("OpenCV", ch2.cv_fix_garbage_F)],
    "2.18": [("OpenCV", ch2.cv_fix_planar_scene)],
    "2.19": [("OpenCV", ch2.cv_fix_matcher)],
    "2.20": [("OpenCV", ch2.cv_fix_cheirality)],
    "2.25": [("kornia", kornia_weighted), ("kornia-unweighted-normalisation", kornia_unweighted_normalisation)],
}
LIBRARY_CASES = [(i, name, fn) for i, impls in LIBRARY.items() for name, fn in impls]


# ----------------------------------------------------------------- the graders

@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(EXERCISES))
def test_reference_gets_full_marks(exercise_id, seed):
    checks.assert_full_marks(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]), seed)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id, library, fn", LIBRARY_CASES, ids=[f"{i}-{n}" for i, n, _ in LIBRARY_CASES])
def test_library_backed_implementation_passes(exercise_id, library, fn, seed):
    checks.assert_library_passes(get(exercise_id), fn, seed)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.fallback is not None])
def test_fallback_passes(exercise_id):
    checks.assert_fallback_passes(EXERCISES[exercise_id])


@pytest.mark.parametrize("exercise_id, name, mutant, hint", MUTANTS, ids=[f"{m[0]}-{m[1]}" for m in MUTANTS])
def test_mutant_is_caught(exercise_id, name, mutant, hint):
    checks.assert_mutant_caught(EXERCISES[exercise_id], name, mutant, hint, SEEDS)


def test_every_code_debug_and_frontier_exercise_has_mutants():
    checks.assert_enough_mutants(EXERCISES, MUTANTS)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.value])
def test_value_hints_are_quiet_on_the_answer(exercise_id):
    checks.assert_value_hints_quiet(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]))


def test_seed_table_slips_are_recognised():
    # The seed's RANSAC table prints k = 435 for w = 0.4, s = 5; the grader names the slip.
    result = grade(EXERCISES["2.4"], 435.0, seed=0)
    assert not result.passed and "mis-print" in result.cases[0].hint


def test_model_choice_accepts_lowercase_and_rejects_bad_letters():
    ex = EXERCISES["2.23"]
    assert grade(ex, ["e", "f", "h", "h", "e", "f"], seed=0).passed
    assert grade(ex, ["E", "F", "H", "F", "E", "F"], seed=0).cases[0].hint.startswith("(d)")
    assert "each" in grade(ex, ["E", "X", "H", "H", "E", "F"], seed=0).cases[0].message


# ----------------------------------------------------------------- oracles agree with each other

def test_opencv_and_kornia_sampson_agree_with_the_ground_truth():
    s = ch2.two_view(np.random.default_rng(5), 50, noise=2.0, outliers=0.2, held_out=1)
    gt = ch2.gt_sampson(s["F"], s["x1"], s["x2"])
    assert np.abs(ch2.cv_sampson(s["F"], s["x1"], s["x2"]) - gt).max() < 1e-9
    assert np.abs(kornia_sampson(s["F"], s["x1"], s["x2"]) - gt).max() < 1e-6
    assert abs(sampson_rms_px(s["F"], s["x1"], s["x2"]) - np.sqrt(np.mean(gt ** 2))) < 1e-12


def test_five_point_oracle_contains_the_true_essential_matrix():
    for seed in range(5):
        s = ch2.two_view(np.random.default_rng(seed), 5, held_out=1)
        sols = ch2.cv_five_point(ch2.to_normalised(s["x1"], s["K1"]), ch2.to_normalised(s["x2"], s["K2"]))
        assert min(up_to_scale(E, s["E"]) for E in sols) < 1e-8


def test_scene_geometry_is_consistent():
    rng = np.random.default_rng(7)
    for kw in [{}, {"motion": "forward"}, {"motion": "sideways"}, {"planar": True}]:
        s = ch2.two_view(rng, 100, **kw)
        assert sampson_rms_px(s["F"], s["x1_true"], s["x2_true"]) < 1e-9
        assert sampson_rms_px(s["F"], *s["held_out"]) < 1e-9
        if kw.get("planar"):
            assert np.abs(ch2.transfer_px(s["H"], s["x1_true"], s["x2_true"])).max() < 1e-8
    s = ch2.two_view(rng, 100, motion="rotation")
    assert np.abs(ch2.transfer_px(s["H"], s["x1_true"], s["x2_true"])).max() < 1e-8


def test_pycolmap_meets_the_ransac_tolerances():
    # The E cases' tolerance is max(0.15°, 3 x pycolmap's error); pycolmap itself must be inside it
    # on scenes like the graded ones, and so must OpenCV's USAC_MAGSAC.
    import cv2
    for seed in SEEDS:
        s = ch2.two_view(np.random.default_rng(100 + seed), 300, noise=0.5, outliers=0.3, same_K=True, held_out=1)
        col = ch2.colmap_essential(s)
        assert col["err_colmap"] < 0.15
        E, mask = cv2.findEssentialMat(s["x1"], s["x2"], s["K1"], cv2.USAC_MAGSAC, 0.999, 1.0)
        inl = mask.ravel().astype(bool)
        n1, n2 = ch2.to_normalised(s["x1"], s["K1"]), ch2.to_normalised(s["x2"], s["K2"])
        R, _ = ch2.cv_recover_pose(E[:3], n1[inl], n2[inl])
        assert rotation_angle_deg(R, s["R"]) < max(0.15, 3 * col["err_colmap"])


def test_debug_symptoms_are_real():
    # Each DEBUG case must show its symptom with the colleague's code, on the case learners get.
    case = ch2.debug_case("2.17", seed=0)
    assert ch2.condition_number(case["x1"], case["x2"]) > 1e5 > 1e3 > ch2.condition_number(case["x1"], case["x2"], True)
    _, truth = ch2.debug_garbage_F(np.random.default_rng(0))
    bad = sampson_rms_px(ch2.broken_eight_point(case["x1"], case["x2"]), *truth["held_out"])
    good = sampson_rms_px(ch2.cv_eight_point(case["x1"], case["x2"]), *truth["held_out"])
    assert bad > 5 * good
    case = ch2.debug_case("2.19", seed=0)
    m = ch2.brute_force_matches(case["desc1"], case["desc2"])
    _, truth = ch2.debug_matcher(np.random.default_rng(0))
    assert np.mean(truth["match"][m[:, 0]] == m[:, 1]) < 0.3   # the seed's "< 30 % inliers"
    case, truth = ch2.debug_cheirality(np.random.default_rng(0))
    assert rotation_angle_deg(case["R_bad"], truth["R"]) > 90 or case["t_bad"] @ truth["t"] < 0


def test_graf_matches_real_data():
    real = ch2.graf_matches()
    if real is None:
        pytest.skip("the homography dataset is not available (python -m graders.datasets fetch homography)")
    x1, x3, ratio, H = real
    inlier = ch2.transfer_px(H, x1, x3) < 3
    assert inlier.mean() < 0.3 < inlier[ratio < 0.8].mean()   # brute force < 30 % inliers; ratio test fixes it


# ----------------------------------------------------------------- engine additions

def test_unordered_matches_regardless_of_order_and_sign():
    A = [np.eye(3), np.diag([1.0, 2.0, 3.0]), np.ones((3, 3))]
    B = [2 * np.ones((3, 3)), -np.eye(3), 0.5 * np.diag([1.0, 2.0, 3.0])]
    assert unordered(A, B, up_to_scale) < 1e-12
    assert unordered(A, A[:2] + [np.eye(3)], up_to_scale) > 0.1   # a duplicate cannot stand in for a root
    with pytest.raises(ValueError):
        unordered(A, B[:2], up_to_scale)
    assert unordered([], [], up_to_scale) == 0.0


def test_sampson_rms_is_scale_and_sign_free():
    s = ch2.two_view(np.random.default_rng(3), 40, noise=1.0, held_out=1)
    e = sampson_rms_px(s["F"], s["x1"], s["x2"])
    assert 0.3 < e < 3 and abs(sampson_rms_px(-7.5 * s["F"], s["x1"], s["x2"]) - e) < 1e-12


def test_case_call_runs_inside_the_sandbox():
    calls = []
    ex = Exercise(id="0.1", title="call hook", name="f", kind="code", points=1, cases=lambda rng: [
        Case("double inside the grader", (), 6.0, lambda a, b: abs(a - b), 1e-9, call=lambda fn: 2 * fn(3.0)),
        Case("plain", (2.0,), 2.0, lambda a, b: abs(a - b), 1e-9)])
    result = grade(ex, lambda x: calls.append(x) or x, seed=0)
    assert result.passed and calls == [3.0, 2.0]
    failing = grade(ex, lambda x: 1 / 0, seed=0)
    assert "ZeroDivisionError" in failing.cases[0].message


def test_ransac_sample_counter_sees_every_sample():
    rng = np.random.default_rng(0)
    pts = np.c_[np.linspace(0, 100, 50), np.linspace(0, 50, 50)] + rng.normal(0, 0.1, (50, 2))
    problem = ch2.line_problem(pts)
    (model, inliers), samples = ch2.run_ransac(ref.ransac, problem)
    assert inliers.all() and 1 <= samples <= 64


# ------------------------------------------------------------ section 5: OpenCV's USAC estimators (ungraded)

def test_usac_comparison_table_is_well_formed():
    rows = ch2.usac_comparison(ch2.gt_ransac, outliers=(0.1, 0.3), noise=(0.5,), n=200)
    methods = list(ch2.USAC_METHODS) + ["LO-RANSAC (2.16)"]
    assert [r["method"] for r in rows] == methods * 2
    assert all(set(r) == set(ch2.demo.COLUMNS) for r in rows)
    for r in rows:
        assert 0.0 <= r["precision"] <= 1.0 and 0.0 <= r["recall"] <= 1.0 and r["ms"] >= 0.0
        assert np.isfinite(r["rms_px"])
    text = ch2.usac_table(rows)
    assert all(m in text for m in methods) and "10% outliers" in text and "30% outliers" in text
    # 10 % wrong matches, 0.5 px noise, τ = 1 px: every estimator with local optimisation (USAC's and
    # the chapter's LO-RANSAC) predicts held-out matches within 0.4 px (0.08-0.22 px over 12 draws).
    lo = [r for r in rows if r["outliers"] == 0.1 and r["method"] not in ("RANSAC", "LMedS")]
    assert all(r["rms_px"] < 0.4 for r in lo), lo


def test_usac_comparison_shows_what_the_notebook_says():
    # The notebook's scenes (seed 0), OpenCV only (its estimators are deterministic for a given input).
    rows = ch2.usac_comparison(None)
    cell = {(r["method"], r["outliers"], r["noise_px"]): r for r in rows}
    for sigma in (0.5, 1.5):
        # MAGSAC++ beats plain RANSAC at 30-50 % wrong matches: its held-out error is at most 0.59 x
        # RANSAC's in all 12 draws tried (0.50 and 0.35 x on the notebook's scenes); 0.7 x bound.
        for o in (0.3, 0.5):
            assert cell[("USAC_MAGSAC", o, sigma)]["rms_px"] < 0.7 * cell[("RANSAC", o, sigma)]["rms_px"]
        # LMedS breaks down beyond 50 % wrong matches: at 70 % its mask keeps about every match
        # (precision 0.30-0.36, the inlier share, over 24 draws) and its F is 5-100 px off.
        lmeds = cell[("LMedS", 0.7, sigma)]
        assert lmeds["precision"] < 0.5 and lmeds["rms_px"] > 3.0
    # τ = 1 px set for 0.5 px noise while the noise is 1.5 px: MAGSAC++ (marginalised over σ) has the
    # lowest held-out error at 30 % wrong matches (in 12 of 12 draws tried).
    at = {m: cell[(m, 0.3, 1.5)]["rms_px"] for m in ch2.USAC_METHODS}
    assert min(at, key=at.get) == "USAC_MAGSAC", at
