"""Questions 2.1-2.4 (CONCEPT) and 2.21-2.24 (DESIGN): the answers, computed from their formulas."""
import numpy as np


def _k(w, s, p=0.99):
    """RANSAC samples for one all-inlier sample with probability p: log(1 - p) / log(1 - w^s)."""
    return np.log(1 - p) / np.log(1 - w ** s)


# 2.1  t = (1, 0, 0), R = I, x1 = (0.5, 0.3, 1): l2 = [t]x R x1 = t x x1
l2_2_1 = np.cross([1.0, 0.0, 0.0], [0.5, 0.3, 1.0])

# 2.2  E: 3 + 3 - 1; F: 9 - 1 - 1; H: 9 - 1
dof_E_F_H = [5, 7, 8]

# 2.3  epipole e1 ~ K1 C2 with K1 = [[500, 0, 320], [0, 500, 240], [0, 0, 1]], C2 = (0.1, 0.05, 1)
_e = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]) @ [0.1, 0.05, 1.0]
epipole_2_3 = _e[:2] / _e[2]

# 2.4  w = 0.4, s = 5, p = 0.99
k_2_4 = np.ceil(_k(0.4, 5))

# 2.21  w = 0.5 at 1 ms per iteration: [8-point, 5-point] in ms
ransac_budget_ms = [np.ceil(_k(0.5, 8)) * 1.0, np.ceil(_k(0.5, 5)) * 1.0]

# 2.22  5-point, 50 ms at 1 ms per iteration, p = 0.99: smallest w with k <= 50
min_inlier_ratio = (1 - 0.01 ** (1 / 50)) ** (1 / 5)

# 2.23  (a) calibrated stereo rig, street; (b) internet photos; (c) drone over a flat field;
#       (d) panorama on the spot; (e) calibrated arm camera, cluttered table; (f) zoom lens, 3D scene
model_choice = ["E", "F", "H", "H", "E", "F"]

# 2.24  5-point: k(w = 0.4) / k(w = 0.6)
matcher_speedup = _k(0.4, 5) / _k(0.6, 5)
