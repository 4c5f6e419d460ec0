"""Chapter 6, DEBUG 6.20: "tracking lost at a fast turn" (the cause, no motion prior, is the learner's to find).

The broken artefact: a frame-to-map tracker that predicts each frame's pose as the previous frame's pose,
projects the map with that prediction and searches a 15 px window round each projection for the keypoint
with the nearest descriptor, then refines the pose from the matches (Gauss-Newton on the reprojection
error). When the camera turns fast (up to 6-8°/frame, 50-70 px of image motion at f = 500 px) the true
keypoints fall outside the windows, the matches collapse below 15 and the tracker is lost for good.

The fix ORB-SLAM makes (Tracking::TrackWithMotionModel): predict with a constant-velocity model,
T_k ≈ V T_{k-1}, V = T_{k-1} T_{k-2}⁻¹. Widening the window instead is no fix here: half the scene has
repeated texture (a twin point 0.8-1.2 m away with the same descriptor), and a 100 px window matches the
twins, which drags the least-squares pose off. The learner names the cause (a graded choice) and returns
the poses of a fixed tracker on fresh hidden sequences; judged by the frames tracked (rotation within 0.5°,
position within 3 cm of the truth) and the position RMS error (the map is given in the world frame, so no
alignment is needed).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from graders.core.convert import as_pose_stack
from graders.core.engine import Case, Exercise, Hint, OutputError, register, shared_run
from graders.kit.geometry import so3_exp
from graders.core.memo import cached

CAUSES = ("a", "b", "c", "d")
CAUSE_TEXT = {
    "a": "no motion prior: each frame's search starts from the previous frame's pose",
    "b": "too few features: the detector's budget is too small",
    "c": "motion blur: the exposure is too long",
    "d": "the map points are wrong: the triangulation is biased",
}
RIGHT_CAUSE = "a"
WINDOW = 15.0        # px, the broken tracker's search radius (ORB-SLAM's th = 15 for monocular motion-model search)
MIN_MATCHES = 15
F, W, H = 500.0, 640, 480
K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1.0]])
D = 16


def yaw_profile(rng: np.random.Generator, n_frames: int = 56, fast_deg: float | None = None) -> np.ndarray:
    """Yaw per frame (rad): slow, a smooth ramp up to a fast turn, hold, ramp down, slow."""
    fast = np.radians(fast_deg if fast_deg is not None else rng.uniform(5.0, 7.0))
    slow = np.radians(rng.uniform(0.2, 0.5))
    a = int(rng.integers(12, 18))
    ramp, hold = 12, int(rng.integers(8, 12))
    rate = np.full(n_frames, slow)
    up = slow + (fast - slow) * 0.5 * (1 - np.cos(np.linspace(0, np.pi, ramp)))
    rate[a:a + ramp] = up
    rate[a + ramp:a + ramp + hold] = fast
    rate[a + ramp + hold:a + 2 * ramp + hold] = up[::-1]
    return np.cumsum(np.r_[0.0, rate[:-1]]) * rng.choice([-1, 1])


def tracking_sequence(rng: np.random.Generator, n_frames: int = 56, fast_deg: float | None = None) -> dict:
    """A camera at the centre of a ring of points turns (mostly yaw) while creeping forward. Returns the map
    (points, descriptors), per-frame keypoints (pixels, descriptors; shuffled; 0.5 px noise), true poses
    T_cw (n_frames, 4, 4)."""
    yaw = yaw_profile(rng, n_frames, fast_deg)
    n = 500
    theta = rng.uniform(-np.pi, np.pi, n)
    r, h = rng.uniform(4, 8, n), rng.uniform(-2, 2, n)
    X = np.c_[r * np.sin(theta), h, r * np.cos(theta)]
    desc = rng.normal(0, 1, (n, D))
    # Repeated texture: half the points have a twin 0.8-1.2 m along the ring (50-150 px) with the same descriptor.
    tw = rng.random(n) < 0.5
    off = rng.uniform(0.8, 1.2, tw.sum()) * rng.choice([-1, 1], tw.sum())
    tangent = np.c_[np.cos(theta[tw]), np.zeros(tw.sum()), -np.sin(theta[tw])]
    X = np.r_[X, X[tw] + off[:, None] * tangent]
    desc = np.r_[desc, desc[tw]]
    T = np.tile(np.eye(4), (n_frames, 1, 1))
    for k in range(n_frames):
        R_wc = so3_exp(np.array([0.0, yaw[k], 0.0]) + rng.normal(0, 0.001, 3))
        C = np.array([0.0, 0.0, 0.01 * k])
        T[k, :3, :3], T[k, :3, 3] = R_wc.T, -R_wc.T @ C
    frames = []
    for k in range(n_frames):
        Xc = X @ T[k, :3, :3].T + T[k, :3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = Xc[:, :2] / Xc[:, 2:] * F + K[:2, 2]
        vis = (Xc[:, 2] > 0.5) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
        vis &= rng.random(len(X)) < 0.9
        idx = rng.permutation(np.flatnonzero(vis))
        frames.append({"uv": uv[idx] + rng.normal(0, 0.5, (len(idx), 2)),
                       "desc": desc[idx] + rng.normal(0, 0.1, (len(idx), D))})
    return {"X": X, "desc": desc, "frames": frames, "T": T}


def match_in_window(seq: dict, T_pred: np.ndarray, k: int, radius: float = WINDOW) -> tuple[np.ndarray, np.ndarray]:
    """Project the map with the predicted pose T_cw, and for each projection inside the image take, among frame
    k's keypoints within `radius` px, the one with the nearest descriptor (accepted if that distance is < 1.5).
    Returns (map point indices (m,), keypoint pixels (m, 2))."""
    from scipy.spatial import cKDTree
    X, fr = seq["X"], seq["frames"][k]
    Xc = X @ T_pred[:3, :3].T + T_pred[:3, 3]
    front = Xc[:, 2] > 0.1
    uv = np.full((len(X), 2), -1e9)
    uv[front] = Xc[front, :2] / Xc[front, 2:] * F + K[:2, 2]
    inside = front & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
    if not len(fr["uv"]) or not inside.any():
        return np.zeros(0, int), np.zeros((0, 2))
    tree = cKDTree(fr["uv"])
    idx_map, idx_kp = [], []
    for i, near in zip(np.flatnonzero(inside), tree.query_ball_point(uv[inside], radius)):
        if not near:
            continue
        d = np.linalg.norm(fr["desc"][near] - seq["desc"][i], axis=1)
        j = int(np.argmin(d))
        if d[j] < 1.5:
            idx_map.append(i)
            idx_kp.append(near[j])
    return np.array(idx_map, int), fr["uv"][np.array(idx_kp, int)].reshape(-1, 2)


def refine_pose(seq: dict, T_init: np.ndarray, idx: np.ndarray, uv: np.ndarray, iters: int = 8) -> np.ndarray:
    """Gauss-Newton on the reprojection error of the matched map points (left perturbation of T_cw)."""
    T = np.array(T_init, float)
    X = seq["X"][idx]
    for _ in range(iters):
        P = X @ T[:3, :3].T + T[:3, 3]
        z = P[:, 2:]
        r = (P[:, :2] / z * F + K[:2, 2] - uv).ravel()
        x, y, zz = P[:, 0], P[:, 1], P[:, 2]
        dp = np.zeros((len(P), 2, 3))
        dp[:, 0, 0], dp[:, 0, 2] = F / zz, -F * x / zz ** 2
        dp[:, 1, 1], dp[:, 1, 2] = F / zz, -F * y / zz ** 2
        skewP = np.zeros((len(P), 3, 3))
        skewP[:, 0, 1], skewP[:, 0, 2], skewP[:, 1, 2] = -zz, y, -x
        skewP[:, 1, 0], skewP[:, 2, 0], skewP[:, 2, 1] = zz, -y, x
        J = np.concatenate([-dp @ skewP, dp], axis=2).reshape(-1, 6)   # d r / d (δθ, δt)
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        dT = np.eye(4)
        dT[:3, :3], dT[:3, 3] = so3_exp(step[:3]), step[3:]
        T = dT @ T
        if np.linalg.norm(step) < 1e-10:
            break
    return T


def run_tracker(case: dict, motion_model: bool = False, radius: float = WINDOW) -> dict:
    """The tracker loop (the broken artefact with the defaults): poses T_cw (n, 4, 4) and the log of matches."""
    n = case["n_frames"]
    T = np.tile(np.eye(4), (n, 1, 1))
    T[0] = case["T0"]
    log, lost = [len(case["frames0_matches"])], False
    for k in range(1, n):
        V = T[k - 1] @ np.linalg.inv(T[k - 2]) if motion_model and k >= 2 else np.eye(4)
        T_pred = V @ T[k - 1]
        idx, uv = case["match"](T_pred, k, radius)
        if lost or len(idx) < MIN_MATCHES:
            lost = True   # no relocalisation: once lost, the pose stays frozen
            T[k] = T[k - 1]
            log.append(len(idx))
            continue
        T[k] = case["refine"](T_pred, idx, uv)
        log.append(len(idx))
    return {"T": T, "matches": np.array(log)}


def debug_tracking(rng: np.random.Generator) -> tuple[dict, dict]:
    """6.20's case: the sequence's callbacks, frame 0's pose, and the broken tracker's log; truth: the poses."""
    seq = tracking_sequence(rng)

    def match(T_pred, k, radius=WINDOW, seq=seq):
        return match_in_window(seq, np.asarray(T_pred, float), int(k), float(min(radius, 200.0)))

    def refine(T_init, idx, uv, seq=seq):
        return refine_pose(seq, np.asarray(T_init, float), np.asarray(idx, int), np.asarray(uv, float))

    case = {"n_frames": len(seq["T"]), "T0": seq["T"][0].copy(), "K": K.copy(), "window_px": WINDOW,
            "match": match, "refine": refine, "frames0_matches": match(seq["T"][0], 0)[0]}
    case["log"] = run_tracker(case)["matches"]
    case["causes"] = dict(CAUSE_TEXT)
    return case, {"T": seq["T"]}


# ----------------------------------------------------------------- judging

def _convert(out, case):
    n = case.args[0]["n_frames"]
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise OutputError("expected (cause, poses): cause one of 'a'-'d', poses (n_frames, 4, 4) T_cw")
    cause = str(out[0]).strip().lower()
    if cause not in CAUSES:
        raise OutputError(f"cause must be one of {', '.join(CAUSES)}; got {out[0]!r}")
    return cause, as_pose_stack(out[1], n)


def pose_errors(T, T_true) -> tuple[np.ndarray, np.ndarray]:
    """Per frame: rotation error (deg) and camera-centre error (m)."""
    dR = np.swapaxes(T_true[:, :3, :3], 1, 2) @ T[:, :3, :3]
    ang = np.degrees(np.arccos(np.clip((np.trace(dR, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    C = -np.einsum("nji,nj->ni", T[:, :3, :3], T[:, :3, 3])
    Ct = -np.einsum("nji,nj->ni", T_true[:, :3, :3], T_true[:, :3, 3])
    return ang, np.linalg.norm(C - Ct, axis=1)


def _untracked(out, truth) -> float:
    ang, pos = pose_errors(out[1], truth["T"])
    return float(np.mean((ang > 0.5) | (pos > 0.03)))


def _ate(out, truth) -> float:
    return float(np.sqrt(np.mean(pose_errors(out[1], truth["T"])[1] ** 2)))


def _cause(out, truth) -> float:
    return float(out[0] != RIGHT_CAUSE)


# 5 % of the frames may be off: the reference tracks 100 % (worst rotation error ~0.05°, position ~5 mm over
# 300 draws); the broken tracker loses 40-70 % at the turn, the 100 px window 20-60 %.
TOL_UNTRACKED = 0.05
TOL_ATE = 0.02   # m RMS: the reference reaches 1-4 mm; a tracker lost at the turn is off by metres.
CAUSE_WEIGHT = 4 / 9  # the cause row's weight: 1/10 of the points beside four repair rows of weight 1


@cached    # the same draw for every grade of a seed: its oracle runs once per process
def cases_tracking(rng: np.random.Generator):
    for i in range(2):
        case, truth = debug_tracking(rng)
        call = shared_run(lambda fn, case=case: fn(case))
        yield Case(f"hidden sequence {i + 1}: frames tracked (rotation < 0.5°, position < 3 cm)", (case,), truth,
                   _untracked, TOL_UNTRACKED, "share lost", convert=_convert, call=call, key=f"tracked-{i + 1}",
                   tags=("tracked",))
        yield Case(f"hidden sequence {i + 1}: position RMS error", (case,), truth, _ate, TOL_ATE, "m",
                   convert=_convert, call=call, key=f"ate-{i + 1}", tags=("ate",))
        if i == 0:
            # A tenth of the points (weight 4/9 beside the four repair rows): the spec describes the broken
            # tracker's prediction and says the frames stay sharp and textured, so naming the cause is reading; the
            # repair is the exercise. Cause + the unrepaired tracker: 0.2 / 2 (6.18, cause handed over: a quarter).
            yield Case("the cause you named", (case,), truth, _cause, 0.0, "wrong", convert=_convert, call=call,
                       key="cause", tags=("cause",), weight=CAUSE_WEIGHT)


def _wrong_cause(case, out):
    return "cause" in case.tags and out[0] != RIGHT_CAUSE


def _lost_at_turn(case, out):
    if "tracked" not in case.tags:
        return False
    ang, _ = pose_errors(out[1], case.expected["T"])
    return bool(np.mean(ang > 0.5) > TOL_UNTRACKED)


HINTS = [
    Hint("the log shows the matches collapsing where the camera turns fastest, while the frames are as sharp and "
         "as textured as before: look at how far each keypoint lies from where the tracker searches for it. "
         "The search starts from the previous pose.", _wrong_cause),
    Hint(lambda case, out: f"your tracker still loses {np.mean(pose_errors(out[1], case.expected['T'])[0] > 0.5):.0%} "
         "of the frames. Predict each pose with a constant-velocity model, T_pred = V T_{k-1} with V = T_{k-1} "
         "T_{k-2}⁻¹ (ORB-SLAM's TrackWithMotionModel). A wider window alone matches the repeated texture's twins.",
         _lost_at_turn),
]


def fixed_tracker(case: dict):
    """Stand-in for 6.20: the constant-velocity tracker."""
    return RIGHT_CAUSE, run_tracker(case, motion_model=True)["T"]


register(
    Exercise(
        id="6.20",
        title="Tracking lost at a fast turn",
        name="fix_tracking",
        kind="debug",
        points=2,
        cases=cases_tracking,
        hints=HINTS,
        fallback=fixed_tracker,
        timeout=60.0,
    ),
)

@lru_cache(maxsize=2)
def _seeded(seed: int) -> tuple[dict, dict]:
    return debug_tracking(np.random.default_rng(seed))


def tracking_case(exercise_id: str = "6.20", seed: int = 0) -> dict:
    """A broken run of DEBUG exercise 6.20 to practise on (the check draws fresh ones)."""
    if exercise_id != "6.20":
        raise KeyError(f"tracking_case is for 6.20, not {exercise_id!r}")
    return dict(_seeded(int(seed))[0])


def tracking_truth(seed: int = 0) -> dict:
    """The true poses of `tracking_case("6.20", seed)` (for pictures after a fix)."""
    return _seeded(int(seed))[1]
