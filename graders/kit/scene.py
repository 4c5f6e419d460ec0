"""Synthetic ground truth: cameras, lenses, poses, points, targets and rendered textured planes.

Every random function takes `rng: np.random.Generator` first, so a grader's seed replays a case
exactly. Conventions (docs/CONVENTIONS.md): world-to-camera `X_c = R @ X_w + t` with `t: (3,)`,
OpenCV camera frame (+X right, +Y down, +Z forward), the centre of the top-left pixel is (0, 0),
`dist = (k1, k2, p1, p2, k3)`, fisheye `D = (k1, k2, k3, k4)` as `cv2.fisheye`.

Nothing here solves an exercise: the functions *make* scenes whose truth is known by construction
(points are sampled in the image and back-projected, homographies are written down from K, R, t).
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from graders.kit.geometry import kb_theta_d

# skimage.data images that ship inside the scikit-image wheel (no download needed).
TEXTURES: tuple[str, ...] = (
    "astronaut", "brick", "camera", "cell", "chelsea", "coffee", "coins", "grass", "gravel",
    "hubble_deep_field", "immunohistochemistry", "moon", "page", "retina", "rocket", "text",
)

# Ranges of (k1, k2, p1|p2 magnitude, k3) per strength of Brown-Conrady distortion.
_DISTORTION_RANGES: dict[str, tuple[tuple[float, float], tuple[float, float], float, tuple[float, float]]] = {
    "none": ((0.0, 0.0), (0.0, 0.0), 0.0, (0.0, 0.0)),
    "mild": ((-0.12, 0.05), (-0.03, 0.03), 5e-4, (0.0, 0.0)),
    "moderate": ((-0.28, -0.10), (0.0, 0.12), 1e-3, (-0.02, 0.02)),
    "strong": ((-0.45, -0.30), (0.08, 0.25), 2e-3, (-0.05, 0.05)),
}


# ============================================================ cameras and lenses ====

def random_intrinsics(rng: np.random.Generator, width: int = 640, height: int = 480,
                      hfov_deg: tuple[float, float] = (50.0, 90.0)) -> np.ndarray:
    """A realistic pinhole K: (3, 3) for a `width` x `height` image.

    Horizontal field of view uniform in `hfov_deg`, fy within 0.5% of fx (square-ish pixels),
    principal point within 3% of the image size from the centre ((w-1)/2, (h-1)/2), zero skew.
    """
    hfov = np.radians(rng.uniform(*hfov_deg))
    fx = (width / 2) / np.tan(hfov / 2)  # the image spans [-0.5, w - 0.5]: w pixels wide
    fy = fx * rng.uniform(0.995, 1.005)
    cx = (width - 1) / 2 + rng.uniform(-0.03, 0.03) * width
    cy = (height - 1) / 2 + rng.uniform(-0.03, 0.03) * height
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def max_normalised_radius(K: np.ndarray, width: int, height: int) -> float:
    """Largest radius |K^-1 (x, y, 1)| over the image's four outer corners (pinhole, no distortion)."""
    corners = np.array([[-0.5, -0.5, 1], [width - 0.5, -0.5, 1], [-0.5, height - 0.5, 1],
                        [width - 0.5, height - 0.5, 1]], float)
    x = np.linalg.solve(K, corners.T).T
    return float(np.max(np.linalg.norm(x[:, :2] / x[:, 2:], axis=1)))


def radial_slope(dist: np.ndarray, r: np.ndarray) -> np.ndarray:
    """d/dr of the distorted radius r (1 + k1 r^2 + k2 r^4 + k3 r^6). dist: (5,), r: (N,) -> (N,)."""
    k1, k2, _, _, k3 = np.asarray(dist, float)
    r2 = np.asarray(r, float) ** 2
    return 1 + 3 * k1 * r2 + 5 * k2 * r2**2 + 7 * k3 * r2**3


def distortion_is_monotonic(dist: np.ndarray, r_max: float, min_slope: float = 0.0) -> bool:
    """True if the radial mapping r -> r (1 + k1 r^2 + k2 r^4 + k3 r^6) keeps rising on [0, r_max].

    A mapping that folds back sends two undistorted radii to one distorted radius: undistortion
    is then ambiguous and iterative inverses diverge near the image corners.
    """
    return bool(np.all(radial_slope(dist, np.linspace(0.0, r_max, 512)) > min_slope))


