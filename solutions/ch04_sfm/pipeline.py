"""Chapter 4, 4.14 — an incremental Structure-from-Motion pipeline in the manner of COLMAP, from scratch.

`incremental_sfm(problem)` takes keypoints and pairwise matches (the format of exercise 4.14 in
notebooks/04_sfm.ipynb) and returns registered cameras, 3D points and their tracks.

The loop (Schönberger & Frahm, "Structure-from-Motion Revisited", CVPR 2016):
  0. unknown cameras start at COLMAP's prior f = 1.2 max(w, h); each focal length is then
     self-calibrated from the fundamental matrices of its verified pairs (`focal_from_fundamental`,
     median over pairs), because landmark photos mix phone and telephoto lenses (here the true f
     runs from 0.65x to 2.3x the prior) and a pair initialised that far off triangulates little.
  1. initial pair: images by number of verified matches, each with its best partners, scored by
     `two_view_init` and ranked by `rank_initial_pairs` (many E inliers, low H/E ratio, wide
     enough triangulation angle); the first pair passing all tests is taken; global BA.
  2. next best view: the unregistered image that sees the most triangulated points; P3P inside
     RANSAC (12 px, as COLMAP), accepted with >= 30 inliers (>= 25 %). Unknown focal: a few focal
     lengths are tried and the best refined with the pose (COLMAP samples focal lengths the same way).
  3. triangulate the tracks the new image completes (multi-view DLT), keep points seen under
     >= 1.5 degrees with every observation within 4 px.
  4. local BA (the new image, its best-connected neighbours and the points it sees), then filter:
     observations over 4 px go, points left with fewer than 2 observations go.
  5. every few images a global BA, filtering, track completion and retriangulation, after which
     the images that failed are tried again (up to 3 failures each, COLMAP's max_reg_trials); when
     no image can be registered, a "rescue" round (global BA, track completion, triangulation of
     every pending track) and another try, for as long as rescues help; two final rounds with f,
     k1, k2 refined, and one more growth if they brought an image to 30 visible points. A model
     that ends with at most half the images is started again from the next initial pair.
  Images of one camera (camera_ids) share f, k1, k2: the camera's first image estimates them in
  PnP, the others reuse them, and BA's per-image copies are tied to their median.
Bundle adjustment is Chapter 5's `bundle_adjust` (BAL camera: rotation, translation, f, k1, k2).

Conventions: world-to-camera (R, t), OpenCV camera frame, pixels (x, y) with the centre of the
top-left pixel at (0, 0). Radial model (COLMAP RADIAL): x_d = x_n (1 + k1 r^2 + k2 r^4),
pixel = K x_d. A camera with unknown K starts at f = 1.2 max(w, h), principal point at the image
centre ((w - 1) / 2, (h - 1) / 2); f, k1, k2 are refined by BA, the principal point is held fixed.
"""
from __future__ import annotations

import time

import numpy as np
from scipy.spatial.transform import Rotation

from ..ch02_epipolar import ransac_essential, ransac_fundamental
from ..ch05_bundle_adjustment import bundle_adjust
from .initial_pair import rank_initial_pairs, self_calibrate, two_view_init
from .model import _Model, default_intrinsics, distort, undistort  # noqa: F401  (distort, undistort: re-exported)
from .pnp import pnp_ransac, pnp_ransac_focal, refine_pose
from .tracks import build_tracks, consistent_tracks
from .triangulation import reprojection_errors, triangulate_multiview


MAX_REPROJ_PX = 4.0         # filtering and inlier threshold (COLMAP: filter_max_reproj_error = 4)


MIN_TRI_ANGLE_DEG = 1.5     # COLMAP: tri_min_angle = filter_min_tri_angle = 1.5


MIN_PNP_INLIERS = 30        # COLMAP: abs_pose_min_num_inliers = 30


MIN_PNP_RATIO = 0.25        # COLMAP: abs_pose_min_inlier_ratio = 0.25


ABS_POSE_PX = 12.0          # COLMAP: abs_pose_max_error = 12 (registration RANSAC threshold)


MAX_REG_TRIALS = 3          # COLMAP: max_reg_trials = 3 (an image that failed is tried again after a global BA)


