"""11.6 — graceful degradation: the odometry mode, frame by frame, from the monitor's alerts.

Modes, best first, and what each needs healthy (the lesson's ladder, made explicit):

    stereo VIO      features, stereo, imu
    direct VO       stereo               (photometric stereo odometry: no features, no IMU)
    mono + IMU      features, imu        (metric scale from the IMU, no stereo depth)
    mono VO         features             (scale drifts)
    dead reckoning  -                    (last pose + wheel odometry: always available)

A component is healthy at a frame when none of its metrics is in alert: features <- `features`,
`inlier_ratio`; stereo <- `reprojection_px`; imu <- `imu_gap_ms` (COMPONENT_OF). Other alerts
(VO error, loop closures, Gaussian count) are symptoms downstream: logged, not a reason to switch.

The machine: at frame 0, the best available mode. Then, at each frame, if the current mode is not
available, switch at once to the best mode available now (fail fast); otherwise upgrade to the best
mode that is better than the current one and has been available for the last `hold` frames (recover
slowly: a component that flickers back for a few frames must not make the robot re-initialise).

The lesson lists the ladder as a sequence (features fail -> direct VO -> stereo fails -> mono + IMU ->
...); read literally, one step down per failure, it sends a robot whose stereo failed first to direct
VO, which here needs stereo (the rung is stereo direct odometry, as Stereo DSO, Wang et al. ICCV 2017; monocular
DSO needs no stereo but has no scale). The modes are chosen by what is healthy, not by counting failures.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from graders.core.engine import Case, Exercise, OutputError, like, register

MODES: list[tuple[str, frozenset]] = [
    ("stereo VIO", frozenset({"features", "stereo", "imu"})), ("direct VO", frozenset({"stereo"})),
    ("mono + IMU", frozenset({"features", "imu"})), ("mono VO", frozenset({"features"})),
    ("dead reckoning", frozenset()),
]
COMPONENT_OF = {"features": "features", "inlier_ratio": "features", "reprojection_px": "stereo",
                "imu_gap_ms": "imu"}
SYMPTOMS = ("vo_error_deg", "loop_closures", "gaussians_high", "gaussians_low")


def _available(alerts, names, modes=MODES, component_of=COMPONENT_OF) -> np.ndarray:
    """(T, len(modes)) bool: mode m's components all healthy at frame t."""
    alerts = np.asarray(alerts, bool)
    failed = {c: np.zeros(len(alerts), bool) for c in ("features", "stereo", "imu")}
    for j, name in enumerate(names):
        if name in component_of:
            failed[component_of[name]] |= alerts[:, j]
    return np.stack([~np.any([failed[c] for c in need], 0) if need else np.ones(len(alerts), bool)
                     for _, need in modes], 1)


def _machine(avail: np.ndarray, hold: int, *, upgrade: bool = True, hold_frames: int | None = None,
             best_now_only: bool = False, fall_below: bool = False) -> list[int]:
    """Mode indices per frame from the availability table (the rule; keywords model known mistakes)."""
    hold = hold if hold_frames is None else hold_frames
    run = np.zeros(avail.shape[1], int)
    modes = []
    for t in range(len(avail)):
        run = np.where(avail[t], run + 1, 0)
        best = int(np.argmax(avail[t]))
        if t == 0 or not avail[t, modes[-1]]:
            below = np.flatnonzero(avail[t, modes[-1] + 1:]) + modes[-1] + 1 if t else [best]
            modes.append(int(below[0]) if fall_below else best)
            continue
        ready = [m for m in range(modes[-1]) if run[m] >= hold and (m == best or not best_now_only)]
        modes.append(ready[0] if ready and upgrade else modes[-1])
    return modes


def gt_degradation_modes(alerts, names, hold: int = 10) -> list[str]:
    """The grader's stand-in: the machine above. alerts: (T, M) bool, names: (M,) metric names -> (T,) modes."""
    return [MODES[m][0] for m in _machine(_available(alerts, names), hold)]


# ---------------------------------------------------------------- fault scenarios

def _interval(rng: np.random.Generator, T: int, start: tuple[float, float], length: tuple[int, int]) -> tuple[int, int]:
    a = int(rng.uniform(*start) * T)
    return a, min(T, a + int(rng.integers(*length)))


