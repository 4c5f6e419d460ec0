"""Chapter 11 beyond the contract suite (tests/chapters/test_contract.py, data in
tests/mutants/ch11_capstone_contract.py): every exercise registered, the lesson's cascade figures, and the
generated cases are what their docstrings say.
"""
from __future__ import annotations

import numpy as np
import pytest

from graders.core.chapters import READY

if 11 not in {c.number for c in READY}:   # a planned chapter: its graders are work in progress, not yet held to the tests
    pytest.skip("chapter 11 is planned (ready=False in graders/core/chapters.py)", allow_module_level=True)

from graders import chapter
from graders import ch11_capstone as ch11

PART_A = ("11.1", "11.2", "11.3", "11.4", "11.5", "11.6", "11.7")
PART_B = ("11.8", "11.9", "11.10", "11.11", "11.12", "11.13", "11.14", "11.15", "11.16", "11.17")   # + budget, monitor, actions, frontier
EXERCISES = {ex.id: ex for ex in chapter(11) if ex.id in PART_A + PART_B}


def test_built_exercises_are_registered():
    assert set(EXERCISES) == set(PART_A + PART_B) == {ex.id for ex in chapter(11)}


def test_cascade_figures_match_the_lesson():
    # The lesson: "a 1 px calibration error can reduce matching quality by 20-30 %"; its worked example of the
    # propagation rule: Z = 5 m, f = 800, B = 0.2 m, 2 px -> 0.31 m; its rig: "22.2 MB/frame = 666 MB/s".
    from graders.ch11_capstone import questions as q
    assert 0.20 <= 1 - q.W_AFTER / q.W_BEFORE <= 0.30
    assert round(q.PROPAGATION[0], 2) == 0.31
    assert abs(q.DATA_FLOW[1] / 666 - 1) < 0.005 and q.DATA_FLOW[1] < 666   # the lesson rounds up, by 0.4 %
    assert q.CASCADE[3] > 5 * q.CASCADE[2]                                  # a 21 % loss, a 7x cost


@pytest.mark.parametrize("seed", range(5))
def test_streams_hold_every_episode_in_every_metric(seed):
    # Each metric column goes past its alert threshold (spikes, faults) and returns to normal; every case's
    # stream raises and clears at least one alert per metric, so each mutant has something to get wrong.
    rng = np.random.default_rng(seed)
    stream = ch11.metric_streams(rng, 3)
    events = ch11.gt_health_monitor(stream, ch11.MONITOR_TABLE, 3)
    for row in ch11.MONITOR_TABLE:
        actions = [a for _, m, a in events if m == row["metric"]]
        assert row["action"] in actions and "clear" in actions, row["metric"]
        assert actions.count("clear") == actions.count(row["action"])     # every alert clears by the end


@pytest.mark.parametrize("seed", range(5))
def test_fault_scenarios_visit_the_ladder(seed):
    # The four scenarios leave stereo VIO and come back; "everything fails" reaches dead reckoning, the sync
    # cable case reaches mono + IMU (not direct VO, which needs stereo).
    rng = np.random.default_rng(seed)
    seen = {}
    for kind in ("dirty lens", "loose sync cable", "IMU dropout in the dark", "everything fails"):
        d = ch11.fault_scenario(rng, kind)
        modes = ch11.gt_degradation_modes(d["alerts"], d["names"], d["hold"])
        assert modes[0] == modes[-1] == "stereo VIO", kind
        seen[kind] = set(modes)
    assert "direct VO" in seen["dirty lens"] and "mono + IMU" in seen["loose sync cable"]
    assert "dead reckoning" in seen["everything fails"]


@pytest.mark.parametrize("seed", range(5))
def test_staggered_recovery_climbs_and_falls_past_a_shortcut(seed):
    # The rule climbs from dead reckoning to direct VO while stereo VIO is back for fewer than `hold` frames, and
    # falls from mono + IMU to direct VO (better than the mode that failed): the two shortcuts of 11.6's mutants.
    d = ch11.fault_scenario(np.random.default_rng(seed), "staggered recovery", hold=9)
    modes = ch11.gt_degradation_modes(d["alerts"], d["names"], d["hold"])
    steps = {(a, b) for a, b in zip(modes, modes[1:]) if a != b}
    assert {("dead reckoning", "direct VO"), ("mono + IMU", "direct VO")} <= steps, steps
    assert modes[0] == modes[-1] == "stereo VIO"


@pytest.mark.parametrize("seed", range(5))
def test_fault_runs_amplify_downstream(seed):
    # A calibration fault: the largest deviation (in baseline sigmas) is downstream of it, the rule's answer is it.
    d = ch11.fault_run(np.random.default_rng(seed), "calibration")
    z = {s: np.max(np.abs((d["observed"][s] - d["baseline"][s].mean(0)) / d["baseline"][s].std(0, ddof=1)))
         for s in d["stages"]}
    assert max(z, key=z.get) != "calibration"
    assert ch11.gt_first_faulty_stage(d["stages"], d["observed"], d["baseline"]) == "calibration"


def test_a_memoised_draw_is_the_fresh_draw_and_cannot_be_poisoned():
    # graders/ch11_capstone/draws.py: 11.11's and 11.13's problems are drawn once per rng state and process; a hit
    # must equal a fresh draw, leave the rng where the fresh draw leaves it, and hand out a copy.
    from graders.core.memo import memo_draw

    @memo_draw(maxsize=2)
    def problem(rng, n=3):
        return {"x": rng.normal(size=n), "k": int(rng.integers(10))}

    first_rng, again_rng = np.random.default_rng(7), np.random.default_rng(7)
    first = problem(first_rng)
    first["x"][:] = 1e9                                   # a caller that edits its problem in place
    again = problem(again_rng)
    fresh_rng = np.random.default_rng(7)
    fresh = problem.__wrapped__(fresh_rng)
    assert np.array_equal(again["x"], fresh["x"]) and again["k"] == fresh["k"]
    assert again_rng.random() == fresh_rng.random()       # the rng moved on exactly as a fresh draw moves it
    assert len(problem.cache) == 1


def test_a_raw_scale_fit_loses_points_on_the_seeds_it_once_passed():
    # 11.17: before stream 4 (the counts spread 3x wider) a fit on the raw counts and ratios kept full marks on
    # seeds 60, 71, 157, 169, 207, 253 and 280 of 0-499 (streams 1-3 differ from the rule by < 2 % of the frames
    # there). The wide stream refuses it, and says why.
    import grader_checks as checks
    from mutants.ch11_capstone_frontier import flags_no_log
    checks.assert_mutant_caught(EXERCISES["11.17"], "no log", flags_no_log, "use the log",
                                [60, 71, 157, 169, 207, 253, 280])
