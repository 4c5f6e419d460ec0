"""Chapter 11 mutant catalogue (part A): realistic wrong implementations, one per known mistake.

Each entry of MUTANTS is (exercise id, short name, function, hint fragment or None). The grader must take
points off every one; where a hint exists for the mistake it must fire. Each mutant is written out on its
own (never on the grader's rule), differing from a correct answer in one mistake.
"""
from __future__ import annotations

import numpy as np

from mutants.ch11_capstone_frontier import MUTANTS as _FRONTIER_MUTANTS
from solutions.ch11_capstone.monitor import COMPONENT, MODES, NEEDS

MUTANTS: list[tuple] = []


# ----------------------------------------------------------------- 11.5 health_monitor

def _monitor(stream, table, k, *, k_raise=None, k_clear=None, clear_band="normal", all_high=False, total=False,
             warn_pauses_clear=False):
    x = np.asarray(stream, float)
    events = []
    for j, row in enumerate(table):
        v = x[:, j]
        if row["bad"] == "high" or all_high:
            past, normal = v > row["alert"], v < row["normal"]
        else:
            past, normal = v < row["alert"], v > row["normal"]
        if clear_band == "not_past":
            normal = ~past
        on, run = False, 0
        for t in range(len(v)):
            if (normal[t] if on else past[t]):
                run += 1
            elif not total and not (warn_pauses_clear and on and not past[t]):
                run = 0
            if run >= ((k_clear or k) if on else (k_raise or k)):
                on, run = not on, 0
                events.append((t, row["metric"], row["action"] if on else "clear"))
    return events


def monitor_without_hysteresis(stream, table, k=3):
    """Raises on the first bad frame and clears on the first normal one."""
    return _monitor(stream, table, k, k_raise=1, k_clear=1)


def monitor_raises_at_once(stream, table, k=3):
    """Hysteresis on the way out only: one frame past the threshold raises the alert."""
    return _monitor(stream, table, k, k_raise=1)


def monitor_clears_on_first_good_frame(stream, table, k=3):
    """Waits k frames to raise, but one normal frame clears the alert."""
    return _monitor(stream, table, k, k_clear=1)


def monitor_ignores_warning_band(stream, table, k=3):
    """Clears after k frames that are no longer past the alert threshold (warning-band frames count as good)."""
    return _monitor(stream, table, k, clear_band="not_past")


def monitor_higher_is_always_bad(stream, table, k=3):
    """`x > alert` for every metric: the "lower is bad" rows (features, inlier ratio, ...) read upside down."""
    return _monitor(stream, table, k, all_high=True)


def monitor_counts_total(stream, table, k=3):
    """Counts bad frames since the last state change instead of consecutive ones."""
    return _monitor(stream, table, k, total=True)


def monitor_warning_pauses_clear(stream, table, k=3):
    """While in alert, only a frame past the alert threshold restarts the clearing run; a warning-band frame merely
    pauses it (the spec: warning frames break both runs)."""
    return _monitor(stream, table, k, warn_pauses_clear=True)


def monitor_forgets_actions(stream, table, k=3):
    """Right frames, but reports "alert" instead of the row's action."""
    return [(t, m, a if a == "clear" else "alert") for t, m, a in _monitor(stream, table, k)]


MUTANTS += [
    ("11.5", "no hysteresis", monitor_without_hysteresis, "no hysteresis"),
    ("11.5", "raises on the first bad frame", monitor_raises_at_once, "raised on the first frame"),
    ("11.5", "clears on the first good frame", monitor_clears_on_first_good_frame, "clears on the first good frame"),
    ("11.5", "warning band counts as recovered", monitor_ignores_warning_band, "no longer past the alert"),
    ("11.5", "lower-is-bad read upside down", monitor_higher_is_always_bad, "read as 'higher is bad'"),
    ("11.5", "bad frames counted in total", monitor_counts_total, "counted in total"),
    ("11.5", "a warning frame pauses the clearing run", monitor_warning_pauses_clear, "breaks the clearing run"),
    ("11.5", "no actions", monitor_forgets_actions, "not the actions"),
]


# ----------------------------------------------------------------- 11.6 degradation_modes

