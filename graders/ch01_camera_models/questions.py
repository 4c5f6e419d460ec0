"""1.1-1.4 (CONCEPT) and 1.15-1.17 (DESIGN): numeric questions, answers computed from their formulas."""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs, relative
from graders.core.engine import numeric_question, register, value_hint
from .frames import gt_frame_change

register(
    # ---------------------------------------------------------------- CONCEPT
    numeric_question(
        id="1.1", title="Project a point by hand", name="pixel_1_1", kind="concept", expected=[480, 560], tol=0.5,
        unit="px", shape=(2,), metric=max_abs,
        explanation="x_c = (1, 2, 5); x/z = 0.2, y/z = 0.4; u = 800·0.2 + 320 = 480, v = 800·0.4 + 240 = 560.",
        hints=[value_hint([160, 320], "the principal point (cx, cy) was not added.")]),
    numeric_question(
        id="1.2", title="How far does k1 move a corner?", name="corner_shift_px", kind="concept", expected=25.6,
        tol=0.3, unit="px", shape=(), metric=max_abs,
        explanation="Corner pixel (0, 0) → normalised (−0.64, −0.48), r = 0.8. The radius becomes r(1 + k1 r²), so "
        "the shift is f·k1·r³ = 1000 · 0.05 · 0.512 = 25.6 px; at the centre it is 0: distortion grows with r³.",
        hints=[value_hint(32.0, "k1·r² is the relative change; the shift in pixels is f·k1·r²·r.")]),
    numeric_question(
        id="1.3", title="Stereo depth uncertainty", name="sigma_Z_m", kind="concept",
        expected=25 * 0.25 / (700 * 0.12), tol=0.001, unit="m", shape=(), metric=max_abs,
        explanation="Z = f B / d, so dZ/dd = −Z²/(f B) and σZ = Z² σ_d / (f B) = 25 · 0.25 / 84 = 0.0744 m.",
        hints=[value_hint(5 * 0.25 / (700 * 0.12), "depth error grows with Z², not Z (differentiate Z = fB/d).")]),
    numeric_question(
        id="1.4", title="OpenCV → ROS camera axes", name="R_cv_to_ros", kind="concept",
        expected=gt_frame_change("opencv", "ros"), tol=1e-9, unit="", shape=(3, 3), metric=max_abs,
        explanation="ROS x = forward = OpenCV z; ROS y = left = −OpenCV x; ROS z = up = −OpenCV y.",
        hints=[value_hint(gt_frame_change("ros", "opencv"), "transposed: that matrix maps ROS vectors to OpenCV.")]),
    # ---------------------------------------------------------------- DESIGN
    numeric_question(
        id="1.15", title="Rolling-shutter skew", name="rs_skew_px", kind="design",
        expected=800 * np.tan(np.radians(90 * 0.033)), tol=0.02 * 41.5, unit="px", shape=(), metric=max_abs,
        explanation="In 33 ms at 90°/s the camera turns 2.97°; at f = 800 px that moves the bottom rows by "
        "800·tan(2.97°) ≈ 41.5 px relative to the top — the pinhole model is badly violated.",
        hints=[value_hint(800 * 90 * 0.033, "degrees must be converted to radians before multiplying by f.")]),
    numeric_question(
        id="1.16", title="Rotation budget for a rolling shutter", name="max_rate_deg_s", kind="design",
        expected=np.degrees(np.arctan(1 / 600) / 0.010), tol=0.02 * 9.55, unit="°/s", shape=(), metric=max_abs,
        explanation="Skew ≤ 1 px means f·tan(ω·t_r) ≤ 1, so ω ≤ atan(1/600)/0.010 s = 0.167 rad/s ≈ 9.5°/s: slower "
        "than a walking robot turns, which is why moving robots use global-shutter cameras."),
    numeric_question(
        id="1.17", title="Pixels per degree: pinhole vs fisheye", name="px_per_deg", kind="design",
        expected=[640 / np.tan(np.radians(45)) * np.pi / 180, 640 / np.radians(95) * np.pi / 180], tol=0.02,
        unit="rel.", shape=(2,), metric=relative,
        explanation="Pinhole with 90° HFOV: f = 640/tan 45° = 640 px, so 11.2 px/° at the centre. Equidistant "
        "fisheye, 190° across 1280 px: f = 640/1.658 rad = 386 px, 6.7 px/° everywhere: 1.7× coarser, 2× the field."),
)
