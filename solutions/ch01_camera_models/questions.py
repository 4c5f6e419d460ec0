"""Chapter 1 — answers to the CONCEPT (1.1-1.4) and DESIGN (1.15-1.17) questions, computed from their formulas."""
import numpy as np

__all__ = ["pixel_1_1", "corner_shift_px", "sigma_Z_m", "R_cv_to_ros", "rs_skew_px", "max_rate_deg_s", "px_per_deg"]

# Exercise 1.1: X = (1, 2, 5), R = I, t = 0, fx = fy = 800, (cx, cy) = (320, 240)
pixel_1_1 = [800 * 1 / 5 + 320, 800 * 2 / 5 + 240]

# Exercise 1.2: corner pixel (0, 0), f = 1000, c = (640, 480), k1 = 0.05: shift = f k1 r^3
_r = np.hypot(640, 480) / 1000
corner_shift_px = 1000 * 0.05 * _r ** 3

# Exercise 1.3: sigma_Z = Z^2 sigma_d / (f B)
sigma_Z_m = 5.0 ** 2 * 0.25 / (700 * 0.12)

# Exercise 1.4: OpenCV camera axes -> ROS body axes: x_ros = z_cv, y_ros = -x_cv, z_ros = -y_cv
R_cv_to_ros = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], float)

# Exercise 1.15: skew = f tan(omega * readout)
rs_skew_px = 800 * np.tan(np.radians(90) * 0.033)

# Exercise 1.16: f tan(omega * readout) <= 1 px
max_rate_deg_s = np.degrees(np.arctan(1 / 600) / 0.010)

# Exercise 1.17: pinhole 90° HFOV over 1280 px (centre) vs equidistant fisheye 190° over 1280 px
px_per_deg = [640 / np.tan(np.radians(45)) * np.pi / 180, 640 / np.radians(95) * np.pi / 180]
