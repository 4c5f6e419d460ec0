"""Chapter 4, 4.14 — the state of an incremental reconstruction (`_Model`: cameras, tracks, points, which
observations are used) and the camera model it uses: COLMAP's prior for an unknown camera and the radial
distortion x_d = x_n (1 + k1 r^2 + k2 r^4). The loop that grows it is `pipeline.incremental_sfm`.
"""
from __future__ import annotations

import numpy as np

from ..geometry import camera_centre


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

    def __init__(self, keypoints, tracks, K_list, sizes, camera_ids=None, focal_prior=None):
        n = len(keypoints)
        self.n, self.tracks = n, tracks
        self.camera = np.arange(n) if camera_ids is None else np.asarray(camera_ids)   # images of one camera
        self.why: dict[int, str] = {}                    # image -> why it is not (yet) registered
        self.known_K = K_list is not None
        self.K = np.array([np.asarray(K, float) for K in K_list]) if self.known_K else \
            np.array([default_intrinsics(w, h) for w, h in sizes])
        if not self.known_K and focal_prior is not None:             # e.g. EXIF: where self-calibration starts
            f = np.asarray(focal_prior, float)
            ok = np.isfinite(f) & (f > 0)
            self.K[ok, 0, 0] = self.K[ok, 1, 1] = f[ok]
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

    def shares_camera(self, i: int) -> bool:
        """True if another registered image was taken with image i's camera (its f is then known)."""
        return bool(np.any(self.registered & (self.camera == self.camera[i]) & (np.arange(self.n) != i)))

    def share_intrinsics(self, imgs: np.ndarray, intr: np.ndarray, moved: np.ndarray) -> bool:
        """The images of one camera share f, k1, k2. BA refines every image's own copy (intr: (len(imgs), 3)
        rows f, k1, k2 after BA, moved: which of them BA was free to change); each camera takes the median
        over its moved images (robust to one image whose f walked off along the focal-depth valley), written
        into intr and into every image of that camera in the model. True if a shared value changed a copy
        by more than 0.1 %, i.e. the poses must adapt to it."""
        changed = False
        for c in np.unique(self.camera[imgs[moved]]):
            mine = self.camera[imgs] == c
            shared = np.median(intr[mine & moved], axis=0)
            changed |= bool(np.any(np.abs(intr[mine, 0] / shared[0] - 1) > 1e-3))
            intr[mine] = shared
            every = self.camera == c
            self.K[every, 0, 0] = self.K[every, 1, 1] = shared[0]
            self.k[every] = shared[1:]
        return changed

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
