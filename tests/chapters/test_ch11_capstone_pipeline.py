"""Chapter 11, part B's pipeline: it runs the course's own stages (graders.oracles, one copy each), a clean run
is healthy, and each injected fault moves the metrics of the stage it hits (the fault x stage table).

Not skipped while chapter 11 is planned: the pipeline and graders/kit/corridor.py's faulted sequence are shared code
that CI should hold to this now. One seed, fixed (the table is deterministic for a seed: the images' noise
comes from it and OpenCV's RANSAC is seeded); the margins below were measured on seeds 0-3 (see each).
"""
from __future__ import annotations

import numpy as np
import pytest

from graders.kit import corridor, scene
from graders.ch11_capstone import pipeline as P
from graders.oracles import camera, features, flow, stereo, two_view

# Tests that use the fault table (a module-scoped fixture) run on one worker of a parallel run, so it is built once
# (conftest.py, ONE_WORKER).

SEED = 0


def test_the_stages_are_the_course_stand_ins_not_copies():
    assert P.STANDINS["track"] is flow.cv_pyramidal_lk
    assert P.STANDINS["essential"] is two_view.essential_ransac
    assert P.STANDINS["triangulate"] is two_view.triangulate
    assert P.STANDINS["pnp"] is two_view.pnp_ransac
    assert P.STANDINS["project"] is camera.cv_project
    assert P.STANDINS["stereo"] is stereo.cv_block_matching
    img = np.zeros((40, 40), np.uint8)
    img[10:30, 10:30] = 200
    assert np.array_equal(P.STANDINS["features"](img), features.cv_fast(img, 20, True))


def test_rig_sequence_depth_is_the_planes_depth():
    """render_corridor's affine inverse depth against scene.plane_depth (the exact ray-plane intersection)."""
    seq = corridor.rig_sequence(np.random.default_rng(SEED), 3)
    K, T = seq["K"], seq["T_cw"][2]
    d = np.full((seq["height"], seq["width"]), np.inf)
    for _, size, Rp, tp in corridor._CORRIDOR:
        Rp, tp = np.asarray(Rp, float).T, np.asarray(tp, float)
        d = np.minimum(d, scene.plane_depth(K, T[:3, :3] @ Rp, T[:3, :3] @ tp + T[:3, 3], size, seq["width"],
                                            seq["height"]))
    both = np.isfinite(d) & np.isfinite(seq["depth"][2])
    assert both.mean() > 0.75 and np.array_equal(np.isfinite(d), np.isfinite(seq["depth"][2]))
    assert np.abs(d[both] - seq["depth"][2][both]).max() < 1e-9     # the same closed form, float64


@pytest.fixture(scope="module")
def table():
    return P.fault_table(SEED)


def test_a_clean_run_is_healthy(table):
    c = table["clean"]
    # seeds 0-3: 2,370-2,380 FAST corners, coverage 0.90, row error 0.04 px, inliers 0.997-1.0, rotation
    # 0.02°/frame, translation 2.2 % of the step, reprojection 0.11 px, 5 % bad disparities, depth 1.4 % off
    assert c["features"] > 1000 and c["coverage"] > 0.8
    assert c["row_error_px"] < 0.2 and c["inlier_ratio"] > 0.95
    assert c["vo_rot_deg"] < 0.1 and c["vo_trans_pct"] < 5 and c["reprojection_px"] < 0.3
    assert c["stereo_bad_pct"] < 10 and c["depth_err_pct"] < 3


@pytest.mark.parametrize("kind, metric, factor", [
    ("exposure_drop", "features", 0.1),        # seeds 0-3: 96-102 corners of 2,370 (x0.04)
    ("motion_blur", "features", 0.3),          # 458-474 (x0.2)
    ("dirty_lens", "features", 0.9),           # x0.78
    ("saturated_sky", "coverage", 0.85),       # 0.90 -> 0.67
    ("calibration_drift", "stereo_matches", 0.6),   # matches off their row refused: 298 -> ~100
    ("exposure_drop", "landmarks", 0.5),       # 298 -> 95
])
def test_a_fault_lowers_its_stage_metric(table, kind, metric, factor):
    assert table[kind][metric] < factor * table["clean"][metric], (kind, metric, table[kind][metric])


