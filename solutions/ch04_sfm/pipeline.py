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
  5. every few images a global BA, filtering and track completion; when no image can be
     registered, a "rescue" round (global BA, track completion, triangulation of every pending
     track) and another try; two final rounds with f, k1, k2 refined.
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
from ..geometry import camera_centre
from .initial_pair import rank_initial_pairs, self_calibrate, two_view_init
from .pnp import pnp_ransac, refine_pose
from .tracks import build_tracks
from .triangulation import triangulate_multiview


MAX_REPROJ_PX = 4.0         # filtering and inlier threshold (COLMAP: filter_max_reproj_error = 4)


MIN_TRI_ANGLE_DEG = 1.5     # COLMAP: tri_min_angle = filter_min_tri_angle = 1.5


MIN_PNP_INLIERS = 30        # COLMAP: abs_pose_min_num_inliers = 30


MIN_PNP_RATIO = 0.25        # COLMAP: abs_pose_min_inlier_ratio = 0.25


ABS_POSE_PX = 12.0          # COLMAP: abs_pose_max_error = 12 (registration RANSAC threshold)


MIN_PAIR_MATCHES = 15       # COLMAP: min_num_inliers of a verified pair = 15


INIT_MIN_INLIERS = 100     # COLMAP: init_min_num_inliers = 100


INIT_MIN_ANGLE_DEG = 5.0    # COLMAP asks 16 degrees, then relaxes; landmark photos are often taken


                            # from one spot (here three telephoto shots < 2 degrees apart)
INIT_MAX_H_RATIO = 0.7      # COLMAP: 0.8 on its own two-view geometry. Our matches are already


                            # F-verified at 4 px, so H explains more of them; a pair whose parallax
                            # H cannot explain (low ratio) is what the initialisation needs
FOCAL_FACTORS = np.geomspace(0.5, 3.0, 7)   # focal lengths tried for an uncalibrated image (x 1.2 max side)


_FLIP = np.diag([-1.0, -1.0, 1.0])          # Rz(pi): our z-forward camera <-> BAL's -z camera


