"""Exercises 3.1-3.4, 3.17-3.18, 3.20-3.22: answers to the CONCEPT and DESIGN questions, computed from their formulas."""
from __future__ import annotations

import numpy as np

# 3.1  eigenvalues (250, 180), (300, 2), (0.6, 0.3): both large, one large, both small
patch_types = ["corner", "edge", "flat"]

# 3.2  M = [[12, 3], [3, 8]], k = 0.04: R = det M - k tr(M)^2
_M = np.array([[12.0, 3.0], [3.0, 8.0]])
harris_R = float(np.linalg.det(_M) - 0.04 * np.trace(_M) ** 2)

# 3.3  SIFT: 128 float32; ORB: 256 bits
descriptor_bytes = [128 * 4, 256 // 8]

# 3.4  N x N x D multiply-adds
flops_per_pair = 2000 * 2000 * 128

# 3.17  100 images exhaustive: N (N - 1) / 2 pairs, each 2000 x 2000 x 128
exhaustive_100 = [100 * 99 / 2, 100 * 99 / 2 * 2000 * 2000 * 128]

# 3.18  10k exhaustive, 10k with top-50 retrieval, 1M with top-20 learned retrieval
pairs_at_scale = [10_000 * 9_999 / 2, 10_000 * 50, 1_000_000 * 20]

# 3.20  s = 3 intervals per octave: s DoG levels searched, each with a DoG level above and below (s + 2 DoG
# images, from s + 3 Gaussian images); k^s = 2; image i has sigma0 k^i, so image s has 2 sigma0
_s = 3
dog_octave = [_s + 3, _s + 2, 2 ** (1 / _s), _s]


# 3.21  FAST-9: 9 contiguous circle pixels all brighter ("b") or all darker ("d"); the circle wraps around
def _fast9(pattern: str, n: int = 9) -> bool:
    ring = pattern + pattern[:n - 1]
    return any(all(ring[i + j] == c for j in range(n)) for c in "bd" for i in range(len(pattern)))


fast9_corners = ["corner" if _fast9(p) else "not"
                 for p in ("sssddddddddddsss", "bbbbbsssssssbbbb", "bbbbbdbbbbbsssss", "ssddddddddssssbs",
                           "bbbbbddddsssssss")]

# 3.22  keep the nearest neighbour if d1 < rho d2
ratio_decisions = ["keep" if d1 < rho * d2 else "reject"
                   for d1, d2, rho in ((0.20, 0.50, 0.8), (0.10, 0.12, 0.8), (0.45, 0.70, 0.8), (0.30, 0.33, 0.8),
                                       (0.50, 0.55, 1.0))]