@pytest.mark.parametrize("kind, metric, least", [
    ("calibration_drift", "row_error_px", 1.0),     # 2.26 px: the mount pitched by up to 1° (f = 288 px)
    ("calibration_drift", "stereo_bad_pct", 40.0),  # 81 %: block matching searches the wrong rows
    ("time_offset", "depth_err_pct", 10.0),         # 31 %: phantom obstacles (5 ms at 1.6°/frame of yaw)
    ("time_offset", "vo_trans_pct", 10.0),          # 22 % of the step: the scale comes from the bad depths
    ("dropped_frames", "vo_trans_pct", 50.0),       # ~100 %: a repeated frame reads as standing still
    ("dropped_frames", "vo_rot_deg", 0.5),          # 1.35°/frame
])
def test_a_fault_raises_its_stage_metric(table, kind, metric, least):
    assert table[kind][metric] > least > 2 * table["clean"][metric], (kind, metric, table[kind][metric])


def test_a_stage_swaps_for_the_learners(table):
    """A stage passed in replaces the stand-in: FAST at a higher threshold finds fewer corners, nothing else
    changes its signature."""
    seq = P.fault_sequence(SEED, None)
    r = P.run_pipeline(seq, {"features": lambda img: features.cv_fast(img, 40, True)}, P.WINDOW)
    a, b = P.WINDOW
    assert np.nanmedian(r["metrics"]["features"][a:b]) < table["clean"]["features"]
    assert np.isnan(r["metrics"]["features"][:a]).all()
    assert r["T_cw"].shape == (b, 4, 4)


def test_monitor_baselines_are_the_pipeline_s():
    # 11.15 (graders/ch11_capstone/design.py) states the clean row error's per-frame mean and sigma: they are the
    # pipeline's own, measured on fault_sequence(seed, None), seeds 0-2, frames 1-15 (45 frames): 0.0400 / 0.0048 px.
    # One seed here (15 frames, CI time): its mean within 0.005 px and sigma within a factor 2 cover seed-to-seed
    # spread (seeds 0-2 each: mean 0.0396-0.0404, sigma 0.0047-0.0050).
    from graders.ch11_capstone import design
    r = P.run_pipeline(P.fault_sequence(SEED, None), None, (1, P.WINDOW[1]))["metrics"]["row_error_px"][1:]
    assert abs(np.mean(r) - design.ROW_MEAN_PX) < 0.005
    assert design.ROW_SIGMA_PX / 2 < np.std(r, ddof=1) < 2 * design.ROW_SIGMA_PX


def test_the_widget_s_run_shows_the_cascade():
    # The notebook's widget (graders/ch11_capstone/demo.py): severity 1 is the fault table's strength; a dropped
    # frame shows first at VO (features, rows and RANSAC are those of the repeated frame: nothing upstream moves).
    from graders.ch11_capstone import demo
    for kind, params in P.FAULTS.items():
        assert demo.severity_params(kind, 1.0) == params or kind == "dirty_lens", kind
    r = demo.cascade_run("dropped_frames", 1.0, seed=SEED)
    assert r["first"] == "VO" and r["image"].dtype == np.uint8


# ------------------------------------------------ the DEBUG rows' proof: the fix applied, the metrics back in range

TRUE_FIX = {"11.9": np.array([[1, 0, 0], [0, np.cos(np.radians(1)), -np.sin(np.radians(1))],
                              [0, np.sin(np.radians(1)), np.cos(np.radians(1))]]),   # scene's pitch about x, 1°
            "11.10": 5.0,                                  # FAULTS["time_offset"]["ms"]
            "11.11": (0.3 * 320, 0.55 * 240, 0.25 * 320),  # scene's default smudge: centre (0.3 w, 0.55 h), r 0.25 w
            "11.12": int(0.45 * 240) + 3,                  # FAULTS["saturated_sky"]["rows"] x 240 + FAST's ring radius
            "11.13": (0.25, 9.0)}                          # proof.FIRMWARE
