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


def test_speckle_filter_drops_small_islands_and_keeps_surfaces():
    from solutions.ch08_dense import filter_speckles
    D = np.full((12, 12), 5.0)
    D[:, 6:] += np.linspace(0, 3, 6)              # a slanted surface: steps of 0.6 px, one region with the rest
    D[2:4, 2:4] = 20.0                            # a 4-pixel island far from its surroundings
    D[8, 1] = np.nan                              # a rejected pixel stays rejected and links nothing
    out = filter_speckles(D, max_size=4, max_diff=1.0)
    assert np.isnan(out[2:4, 2:4]).all() and np.isnan(out[8, 1])
    assert np.isfinite(out).sum() == 144 - 5 and np.allclose(out[np.isfinite(out)], D[np.isfinite(out)])
    assert np.isfinite(filter_speckles(D, max_size=3, max_diff=1.0)[2:4, 2:4]).all()     # 4 > 3: kept


def test_speckle_filter_matches_opencv_on_random_disparities():
    """cv2.filterSpeckles (4-connected, |d_p - d_q| <= maxDiff, regions of <= maxSpeckleSize pixels) on 1/16 px."""
    cv2 = __import__("pytest").importorskip("cv2")
    from solutions.ch08_dense import filter_speckles
    rng = np.random.default_rng(3)
    D = np.round(ndimage.zoom(rng.uniform(0, 30, (6, 8)), 6, order=0) + rng.integers(0, 3, (36, 48)))
    D[rng.uniform(size=D.shape) < 0.1] = np.nan
    fixed = np.where(np.isnan(D), -16, D * 16).astype(np.int16)
    cv2.filterSpeckles(fixed, -16, 20, 16)
    assert np.array_equal(np.isnan(filter_speckles(D, 20, 1.0)), fixed == -16)


def test_uniqueness_rejects_an_ambiguous_winner_only():
    from solutions.ch08_dense.stereo import _wta_subpixel_lr
    C = np.full((1, 8, 12), 100.0)                # (H, D, W): every pixel's costs over 8 disparities
    C[0, 3, :] = 50.0                             # a clear winner at d = 3 for every x ...
    C[0, 4, :] = 52.0                             # ... whose neighbour d = 4 is no rival (|d - 3| <= 1)
    C[0, 7, 9] = 54.0                             # x = 9: a distant rival within 100 / (100 - 10) of the best
    D = _wta_subpixel_lr(C, max_lr_diff=8, uniqueness=10)
    assert np.isnan(D[0, 9]) and np.isfinite(D[0, 3:9]).all() and np.isfinite(D[0, 10:]).all()
    assert np.isfinite(_wta_subpixel_lr(C, max_lr_diff=8, uniqueness=5)[0, 9])      # 54 * 95 >= 50 * 100


def test_synthetic_scene_ground_truth_is_exact():
    """benchmarks.ch08_dense_scenes: every left pixel that the right view sees (not occluded) has the right image's value
    at x - d_gt (up to the added noise), and the textureless patches are flat in the left view."""
    from benchmarks.ch08_dense_scenes import scene_pair
    p = scene_pair(np.random.default_rng(4), H=60, W=120, d_max=24, noise=0.0, contrast=(0.15, 0.15))
    yy, xx = np.mgrid[0:60, 0:120].astype(float)
    warped = ndimage.map_coordinates(p["I_r"], [yy, xx - p["D_gt"]], order=3, mode="nearest")
    seen = ~p["occluded"] & (xx - p["D_gt"] > 3) & (xx < 117)
    assert p["occluded"].any() and seen.mean() > 0.6 and 2 <= p["D_gt"].min() and p["D_gt"].max() <= 24 - 4
    assert np.median(np.abs(warped - p["I_l"])[seen]) < 0.01         # vs ~0.15 contrast: the right pixel
    assert np.abs(warped - p["I_l"])[seen].mean() < 0.02
    g = np.abs(ndimage.sobel(p["I_l"], 1))
    core = ndimage.binary_erosion(p["flat"], iterations=3)
    assert core.any() and g[core].mean() < 0.2 * g[~p["flat"]].mean()
