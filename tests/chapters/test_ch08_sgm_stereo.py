"""The reference SGM's pieces beyond 8.9: the NaN-aware 3×3 post-filter (solutions.ch08_dense.nan_median3) — a
rejected (NaN) neighbour must not vote as disparity 0 — and the optional 16 paths."""
import numpy as np
from scipy import ndimage

from solutions.ch08_dense.stereo import nan_median3


def test_rejected_neighbours_do_not_vote():
    D = np.full((3, 3), np.nan)
    D[1, 1], D[0, 0], D[0, 1], D[2, 2] = 10.0, 10.0, 11.0, 12.0       # 4 kept, 5 rejected
    out = nan_median3(D)
    assert out[1, 1] == 10.5                                   # median of (10, 10, 11, 12), not of five 0s
    assert np.isnan(out[np.isnan(D)]).all()                    # rejected pixels stay rejected


def test_equals_the_plain_median_where_every_neighbour_is_kept():
    D = np.random.default_rng(0).uniform(0, 64, (20, 30))
    assert np.allclose(nan_median3(D)[1:-1, 1:-1], ndimage.median_filter(D, size=3)[1:-1, 1:-1])


def _path_brute(C, P1, P2, dy, dx):
    """L_r for r = (dy, dx), one pixel at a time in an order that visits p − r before p."""
    H, W, _ = C.shape
    L = np.zeros_like(C)
    for y in (range(H) if dy >= 0 else range(H - 1, -1, -1)):
        for x in (range(W) if dx >= 0 else range(W - 1, -1, -1)):
            py, px = y - dy, x - dx
            if not (0 <= py < H and 0 <= px < W):
                L[y, x] = C[y, x]
                continue
            prev = L[py, px]
            near = np.minimum(np.r_[np.inf, prev[:-1]], np.r_[prev[1:], np.inf]) + P1
            L[y, x] = C[y, x] + np.minimum(np.minimum(prev, near), prev.min() + P2) - prev.min()
    return L


def test_sixteen_paths_are_hirschmullers_sixteen_directions():
    from solutions.ch08_dense import sgm
    C = np.random.default_rng(1).uniform(0, 10, (9, 11, 5))
    dirs = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1),           # (dy, dx)
            (1, 2), (1, -2), (-1, 2), (-1, -2), (2, 1), (2, -1), (-2, 1), (-2, -1)]
    assert len(dirs) == 16
    assert np.allclose(sgm(C, 1.0, 5.0, 16), sum(_path_brute(C, 1.0, 5.0, *r) for r in dirs))