def random_distortion(rng: np.random.Generator, strength: str = "moderate", r_max: float = 1.4,
                      max_tries: int = 1000) -> np.ndarray:
    """Brown-Conrady `dist = (k1, k2, p1, p2, k3)`: (5,) of a given strength.

    strength: 'none' | 'mild' | 'moderate' | 'strong' (barrel, k1 in [-0.45, -0.3], with k2, k3 and
    small tangential terms). Coefficients are redrawn until the radial mapping is monotonic (slope
    >= 0.1) up to the normalised radius `r_max`; 1.4 covers the corners of a 4:3 image at 90°
    horizontal FOV from `random_intrinsics` (use `max_normalised_radius(K, w, h)` for another camera).
    """
    if strength not in _DISTORTION_RANGES:
        raise ValueError(f"strength must be one of {list(_DISTORTION_RANGES)}, got {strength!r}")
    k1r, k2r, p, k3r = _DISTORTION_RANGES[strength]
    for _ in range(max_tries):
        dist = np.array([rng.uniform(*k1r), rng.uniform(*k2r), rng.uniform(-p, p), rng.uniform(-p, p),
                         rng.uniform(*k3r)])
        if distortion_is_monotonic(dist, r_max, min_slope=0.1):
            return dist
    raise RuntimeError(f"no monotonic {strength!r} distortion found up to r_max={r_max}; lower r_max")


def fisheye_theta_d(D: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Kannala-Brandt distorted angle: `graders.kit.geometry.kb_theta_d(theta, D)` (the one copy), kept
    under this name and argument order for existing callers. theta: (N,) -> (N,)."""
    return kb_theta_d(theta, D)


def fisheye_rises(D: np.ndarray, theta_max: float, min_slope: float = 0.3) -> bool:
    """True if theta_d(theta) rises with slope > `min_slope` on [0, theta_max] (radians): the lens maps
    those angles one-to-one, and its inverse is well conditioned there (no turnover near the range)."""
    theta = np.linspace(0.0, float(theta_max), 512)
    return bool(np.all(np.diff(kb_theta_d(theta, D)) / np.diff(theta) > min_slope))


def random_fisheye(rng: np.random.Generator, width: int = 1280, height: int = 1024,
                   fov_deg: float = 190.0, max_tries: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """A realistic Kannala-Brandt fisheye: K: (3, 3), D: (4,) for a `width` x `height` sensor.

    Near-equidistant (f = 320-380 px, small D), principal point within 1.5% of the centre. D is
    redrawn until theta_d keeps rising (slope >= 0.3) up to 5° beyond half the field of view.
    """
    f = rng.uniform(320, 380)
    K = np.array([[f, 0.0, (width - 1) / 2 + rng.uniform(-0.015, 0.015) * width],
                  [0.0, f * rng.uniform(0.995, 1.005), (height - 1) / 2 + rng.uniform(-0.015, 0.015) * height],
                  [0.0, 0.0, 1.0]])
    theta_max = np.radians(fov_deg / 2 + 5)
    for _ in range(max_tries):
        D = np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.02, 0.02), rng.uniform(-0.01, 0.01),
                      rng.uniform(-0.003, 0.003)])
        if fisheye_rises(D, theta_max):
            return K, D
    raise RuntimeError("no monotonic fisheye distortion found")


# ============================================================ poses ====

def look_at(C: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, -1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera (R: (3, 3), t: (3,)) of a camera at C: (3,) whose optical axis (+Z) passes
    through target: (3,), with the world direction `up` pointing up in the image (camera -Y).

    The default up = (0, -1, 0) suits a world that is itself y-down; pass (0, 0, 1) for z-up worlds.
    """
    C, target, up = (np.asarray(v, float) for v in (C, target, up))
    z = target - C
    if np.linalg.norm(z) == 0:
        raise ValueError("look_at: the camera centre and the target coincide")
    z = z / np.linalg.norm(z)
    x = np.cross(-up, z)  # right = down x forward, as in the OpenCV frame (x = y cross z)
    if np.linalg.norm(x) < 1e-9 * np.linalg.norm(up):
        raise ValueError("look_at: the viewing direction is parallel to `up`; pick another up vector")
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])  # rows: camera axes expressed in the world
    return R, -R @ C


def rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix R: (3, 3) of `angle` radians about `axis`: (3,) (Rodrigues' formula)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx


def random_rotation(rng: np.random.Generator, max_angle_deg: float | None = None) -> np.ndarray:
    """A random R: (3, 3). None: uniform over SO(3); else a uniformly random axis and an angle
    uniform in [0, max_angle_deg]."""
    if max_angle_deg is None:
        q = rng.normal(size=4)  # a normalised Gaussian 4-vector is a uniform unit quaternion
        w, x, y, z = q / np.linalg.norm(q)
        return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return rotation_about(rng.normal(size=3), np.radians(rng.uniform(0.0, max_angle_deg)))


def camera_centre(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Camera centre C: (3,) in the world, C = -R^T t."""
    return -np.asarray(R, float).T @ np.asarray(t, float)


def _perpendicular_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors e1, e2 with (e1, e2, n) orthonormal."""
    n = n / np.linalg.norm(n)
    a = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def random_rig(rng: np.random.Generator, n_cams: int, radius: float = 5.0,
               target: np.ndarray = (0.0, 0.0, 0.0), arc_deg: float = 360.0,
               elevation_deg: tuple[float, float] = (10.0, 30.0), jitter: float = 0.05,
               up: np.ndarray = (0.0, -1.0, 0.0)) -> list[tuple[np.ndarray, np.ndarray]]:
    """`n_cams` cameras on a ring (a band of a sphere cap) around `target`, all looking at it.

    Azimuths are evenly spaced over `arc_deg` from a random start, elevations above the plane
    perpendicular to `up` are uniform in `elevation_deg`, and `jitter` (metres, Gaussian std) moves
    each centre and each look-at point so the cameras are not perfectly symmetric.
    Returns [(R: (3, 3), t: (3,)), ...] world-to-camera.
    """
    target, up = np.asarray(target, float), np.asarray(up, float)
    u = up / np.linalg.norm(up)
    e1, e2 = _perpendicular_basis(u)
    step = np.radians(arc_deg) / (n_cams if arc_deg >= 360 else max(n_cams - 1, 1))
    start = rng.uniform(0, 2 * np.pi)
    rig = []
    for i in range(n_cams):
        az, el = start + i * step, np.radians(rng.uniform(*elevation_deg))
        C = target + radius * (np.cos(el) * (np.cos(az) * e1 + np.sin(az) * e2) + np.sin(el) * u)
        rig.append(look_at(C + jitter * rng.normal(size=3), target + jitter * rng.normal(size=3), up))
    return rig


# ============================================================ points and targets ====

def random_points_in_view(rng: np.random.Generator, K: np.ndarray, R: np.ndarray, t: np.ndarray, n: int,
                          depth: tuple[float, float] = (2.0, 10.0), width: int = 640, height: int = 480,
                          margin: float = 0.0) -> np.ndarray:
    """World points X: (n, 3) that a pinhole camera (K, R, t) sees inside its image.

    Exact by construction: pixels are drawn uniformly in [margin, width-1-margin] x
    [margin, height-1-margin], depths (camera Z, not distance) uniformly in `depth`, then
    back-projected. With lens distortion the projections move; pass a margin to keep them in.
    """
    uv1 = np.c_[rng.uniform(margin, width - 1 - margin, n), rng.uniform(margin, height - 1 - margin, n), np.ones(n)]
    X_c = rng.uniform(*depth, (n, 1)) * np.linalg.solve(K, uv1.T).T  # rays with Z = 1, scaled
    return (X_c - np.asarray(t, float)) @ np.asarray(R, float)  # R^T (X_c - t), row-wise


def random_point_cloud(rng: np.random.Generator, n: int, centre: np.ndarray = (0.0, 0.0, 0.0),
                       extent: float | np.ndarray = 1.0) -> np.ndarray:
    """X: (n, 3) uniform in the axis-aligned box of side(s) `extent` (scalar or (3,)) around `centre`."""
    return np.asarray(centre, float) + (rng.uniform(-0.5, 0.5, (n, 3)) * np.asarray(extent, float))


def chessboard(rows: int = 6, cols: int = 9, square: float = 0.025) -> np.ndarray:
    """Inner corners of a planar chessboard in its own frame: X: (rows*cols, 3), z = 0.

    Row-major like `cv2.findChessboardCorners(img, (cols, rows))`: x grows along a row (cols),
    y from one row to the next; the first corner is the origin.
    """
    j, i = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.c_[j.ravel() * square, i.ravel() * square, np.zeros(rows * cols)]


def add_noise(rng: np.random.Generator, x: np.ndarray, sigma: float) -> np.ndarray:
    """x plus i.i.d. Gaussian noise of std `sigma` on every coordinate (a new float64 array)."""
    x = np.asarray(x, float)
    return x + sigma * rng.normal(size=x.shape)


def add_outliers(rng: np.random.Generator, x: np.ndarray, fraction: float, width: int, height: int,
                 min_offset: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """Replace round(fraction * N) of the points x: (N, 2) by uniform random pixels.

    Each replacement lies at least `min_offset` px from the point it replaces, so every flagged
    point really is wrong. Returns (x_out: (N, 2), is_outlier: (N,) bool).
    """
    x = np.asarray(x, float)
    out = x.copy()
    is_outlier = np.zeros(len(x), bool)
    is_outlier[rng.choice(len(x), int(round(fraction * len(x))), replace=False)] = True
    todo = is_outlier.copy()
    while todo.any():
        out[todo] = np.c_[rng.uniform(0, width - 1, todo.sum()), rng.uniform(0, height - 1, todo.sum())]
        todo &= np.linalg.norm(out - x, axis=1) < min_offset
    return out, is_outlier


# ============================================================ textures and rendering ====

@lru_cache(maxsize=None)
def _texture(name: str) -> np.ndarray:
    import skimage.data
    from skimage.color import rgb2gray, rgba2rgb
    img = getattr(skimage.data, name)()
    if img.ndim == 3 and img.shape[2] == 4:
        img = rgba2rgb(img)
    if img.ndim == 3:
        img = rgb2gray(img)  # float in [0, 1]
    elif img.dtype == np.uint8:
        img = img / 255.0
    img = np.clip(np.asarray(img, np.float32), 0.0, 1.0)
    img.setflags(write=False)  # shared by the cache
    return img


def texture(name: str = "astronaut", size: tuple[int, int] | None = None) -> np.ndarray:
    """A grey float32 image in [0, 1] from skimage.data (names in TEXTURES); (H, W).

    size: optional (width, height) to resample to.
    """
    if name not in TEXTURES:
        raise ValueError(f"unknown texture {name!r}; choose one of {TEXTURES}")
    img = _texture(name)
    if size is not None:
        shrink = size[0] * size[1] < img.shape[0] * img.shape[1]
        img = cv2.resize(img, tuple(size), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    return np.clip(img, 0.0, 1.0).astype(np.float32)


def _plane_homography(K: np.ndarray, R: np.ndarray, t: np.ndarray, plane_size_m: tuple[float, float],
                      tex_shape: tuple[int, ...]) -> np.ndarray:
    """Unnormalised texture-pixel -> image-pixel homography whose third output is the camera depth."""
    rows, cols = tex_shape[:2]
    sx, sy = plane_size_m[0] / cols, plane_size_m[1] / rows
    # Texel (i, j) covers [i - 0.5, i + 0.5] in pixel-centre coordinates, so its centre sits at
    # ((i + 0.5) sx, (j + 0.5) sy) metres on the plane, and the texture spans [0, w] x [0, h].
    S = np.array([[sx, 0.0, sx / 2], [0.0, sy, sy / 2], [0.0, 0.0, 1.0]])
    R, t = np.asarray(R, float), np.asarray(t, float)
    return np.asarray(K, float) @ np.c_[R[:, 0], R[:, 1], t] @ S  # z = 0 drops R's third column


def _normalised(H: np.ndarray) -> np.ndarray:
    """H scaled so H[2, 2] = 1 (unit Frobenius norm in the rare case H[2, 2] ~ 0)."""
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 * np.linalg.norm(H) else H / np.linalg.norm(H)


def homography_from_plane(K: np.ndarray, R: np.ndarray, t: np.ndarray, plane_size_m: tuple[float, float],
                          tex_shape: tuple[int, ...]) -> np.ndarray:
    """H: (3, 3) mapping texture pixels to image pixels for a texture of shape `tex_shape` (rows,
    cols[, ...]) spread over the rectangle [0, w] x [0, h] metres of the world plane z = 0, seen by
    the camera (K, R, t). Both sides use pixel-centre coordinates; H[2, 2] = 1."""
    return _normalised(_plane_homography(K, R, t, plane_size_m, tex_shape))


def render_plane(texture_img: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                 plane_size_m: tuple[float, float] | None = None, width: int = 640, height: int = 480,
                 interpolation: int = cv2.INTER_LINEAR) -> tuple[np.ndarray, np.ndarray]:
    """Render the textured rectangle [0, w] x [0, h] of the world plane z = 0 into camera (K, R, t).

    plane_size_m: (w, h) in metres; default: 1 m wide with the texture's aspect ratio.
    Returns (image: (height, width) of texture_img's dtype, H: (3, 3) texture pixel -> image pixel,
    H[2, 2] = 1). Pixels the plane does not cover are 0; so are pixels whose ray meets the plane
    behind the camera. No lens distortion.
    """
    rows, cols = texture_img.shape[:2]
    if plane_size_m is None:
        plane_size_m = (1.0, rows / cols)
    H_raw = _plane_homography(K, R, t, plane_size_m, texture_img.shape)
    H = _normalised(H_raw)
    # warpPerspective samples src at H^-1 (x, y) with integer (x, y) = pixel centres: the same
    # convention as H, so H goes in unchanged.
    image = cv2.warpPerspective(texture_img, H, (width, height), flags=interpolation,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    w, h = plane_size_m
    corners = np.array([[0, 0, 0], [w, 0, 0], [0, h, 0], [w, h, 0]], float)
    if np.any((corners @ np.asarray(R, float).T + np.asarray(t, float))[:, 2] <= 0):
        # Part of the plane is behind the camera: the homography also maps those points, mirrored,
        # into the image. H_raw^-1 (x, y, 1) = (u, v, 1) / Z_c, so the ray hits in front iff > 0.
        xs, ys = np.meshgrid(np.arange(width), np.arange(height))
        inv_depth = np.tensordot(np.linalg.inv(H_raw)[2], np.stack([xs, ys, np.ones_like(xs)]), axes=1)
        image[inv_depth <= 0] = 0
    return image, H


def plane_depth(K: np.ndarray, R: np.ndarray, t: np.ndarray, plane_size_m: tuple[float, float],
                width: int = 640, height: int = 480) -> np.ndarray:
    """Exact depth (camera-frame Z) of the rectangle [0, w] x [0, h] of the world plane z = 0 seen by the
    camera (K, R, t), at every pixel centre: (height, width), inf where the ray misses the rectangle or
    meets the plane behind the camera. The depth map of `render_plane`'s image (same camera, same plane)."""
    R, t = np.asarray(R, float), np.asarray(t, float)
    n_c = R[:, 2]                                   # the plane's normal in the camera frame
    xs, ys = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    rays = np.stack([xs, ys, np.ones_like(xs)], -1) @ np.linalg.inv(np.asarray(K, float)).T   # (h, w, 3), z = 1
    with np.errstate(divide="ignore", invalid="ignore"):
        Z = (n_c @ t) / (rays @ n_c)                 # n_cᵀ (Z ray) = n_cᵀ t on the plane
    X_w = (Z[..., None] * rays - t) @ R              # back to the world: R^T (X_c - t)
    w, h = plane_size_m
    inside = (Z > 0) & (X_w[..., 0] >= 0) & (X_w[..., 0] <= w) & (X_w[..., 1] >= 0) & (X_w[..., 1] <= h)
    return np.where(inside, Z, np.inf)


def random_homography_pair(rng: np.random.Generator, texture_img: np.ndarray, max_angle_deg: float = 40.0,
                           width: int = 640, height: int = 480, max_roll_deg: float = 20.0,
                           scale_range: tuple[float, float] = (0.8, 1.25)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two views of a textured plane and the exact homography between them.

    View 1 looks at the plane almost head-on (within 5°) and sees nothing but the plane (its
    footprint spans 50-80% of the plane's width or height); view 2 is tilted by max_angle_deg/2..max_angle_deg about a random in-plane axis,
    rolled by up to `max_roll_deg`, and moved closer or further by a factor in `scale_range`.
    Returns (img1, img2, H12: (3, 3)) with x2 ~ H12 x1 in pixel-centre coordinates, H12[2, 2] = 1.
    """
    rows, cols = texture_img.shape[:2]
    size = (1.0, rows / cols)
    centre = np.array([size[0] / 2, size[1] / 2, 0.0])
    K = random_intrinsics(rng, width, height)
    # Distance at which the view's footprint is `coverage` of the plane in its tighter direction.
    d1 = rng.uniform(0.5, 0.8) * min(size[0] * K[0, 0] / width, size[1] * K[1, 1] / height)

    def view(tilt_deg: tuple[float, float], roll_deg: float, d: float, wander: float):
        in_plane = np.r_[rng.normal(size=2), 0.0]
        tilt = rotation_about(in_plane, np.radians(rng.uniform(*tilt_deg)))
        target = centre + np.r_[rng.uniform(-wander, wander, 2) * size, 0.0]
        R, t = look_at(target + d * tilt @ np.array([0.0, 0.0, -1.0]), target)  # camera on the z < 0 side
        roll = rotation_about([0.0, 0.0, 1.0], np.radians(rng.uniform(-roll_deg, roll_deg)))
        return roll @ R, roll @ t

    R1, t1 = view((0.0, 5.0), 5.0, d1, 0.03)
    R2, t2 = view((max_angle_deg / 2, max_angle_deg), max_roll_deg, d1 * rng.uniform(*scale_range), 0.1)
    img1, H1 = render_plane(texture_img, K, R1, t1, size, width, height)
    img2, H2 = render_plane(texture_img, K, R2, t2, size, width, height)
    return img1, img2, _normalised(H2 @ np.linalg.inv(H1))


# ============================================================ two-view scenes ====
# The two-view scenes of chapters 2 (epipolar geometry) and 4 (triangulation, two-view initialisation).

class _NotVisible(Exception):
    pass


def two_view(rng: np.random.Generator, n: int, **kw) -> dict:
    """A two-view scene with known geometry; see `_two_view_once` for the options. A draw in which
    camera 2 hardly sees the points is replaced by a fresh one (same generator, so still seeded)."""
    for _ in range(100):
        try:
            return _two_view_once(rng, n, **kw)
        except _NotVisible:
            continue
    raise RuntimeError(f"two_view: no visible scene for {kw}")


def _two_view_camera(rng: np.random.Generator, K1, depth, motion, baseline):
    """Camera 2's pose (R, t) and the scene's target for `_two_view_once`."""
    target = np.array([0.0, 0.0, np.mean(depth)]) + rng.normal(0, 0.1 * np.mean(depth), 3) * [1, 1, 0]
    if motion == "general":
        d = rng.normal(size=3) * [1.0, 0.5, 0.5]
    elif motion == "sideways":
        d = np.array([rng.choice([-1, 1]), 0.0, 0.0]) + rng.normal(0, 0.05, 3)
    elif motion == "forward":
        d = np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.08, 3) * [1, 1, 0]
        target = np.array([0.0, 0.0, 50.0]) + rng.normal(0, 3.0, 3) * [1, 1, 0]
    elif motion == "rotation":
        d = np.zeros(3)
    else:
        raise ValueError(motion)
    C2 = baseline * d / max(np.linalg.norm(d), 1e-12)
    up = np.array([0.0, -1.0, 0.0]) + rng.normal(0, 0.15, 3)   # a little roll
    if motion == "rotation":
        return random_rotation(rng, 12.0), np.zeros(3), target
    R, t = look_at(C2, target, up)
    return R, t, target


def _two_view_once(rng: np.random.Generator, n: int, *, width: int = 1280, height: int = 960,
                   noise: float = 0.0, outliers: float = 0.0, depth: tuple[float, float] = (2.0, 10.0),
                   motion: str = "general", baseline: float = 1.0,
                   roi: tuple[float, float, float, float] | None = None, planar: bool = False,
                   same_K: bool = False, held_out: int = 300,
                   hfov_deg: tuple[float, float] = (50.0, 90.0)) -> dict:
    """A two-view scene with known geometry. Camera 1 is (I, 0); camera 2 (R, t) looks at the scene.

    motion: 'general', 'sideways' (along camera 1's x), 'forward' (along its optical axis: the epipoles
    fall inside the images), 'rotation' (no translation: H = K2 R K1^-1). roi: (x0, y0, w, h) region of
    image 1 the points come from. planar: the points lie on one plane. Returns dict(K1, K2, R, t (unit,
    or 0), E, F, H (plane or rotation, else None), x1, x2 (noisy pixels, with outliers in x2), x1_true,
    x2_true, is_outlier, X, held_out=(x1, x2) noise-free matches of the same scene, width, height)."""
    from graders.kit.geometry import project, skew, to_h
    K1 = random_intrinsics(rng, width, height, hfov_deg=hfov_deg)
    K2 = K1.copy() if same_K else random_intrinsics(rng, width, height, hfov_deg=hfov_deg)
    R, t, target = _two_view_camera(rng, K1, depth, motion, baseline)
    plane = None
    if planar:
        n_plane = -np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.35, 3) * [1, 1, 0]
        n_plane /= np.linalg.norm(n_plane)
        plane = (n_plane, -n_plane @ target)                    # n . X + d0 = 0 through the target

    def draw(m):
        X, rounds = [], 0
        while sum(len(a) for a in X) < m:
            rounds += 1
            if rounds > 25:   # camera 2 hardly sees this region: draw another scene
                raise _NotVisible
            k = 4 * m
            box = (0, 0, width - 1, height - 1) if roi is None else roi
            uv = np.c_[rng.uniform(box[0], box[0] + box[2], k), rng.uniform(box[1], box[1] + box[3], k)]
            rays = np.linalg.solve(K1, to_h(uv).T).T
            Xi = rays * (rng.uniform(*depth, (k, 1)) if plane is None else (-plane[1] / (rays @ plane[0]))[:, None])
            u2, z2 = project(Xi, K2, R, t)
            inside = (u2[:, 0] >= 0) & (u2[:, 0] <= width - 1) & (u2[:, 1] >= 0) & (u2[:, 1] <= height - 1)
            X.append(Xi[(Xi[:, 2] > 0.5) & (z2 > 0.5) & inside])
        X = np.concatenate(X)[:m]
        return X, project(X, K1, np.eye(3), np.zeros(3))[0], project(X, K2, R, t)[0]

    X, x1_true, x2_true = draw(n)
    _, h1, h2 = draw(held_out)
    x1, x2 = add_noise(rng, x1_true, noise), add_noise(rng, x2_true, noise)
    is_outlier = np.zeros(n, bool)
    if outliers > 0:
        x2, is_outlier = add_outliers(rng, x2, outliers, width, height, min_offset=10.0)
    t_unit = t / np.linalg.norm(t) if np.linalg.norm(t) > 0 else t
    E = skew(t_unit) @ R
    H = None
    if plane is not None:   # X on n.X + d0 = 0:  X_2 = (R - t n^T / d0) X_1
        H = K2 @ (R - np.outer(t, plane[0]) / plane[1]) @ np.linalg.inv(K1)
    elif motion == "rotation":
        H = K2 @ R @ np.linalg.inv(K1)
    F = np.linalg.inv(K2).T @ E @ np.linalg.inv(K1)
    return {"K1": K1, "K2": K2, "R": R, "t": t_unit, "E": E,
            "F": F / np.linalg.norm(F) if np.linalg.norm(t) > 0 else np.zeros((3, 3)),
            "H": None if H is None else H / H[2, 2], "x1": x1, "x2": x2, "x1_true": x1_true,
            "x2_true": x2_true, "is_outlier": is_outlier, "X": X, "held_out": (h1, h2), "width": width,
            "height": height}