MIN_PAIR_MATCHES = 15       # COLMAP: min_num_inliers of a verified pair = 15


INIT_MIN_INLIERS = 100     # COLMAP: init_min_num_inliers = 100


INIT_MIN_ANGLE_DEG = 5.0    # COLMAP asks 16 degrees, then relaxes; landmark photos are often taken


                            # from one spot (here three telephoto shots < 2 degrees apart)
INIT_MAX_H_RATIO = 0.7      # COLMAP: 0.8 on its own two-view geometry. Our matches are already


                            # F-verified at 4 px, so H explains more of them; a pair whose parallax
                            # H cannot explain (low ratio) is what the initialisation needs
                            # COLMAP also rejects a baseline along the optical axis (init_max_forward_motion:
                            # |t_z| > 0.95 of the unit t); not here: landmark photos are taken from the front at
                            # several distances, and on Sacre Coeur the test turned down the pair (|t_z| = 0.995,
                            # 10.4 degrees) that registers all 10 photos for one that registers 5
INIT_MAX_TRIALS = 2         # initial pairs tried while the model holds at most half the images
FOCAL_FACTORS = np.geomspace(0.5, 3.0, 7)   # focal lengths tried for an uncalibrated image (x 1.2 max side)


_FLIP = np.diag([-1.0, -1.0, 1.0])          # Rz(pi): our z-forward camera <-> BAL's -z camera


def _triangulate_tracks(m: _Model, trks: np.ndarray) -> int:
    """(Re)triangulate the given tracks from their observations in registered images, drop the
    observations over 4 px and triangulate again, then keep points in front of every camera,
    within 4 px everywhere and seen under >= 1.5 degrees. Returns the number of new points."""
    if len(trks) == 0:
        return 0
    want = np.zeros(len(m.tracks), bool)
    want[trks] = True
    sel = want[m.obs_trk] & m.registered[m.obs_img]
    for _ in range(2):
        idx = np.flatnonzero(sel)
        P = np.concatenate([m.R[m.obs_img[idx]], m.t[m.obs_img[idx], :, None]], axis=2)
        X = triangulate_multiview(P, m.normalised(idx), m.obs_trk[idx], len(m.tracks))
        m.X[want] = X[want]
        ok = np.isfinite(m.X[m.obs_trk[idx]]).all(1)
        err = np.full(len(idx), np.inf)
        err[ok] = m.reproject(idx[ok])[0]
        good = err < MAX_REPROJ_PX
        if good.all():
            break
        sel[idx[~good]] = False
    idx = np.flatnonzero(sel)
    err = np.full(len(idx), np.inf)
    ok = np.isfinite(m.X[m.obs_trk[idx]]).all(1)
    err[ok] = m.reproject(idx[ok])[0]
    idx = idx[err < MAX_REPROJ_PX]
    count = np.bincount(m.obs_trk[idx], minlength=len(m.tracks))
    angle = m.max_angles(idx) if len(idx) else np.zeros(len(m.tracks))
    keep = want & (count >= 2) & (angle >= MIN_TRI_ANGLE_DEG)
    m.has_X[want] = keep[want]
    m.X[want & ~keep] = np.nan
    on = np.zeros(len(m.obs_on), bool)
    on[idx] = True
    m.obs_on[want[m.obs_trk]] = on[want[m.obs_trk]] & keep[m.obs_trk[want[m.obs_trk]]]
    return int(keep.sum())


def _filter(m: _Model) -> None:
    """COLMAP's filtering: drop observations over 4 px (or behind their camera), then points with
    fewer than 2 observations left or a largest triangulation angle under 1.5 degrees."""
    idx = np.flatnonzero(m.obs_on)
    err, _ = m.reproject(idx)
    m.obs_on[idx[err > MAX_REPROJ_PX]] = False
    idx = np.flatnonzero(m.obs_on)
    count = np.bincount(m.obs_trk[idx], minlength=len(m.tracks))
    angle = m.max_angles(idx) if len(idx) else np.zeros(len(m.tracks))
    dead = m.has_X & ((count < 2) | (angle < MIN_TRI_ANGLE_DEG))
    m.has_X[dead] = False
    m.X[dead] = np.nan
    m.obs_on &= m.has_X[m.obs_trk]


