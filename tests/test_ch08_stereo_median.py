"""The reference SGM's post-filter (solutions.ch08_dense.nan_median3): a 3×3 median over the kept disparities
only — a rejected (NaN) neighbour must not vote as disparity 0."""
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