# A fix measured by a function (stand-in, reference) rather than known: 11.10's offset comes out 0.18-0.36 ms low on
# the route (seeds 0-5, stand-in and reference alike: the tracked velocities carry the tracker's noise, which flattens a
# fitted slope), and that residual leaves the depth error at up to 2.07 % against the clean runs' 1.41-1.53 % (seed 3).
# Held to 50 % above the clean run there; every other metric to the line.
ESTIMATED = {"11.10": {"depth_err_pct": 0.5}}


def _assert_proof(p, row, allow=None):
    from graders.ch11_capstone.proof import NOT_RESTORED
    assert p["out"]["faulty"], f"{row}: the fault moved no metric out of range"
    for name in p["out"]["fixed"]:
        if name in NOT_RESTORED.get(row, {}):
            continue
        c, x, margin = p["clean"][name], p["fixed"][name], (allow or {}).get(name)
        assert margin is not None and abs(x - c) <= margin * abs(c), (row, name, c, p["faulty"][name], x)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("row", list(TRUE_FIX))
def test_the_true_fix_brings_the_metrics_back(row, seed):
    from graders.ch11_capstone import proof
    _assert_proof(proof.prove_fix(row, TRUE_FIX[row], seed), row)


@pytest.mark.parametrize("row", list(TRUE_FIX))
def test_the_stand_in_s_diagnosis_on_the_faulted_run_fixes_it(row):
    # The stand-ins of 11.9-11.13 measure the fix on the faulted run itself (proof.debug_inputs), as the learner's
    # function does in the notebook; seed 1 (seed 0 is the notebook's).
    from graders import ch11_capstone as ch11
    from graders.ch11_capstone import proof
    fn = {"11.9": ch11.gt_fix_right_mount, "11.10": ch11.gt_sync_offset, "11.11": ch11.gt_smudge,
          "11.12": ch11.cv_sky_rows, "11.13": ch11.cv_exposure_change}[row]
    _assert_proof(proof.prove_fix(row, fn, 1), row, ESTIMATED.get(row))


def test_a_digital_gain_alone_does_not_undo_the_firmware_change():
    # The honest half of 11.13: x 1 / gain on today's images brings the corners back only partly and not the dense
    # stereo (the smear stays); rolling the settings back brings every metric back (the test above).
    from graders.ch11_capstone import proof
    p = proof.prove_fix("11.13", TRUE_FIX["11.13"], SEED, how="digital gain")
    assert {"features", "stereo_bad_pct", "stereo_density"} <= set(p["out"]["fixed"])
    assert set(p["out"]["fixed"]) <= set(proof.NOT_RESTORED["11.13 digital gain"])
    assert p["faulty"]["features"] < p["fixed"]["features"] < 0.75 * p["clean"]["features"]


def test_an_unfixed_or_wrong_fix_leaves_the_metrics_out():
    # The proof is not a formality: no repair (identity, 0 ms, no mask) leaves the fault's metrics out of range.
    from graders.ch11_capstone import proof
    for row, nothing in (("11.9", np.eye(3)), ("11.10", 0.0), ("11.12", 0)):
        p = proof.prove_fix(row, nothing, SEED)
        assert p["out"]["fixed"] == p["out"]["faulty"] != [], row


@pytest.mark.parametrize("row", list(TRUE_FIX))
def test_the_course_s_reference_passes_the_proof(row):
    # The solved notebook's tables: the references of 11.9-11.13 measure a fix on the faulted run that brings the
    # metrics back (11.9's holds yaw at 0: a yaw fitted to row noise, ~0.02°, took the depth error 1.4 -> 1.9-2.2 %).
    # Seed 3: the largest 11.10 residual of seeds 0-5.
    import solutions.ch11_capstone as ref
    from graders.ch11_capstone import proof
    fn = {"11.9": ref.fix_right_mount, "11.10": ref.sync_offset, "11.11": ref.find_smudge, "11.12": ref.sky_rows,
          "11.13": ref.exposure_change}[row]
    _assert_proof(proof.prove_fix(row, fn, 3), row, ESTIMATED.get(row))
