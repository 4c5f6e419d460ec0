"""11.12: the sky is the leading run of rows most of whose pixels are near-white (>= 250: the sensor noise leaves
clipped pixels at 253-255) over the frames; FAST's ring (radius 3) must not reach it, so mask 3 rows more."""
from __future__ import annotations

import numpy as np


def sky_rows(images, threshold=250, ring_radius=3):
    sat = np.mean([np.asarray(im) >= threshold for im in images], axis=(0, 2))   # saturated fraction of each row
    ground = np.flatnonzero(sat <= 0.5)
    first = int(ground[0]) if ground.size else sat.size
    return first + ring_radius