def _modes(alerts, names, hold, *, needs=NEEDS, component=COMPONENT, recover=True, hold_used=None,
           best_now_only=False, fall_below=False):
    alerts = np.asarray(alerts, bool)
    failed = [{component[n] for j, n in enumerate(names) if n in component and a[j]} for a in alerts]
    ok = [[not needs[m] & f for m in MODES] for f in failed]
    hold = hold if hold_used is None else hold_used
    streak, out, cur = np.zeros(len(MODES), int), [], None
    for t, row in enumerate(ok):
        streak = np.where(row, streak + 1, 0)
        if cur is None or not row[cur]:
            cur = row.index(True, cur + 1) if fall_below and cur is not None else row.index(True)
        elif recover:
            better = [m for m in range(cur) if streak[m] >= hold]
            if best_now_only:                                  # only the best mode available now may be climbed to
                better = [m for m in better if m == row.index(True)]
            cur = better[0] if better else cur
        out.append(MODES[cur])
    return out


def modes_upgrade_at_once(alerts, names, hold=10):
    """Returns to the better mode on the first frame it is available again."""
    return _modes(alerts, names, hold, hold_used=1)


def modes_never_recover(alerts, names, hold=10):
    """Falls back correctly but stays down for the rest of the run."""
    return _modes(alerts, names, hold, recover=False)


def modes_direct_vo_without_stereo(alerts, names, hold=10):
    """The lesson's ladder read literally: direct VO is the next rung whatever failed (it needs nothing)."""
    return _modes(alerts, names, hold, needs=dict(NEEDS, **{"direct VO": set()}))


def modes_symptoms_are_failures(alerts, names, hold=10):
    """Every alert counts against the features, VO error and loop closures included."""
    component = {n: COMPONENT.get(n, "features") for n in names}
    return _modes(alerts, names, hold, component=component)


def modes_upgrade_to_best_now_only(alerts, names, hold=10):
    """Climbs only to the best mode available now, once it has had its hold; a better-than-current mode that has had
    its hold is ignored while a still better one is back for fewer than hold frames."""
    return _modes(alerts, names, hold, best_now_only=True)


def modes_fall_below_only(alerts, names, hold=10):
    """On a failure, the best available mode below the failed one (one-way down), not the best available now."""
    return _modes(alerts, names, hold, fall_below=True)


def modes_by_failure_count(alerts, names, hold=10):
    """One rung down per failed component (0 -> stereo VIO, 1 -> direct VO, ...), no hold."""
    alerts = np.asarray(alerts, bool)
    failed = [len({COMPONENT[n] for j, n in enumerate(names) if n in COMPONENT and a[j]}) for a in alerts]
    return [MODES[f if f < 3 else 4] for f in failed]


MUTANTS += [
    ("11.6", "upgrades at once", modes_upgrade_at_once, "upgrades as soon as"),
    ("11.6", "never recovers", modes_never_recover, "never comes back"),
    ("11.6", "direct VO without stereo", modes_direct_vo_without_stereo, "direct VO needs stereo"),
    ("11.6", "climbs only to the best mode available now", modes_upgrade_to_best_now_only, "has had its hold"),
    ("11.6", "falls only below the failed mode", modes_fall_below_only, "can be better than the one that failed"),
    ("11.6", "symptoms switch the mode", modes_symptoms_are_failures, "downstream symptoms"),
    ("11.6", "one rung per failure", modes_by_failure_count, None),
]


# ----------------------------------------------------------------- 11.7 first_faulty_stage

def _z(observed, baseline, stage):
    b = np.asarray(baseline[stage], float)
    return np.abs(np.asarray(observed[stage], float) - b.mean(0)) / b.std(0, ddof=1)


def blame_largest_deviation(stages, observed, baseline, z_max=4.0):
    """The stage that moved most (in sigmas): the loudest symptom, usually downstream."""
    return max(stages, key=lambda s: _z(observed, baseline, s).max())


def blame_stage_rms(stages, observed, baseline, z_max=4.0):
    """A stage score: the RMS of its metrics' z against z_max (one metric far off is diluted by the others)."""
    return next((s for s in stages if np.sqrt(np.mean(_z(observed, baseline, s) ** 2)) > z_max), None)


def blame_last_stage(stages, observed, baseline, z_max=4.0):
    """Walks the pipeline and keeps the last stage out of its baseline."""
    out = None
    for s in stages:
        if _z(observed, baseline, s).max() > z_max:
            out = s
    return out