def fault_scenario(rng: np.random.Generator, kind: str, hold: int = 10, T: int = 240) -> dict:
    """A scenario's alert states: `alerts` (T, M) bool over `names` (the monitor's metrics, shuffled), with
    symptom alerts (VO error, loop closures, ...) sprinkled at random. kind: "dirty lens", "loose sync cable",
    "IMU dropout in the dark", "everything fails", "staggered recovery" (the rule's two clauses where a shortcut
    differs: the upgrade goes to the best mode that has had its `hold`, not only to the best available now; a
    failure goes to the best mode available now, which may be better than the one that failed)."""
    metrics = ("reprojection_px", "features", "inlier_ratio", "vo_error_deg", "loop_closures", "gaussians_high",
               "gaussians_low", "imu_gap_ms")
    names = [metrics[i] for i in rng.permutation(len(metrics))]
    on = {n: np.zeros(T, bool) for n in names}

    def fault(name, start, length):
        a, b = _interval(rng, T, start, length)
        on[name][a:b] = True
        return a, b

    if kind == "dirty lens":                          # features fail, and matching with them; stereo fine
        a, b = fault("features", (0.1, 0.3), (40, 80))
        on["inlier_ratio"][a + int(rng.integers(0, 6)):b + int(rng.integers(-5, 6))] = True
    elif kind == "loose sync cable":                  # stereo fails, flickers back (< hold frames), fails again
        a, b = fault("reprojection_px", (0.1, 0.25), (30, 50))
        gap = int(rng.integers(2, hold))
        on["reprojection_px"][b + gap:b + gap + int(rng.integers(10, 30))] = True
    elif kind == "IMU dropout in the dark":           # features fail, then the IMU drops out in the middle
        a, b = fault("features", (0.1, 0.2), (90, 130))
        on["imu_gap_ms"][a + int(rng.integers(15, 30)):a + int(rng.integers(45, 80))] = True
    elif kind == "staggered recovery":                # components return fewer than `hold` frames apart
        # features and stereo fail; stereo returns 2 to hold - 1 frames before the features: direct VO has been
        # available for `hold` frames before stereo VIO has, so the robot climbs to direct VO first
        a, b = fault("features", (0.05, 0.1), (40, 60))
        back = b - int(rng.integers(2, hold))
        on["reprojection_px"][a + int(rng.integers(5, 15)):back] = True
        # later stereo fails alone (mono + IMU), and the IMU drops out 1 to hold - 1 frames after stereo returned:
        # the best mode available then is direct VO, better than the one that failed
        c = b + 2 * hold + int(rng.integers(0, hold))
        d = c + int(rng.integers(15, 30))
        on["reprojection_px"][c:d] = True
        g = d + int(rng.integers(1, hold))
        on["imu_gap_ms"][g:g + int(rng.integers(15, 30))] = True
    else:                                             # everything: features, stereo and IMU, staggered
        a, b = fault("features", (0.05, 0.15), (100, 140))
        on["reprojection_px"][a + int(rng.integers(10, 25)):b - int(rng.integers(10, 25))] = True
        on["imu_gap_ms"][a + int(rng.integers(5, 40)):b + int(rng.integers(-30, 20))] = True
    for n in SYMPTOMS:                                # downstream symptoms: never a reason to switch
        for _ in range(int(rng.integers(1, 3))):
            fault(n, (0.0, 0.9), (3, 40))
    return {"alerts": np.stack([on[n] for n in names], 1), "names": names, "hold": hold}


def _canonical(out: Any, case: Case) -> list[str]:
    known = [m for m, _ in MODES]
    if isinstance(out, str):
        raise OutputError(f"expected one mode per frame ({len(case.expected)}), got a single string")
    try:
        modes = [str(m) for m in out]
    except TypeError:
        raise OutputError(f"expected a list of {len(case.expected)} mode names") from None
    if len(modes) != len(case.expected):
        raise OutputError(f"expected {len(case.expected)} modes (one per frame), got {len(modes)}")
    unknown = sorted(set(modes) - set(known))
    if unknown:
        raise OutputError(f"unknown modes {unknown}; the modes are {known}")
    return modes


def _wrong_frames(out: list[str], expected: list[str]) -> float:
    return float(sum(a != b for a, b in zip(out, expected)))


KINDS = ("dirty lens", "loose sync cable", "IMU dropout in the dark", "everything fails", "staggered recovery")


def _cases(rng: np.random.Generator) -> list[Case]:
    cases = []
    for kind, hold in zip(KINDS, (10, 8, 12, 10, 9)):
        d = fault_scenario(rng, kind, hold)
        args = (d["alerts"], d["names"], hold)
        # Exact: a mode per frame, defined by the rule.
        cases.append(Case(f"{kind} (hold {hold})", args, gt_degradation_modes(*args), _wrong_frames, 0, "frames wrong",
                          convert=_canonical, key=kind.replace(" ", "-").lower()))
    return cases


def _model(symptoms_fail_features: bool = False, direct_needs_nothing: bool = False, **machine):
    """What a known mistake returns on a case (for the hints)."""
    comp = dict(COMPONENT_OF, **({n: "features" for n in SYMPTOMS} if symptoms_fail_features else {}))
    modes = [(m, frozenset() if direct_needs_nothing and m == "direct VO" else need) for m, need in MODES]

    def bug(case):
        alerts, names, hold = case.args
        return [MODES[m][0] for m in _machine(_available(alerts, names, modes, comp), hold, **machine)]
    return bug


DEGRADATION_HINTS = [
    like(_model(hold_frames=1), "the machine upgrades as soon as a better mode is available: wait until it has "
         "been available for `hold` consecutive frames (a flickering sync cable must not re-initialise VIO)."),
    like(_model(upgrade=False), "the machine never comes back: when the failed component has been healthy for "
         "`hold` frames, return to the better mode."),
    like(_model(direct_needs_nothing=True), "this ladder's direct VO needs stereo (its rung is stereo direct "
         "odometry, as Stereo DSO; monocular DSO would be a rung of its own, without scale): when stereo fails, fall to "
         "mono + IMU, not to direct VO."),
    like(_model(best_now_only=True), "the machine waits for the best mode available now while a better-than-current "
         "one has had its hold: move up to the best mode that has had its hold (stereo back, features back fewer than "
         "`hold` frames later: direct VO first)."),
    like(_model(fall_below=True), "on a failure, switch to the best mode available now, which can be better than "
         "the one that failed (stereo came back while mono + IMU ran; the IMU then fails: direct VO, not mono VO)."),
    like(_model(symptoms_fail_features=True), "VO error, loop closures and Gaussian counts are downstream "
         "symptoms: they do not make a component unhealthy."),
]

register(Exercise(
    id="11.6", title="Graceful degradation: a mode state machine", name="degradation_modes", kind="code",
    points=3, cases=_cases, hints=DEGRADATION_HINTS, fallback=gt_degradation_modes, timeout=20.0,
    arg_names=("alerts", "names", "hold")))
