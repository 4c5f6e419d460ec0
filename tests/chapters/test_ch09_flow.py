"""Chapter 9 beyond the contract suite (tests/chapters/test_contract.py, data in
tests/mutants/ch09_flow_contract.py): .flo bytes against OpenCV, 9.15's premise (joint tracking beats independent
tracking), 9.14's mask against the exactly known occlusion, and the DEBUG split of 9.17-9.20 (the right cause
with the colleague's unrepaired output earns the cause's half only).
"""
from __future__ import annotations

import numpy as np

from graders import ch09_flow as ch9
from solutions import ch09_flow as flow


def test_flo_round_trip_matches_opencv(tmp_path):
    # Our .flo bytes are what cv2.writeOpticalFlow writes, and cv2.readOpticalFlow reads them back.
    import cv2

    F = np.random.default_rng(0).normal(size=(7, 11, 2)).astype(np.float32)
    p = tmp_path / "f.flo"
    cv2.writeOpticalFlow(str(p), F)
    assert p.read_bytes() == flow.write_flo(F)
    assert np.array_equal(flow.read_flo(p.read_bytes()), F)


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


def test_the_right_cause_with_the_unrepaired_output_earns_the_cause_s_half_only():
    # ENGINE.md's DEBUG split: the named cause is half the points, the repair the other half. The colleague's own
    # output with the right cause earned 1.33-1.67 / 2 on 9.18-9.20 when the repair rows were several and some
    # of them held for the broken output too.
    from graders import grade
    from graders.core.engine import get
    from mutants.ch09_flow import drift_unchanged, motion_unchanged
    from mutants.ch09_flow_tracking import lost_unchanged, noisy_unsmoothed
    for exercise_id, unrepaired in [("9.17", drift_unchanged), ("9.18", motion_unchanged), ("9.19", lost_unchanged),
                                    ("9.20", noisy_unsmoothed)]:
        ex = get(exercise_id)
        result = grade(ex, unrepaired, seed=0)
        assert [row.passed for row in result.cases if row.key == "cause"] == [True], exercise_id
        assert result.score <= ex.points / 2 + 1e-9, (exercise_id, result.score)