def blame_relative_change(stages, observed, baseline, z_max=4.0):
    """Ignores the baseline's spread: a metric more than 25 % from its baseline mean is a deviation."""
    for s in stages:
        mean = np.asarray(baseline[s], float).mean(0)
        if np.any(np.abs(np.asarray(observed[s], float) / mean - 1) > 0.25):
            return s
    return None


def blame_first_metric_only(stages, observed, baseline, z_max=4.0):
    """Looks at each stage's headline metric (the first) only."""
    for s in stages:
        if _z(observed, baseline, s)[0] > z_max:
            return s
    return None


def blame_fixed_threshold(stages, observed, baseline, z_max=4.0):
    """The rule with the lesson's 4 sigma written in: the z_max the caller passes is ignored."""
    for s in stages:
        if _z(observed, baseline, s).max() > 4.0:
            return s
    return None


def blame_in_dict_order(stages, observed, baseline, z_max=4.0):
    """Walks `observed` in its own (insertion) order, not the pipeline order `stages` gives."""
    for s in observed:
        if _z(observed, baseline, s).max() > z_max:
            return s
    return None


MUTANTS += [
    ("11.7", "z_max ignored (4 written in)", blame_fixed_threshold, "use the threshold you are given"),
    ("11.7", "dict order, not the stages' order", blame_in_dict_order, "not in the pipeline order"),
    ("11.7", "largest deviation", blame_largest_deviation, "largest deviation"),
    ("11.7", "RMS of the stage's z", blame_stage_rms, "any one of its metrics"),
    ("11.7", "last stage", blame_last_stage, "last stage out of its baseline"),
    ("11.7", "ignores the baseline spread", blame_relative_change, "relative change is not a deviation"),
    ("11.7", "first metric only", blame_first_metric_only, None),
]


# ----------------------------------------------------------------- 11.8 hybrid_odometry

def _hybrid(features, inlier_ratio, T_classical, T_direct, min_features, min_inliers, k, *, test="both",
            wait=True, switch_late=False, right_multiply=False, never=False):
    poses = [np.eye(4)]
    direct, streak = False, 0
    for i in range(1, len(features)):
        f_ok, w_ok = features[i] >= min_features, inlier_ratio[i] >= min_inliers
        ok = {"both": f_ok and w_ok, "features": f_ok, "inliers": w_ok}[test] or never
        streak = streak + 1 if ok else 0
        use_direct = direct
        if not direct and not ok:
            direct = True
        elif direct and streak >= (k if wait else 1):
            direct = False
        if not switch_late:
            use_direct = direct
        step = np.asarray(T_direct[i] if use_direct else T_classical[i], float)
        poses.append(poses[-1] @ step if right_multiply else step @ poses[-1])
    return np.array(poses)


def hybrid_never_switches(features, inlier_ratio, T_classical, T_direct, min_features=80, min_inliers=0.3, k=2):
    """Trusts the classical front end on every frame."""
    return _hybrid(features, inlier_ratio, T_classical, T_direct, min_features, min_inliers, k, never=True)


def hybrid_no_hysteresis(features, inlier_ratio, T_classical, T_direct, min_features=80, min_inliers=0.3, k=2):
    """Comes back to the classical estimate on the first confident frame (ignores k)."""
    return _hybrid(features, inlier_ratio, T_classical, T_direct, min_features, min_inliers, k, wait=False)


def hybrid_counts_features_only(features, inlier_ratio, T_classical, T_direct, min_features=80, min_inliers=0.3,
                                k=2):
    """The confidence test looks at the feature count only."""
    return _hybrid(features, inlier_ratio, T_classical, T_direct, min_features, min_inliers, k, test="features")


def hybrid_switches_a_frame_late(features, inlier_ratio, T_classical, T_direct, min_features=80, min_inliers=0.3,
                                 k=2):
    """Decides the mode on frame i but applies it from frame i+1: the failing frame keeps the bad estimate."""
    return _hybrid(features, inlier_ratio, T_classical, T_direct, min_features, min_inliers, k, switch_late=True)


def hybrid_chains_on_the_right(features, inlier_ratio, T_classical, T_direct, min_features=80, min_inliers=0.3,
                               k=2):
    """T_cw[i] = T_cw[i-1] @ T_rel[i]: the motions composed on the wrong side."""
    return _hybrid(features, inlier_ratio, T_classical, T_direct, min_features, min_inliers, k, right_multiply=True)


