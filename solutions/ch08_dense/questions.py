"""Chapter 8's geometry CONCEPT (8.1-8.3) and DESIGN (8.24) answers."""
from __future__ import annotations

import numpy as np

__all__ = ["depth_numbers", "sgm_decisions", "sweep_numbers", "method_choice"]

# 8.1: f = 700 px, B = 0.12 m, d = 14 px, ±0.25 px, Z_min = 0.5 m
_fB = 700 * 0.12
depth_numbers = [_fB / 14, (_fB / 14) ** 2 / _fB * 0.25, np.ceil(_fB / 0.5)]

# 8.2
sgm_decisions = ["none", "P1", "P2", "rejected", "kept", "rejected"]

# 8.3: X2 = X1 - C2 on the plane Z = 4: (0.64 - 0.2, 0, 4) -> x2 = 320 + 500 * 0.44 / 4
sweep_numbers = [320 + 500 * (0.64 - 0.2) / 4, 240.0, 2]

# 8.24
method_choice = ["SGM", "MVS", "3DGS", "NeRF", "SGM"]
