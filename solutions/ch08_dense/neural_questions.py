"""Chapter 8's neural CONCEPT (8.4-8.7) and DESIGN (8.22-8.23) answers."""
from __future__ import annotations

import numpy as np

__all__ = ["quadrature_weights", "encoding_numbers", "gaussian_numbers", "raster_decisions", "memory_numbers",
           "flops_numbers"]

# 8.4: σ = (0, 1, 4, 2) / m, δ = 0.5 m
_a = 1 - np.exp(-np.array([0.0, 1.0, 4.0, 2.0]) * 0.5)
_w = np.cumprod(np.r_[1.0, 1 - _a[:-1]]) * _a
quadrature_weights = list(_w) + [_w.sum()]

# 8.5: 3 × 2 × 10; CDF (0, .1, .7, .9, 1) -> 3 + 0.4 / 0.6; 64 + 64 + 128
encoding_numbers = [60, 3 + 0.4 / 0.6, 256]

# 8.6: 3 + 4 + 3 + 1 + 48 = 59 floats
gaussian_numbers = [59, 236, 236]

# 8.7
raster_decisions = ["clone", "split", "prune", "reset", "dilate", "stop"]

# 8.22: 3.2 M Gaussians
memory_numbers = [3.2e6 * 236 / 1e6, 3.2e6 * 56 / 1e6, 4 * 3.2e6 * 236 / 1e6]

# 8.23: 800 × 800, 256 evaluations per ray, 593 408 MACs
_macs = 63 * 256 + 4 * 256 * 256 + 319 * 256 + 2 * 256 * 256 + 256 + 256 * 256 + 283 * 128 + 128 * 3
flops_numbers = [640000, 640000 * 256, 2 * _macs * 640000 * 256 / 1e12, 2 * _macs * 640000 * 256 / 1e12 / 10]