def hybrid_fixed_thresholds(features, inlier_ratio, T_classical, T_direct, min_features=80, min_inliers=0.3, k=2):
    """The lesson's 80 features and 0.3 inlier ratio written in: the thresholds passed are ignored."""
    return _hybrid(features, inlier_ratio, T_classical, T_direct, 80, 0.3, k)


def hybrid_fixed_k(features, inlier_ratio, T_classical, T_direct, min_features=80, min_inliers=0.3, k=2):
    """Two confident frames in a row, whatever k is passed."""
    return _hybrid(features, inlier_ratio, T_classical, T_direct, min_features, min_inliers, 2)


MUTANTS += [
    ("11.8", "never switches", hybrid_never_switches, "never switched"),
    ("11.8", "thresholds written in", hybrid_fixed_thresholds, "thresholds 80 and 0.3 written in"),
    ("11.8", "k = 2 written in", hybrid_fixed_k, "k = 2 written in"),
    ("11.8", "no hysteresis", hybrid_no_hysteresis, "k confident frames in a row"),
    ("11.8", "features only", hybrid_counts_features_only, "only the feature count is tested"),
    ("11.8", "switches a frame late", hybrid_switches_a_frame_late, None),
    ("11.8", "chains on the right", hybrid_chains_on_the_right, "chained on the wrong side"),
]


# ----------------------------------------------------------------- 11.9 fix_right_mount

def _mount_fit(x_left, x_right, K, *, loss="soft_l1", axes=(0, 2), pixels=False, transpose=False):
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation
    x_left, x_right = np.asarray(x_left, float), np.asarray(x_right, float)
    K = np.eye(3) if pixels else np.asarray(K, float)

    def R_of(p):
        w = np.zeros(3)
        w[list(axes)] = p
        return Rotation.from_rotvec(w).as_matrix()

    def rows(p):
        h = np.c_[x_right, np.ones(len(x_right))] @ (K @ R_of(p).T @ np.linalg.inv(K)).T
        return h[:, 1] / h[:, 2] - x_left[:, 1]

    R = R_of(least_squares(rows, np.zeros(len(axes)), loss=loss, f_scale=0.5).x)
    return R.T if transpose else R


def mount_transposed(x_left, x_right, K):
    """Fits the repair rotation and returns it as the mount (R_m^T where R_m is asked)."""
    return _mount_fit(x_left, x_right, K, transpose=True)


def mount_least_squares(x_left, x_right, K):
    """Plain least squares on every match: the repetitive texture's wrong matches pull it."""
    return _mount_fit(x_left, x_right, K, loss="linear")


def mount_pitch_only(x_left, x_right, K):
    """Explains the row error by a pitch alone (one offset), robustly: the roll stays."""
    return _mount_fit(x_left, x_right, K, axes=(0,))


def mount_in_pixels(x_left, x_right, K):
    """Turns the pixels themselves (K left out): a rotation of pixel coordinates is not the camera's."""
    return _mount_fit(x_left, x_right, K, pixels=True)


def mount_with_yaw(x_left, x_right, K):
    """Fits pitch, roll and yaw to the rows, robustly: the rows are fixed, the yaw is fitted to noise and shifts
    every disparity (the chapter's proof: depth error ~2 % instead of 1.4 %)."""
    return _mount_fit(x_left, x_right, K, axes=(0, 1, 2))


MUTANTS += [
    ("11.9", "transposed", mount_transposed, "wrong way"),
    ("11.9", "plain least squares", mount_least_squares, "plain least-squares fit"),
    ("11.9", "pitch only", mount_pitch_only, "no roll"),
    ("11.9", "K left out", mount_in_pixels, None),
    ("11.9", "yaw fitted too", mount_with_yaw, "your repair has a yaw"),
]


# ----------------------------------------------------------------- 11.10 sync_offset

def _offset_fit(x_left, x_right, v_left, *, axis=1, scale=1000.0 / 30.0, sign=1.0, intercept=True):
    d = np.asarray(x_right, float)[:, axis] - np.asarray(x_left, float)[:, axis]
    v = np.asarray(v_left, float)[:, axis]
    slope = np.polyfit(v, d, 1)[0] if intercept else np.dot(v, d) / np.dot(v, v)
    return float(sign * slope * scale)


