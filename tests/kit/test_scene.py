"""graders.kit.scene makes ground truth; these tests check it against OpenCV, not against itself."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from graders.kit import scene


def project(X: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, dist: np.ndarray | None = None) -> np.ndarray:
    """cv2.projectPoints as the independent oracle. X: (N, 3) -> (N, 2)."""
    uv, _ = cv2.projectPoints(np.asarray(X, float).reshape(-1, 1, 3), cv2.Rodrigues(R)[0], t.reshape(3, 1), K,
                              np.zeros(5) if dist is None else dist)
    return uv.reshape(-1, 2)


def is_rotation(R: np.ndarray) -> bool:
    return np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(R), 1.0)


# ============================================================ cameras ====

@pytest.mark.parametrize("seed", range(5))
def test_random_intrinsics_are_realistic(seed):
    rng = np.random.default_rng(seed)
    K = scene.random_intrinsics(rng, width=1280, height=960, hfov_deg=(50, 90))
    assert K.shape == (3, 3) and K[0, 1] == 0 and np.array_equal(K[2], [0, 0, 1])
    assert abs(K[1, 1] / K[0, 0] - 1) < 0.01
    assert abs(K[0, 2] - 639.5) <= 0.03 * 1280 and abs(K[1, 2] - 479.5) <= 0.03 * 960
    hfov = np.degrees(2 * np.arctan(640 / K[0, 0]))
    assert 50 - 1e-9 <= hfov <= 90 + 1e-9


@pytest.mark.parametrize("strength", ["mild", "moderate", "strong"])
def test_distortion_is_monotonic_over_the_whole_image(strength):
    # Independent check with OpenCV: points on the ray to the farthest image corner must land
    # further and further from the principal point once distorted.
    rng = np.random.default_rng(7)
    for _ in range(40):
        K = scene.random_intrinsics(rng, width=1280, height=960, hfov_deg=(85, 90))
        r_max = scene.max_normalised_radius(K, 1280, 960)
        assert r_max < 1.4  # the default r_max of random_distortion covers this camera
        dist = scene.random_distortion(rng, strength)
        assert dist.shape == (5,)
        direction = rng.normal(size=2)
        direction /= np.linalg.norm(direction)
        r = np.linspace(0.0, r_max, 400)
        X = np.c_[r[:, None] * direction, np.ones_like(r)]
        uv = project(X, K, np.eye(3), np.zeros(3), dist)
        radii = np.linalg.norm((uv - K[:2, 2]) / np.diag(K)[:2], axis=1)
        assert np.all(np.diff(radii) > 0), dist


def test_distortion_strengths():
    rng = np.random.default_rng(0)
    assert np.array_equal(scene.random_distortion(rng, "none"), np.zeros(5))
    strong = np.array([scene.random_distortion(rng, "strong") for _ in range(50)])
    assert np.all((strong[:, 0] >= -0.45) & (strong[:, 0] <= -0.3))  # barrel
    assert np.all(np.abs(strong[:, 2:4]) <= 2e-3)
    assert not scene.distortion_is_monotonic(np.array([-0.45, 0.0, 0, 0, 0]), 1.4)  # folds back at r ~ 0.86
    with pytest.raises(ValueError, match="strength"):
        scene.random_distortion(rng, "extreme")


def test_random_fisheye_is_monotonic_through_90_degrees():
    rng = np.random.default_rng(3)
    for _ in range(20):
        K, D = scene.random_fisheye(rng)
        assert K.shape == (3, 3) and D.shape == (4,) and 320 <= K[0, 0] <= 380
        theta = np.radians(np.linspace(1, 89, 200))
        X = np.c_[np.sin(theta), np.zeros_like(theta), np.cos(theta)].reshape(-1, 1, 3)
        uv, _ = cv2.fisheye.projectPoints(X, np.zeros((3, 1)), np.zeros((3, 1)), K, D)
        assert np.all(np.diff(uv.reshape(-1, 2)[:, 0]) > 0)
        assert np.allclose(uv.reshape(-1, 2)[:, 0] - K[0, 2], K[0, 0] * scene.fisheye_theta_d(D, theta))


# ============================================================ poses ====

@pytest.mark.parametrize("seed", range(5))
def test_look_at_puts_the_target_on_the_optical_axis_in_front(seed):
    rng = np.random.default_rng(seed)
    C, target = rng.normal(0, 3, 3), rng.normal(0, 1, 3)
    R, t = scene.look_at(C, target)
    assert is_rotation(R) and t.shape == (3,)
    assert np.allclose(scene.camera_centre(R, t), C)
    X_c = R @ target + t
    assert np.allclose(X_c[:2], 0, atol=1e-12) and np.isclose(X_c[2], np.linalg.norm(target - C))
    K = scene.random_intrinsics(rng)
    assert np.allclose(project(target[None], K, R, t), K[:2, 2], atol=1e-9)
    # world "up" (0, -1, 0) points up in the image: negative camera y
    assert (R @ np.array([0.0, -1.0, 0.0]))[1] < 0


def test_look_at_opencv_frame_and_degenerate_up():
    R, t = scene.look_at(np.zeros(3), [0, 0, 5])  # a y-down world seen from its origin: identity
    assert np.allclose(R, np.eye(3)) and np.allclose(t, 0)
    with pytest.raises(ValueError, match="parallel"):
        scene.look_at(np.zeros(3), [0, 3, 0])


def test_random_rotation():
    rng = np.random.default_rng(1)
    for _ in range(20):
        assert is_rotation(scene.random_rotation(rng))
        R = scene.random_rotation(rng, max_angle_deg=10)
        angle = np.degrees(np.linalg.norm(cv2.Rodrigues(R)[0]))
        assert is_rotation(R) and angle <= 10 + 1e-9


def test_random_rig_looks_at_the_target():
    rng = np.random.default_rng(2)
    target = np.array([0.5, -0.2, 1.0])
    rig = scene.random_rig(rng, 8, radius=4.0, target=target, jitter=0.0)
    K = scene.random_intrinsics(rng)
    centres = np.array([scene.camera_centre(R, t) for R, t in rig])
    assert len(rig) == 8 and all(is_rotation(R) for R, _ in rig)
    assert np.allclose(np.linalg.norm(centres - target, axis=1), 4.0)
    for R, t in rig:
        assert np.allclose(project(target[None], K, R, t), K[:2, 2], atol=1e-9)
    # evenly spread around the ring: no two cameras share a place
    gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2) + np.eye(8) * 99
    assert gaps.min() > 1.0


@pytest.mark.parametrize("seed", range(4))
def test_random_points_in_view_project_inside_at_the_right_depth(seed):
    rng = np.random.default_rng(seed)
    w, h = 1280, 960
    K = scene.random_intrinsics(rng, width=w, height=h)
    R, t = scene.random_rotation(rng), rng.normal(0, 2, 3)
    X = scene.random_points_in_view(rng, K, R, t, 500, depth=(2, 10), width=w, height=h, margin=20)
    assert X.shape == (500, 3)
    uv = project(X, K, R, t)
    assert np.all((uv >= 20 - 1e-6) & (uv <= np.array([w - 21, h - 21]) + 1e-6))
    z = (X @ R.T + t)[:, 2]
    assert np.all((z >= 2) & (z <= 10))
    assert np.ptp(uv[:, 0]) > 0.9 * (w - 41) and np.ptp(uv[:, 1]) > 0.9 * (h - 41)  # covers the frame


def test_point_cloud_chessboard_noise_outliers():
    rng = np.random.default_rng(4)
    X = scene.random_point_cloud(rng, 1000, centre=(1, 2, 3), extent=(2, 4, 6))
    assert np.all(np.abs(X - [1, 2, 3]) <= [1, 2, 3])
    B = scene.chessboard(rows=6, cols=9, square=0.025)
    assert B.shape == (54, 3) and np.all(B[:, 2] == 0)
    assert np.allclose(B[1] - B[0], [0.025, 0, 0]) and np.allclose(B[9] - B[0], [0, 0.025, 0])  # row-major
    x = rng.uniform(0, 600, (200, 2))
    assert np.std(scene.add_noise(rng, x, 0.5) - x) == pytest.approx(0.5, rel=0.1)
    x_out, is_out = scene.add_outliers(rng, x, 0.3, 640, 480)
    assert is_out.sum() == 60 and np.array_equal(x_out[~is_out], x[~is_out])
    assert np.all(np.linalg.norm(x_out[is_out] - x[is_out], axis=1) >= 10)
    assert np.all((x_out[is_out] >= 0) & (x_out[is_out] <= [639, 479]))


# ============================================================ textures and rendering ====

def test_textures():
    for name in scene.TEXTURES:
        img = scene.texture(name)
        assert img.ndim == 2 and img.dtype == np.float32 and 0 <= img.min() and img.max() <= 1, name
    small = scene.texture("brick", size=(100, 60))
    assert small.shape == (60, 100)
    small[:] = 0  # a copy: the cached texture is untouched
    assert scene.texture("brick").max() > 0


def _viewing_camera(rng, size_m, width=640, height=480):
    K = scene.random_intrinsics(rng, width, height)
    centre = np.array([size_m[0] / 2, size_m[1] / 2, 0.0])
    C = centre + scene.random_rotation(rng, 35) @ np.array([0.0, 0.0, -1.5])
    return K, *scene.look_at(C, centre + rng.uniform(-0.1, 0.1, 3) * [1, 1, 0])


@pytest.mark.parametrize("seed", range(5))
def test_render_plane_homography_maps_texture_corners_onto_projected_plane_corners(seed):
    rng = np.random.default_rng(seed)
    tex = scene.texture("gravel", size=(300, 200))
    size_m = (1.2, 0.8)
    K, R, t = _viewing_camera(rng, size_m)
    image, H = scene.render_plane(tex, K, R, t, size_m, 640, 480)
    assert image.shape == (480, 640) and image.dtype == np.float32 and H[2, 2] == pytest.approx(1)
    # the texture's outer corners (pixel-centre convention) are the plane's metric corners
    tex_corners = np.array([[-0.5, -0.5], [299.5, -0.5], [-0.5, 199.5], [299.5, 199.5]])
    plane_corners = np.array([[0, 0, 0], [1.2, 0, 0], [0, 0.8, 0], [1.2, 0.8, 0]], float)
    mapped = cv2.perspectiveTransform(tex_corners.reshape(-1, 1, 2), H).reshape(-1, 2)
    assert np.abs(mapped - project(plane_corners, K, R, t)).max() < 0.01
    assert np.allclose(H, scene.homography_from_plane(K, R, t, size_m, tex.shape))
    # the rendered image is the texture warped by H: compare well inside the plane
    inside = cv2.warpPerspective(np.ones_like(tex), H, (640, 480), flags=cv2.INTER_NEAREST) > 0
    inside = cv2.erode(inside.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    assert inside.sum() > 1000 and image[inside].std() > 0.05 and np.all(image[~inside][:100] >= 0)


@pytest.mark.parametrize("interpolation", [cv2.INTER_LINEAR, cv2.INTER_NEAREST])
def test_render_plane_pixel_centre_convention_with_a_single_bright_texel(interpolation):
    # Fronto-parallel camera, 4.37 px per texel: the blob of texel (i, j) must be centred where
    # cv2.projectPoints puts the texel's centre ((i + 0.5) s, (j + 0.5) s, 0). A corner-vs-centre
    # mix-up would move it by ~2 px.
    rows, cols, s = 40, 60, 0.01
    tex = np.zeros((rows, cols), np.float32)
    i, j = 23, 11
    tex[j, i] = 1.0
    f, d = 437.0, 1.0  # 1 cm texel at 1 m -> 4.37 px
    K = np.array([[f, 0, 301.3], [0, f, 217.8], [0, 0, 1]])
    R, t = scene.look_at([0.31, 0.22, -d], [0.31, 0.22, 0.0])
    image, H = scene.render_plane(tex, K, R, t, (cols * s, rows * s), 640, 480, interpolation=interpolation)
    expected = project(np.array([[(i + 0.5) * s, (j + 0.5) * s, 0.0]]), K, R, t)[0]
    ys, xs = np.nonzero(image)
    wts = image[ys, xs]
    centroid = np.array([np.sum(wts * xs), np.sum(wts * ys)]) / wts.sum()
    # nearest neighbour lights whole pixels, so its centroid is only good to about half a pixel
    tol = 0.05 if interpolation == cv2.INTER_LINEAR else 0.5
    assert np.abs(centroid - expected).max() < tol, (centroid, expected)
    assert np.allclose(cv2.perspectiveTransform(np.array([[[i, j]]], float), H)[0, 0], expected, atol=1e-9)


def test_render_plane_blanks_what_lies_behind_the_camera():
    # A camera 0.2 m above a 4 m plane, looking along it at a grazing angle: part of the plane is
    # behind the camera, and its mirror image must not be drawn.
    tex = np.ones((100, 100), np.float32)
    K = np.array([[300.0, 0, 319.5], [0, 300.0, 239.5], [0, 0, 1]])
    R, t = scene.look_at([2.0, 2.0, -0.2], [2.0, 3.0, 0.0])
    image, _ = scene.render_plane(tex, K, R, t, (4.0, 4.0), 640, 480)
    xs, ys = np.meshgrid(np.arange(640), np.arange(480))
    rays = np.linalg.solve(K, np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])).T @ R  # world directions
    C = scene.camera_centre(R, t)
    lam = -C[2] / rays[:, 2]  # where each ray meets z = 0
    hit = C + lam[:, None] * rays
    visible = (lam > 0) & np.all((hit[:, :2] > 0.05) & (hit[:, :2] < 3.95), axis=1)
    hidden = (lam < 0) | np.any((hit[:, :2] < -0.05) | (hit[:, :2] > 4.05), axis=1)
    img = image.ravel()
    assert visible.any() and hidden.any()
    assert np.all(img[visible] > 0.99) and np.all(img[hidden] == 0)


@pytest.mark.parametrize("seed", range(3))
def test_random_homography_pair_is_exact(seed):
    rng = np.random.default_rng(seed)
    tex = 0.1 + 0.9 * scene.texture("astronaut")  # no black texels: 0 means "not the plane"
    img1, img2, H12 = scene.random_homography_pair(rng, tex, max_angle_deg=40)
    assert img1.shape == img2.shape == (480, 640) and H12.shape == (3, 3)
    assert np.all(img1 > 0)  # view 1 sees only the plane
    warped = cv2.warpPerspective(img1, H12, (640, 480))
    valid = cv2.warpPerspective(np.ones_like(img1), H12, (640, 480)) > 0.999
    valid &= cv2.erode((img2 > 0).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    assert valid.mean() > 0.3
    # resampling twice blurs a little; a wrong H would leave errors of ~0.2
    assert np.median(np.abs(warped[valid] - img2[valid])) < 0.02
