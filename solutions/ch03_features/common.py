"""Chapter 3 reference: what every topic module needs (numpy only)."""
from __future__ import annotations

import numpy as np


def gray(img: np.ndarray) -> np.ndarray:
    """(H, W) uint8 or float image -> float64 in [0, 1]."""
    img = np.asarray(img)
    return img / 255.0 if img.dtype == np.uint8 else img.astype(np.float64)