def sync_left_minus_right(x_left, x_right, v_left):
    """Takes the row difference the other way round (y_l - y_r): the sign flips."""
    return _offset_fit(x_left, x_right, v_left, sign=-1.0)


def sync_in_frames(x_left, x_right, v_left):
    """Returns the slope itself: the delay in frames, not ms."""
    return _offset_fit(x_left, x_right, v_left, scale=1.0)


def sync_from_columns(x_left, x_right, v_left):
    """Fits the columns: their difference is mostly the disparity, which the velocity does not explain."""
    return _offset_fit(x_left, x_right, v_left, axis=0, intercept=False)


def sync_median_of_ratios(x_left, x_right, v_left):
    """The median of per-point ratios dy / v_y: each carries the rectification's constant row offset as c / v_y."""
    dy = np.asarray(x_right, float)[:, 1] - np.asarray(x_left, float)[:, 1]
    return float(np.median(dy / np.asarray(v_left, float)[:, 1]) * 1000.0 / 30.0)


def sync_through_origin(x_left, x_right, v_left):
    """A line through the origin (no intercept): the constant row offset pulls its slope."""
    return _offset_fit(x_left, x_right, v_left, intercept=False)


MUTANTS += [
    ("11.10", "left minus right", sync_left_minus_right, "the sign"),
    ("11.10", "frames, not ms", sync_in_frames, "offset in frames"),
    ("11.10", "columns", sync_from_columns, "you fitted the columns"),
    ("11.10", "median of dy / v_y", sync_median_of_ratios, "constant offset c"),
    ("11.10", "line through the origin", sync_through_origin, "constant offset c"),
]


# ----------------------------------------------------------------- 11.11 find_smudge

