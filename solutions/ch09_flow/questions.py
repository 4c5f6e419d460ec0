"""Chapter 9's CONCEPT (9.1-9.4) and DESIGN (9.21-9.23) answers."""
from __future__ import annotations

import math

normal_flow = [1.6, 1.2]                       # Exercise 9.1: −I_t ∇I / |∇I|² = 10 (4, 3) / 25
window_kinds = ["corner", "edge", "flat", "edge"]   # Exercise 9.2: λ_min ≥ 1 / only λ_max / neither
hs_update = [1 + 2 / 12, 0.5 + 1 / 12]         # Exercise 9.3: r = (2 + 0.5 − 3) / (1 + 4 + 1)
pyramid_levels = [4, 3, 5]                     # Exercise 9.4: smallest L with (2^(L+1) − 1) r ≥ D
application_trackers = ["CoTracker", "TAPIR", "RAFT", "LK", "CoTracker"]   # Exercise 9.21
budget_30hz = [1000 / 30, 6, 16]               # Exercise 9.22: ms per frame, RAFT every n-th frame, LK calls
corr_memory = [(90 * 160) ** 2 * 4 / 1e9, (47 * 156) ** 2 * 4 / 1e9, 8 * (1e9 / 4) ** 0.25]   # Exercise 9.23