def default_intrinsics(width: int, height: int) -> np.ndarray:
    """COLMAP's prior for an unknown camera: f = 1.2 max(w, h), principal point at the centre. (3, 3)."""
    f = 1.2 * max(width, height)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def distort(xn: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Radial distortion of normalised points: x_d = x_n (1 + k1 r^2 + k2 r^4).
    xn: (N, 2); k: (2,) one camera or (N, 2) one per point. Returns (N, 2)."""
    k = np.asarray(k, float)
    r2 = np.sum(xn * xn, axis=-1, keepdims=True)
    return xn * (1 + k[..., 0:1] * r2 + k[..., 1:2] * r2 * r2)


def undistort(xd: np.ndarray, k: np.ndarray, iters: int = 20) -> np.ndarray:
    """Invert `distort` by fixed-point iteration x_n <- x_d / (1 + k1 r^2 + k2 r^4) (converges for
    the mild distortion of photos). (N, 2) -> (N, 2)."""
    if not np.any(k):
        return xd
    xn = xd.copy()
    for _ in range(iters):
        r2 = np.sum(xn * xn, axis=-1, keepdims=True)
        xn = xd / (1 + k[0] * r2 + k[1] * r2 * r2)
    return xn


class _Model:
    """The growing reconstruction: cameras, tracks, 3D points and which observations are used.

    Observations are flattened over all tracks: obs_img, obs_trk (M,) ints and obs_xy (M, 2)
    pixels; obs_on (M,) marks those used by the model (image registered, point triangulated,
    error within 4 px). Points are indexed by track: X (T, 3), has_X (T,).
    """

    def __init__(self, keypoints, tracks, K_list, sizes):
        n = len(keypoints)
        self.n, self.tracks = n, tracks
        self.known_K = K_list is not None
        self.K = np.array([np.asarray(K, float) for K in K_list]) if self.known_K else \
            np.array([default_intrinsics(w, h) for w, h in sizes])
        self.k = np.zeros((n, 2))
        self.max_side = np.array([max(w, h) for w, h in sizes], float)
        self.half_diag = np.array([np.hypot(w, h) / 2 for w, h in sizes], float)
        self.R, self.t = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3))
        self.registered = np.zeros(n, bool)
        self.order: list[int] = []                       # registration order
        lengths = [len(tr) for tr in tracks]
        self.obs_trk = np.repeat(np.arange(len(tracks)), lengths).astype(np.int64)
        self.obs_img = np.array([i for tr in tracks for i in tr], np.int64)
        self.obs_kp = np.array([kp for tr in tracks for kp in tr.values()], np.int64)
        self.obs_xy = np.zeros((len(self.obs_img), 2))
        for i in range(n):
            sel = self.obs_img == i
            self.obs_xy[sel] = np.asarray(keypoints[i], float)[self.obs_kp[sel], :2]
        self.obs_on = np.zeros(len(self.obs_img), bool)
        self.X = np.full((len(tracks), 3), np.nan)
        self.has_X = np.zeros(len(tracks), bool)
        self.gauge = (-1, -1)                            # the initial pair fixes the gauge in BA

    # --- geometry of observations
    def normalised(self, sel: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates of observations sel: (m, 2)."""
        img, xy = self.obs_img[sel], self.obs_xy[sel]
        out = np.empty_like(xy)
        for i in np.unique(img):
            s = img == i
            xn = (xy[s] - self.K[i, :2, 2]) @ np.linalg.inv(self.K[i, :2, :2]).T
            out[s] = undistort(xn, self.k[i])
        return out

    def reproject(self, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Reprojection error (px) and depth of observations sel with their current points: (m,), (m,)."""
        img, X = self.obs_img[sel], self.X[self.obs_trk[sel]]
        Xc = np.einsum("mij,mj->mi", self.R[img], X) + self.t[img]
        z = Xc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xd = distort(Xc[:, :2] / z[:, None], self.k[img])
            uv = np.einsum("mij,mj->mi", self.K[img, :2, :2], xd) + self.K[img, :2, 2]
            err = np.linalg.norm(uv - self.obs_xy[sel], axis=1)
        return np.where((z > 0) & np.isfinite(err), err, np.inf), z

    def max_angles(self, sel: np.ndarray) -> np.ndarray:
        """For observations sel, the largest triangulation angle (deg) of each track they belong
        to, over pairs of those observations. Returns (T,) with 0 for tracks without two of them."""
        trk, img = self.obs_trk[sel], self.obs_img[sel]
        rays = camera_centre(self.R[img], self.t[img]) - self.X[trk]
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        order = np.argsort(trk, kind="stable")
        trk, rays = trk[order], rays[order]
        start = np.searchsorted(trk, trk)
        slot = np.arange(len(trk)) - start
        L = int(slot.max()) + 1 if len(slot) else 1
        uniq, row = np.unique(trk, return_inverse=True)
        pad = np.full((len(uniq), L, 3), np.nan)         # tracks x observations x 3, nan padded
        pad[row, slot] = rays
        cos = np.einsum("tac,tbc->tab", pad, pad)        # pairwise cosines, nan where padded
        out = np.zeros(len(self.tracks))
        with np.errstate(invalid="ignore"):
            out[uniq] = np.degrees(np.arccos(np.clip(np.nan_to_num(np.nanmin(cos.reshape(len(uniq), -1), 1),
                                                                   nan=1.0), -1, 1)))
        return out


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
                verbose: bool = False) -> bool:
    """Pick and reconstruct the initial pair, in COLMAP's order: first images by their number of
    verified matches overall (a pair inside a small, weakly attached cluster would strand the
    rest), each with its best-matched partners. The partners of a first image are scored with
    `two_view_init` (E and H inliers, median angle) and ranked by `rank_initial_pairs`; the
    first pair passing all three of its tests and giving >= 30 good points is taken. If no pair
    passes, a second round with twice the first images and partners; then every scored pair is tried in
    rank order."""
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
            partners = sorted((p for p in matches if a in p), key=lambda p: -len(matches[p]))[:k_partners]
            stats = [score(p)[1] for p in partners]
            for r in rank_initial_pairs(stats, INIT_MIN_INLIERS, INIT_MAX_H_RATIO, INIT_MIN_ANGLE_DEG):
                if passes(stats[r]) and _try_pair(m, matches, partners[r], scored[partners[r]][0]):
                    return True
    pairs = list(scored)
    for r in rank_initial_pairs([scored[p][1] for p in pairs], INIT_MIN_INLIERS, INIT_MAX_H_RATIO, INIT_MIN_ANGLE_DEG):
        if _try_pair(m, matches, pairs[r], scored[pairs[r]][0]):
            return True
    return False


def _register(m: _Model, i: int, seed: int = 0) -> bool:
    """Register image i by P3P RANSAC on its 2D-3D correspondences, COLMAP's way: inlier threshold
    12 px (abs_pose_max_error; the 4 px filter after BA is the tight one), accepted with >= 30
    inliers making up >= 25 % of the correspondences. With an unknown focal length, the factors
    FOCAL_FACTORS x f are tried (a wrong f bends the bearings, so it finds fewer inliers), the
    pose and f of the best are refined together on its inliers, and RANSAC runs once more with
    that f. Activates the inlier observations."""
    sel = np.flatnonzero((m.obs_img == i) & m.has_X[m.obs_trk])
    if len(sel) < MIN_PNP_INLIERS:
        return False
    X, x = m.X[m.obs_trk[sel]], m.obs_xy[sel]
    if m.known_K:
        R, t, inl = pnp_ransac(X, x, m.K[i], thresh_px=ABS_POSE_PX, seed=seed)
    else:
        best = (None, None, np.zeros(len(sel), bool), None)
        for factor in FOCAL_FACTORS:
            K = m.K[i].copy()
            K[:2, :2] *= factor
            R, t, inl = pnp_ransac(X, x, K, thresh_px=ABS_POSE_PX, seed=seed, max_iters=300)
            if R is not None and inl.sum() > best[2].sum():
                best = (R, t, inl, K)
        R, t, inl, K = best
        if R is None or inl.sum() < MIN_PNP_INLIERS:
            return False
        R, t, K = refine_pose(X[inl], x[inl], K, R, t, iters=20, refine_focal=True)
        R, t, inl = pnp_ransac(X, x, K, thresh_px=ABS_POSE_PX, seed=seed, max_iters=1000)
        if R is None:
            return False
        R, t, K = refine_pose(X[inl], x[inl], K, R, t, iters=10, refine_focal=True)
        m.K[i] = K
    if R is None or inl.sum() < MIN_PNP_INLIERS or inl.mean() < MIN_PNP_RATIO:
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
    seen = np.bincount(m.obs_trk[m.registered[m.obs_img]], minlength=len(m.tracks))
    _triangulate_tracks(m, np.flatnonzero(~m.has_X & (seen >= 2)))
    _bundle_adjust(m, max_iter=max_iter, refine=refine)
    _filter(m)


def incremental_sfm(problem: dict, seed: int = 0, local_window: int = 6, global_every: int = 3,
                    verbose: bool = False) -> dict:
    """Exercise 4.14: Incremental SfM (see the module docstring). problem (the 4.14 stub in notebooks/04_sfm.ipynb):
    keypoints: list of (N_i, 2) pixels; matches: {(i, j): (M, 2) int keypoint pairs}, i < j, raw or
    verified (they are verified again unless problem["verified"] is True); image_sizes: list of
    (width, height); K: list of (3, 3), or None for unknown intrinsics (f = 1.2 max(w, h), f, k1,
    k2 refined per camera); optional camera_ids: (n,) ints, images taken with one camera (same lens and
    zoom) share one self-calibrated starting f.
    Returns {"cameras": {i: {"R", "t", "K", "k"}} (registered only), "points": (P, 3),
    "tracks": list of P {image: keypoint}}.
    """
    start = time.perf_counter()
    keypoints = [np.asarray(k, float)[:, :2] for k in problem["keypoints"]]
    K_list = problem.get("K")
    sizes = problem.get("image_sizes") or [(int(k[:, 0].max()) + 1, int(k[:, 1].max()) + 1) for k in keypoints]
    matches = {tuple(map(int, p)): np.asarray(v, np.int64).reshape(-1, 2) for p, v in problem["matches"].items()}
    matches = {(i, j) if i < j else (j, i): (v if i < j else v[:, ::-1]) for (i, j), v in matches.items()}
    if not problem.get("verified", False):
        matches = _verify(keypoints, matches, K_list, seed)
    m = _Model(keypoints, build_tracks(matches), K_list, sizes)
    if K_list is None and problem.get("self_calibrate", True):
        self_calibrate(m.K, keypoints, matches, min_matches=2 * MIN_PAIR_MATCHES, groups=problem.get("camera_ids"))
    log = (lambda *a: print(f"[{time.perf_counter() - start:6.2f} s]", *a)) if verbose else (lambda *a: None)
    if not _initialise(m, keypoints, matches, seed=seed, verbose=verbose):
        log("no initial pair")
        return {"cameras": {}, "points": np.zeros((0, 3)), "tracks": []}
    log(f"initial pair {m.order}: {m.has_X.sum()} points")
    failed_at: dict[int, int] = {}                      # image -> visible points when it last failed
    since_global, rescues = 0, 0
    while True:
        visible = np.bincount(m.obs_img[m.has_X[m.obs_trk]], minlength=m.n)
        cands = [i for i in np.argsort(-visible, kind="stable") if not m.registered[i]
                 and visible[i] >= MIN_PNP_INLIERS and visible[i] > failed_at.get(int(i), -1)]
        if not cands and failed_at and rescues < 2 and not m.registered.all():
            # Stuck: refine everything, complete tracks and triangulate what the registered images
            # now allow (COLMAP's retriangulation); the images that failed may see more points.
            _refine_all(m, max_iter=20, refine="fk1")
            rescues += 1
            failed_at.clear()                           # refined intrinsics and points: try them all again
            log(f"rescue round {rescues}: {m.has_X.sum()} points")
            continue
        if not cands:
            break
        i = int(cands[0])
        if not _register(m, i, seed):
            failed_at[i] = int(visible[i])
            log(f"image {i}: registration failed ({visible[i]} visible points)")
            continue
        new_trks = np.unique(m.obs_trk[(m.obs_img == i) & ~m.has_X[m.obs_trk]])
        n_new = _triangulate_tracks(m, new_trks)
        _bundle_adjust(m, cams=[i, *_neighbours(m, i, local_window - 1)],
                       points=np.unique(m.obs_trk[m.obs_on & (m.obs_img == i)]), max_iter=10, ftol=1e-4,
                       refine="f", intrinsics_of=[i])
        _filter(m)
        since_global += 1
        if since_global >= global_every:
            _bundle_adjust(m, max_iter=20, ftol=1e-5, refine="fk1" if m.registered.sum() >= 4 else "f")
            _filter(m)
            _complete_tracks(m)
            since_global = 0
        log(f"image {i}: registered, {n_new} new points, {m.has_X.sum()} in total")
    for _ in range(2):
        _refine_all(m, max_iter=50, refine="fk")
    log(f"done: {m.registered.sum()} images, {m.has_X.sum()} points")
    return _export(m)


def _export(m: _Model) -> dict:
    cameras = {int(i): {"R": m.R[i].copy(), "t": m.t[i].copy(), "K": m.K[i].copy(), "k": m.k[i].copy()}
               for i in np.flatnonzero(m.registered)}
    pts = np.flatnonzero(m.has_X)
    on = np.flatnonzero(m.obs_on)
    by_trk: dict[int, dict[int, int]] = {}
    for s in on:
        by_trk.setdefault(int(m.obs_trk[s]), {})[int(m.obs_img[s])] = int(m.obs_kp[s])
    tracks = [by_trk.get(int(p), {}) for p in pts]
    return {"cameras": cameras, "points": m.X[pts].copy(), "tracks": tracks}


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