def _complete_tracks(m: _Model) -> None:
    """Re-attach observations of triangulated points in registered images that fit within 4 px
    (e.g. dropped by an earlier, worse pose), as COLMAP's track completion does."""
    idx = np.flatnonzero(~m.obs_on & m.has_X[m.obs_trk] & m.registered[m.obs_img])
    if len(idx):
        err, _ = m.reproject(idx)
        m.obs_on[idx[err < MAX_REPROJ_PX]] = True


def _bundle_adjust(m: _Model, cams: list[int] | None = None, points: np.ndarray | None = None,
                   max_iter: int = 30, loss: str = "cauchy", ftol: float = 1e-6, refine: str = "f",
                   intrinsics_of: list[int] | None = None) -> None:
    """Chapter 5's BA on the model: all registered cameras and points (global), or only cameras
    `cams` and points `points` (a local BA; the other cameras observing those points stay fixed).

    Cameras go to BAL form: R_bal = Rz(pi) R, t_bal = Rz(pi) t (BAL looks down -z), observations
    about the principal point. A known K is applied to the observations beforehand (x' = f0 K^-1 x,
    f0 = K[0, 0]) so BA sees a camera (f0, 0, 0) held fixed; an unknown camera refines f, k1, k2.
    The gauge: the first initial image's pose and one coordinate of the second's centre are fixed.
    refine: which intrinsics of unknown cameras move: "none", "f", "fk1" or "fk" (f, k1, k2);
    only those of images `intrinsics_of` (default: every free camera), and k only for cameras
    with >= 100 observations: from two views or a handful of points, f trades off against
    depth and k against the pose, and BA would wander off along those valleys.
    """
    if points is None:
        points = np.flatnonzero(m.has_X)
    pt_mask = np.zeros(len(m.tracks), bool)
    pt_mask[points] = True
    sel = np.flatnonzero(m.obs_on & pt_mask[m.obs_trk])
    if len(sel) == 0:
        return
    img_ids = np.unique(m.obs_img[sel])
    cam_of = {int(i): c for c, i in enumerate(img_ids)}
    pt_ids = np.unique(m.obs_trk[sel])
    pt_of = np.full(len(m.tracks), -1)
    pt_of[pt_ids] = np.arange(len(pt_ids))
    cam_idx = np.array([cam_of[int(i)] for i in m.obs_img[sel]])
    pt_idx = pt_of[m.obs_trk[sel]]
    obs = np.empty((len(sel), 2))
    cameras = np.zeros((len(img_ids), 9))
    for c, i in enumerate(img_ids):
        s = cam_idx == c
        K = m.K[i]
        xy = m.obs_xy[sel[s]]
        if m.known_K:
            obs[s] = K[0, 0] * ((xy - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T)
        else:
            obs[s] = xy - K[:2, 2]
        cameras[c, :3] = Rotation.from_matrix(_FLIP @ m.R[i]).as_rotvec()
        cameras[c, 3:6] = _FLIP @ m.t[i]
        cameras[c, 6], cameras[c, 7:9] = K[0, 0], m.k[i]
    fixed = np.zeros(cameras.shape, bool)
    n_free = {"none": 0, "f": 1, "fk1": 2, "fk": 3}[refine]
    fixed[:, 6 + n_free:] = True
    if m.known_K:
        fixed[:, 6:] = True
    if intrinsics_of is not None:
        fixed[~np.isin(img_ids, intrinsics_of), 6:] = True
    few = np.bincount(cam_idx, minlength=len(img_ids)) < 100
    fixed[few, 7:] = True
    # A coefficient that cannot move the image corner by 10 px per unit is not observable, only a
    # trade-off partner of f (a telephoto lens: r_max = 0.18, k2 moves the corner by 0.5 px)
    r_max = m.half_diag[img_ids] / cameras[:, 6]
    corner_px = m.half_diag[img_ids]
    fixed[r_max ** 2 * corner_px < 10, 7] = True
    fixed[r_max ** 4 * corner_px < 10, 8] = True
    if cams is not None:
        free = np.isin(img_ids, cams)
        fixed[~free] = True
    g0, g1 = m.gauge
    if g0 in cam_of:
        fixed[cam_of[g0], :6] = True
    if g1 in cam_of and g0 >= 0:
        rel = m.t[g1] - m.R[g1] @ m.R[g0].T @ m.t[g0]        # moves under a change of scale
        fixed[cam_of[g1], 3 + int(np.argmax(np.abs(_FLIP @ rel)))] = True
    start = cameras.copy()
    for _ in range(2):
        cameras, X, _ = bundle_adjust(start, m.X[pt_ids], cam_idx, pt_idx, obs, loss=loss, scale=2.0,
                                      max_iter=max_iter, ftol=ftol, fixed=fixed)
        # COLMAP's bogus-camera test: f / max(w, h) outside [0.1, 10] or |k| > 1 means BA walked down
        # the focal-depth (or distortion-pose) valley. Solve again with those intrinsics held.
        ratio = cameras[:, 6] / m.max_side[img_ids]
        bogus = (ratio < 0.1) | (ratio > 10) | np.any(np.abs(cameras[:, 7:9]) > 1.0, axis=1)
        if m.known_K or not bogus.any():
            break
        fixed[bogus, 6:] = True
    # Images of one camera: the shared f, k1, k2 (the median of the copies), then the poses and points adapt to it
    if not m.known_K and m.share_intrinsics(img_ids, cameras[:, 6:9], ~fixed[:, 6]):
        fixed[:, 6:] = True
        cameras, X, _ = bundle_adjust(cameras, X, cam_idx, pt_idx, obs, loss=loss, scale=2.0,
                                      max_iter=min(max_iter, 10), ftol=ftol, fixed=fixed)
    for c, i in enumerate(img_ids):
        m.R[i] = _FLIP @ Rotation.from_rotvec(cameras[c, :3]).as_matrix()
        m.t[i] = _FLIP @ cameras[c, 3:6]
        if not m.known_K:
            m.K[i, 0, 0] = m.K[i, 1, 1] = cameras[c, 6]
            m.k[i] = cameras[c, 7:9]
    m.X[pt_ids] = X


def _verify(keypoints, matches: dict, K_list, seed: int = 0) -> dict:
    """Geometric verification of raw matches: E by five-point RANSAC (known K) or F by seven-point
    RANSAC, 4 px; pairs with fewer than 15 inliers are dropped."""
    out = {}
    for (i, j), mt in matches.items():
        mt = np.asarray(mt, np.int64).reshape(-1, 2)
        if len(mt) < MIN_PAIR_MATCHES:
            continue
        x1, x2 = keypoints[i][mt[:, 0], :2], keypoints[j][mt[:, 1], :2]
        if K_list is not None:
            E, _, _, inl = ransac_essential(x1, x2, K_list[i], K_list[j], threshold=MAX_REPROJ_PX, rng=seed,
                                            max_iters=1000)
        else:
            E, inl = ransac_fundamental(x1, x2, threshold=MAX_REPROJ_PX, rng=seed, max_iters=2000)
        if E is not None and inl.sum() >= MIN_PAIR_MATCHES:
            out[(i, j)] = mt[inl]
    return out


def _try_pair(m: _Model, matches: dict, pair: tuple[int, int], result) -> bool:
    """Set up the model from one two-view result; True if it gave >= 30 good points."""
    (i, j), (R, t, _, inl) = pair, result
    if inl.sum() < MIN_PNP_INLIERS:
        return False
    m.R[i], m.t[i], m.R[j], m.t[j] = np.eye(3), np.zeros(3), R, t
    m.registered[[i, j]] = True
    m.order = [i, j]
    m.gauge = (i, j)
    mt = matches[(i, j)][inl]
    of_i = m.obs_img == i                               # keypoint of image i -> its track
    trk_of = np.full(max(int(mt[:, 0].max()), int(m.obs_kp[of_i].max(initial=0))) + 1, -1)
    trk_of[m.obs_kp[of_i]] = m.obs_trk[of_i]
    trks = np.unique(trk_of[mt[:, 0]])
    trks = trks[trks >= 0]
    if _triangulate_tracks(m, trks) >= MIN_PNP_INLIERS:
        _bundle_adjust(m, refine="none")
        _filter(m)
        return True
    m.registered[[i, j]] = False
    m.order, m.gauge = [], (-1, -1)
    m.has_X[:] = False
    m.obs_on[:] = False
    return False


def _initialise(m: _Model, keypoints, matches: dict, n_first: int = 3, n_partners: int = 3, seed: int = 0,
                verbose: bool = False, exclude: frozenset = frozenset()) -> bool:
    """Pick and reconstruct the initial pair, in COLMAP's order: first images by their number of
    verified matches overall (a pair inside a small, weakly attached cluster would strand the
    rest), each with its best-matched partners. The partners of a first image are scored with
    `two_view_init` (E and H inliers, median angle) and ranked by `rank_initial_pairs`; the
    first pair passing all three of its tests and giving >= 30 good points is taken. If no pair passes, a second round with twice the first images and partners; then every scored pair
    is tried in rank order. Pairs in `exclude` (tried before) are skipped."""
    degree = np.zeros(m.n)
    for (i, j), mt in matches.items():
        degree[[i, j]] += len(mt)
    scored: dict[tuple[int, int], tuple] = {}            # pair -> (two-view result, stats)

    def score(p):
        if p not in scored:
            mt, st = matches[p], {}
            res = two_view_init(keypoints[p[0]][mt[:, 0], :2], keypoints[p[1]][mt[:, 1], :2], m.K[p[0]], m.K[p[1]],
                                thresh_px=MAX_REPROJ_PX, seed=seed, stats=st)
            scored[p] = (res, st)
            if verbose:
                print("initial pair candidate", p, st)
        return scored[p]

    def passes(st):
        return (st["n_inliers_E"] >= INIT_MIN_INLIERS and st["median_angle_deg"] >= INIT_MIN_ANGLE_DEG
                and st["n_inliers_H"] <= INIT_MAX_H_RATIO * st["n_inliers_E"])

    # COLMAP's order; when no pair passes, a wider round (more first images, more partners) before any pair
    # that fails a test: on a larger set the best-connected images can all be shots from one spot
    for k_first, k_partners in ((n_first, n_partners), (2 * n_first, 2 * n_partners)):
        for a in np.argsort(-degree, kind="stable")[:k_first]:
            partners = sorted((p for p in matches if a in p and p not in exclude),
                              key=lambda p: -len(matches[p]))[:k_partners]
            stats = [score(p)[1] for p in partners]
            for r in rank_initial_pairs(stats, INIT_MIN_INLIERS, INIT_MAX_H_RATIO, INIT_MIN_ANGLE_DEG):
                if passes(stats[r]) and _try_pair(m, matches, partners[r], scored[partners[r]][0]):
                    return True
    pairs = [p for p in scored if p not in exclude]
    for r in rank_initial_pairs([scored[p][1] for p in pairs], INIT_MIN_INLIERS, INIT_MAX_H_RATIO, INIT_MIN_ANGLE_DEG):
        if _try_pair(m, matches, pairs[r], scored[pairs[r]][0]):
            return True
    return False


def _register(m: _Model, i: int, seed: int = 0) -> bool:
    """Register image i by P3P RANSAC on its 2D-3D correspondences, COLMAP's way: inlier threshold
    12 px (abs_pose_max_error; the 4 px filter after BA is the tight one), accepted with >= 30
    inliers making up >= 25 % of the correspondences. With an unknown focal length, the factors
    FOCAL_FACTORS x f are tried in one RANSAC (`pnp_ransac_focal`: every sample solved at every f; a
    wrong f bends the bearings, so it finds fewer inliers), the pose and f of the best are refined
    together on its inliers, and RANSAC runs once more with that f. Activates the inlier observations."""
    sel = np.flatnonzero((m.obs_img == i) & m.has_X[m.obs_trk])
    if len(sel) < MIN_PNP_INLIERS:
        m.why[i] = f"sees {len(sel)} triangulated points (< {MIN_PNP_INLIERS})"
        return False
    X, x = m.X[m.obs_trk[sel]], m.obs_xy[sel]
    if m.known_K or m.shares_camera(i):                 # f known, or refined on the camera's other images
        R, t, inl = pnp_ransac(X, x, m.K[i], thresh_px=ABS_POSE_PX, seed=seed)
    else:
        R, t, K, inl = pnp_ransac_focal(X, x, m.K[i], FOCAL_FACTORS, thresh_px=ABS_POSE_PX, seed=seed,
                                        max_iters=300)
        for _ in range(2 if R is not None else 0):      # pose and f on the inliers, which grow as they improve
            R, t, K = refine_pose(X[inl], x[inl], K, R, t, iters=20, refine_focal=True)
            inl = reprojection_errors(K, R, t, X, x) < ABS_POSE_PX
        if R is None or inl.sum() < MIN_PNP_INLIERS:
            m.why[i] = f"PnP: {inl.sum()} inliers of {len(sel)} at any focal length (< {MIN_PNP_INLIERS})"
            return False
        R, t, inl = pnp_ransac(X, x, K, thresh_px=ABS_POSE_PX, seed=seed, max_iters=1000)
        if R is None:
            m.why[i] = "PnP failed with the refined focal length"
            return False
        R, t, K = refine_pose(X[inl], x[inl], K, R, t, iters=10, refine_focal=True)
        m.K[i] = K
    if R is None or inl.sum() < MIN_PNP_INLIERS or inl.mean() < MIN_PNP_RATIO:
        n_in = 0 if R is None else int(inl.sum())
        m.why[i] = (f"PnP: {n_in} inliers of {len(sel)} 2D-3D matches (needs >= {MIN_PNP_INLIERS} and "
                    f">= {MIN_PNP_RATIO:.0%})")
        return False
    m.R[i], m.t[i] = R, t
    m.registered[i] = True
    m.order.append(i)
    m.obs_on[sel[inl]] = True
    return True


def _neighbours(m: _Model, i: int, n: int) -> list[int]:
    """The n registered images sharing the most used points with image i."""
    pts = np.unique(m.obs_trk[m.obs_on & (m.obs_img == i)])
    on = m.obs_on & np.isin(m.obs_trk, pts) & (m.obs_img != i)
    counts = np.bincount(m.obs_img[on], minlength=m.n)
    return [int(j) for j in np.argsort(-counts)[:n] if counts[j] > 0]


def _refine_all(m: _Model, max_iter: int, refine: str) -> None:
    """Track completion, triangulation of every pending track seen by 2+ registered images, a
    global BA and filtering."""
    _complete_tracks(m)
    _retriangulate(m)
    _bundle_adjust(m, max_iter=max_iter, refine=refine)
    _filter(m)


def _retriangulate(m: _Model) -> None:
    """Triangulate every pending track seen by 2+ registered images (after a BA moved the cameras, tracks
    that failed the 4 px or 1.5 degree tests may pass them now: COLMAP's retriangulation)."""
    seen = np.bincount(m.obs_trk[m.registered[m.obs_img]], minlength=len(m.tracks))
    _triangulate_tracks(m, np.flatnonzero(~m.has_X & (seen >= 2)))


def _grow(m: _Model, seed: int, local_window: int, global_every: int, log) -> None:
    """Steps 2-5 of the module docstring: register the next best view until none is left that can be.

    An image that fails is tried again when it sees more points, or after the next global BA (a better
    model; at most MAX_REG_TRIALS failures, COLMAP's max_reg_trials), or after a rescue round (global BA,
    track completion, retriangulation) when nothing else can be tried; rescues go on while they help
    (at most 2 in a row that register nothing)."""
    failed_at: dict[int, int] = {}                      # image -> visible points when it last failed
    trials = np.zeros(m.n, int)                         # failed registrations per image
    since_global, stalls = 0, 0
    while True:
        visible = np.bincount(m.obs_img[m.has_X[m.obs_trk]], minlength=m.n)
        cands = [i for i in np.argsort(-visible, kind="stable") if not m.registered[i]
                 and visible[i] >= MIN_PNP_INLIERS and visible[i] > failed_at.get(int(i), -1)]
        if not cands and failed_at and stalls < 2 and not m.registered.all():
            # Stuck: refine everything, complete tracks and triangulate what the registered images
            # now allow; the images that failed may see more points.
            _refine_all(m, max_iter=20, refine="fk1")
            stalls += 1
            failed_at.clear()                           # refined intrinsics and points: try them all again
            log(f"rescue round: {m.has_X.sum()} points")
            continue
        if not cands:
            break
        i = int(cands[0])
        if not _register(m, i, seed):
            failed_at[i] = int(visible[i])
            trials[i] += 1
            log(f"image {i}: registration failed ({m.why.get(i, '')})")
            continue
        stalls = 0
        m.why.pop(i, None)
        new_trks = np.unique(m.obs_trk[(m.obs_img == i) & ~m.has_X[m.obs_trk]])
        n_new = _triangulate_tracks(m, new_trks)
        # a camera already refined on other images keeps its intrinsics in the local BA (COLMAP's rule)
        _bundle_adjust(m, cams=[i, *_neighbours(m, i, local_window - 1)],
                       points=np.unique(m.obs_trk[m.obs_on & (m.obs_img == i)]), max_iter=10, ftol=1e-4,
                       refine="f", intrinsics_of=[] if m.shares_camera(i) else [i])
        _filter(m)
        since_global += 1
        if since_global >= global_every:
            _bundle_adjust(m, max_iter=20, ftol=1e-5, refine="fk1" if m.registered.sum() >= 4 else "f")
            _filter(m)
            _complete_tracks(m)
            _retriangulate(m)
            since_global = 0
            failed_at = {j: v for j, v in failed_at.items() if trials[j] >= MAX_REG_TRIALS}
        log(f"image {i}: registered, {n_new} new points, {m.has_X.sum()} in total")


def incremental_sfm(problem: dict, seed: int = 0, local_window: int = 6, global_every: int = 3,
                    verbose: bool = False, split_tracks: bool = False) -> dict:
    """Exercise 4.14: Incremental SfM (see the module docstring). problem (the 4.14 stub in notebooks/04_sfm.ipynb):
    keypoints: list of (N_i, 2) pixels; matches: {(i, j): (M, 2) int keypoint pairs}, i < j, raw or
    verified (they are verified again unless problem["verified"] is True); image_sizes: list of
    (width, height); K: list of (3, 3), or None for unknown intrinsics (f = 1.2 max(w, h), f, k1,
    k2 refined per camera); optional camera_ids: (n,) ints, images taken with one camera (same lens and
    zoom) share f, k1, k2 (self-calibrated together, then refined by BA as one: `_Model.share_intrinsics`);
    optional focal_prior: (n,) starting f in pixels (nan: none), e.g. from EXIF, searched around, not trusted.
    split_tracks: a component of matches with two keypoints of one image is split (`consistent_tracks`) rather
    than dropped (`build_tracks`, 4.11): repeated facades need it (Sceaux keeps 98.5 % of its matched keypoints
    instead of 71.5 %), at ~20 % more mapping CPU for the extra points; `reconstruct_folder` turns it on.
    Returns {"cameras": {i: {"R", "t", "K", "k"}} (registered only), "points": (P, 3),
    "tracks": list of P {image: keypoint}, "left_out": {i: why image i is not registered}}.
    """
    start = time.perf_counter()
    keypoints = [np.asarray(k, float)[:, :2] for k in problem["keypoints"]]
    K_list = problem.get("K")
    sizes = problem.get("image_sizes") or [(int(k[:, 0].max()) + 1, int(k[:, 1].max()) + 1) for k in keypoints]
    matches = {tuple(map(int, p)): np.asarray(v, np.int64).reshape(-1, 2) for p, v in problem["matches"].items()}
    matches = {(i, j) if i < j else (j, i): (v if i < j else v[:, ::-1]) for (i, j), v in matches.items()}
    if not problem.get("verified", False):
        matches = _verify(keypoints, matches, K_list, seed)
    tracks = consistent_tracks(matches) if split_tracks else build_tracks(matches)
    m = _Model(keypoints, tracks, K_list, sizes, problem.get("camera_ids"), problem.get("focal_prior"))
    if K_list is None and problem.get("self_calibrate", True):
        self_calibrate(m.K, keypoints, matches, min_matches=2 * MIN_PAIR_MATCHES, groups=problem.get("camera_ids"))
    K0 = m.K.copy()
    log = (lambda *a: print(f"[{time.perf_counter() - start:6.2f} s]", *a)) if verbose else (lambda *a: None)
    best, tried = None, set()
    # A model that stops with at most half the images may have started from a poor pair (a narrow or
    # repeated-structure one): start again from the best pair not tried yet and keep the larger model
    # (COLMAP's init_max_reg_trials = 2 and its further models).
    for attempt in range(INIT_MAX_TRIALS):
        if attempt:
            m = _Model(keypoints, tracks, K_list, sizes, problem.get("camera_ids"))
            m.K = K0.copy()
        if not _initialise(m, keypoints, matches, seed=seed, verbose=verbose, exclude=frozenset(tried)):
            log("no initial pair" + (" left" if tried else ""))
            break
        tried.add(tuple(m.order[:2]))
        log(f"initial pair {m.order}: {m.has_X.sum()} points")
        for _grow_round in range(2):   # the final refinement can bring an image to 30 visible points: grow once more
            _grow(m, seed, local_window, global_every, log)
            for _ in range(2):
                _refine_all(m, max_iter=50, refine="fk")
            visible = np.bincount(m.obs_img[m.has_X[m.obs_trk]], minlength=m.n)
            if not np.any(~m.registered & (visible >= MIN_PNP_INLIERS)):
                break
        log(f"done: {m.registered.sum()} images, {m.has_X.sum()} points")
        if best is None or m.registered.sum() > best.registered.sum():
            best = m
        if 2 * best.registered.sum() > best.n:
            break
    if best is None:
        return {"cameras": {}, "points": np.zeros((0, 3)), "tracks": [],
                "left_out": {i: "no initial pair: no pair passed the two-view tests" for i in range(len(keypoints))}}
    return _export(best)


def _export(m: _Model) -> dict:
    cameras = {int(i): {"R": m.R[i].copy(), "t": m.t[i].copy(), "K": m.K[i].copy(), "k": m.k[i].copy()}
               for i in np.flatnonzero(m.registered)}
    pts = np.flatnonzero(m.has_X)
    on = np.flatnonzero(m.obs_on)
    by_trk: dict[int, dict[int, int]] = {}
    for s in on:
        by_trk.setdefault(int(m.obs_trk[s]), {})[int(m.obs_img[s])] = int(m.obs_kp[s])
    tracks = [by_trk.get(int(p), {}) for p in pts]
    visible = np.bincount(m.obs_img[m.has_X[m.obs_trk]], minlength=m.n)
    left_out = {int(i): m.why.get(int(i), f"sees {visible[i]} triangulated points" + (
        f" (< {MIN_PNP_INLIERS}): too few verified matches with the registered images" if visible[i] < MIN_PNP_INLIERS
        else " after the last refinement, not tried again")) for i in np.flatnonzero(~m.registered)}
    return {"cameras": cameras, "points": m.X[pts].copy(), "tracks": tracks, "left_out": left_out}


def reprojection_stats(recon: dict, keypoints: list) -> dict:
    """Mean / median reprojection error (px) and observation count of a reconstruction dict."""
    errs = []
    for X, tr in zip(recon["points"], recon["tracks"]):
        for i, kp in tr.items():
            c = recon["cameras"][i]
            Xc = c["R"] @ X + c["t"]
            xd = distort(Xc[None, :2] / Xc[2], c["k"])[0]
            uv = c["K"][:2, :2] @ xd + c["K"][:2, 2]
            errs.append(np.linalg.norm(uv - np.asarray(keypoints[i])[kp, :2]))
    e = np.array(errs)
    return {"mean_px": float(e.mean()) if len(e) else np.nan, "median_px": float(np.median(e)) if len(e) else np.nan,
            "observations": len(e)}