def _smudge_fit(before, now, shape, *, baseline=True):
    """Least squares over 8-px cells: today's counts = reference counts x the part of each cell outside a disc."""
    from scipy.optimize import minimize
    h, w = shape
    rng_ = ((0, h), (0, w))
    hn = sum(np.histogram2d(k[:, 1], k[:, 0], bins=(h // 8, w // 8), range=rng_)[0] for k in now)
    hb = (sum(np.histogram2d(k[:, 1], k[:, 0], bins=(h // 8, w // 8), range=rng_)[0] for k in before) if baseline
          else np.full_like(hn, hn.mean()))                      # no baseline: "features should be uniform"
    yc, xc = (np.arange(h // 8) + 0.5) * 8, (np.arange(w // 8) + 0.5) * 8

    def cost(p):
        inside = np.clip((abs(p[2]) - np.hypot(yc[:, None] - p[1], xc[None] - p[0])) / 8 + 0.5, 0, 1)
        return float(np.sum((hn - hb * (1 - inside)) ** 2))
    grid = [(x, y, r) for x in range(24, w - 23, 16) for y in range(24, h - 23, 16) for r in (32, 48, 64, 80)]
    p = minimize(cost, min(grid, key=cost), method="Nelder-Mead").x
    return np.array([p[0], p[1], abs(p[2]) / 0.9])


def smudge_without_baseline(before, now, shape):
    """Reads today's heatmap alone: the emptiest region wins, smudged or just textureless."""
    return _smudge_fit(before, now, shape, baseline=False)


def smudge_largest_empty_disc(before, now, shape):
    """Today's keypoints alone: the largest disc with none inside (4-px grid of centres, kept inside the image)."""
    from scipy.spatial import cKDTree
    h, w = shape
    cx, cy = np.meshgrid(np.arange(8, w - 8, 4.0), np.arange(8, h - 8, 4.0))
    c = np.c_[cx.ravel(), cy.ravel()]
    r = cKDTree(np.concatenate([np.asarray(k, float) for k in now])).query(c)[0]     # nearest keypoint
    r = np.minimum(r, np.minimum.reduce([c[:, 0], c[:, 1], w - 1 - c[:, 0], h - 1 - c[:, 1]]))
    return np.r_[c[np.argmax(r)], r.max()]


def smudge_diameter(before, now, shape):
    """Reports the diameter in the radius slot."""
    cx, cy, r = _smudge_fit(before, now, shape)
    return np.array([cx, cy, 2 * r])


def smudge_row_col(before, now, shape):
    """Returns (row, column, r): the image-array order, not (x, y)."""
    cx, cy, r = _smudge_fit(before, now, shape)
    return np.array([cy, cx, r])


MUTANTS += [
    ("11.11", "no baseline", smudge_without_baseline, "not where the features went"),
    ("11.11", "largest empty disc today", smudge_largest_empty_disc, "not where the features went"),
    ("11.11", "diameter", smudge_diameter, "not the diameter"),
    ("11.11", "row, column", smudge_row_col, "x and y swapped"),
]


# ----------------------------------------------------------------- 11.12 sky_rows

def _sky_count(images, *, strict=False):
    """Leading rows that are sky: each row's mean brightness over the frames >= 250 (or, strict, every pixel 255)."""
    stack = np.asarray(images, float)
    is_sky = (stack == 255).all(axis=(0, 2)) if strict else stack.mean(axis=(0, 2)) >= 250
    return int(np.argmin(is_sky)) if not is_sky.all() else len(is_sky)


def sky_without_margin(images):
    """Masks the clipped rows only: FAST's ring still reaches the sky from the 3 rows below."""
    return _sky_count(images)


def sky_ring_diameter(images):
    """Adds the ring's diameter (7 px, minus the centre) instead of its radius."""
    return _sky_count(images) + 6


def sky_as_fraction(images):
    """Returns the masked share of the image height."""
    return (_sky_count(images) + 3) / np.asarray(images[0]).shape[0]


def sky_every_pixel_white(images):
    """A row is sky only if every pixel is 255: the sensor noise stops it at the first noisy row."""
    return _sky_count(images, strict=True) + 3


MUTANTS += [
    ("11.12", "no ring margin", sky_without_margin, "FAST's 16-pixel ring has radius 3"),
    ("11.12", "ring diameter", sky_ring_diameter, "not its diameter"),
    ("11.12", "fraction", sky_as_fraction, "a fraction of the image height"),
    ("11.12", "every pixel 255", sky_every_pixel_white, "'every pixel == 255'"),
]


# ----------------------------------------------------------------- 11.13 exposure_change

def _exposure_fit(before, now, *, axis=1, fit_gain=True, max_length=25, m=16):
    """(gain, L): box-blur the baseline along `axis` for each L (scipy's uniform_filter1d), gain by least squares
    (or fixed at 1 with the ratio of means reported), the smallest residual away from the borders."""
    from scipy.ndimage import uniform_filter1d
    B = [np.asarray(b, float) for b in before]
    N = [np.asarray(x, float)[m:-m, m:-m] for x in now]
    best = (np.inf, 1.0, 1)
    for length in range(1, max_length + 1):
        bb = [uniform_filter1d(b, length, axis=axis)[m:-m, m:-m] for b in B]
        gain = (sum((x * y).sum() for x, y in zip(bb, N)) / sum((x * x).sum() for x in bb)) if fit_gain else 1.0
        res = sum(((y - gain * x) ** 2).sum() for x, y in zip(bb, N))
        if res < best[0]:
            best = (res, gain, length)
    gain = best[1] if fit_gain else float(np.mean(N) / np.mean([b[m:-m, m:-m] for b in B]))
    return np.array([gain, float(best[2])])


def exposure_correction_gain(before, now):
    """Reports the correction to apply (1 / gain) where the measured gain is asked."""
    g, length = _exposure_fit(before, now)
    return np.array([1 / g, length])


def exposure_half_width(before, now):
    """Reports the box's half-width as the blur length."""
    g, length = _exposure_fit(before, now)
    return np.array([g, length / 2])


def exposure_blur_along_columns(before, now):
    """Smears the baseline down the columns: the robot's motion is sideways in the image."""
    return _exposure_fit(before, now, axis=0)


def exposure_blur_without_gain(before, now):
    """Picks the blur that matches today's images with the baseline's brightness (gain from the means only)."""
    return _exposure_fit(before, now, fit_gain=False)


MUTANTS += [
    ("11.13", "correction gain", exposure_correction_gain, "(1 / gain)"),
    ("11.13", "half-width", exposure_half_width, "not its half-width"),
    ("11.13", "columns", exposure_blur_along_columns, "not down the columns"),
    ("11.13", "blur without gain", exposure_blur_without_gain, "not brightness-matched"),
]

MUTANTS += _FRONTIER_MUTANTS   # 11.17, in ch11_capstone_frontier.py
