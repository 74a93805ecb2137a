"""Stereo on refraction-free (pinhole) images: calibration, rectification, matching, triangulation.

Synthetic data only: smooth random textures (Gaussian-filtered noise) seen by exact pinholes, or a
rectified pair built from a known disparity field.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import ndimage

from lfrefract import ParameterError, PinholeCamera
from lfrefract.metrics import fit_plane_ransac
from lfrefract.optics.pose import rotation_from_euler_xyz
from lfrefract.stereo.geometry import (
    Rectification,
    StereoCalibration,
    calibrate_stereo,
    disparity_to_depth,
    disparity_to_points,
    rectify,
)
from lfrefract.stereo.matching import sgbm_disparity, zncc_disparity
from tests.tolerances import (
    FLOAT64_GEOMETRY_M,
    FLOAT64_PIXEL_PX,
    FLOAT64_RELATIVE,
    FLOAT64_UNIT,
    RECTIFY_MAP_PX,
    SGBM_COMPLETENESS_MIN,
    SGBM_NAN_MATCH_INVALID_MIN,
    SGBM_SLANTED_RMS_PX,
    STEREO_CALIB_RMS_PX,
    STEREO_CALIB_ROTATION_RAD,
    STEREO_CALIB_TRANSLATION_M,
    STEREO_PLANE_NORMAL_DEG,
    STEREO_PLANE_OFFSET_M,
    STEREO_PLANE_RMSE_RELATIVE,
    ZNCC_COMPLETENESS_MIN,
    ZNCC_INTEGER_RMS_MIN_PX,
    ZNCC_MAX_ERROR_PX,
    ZNCC_NO_CHECK_OCCLUDED_MAX,
    ZNCC_OCCLUDED_INVALID_MIN,
    ZNCC_SLANTED_RMS_PX,
)

WINDOW_PX = 9  # zncc_disparity's default window


def smooth_texture(shape, sigma_px: float, seed: int) -> np.ndarray:
    """Gaussian-filtered uniform noise scaled to mean 0.5 and standard deviation 0.1."""
    t = ndimage.gaussian_filter(np.random.default_rng(seed).random(shape), sigma_px)
    return 0.5 + 0.1 * (t - t.mean()) / t.std()


# =============================================================================== rectified pairs
# A rectified pair with the disparity field of a slanted plane, d(x, y) = A + B x + C y on left
# pixels (disparity is affine in the image for any plane). Right pixel x_r shows the left pixel x
# with x - d(x, y) = x_r, i.e. x = (x_r + A + C y) / (1 - B).
SLANT = (20.0, 0.03, 0.02)
MIN_D, NUM_D = 8, 32


@pytest.fixture(scope="module")
def slanted_pair():
    height, width, pad = 160, 240, 64
    texture = smooth_texture((height, width + 2 * pad), 2.0, seed=0)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    a, b, c = SLANT
    left = ndimage.map_coordinates(texture, [yy, xx + pad], order=3)
    right = ndimage.map_coordinates(texture, [yy, (xx + a + c * yy) / (1.0 - b) + pad], order=3)
    truth = a + b * xx + c * yy
    # Pixels that can be matched: the left window and the right windows of the two integer
    # disparities around the truth (and their neighbours, for the parabola) inside the images.
    h = WINDOW_PX // 2
    matchable = (
        (yy >= h) & (yy < height - h) & (xx >= h) & (xx < width - h)
        & (xx - np.ceil(truth) - 1 - h >= 0) & (xx - np.floor(truth) + 1 + h < width)
    )  # fmt: skip
    return left.astype(np.float32), right.astype(np.float32), truth, matchable


def test_zncc_recovers_a_slanted_plane(slanted_pair):
    left, right, truth, matchable = slanted_pair
    disp = zncc_disparity(left, right, min_disparity_px=MIN_D, num_disparities=NUM_D)
    assert disp.dtype == np.float32
    assert disp.shape == left.shape
    valid = np.isfinite(disp)
    assert valid[matchable].mean() >= ZNCC_COMPLETENESS_MIN
    err = disp[valid] - truth[valid]
    assert np.sqrt(np.mean(err**2)) <= ZNCC_SLANTED_RMS_PX
    assert np.max(np.abs(err)) <= ZNCC_MAX_ERROR_PX
    # Only pixels whose left window lies in the image, with a match in the right image, get one.
    assert not valid[:, : MIN_D + WINDOW_PX // 2].any()
    assert not valid[: WINDOW_PX // 2].any()
    assert not valid[-(WINDOW_PX // 2) :].any()

    # Without the parabola the disparities are integers, off by ~1/sqrt(12) px RMS.
    integer = zncc_disparity(left, right, min_disparity_px=MIN_D, num_disparities=NUM_D, subpixel=False)
    ok = np.isfinite(integer)
    np.testing.assert_array_equal(integer[ok], np.round(integer[ok]))
    assert np.sqrt(np.mean((integer[ok] - truth[ok]) ** 2)) >= ZNCC_INTEGER_RMS_MIN_PX


def test_zncc_is_invariant_to_gain_and_offset(slanted_pair):
    left, right, _, _ = slanted_pair
    disp = zncc_disparity(left, right, min_disparity_px=MIN_D, num_disparities=NUM_D)
    scaled = zncc_disparity(left, 3.0 * right + 7.0, min_disparity_px=MIN_D, num_disparities=NUM_D)
    # Equal up to float32 round-off of the scaled image (the valid sets may differ at a tie).
    both = np.isfinite(disp) & np.isfinite(scaled)
    assert both.sum() >= 0.99 * np.isfinite(disp).sum()
    np.testing.assert_allclose(scaled[both], disp[both], atol=1e-3)


def test_zncc_and_sgbm_search_only_the_requested_range(slanted_pair):
    left, right, _truth, _ = slanted_pair
    # Truth spans 20 .. 29.4 px; a range that stops at 25 must not report 26 and more.
    for method in (zncc_disparity, sgbm_disparity):
        disp = method(left, right, min_disparity_px=MIN_D, num_disparities=18)
        assert np.nanmax(disp) <= MIN_D + 18 - 1
        assert np.isfinite(disp).any()


@pytest.fixture(scope="module")
def occlusion_pair():
    """Background at 12 px disparity; a foreground strip at 24 px over left columns [100, 150).

    In the right view the strip moves 12 px further left and covers the background that the left
    view shows at columns [88, 100): those left pixels have no match (an occluded band).
    """
    height, width, pad = 120, 200, 64
    back = smooth_texture((height, width + 2 * pad), 2.0, seed=1)
    front = smooth_texture((height, width + 2 * pad), 2.0, seed=2)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    d_back, d_front, x0, x1 = 12.0, 24.0, 100, 150

    def view(right: bool) -> np.ndarray:
        bg = ndimage.map_coordinates(back, [yy, xx + pad + (d_back if right else 0.0)], order=3)
        fg = ndimage.map_coordinates(front, [yy, xx + pad + (d_front if right else 0.0)], order=3)
        x_left = xx + (d_front if right else 0.0)
        return np.where((x_left >= x0) & (x_left < x1), fg, bg).astype(np.float32)

    truth = np.where((xx >= x0) & (xx < x1), d_front, d_back)
    band = (xx >= x0 - (d_front - d_back)) & (xx < x0)
    return view(False), view(True), truth, band


def test_left_right_check_invalidates_the_occluded_band(occlusion_pair):
    left, right, _, band = occlusion_pair
    checked = zncc_disparity(left, right, min_disparity_px=4, num_disparities=NUM_D)
    unchecked = zncc_disparity(left, right, min_disparity_px=4, num_disparities=NUM_D, left_right_max_diff_px=None)
    assert np.isnan(checked[band]).mean() >= ZNCC_OCCLUDED_INVALID_MIN
    assert np.isnan(unchecked[band]).mean() <= ZNCC_NO_CHECK_OCCLUDED_MAX
    # The check removes estimates, it never adds or changes one.
    kept = np.isfinite(checked)
    assert np.all(np.isfinite(unchecked[kept]))
    np.testing.assert_array_equal(checked[kept], unchecked[kept])


def test_nan_input_gives_nan(occlusion_pair):
    left, right, _, _ = occlusion_pair
    left, right = left.copy(), right.copy()
    left[30:50, 40:60] = np.nan
    right[70:90, 40:60] = np.nan  # seen by left columns 52..71 (background, 12 px)
    h = WINDOW_PX // 2
    disp = zncc_disparity(left, right, min_disparity_px=4, num_disparities=NUM_D)
    assert np.all(np.isnan(disp[30 - h : 50 + h, 40 - h : 60 + h]))
    assert np.all(np.isnan(disp[70:90, 52:72]))
    assert np.isfinite(disp[5:25, 40:60]).all()  # unaffected elsewhere
    sgbm = sgbm_disparity(left, right, min_disparity_px=0, num_disparities=NUM_D, block_size_px=5)
    assert np.all(np.isnan(sgbm[28:52, 38:62]))
    # SGBM's own left-right check does not catch every left pixel whose true match is NaN: one
    # may find a wrong partner just beside the hole.
    assert np.isnan(sgbm[70:90, 52:72]).mean() >= SGBM_NAN_MATCH_INVALID_MIN
    assert np.isfinite(sgbm[5:25, 40:60]).mean() > 0.9
    # Images that are all NaN, or without texture, give no estimate at all.
    for a, b in ((np.full_like(left, np.nan), right), (np.full_like(left, 0.5), np.full_like(right, 0.5))):
        assert np.isnan(zncc_disparity(a, b, min_disparity_px=0, num_disparities=16)).all()
        assert np.isnan(sgbm_disparity(a, b, min_disparity_px=0, num_disparities=16)).all()


def test_sgbm_recovers_a_slanted_plane(slanted_pair):
    left, right, truth, matchable = slanted_pair
    disp = sgbm_disparity(left, right, min_disparity_px=MIN_D, num_disparities=NUM_D)
    assert disp.dtype == np.float32
    valid = np.isfinite(disp)
    assert valid[matchable].mean() >= SGBM_COMPLETENESS_MIN
    err = disp[valid] - truth[valid]
    assert np.sqrt(np.mean(err**2)) <= SGBM_SLANTED_RMS_PX


# =============================================================================== calibration
LEFT = PinholeCamera(focal_px=400.0, cx_px=161.0, cy_px=118.5, width_px=320, height_px=240)
RIGHT = PinholeCamera(focal_px=420.0, cx_px=158.0, cy_px=121.0, width_px=320, height_px=240)
RIG_ROTATION = rotation_from_euler_xyz((0.02, -0.06, 0.015))
RIG_CENTRE_M = np.array([0.12, 0.004, -0.01])  # right camera centre in the left frame
RIG_TRANSLATION_M = -RIG_ROTATION @ RIG_CENTRE_M  # X_r = R X_l + t
EXACT = StereoCalibration(left=LEFT, right=RIGHT, rotation=RIG_ROTATION, translation_m=RIG_TRANSLATION_M)


def board_views(n_views: int, seed: int = 0):
    """Noiseless corners of a 9 x 6 board (25 mm squares) in front of the rig, as seen by both cameras."""
    gx, gy = np.meshgrid(np.arange(9), np.arange(6))
    board = np.stack([gx.ravel(), gy.ravel()], axis=1) * 0.025
    rng = np.random.default_rng(seed)
    left, right = [], []
    for _ in range(n_views):
        rot = rotation_from_euler_xyz(tuple(rng.uniform(-0.4, 0.4, 3)))
        centre = np.array([0.06 + rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(0.6, 0.9)])
        points = np.concatenate([board - board.mean(axis=0), np.zeros((len(board), 1))], axis=1) @ rot.T + centre
        uv_left = LEFT.project(points)
        uv_right = RIGHT.project(points @ RIG_ROTATION.T + RIG_TRANSLATION_M)
        for uv, cam in ((uv_left, LEFT), (uv_right, RIGHT)):
            assert uv.min() > 0
            assert uv[:, 0].max() < cam.width_px - 1
            assert uv[:, 1].max() < cam.height_px - 1
        left.append(uv_left)
        right.append(uv_right)
    return left, right, board


def rotation_angle_rad(a: np.ndarray, b: np.ndarray) -> float:
    return math.acos(min(1.0, max(-1.0, (np.trace(a @ b.T) - 1.0) / 2.0)))


def test_calibrate_stereo_recovers_the_rig_from_noiseless_corners():
    left, right, board = board_views(6)
    cal = calibrate_stereo(left, right, board, left=LEFT, right=RIGHT)
    assert rotation_angle_rad(cal.rotation, RIG_ROTATION) <= STEREO_CALIB_ROTATION_RAD
    assert np.max(np.abs(cal.translation_m - RIG_TRANSLATION_M)) <= STEREO_CALIB_TRANSLATION_M
    assert cal.rms_px <= STEREO_CALIB_RMS_PX
    assert cal.left is LEFT
    assert cal.right is RIGHT
    np.testing.assert_allclose(cal.right_centre_m, RIG_CENTRE_M, rtol=0, atol=2 * STEREO_CALIB_TRANSLATION_M)


def test_calibration_dict_round_trip():
    cal = StereoCalibration(
        left=LEFT, right=RIGHT, rotation=RIG_ROTATION, translation_m=RIG_TRANSLATION_M, rms_px=0.125
    )
    back = StereoCalibration.from_dict(json.loads(json.dumps(cal.to_dict())))
    assert back.left == LEFT
    assert back.right == RIGHT
    assert back.rms_px == 0.125
    np.testing.assert_array_equal(back.rotation, RIG_ROTATION)
    np.testing.assert_array_equal(back.translation_m, RIG_TRANSLATION_M)
    assert back.baseline_m == pytest.approx(np.linalg.norm(RIG_CENTRE_M), rel=FLOAT64_RELATIVE)
    with pytest.raises(ValueError, match=r"assignment|read-only"):
        back.rotation[0, 0] = 2.0


# =============================================================================== rectification
def random_points(n: int, seed: int) -> np.ndarray:
    """Points in the left frame, 0.5-2 m away, seen by both cameras."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.5, 2.0, n)
    uv = rng.uniform([20.0, 20.0], [300.0, 220.0], (n, 2))
    points = np.concatenate([(uv - [LEFT.cx_px, LEFT.cy_px]) / LEFT.focal_px, np.ones((n, 1))], axis=1) * z[:, None]
    right_uv = RIGHT.project(points @ RIG_ROTATION.T + RIG_TRANSLATION_M)
    inside = np.all((right_uv > 0) & (right_uv < [RIGHT.width_px - 1, RIGHT.height_px - 1]), axis=1)
    return points[inside]


def test_rectification_puts_corresponding_points_on_one_row():
    rect = rectify(EXACT)
    assert isinstance(rect, Rectification)
    assert rect.size_px == (320, 240)
    points = random_points(400, seed=3)
    assert len(points) > 200
    q_left = rect.rectify_pixels(LEFT.project(points), camera="left")
    q_right = rect.rectify_pixels(RIGHT.project(points @ RIG_ROTATION.T + RIG_TRANSLATION_M), camera="right")
    np.testing.assert_allclose(q_left[:, 1], q_right[:, 1], rtol=0, atol=FLOAT64_PIXEL_PX)
    # Disparity f B / Z with Z the depth in the rectified left frame (rotated about the left centre).
    z_rect = (points @ rect.R1.T)[:, 2]
    assert rect.baseline_m == pytest.approx(EXACT.baseline_m, rel=FLOAT64_RELATIVE)
    np.testing.assert_allclose(
        q_left[:, 0] - q_right[:, 0], rect.focal_px * rect.baseline_m / z_rect, rtol=0, atol=FLOAT64_PIXEL_PX
    )
    # The rectified left image is the left camera turned by R1: its projection of R1 X is q_left.
    np.testing.assert_allclose(rect.left_camera.project(points @ rect.R1.T), q_left, rtol=0, atol=FLOAT64_PIXEL_PX)
    # The maps point every rectified pixel back to its source pixel: sample them at q.
    for cam, q, uv in (
        ("left", q_left, LEFT.project(points)),
        ("right", q_right, RIGHT.project(points @ RIG_ROTATION.T + RIG_TRANSLATION_M)),
    ):
        inside = np.all((q > 0) & (q < [319, 239]), axis=1)
        mx, my = (rect.left_map_x, rect.left_map_y) if cam == "left" else (rect.right_map_x, rect.right_map_y)
        back = np.stack([ndimage.map_coordinates(m, [q[inside, 1], q[inside, 0]], order=1) for m in (mx, my)], 1)
        np.testing.assert_allclose(back, uv[inside], rtol=0, atol=RECTIFY_MAP_PX)


def test_rectification_with_alpha_one_keeps_every_pixel():
    zoomed, whole = rectify(EXACT, alpha=0.0), rectify(EXACT, alpha=1.0, size=(400, 300))
    assert whole.size_px == (400, 300)
    assert whole.left_map_x.shape == (300, 400)
    # alpha = 0: every rectified pixel samples inside both images; alpha = 1: every corner of
    # the original images appears in the rectified ones.
    for mx, my in ((zoomed.left_map_x, zoomed.left_map_y), (zoomed.right_map_x, zoomed.right_map_y)):
        assert mx.min() >= -0.5
        assert mx.max() <= 319.5
        assert my.min() >= -0.5
        assert my.max() <= 239.5
    corners = np.array([[0.0, 0.0], [319.0, 0.0], [0.0, 239.0], [319.0, 239.0]])
    for cam in ("left", "right"):
        q = whole.rectify_pixels(corners, camera=cam)
        assert np.all(q >= -0.5)
        assert np.all(q <= [399.5, 299.5])


def test_apply_keeps_nan_and_handles_channels():
    rect = rectify(EXACT)
    left = smooth_texture((240, 320), 2.0, seed=4).astype(np.float32)
    right = smooth_texture((240, 320), 2.0, seed=5).astype(np.float32)
    left_nan = left.copy()
    left_nan[100:110, 150:160] = np.nan
    a, b = rect.apply(left_nan, right)
    assert a.dtype == np.float32
    assert a.shape == (240, 320)
    assert b.shape == (240, 320)
    # Rectified pixels whose source lies in the NaN block are NaN; those far from it are not.
    q = rect.rectify_pixels(np.array([[154.5, 104.5]]), camera="left")[0]
    assert np.isnan(a[round(q[1]), round(q[0])])
    clean, _ = rect.apply(left, right)
    far = np.hypot(*np.meshgrid(np.arange(320) - q[0], np.arange(240) - q[1])) > 20
    np.testing.assert_array_equal(a[far], clean[far])
    assert np.isnan(a[~far]).sum() >= 80  # the 10 x 10 block, resampled
    assert np.isfinite(clean).all()  # alpha = 0: no empty border
    # Channels are resampled alike; a NaN stays in its channel.
    colour = np.stack([left_nan, right, 2.0 * left], axis=2)
    ca, cb = rect.apply(colour, colour)
    assert ca.shape == (240, 320, 3)
    np.testing.assert_array_equal(ca[..., 0], a)
    np.testing.assert_array_equal(cb[..., 1], b)
    assert np.isfinite(ca[..., 1]).all()
    # Outside the source image is NaN (alpha = 1 shows a border).
    wide = rectify(EXACT, alpha=1.0)
    wa, _ = wide.apply(left, right)
    assert np.isnan(wa).any()
    assert np.isfinite(wa).mean() > 0.8


# =============================================================================== triangulation
PLANE_NORMAL = np.array([0.25, -0.15, 1.0]) / np.linalg.norm([0.25, -0.15, 1.0])  # left frame
PLANE_OFFSET_M = 0.9  # {X : n . X = 0.9 m}


def plane_depth_rectified(rect: Rectification) -> np.ndarray:
    """Depth (rectified left frame) of the plane at every rectified pixel."""
    width, height = rect.size_px
    cam = rect.left_camera
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    rays = np.stack([(u - cam.cx_px) / cam.focal_px, (v - cam.cy_px) / cam.focal_px, np.ones_like(u)], axis=-1)
    return PLANE_OFFSET_M / (rays @ (rect.R1 @ PLANE_NORMAL))


def test_disparity_to_points_reproduces_a_plane_in_the_left_frame():
    rect = rectify(EXACT)
    depth = plane_depth_rectified(rect)
    disparity = rect.focal_px * rect.baseline_m / depth
    disparity[:10, :10] = np.nan  # no estimate there
    got_depth = disparity_to_depth(disparity, rect)
    valid = np.isfinite(got_depth)
    np.testing.assert_array_equal(valid, np.isfinite(disparity))
    np.testing.assert_allclose(got_depth[valid], depth[valid], rtol=FLOAT64_RELATIVE, atol=0)
    points = disparity_to_points(disparity, rect)
    assert points.shape == (valid.sum(), 3)
    np.testing.assert_allclose(points @ PLANE_NORMAL, PLANE_OFFSET_M, rtol=0, atol=FLOAT64_GEOMETRY_M)
    # Row-major order of the valid pixels: each point projects to its pixel in the left camera,
    # via the rectified pixel it came from.
    v, u = np.nonzero(valid)
    source = np.stack([rect.left_map_x[v, u], rect.left_map_y[v, u]], axis=1)
    np.testing.assert_allclose(LEFT.project(points), source, rtol=0, atol=RECTIFY_MAP_PX)
    # Rotated back by R1: the same points in the rectified frame are off the left-frame plane.
    assert np.max(np.abs((points @ rect.R1.T) @ PLANE_NORMAL - PLANE_OFFSET_M)) > 1e-3
    # Non-positive disparity has no point in front of the cameras.
    assert np.isnan(disparity_to_depth(np.zeros((240, 320)), rect)).all()
    assert disparity_to_points(np.full((240, 320), -1.0), rect).shape == (0, 3)
    np.testing.assert_allclose(np.linalg.norm(rect.R1 @ PLANE_NORMAL), 1.0, atol=FLOAT64_UNIT)


def render_plane(cam: PinholeCamera, rotation: np.ndarray, centre_m: np.ndarray, texture: np.ndarray) -> np.ndarray:
    """Pinhole image (point-sampled at pixel centres) of the textured plane, 1 mm texels.

    ``rotation`` and ``centre_m`` place the camera in the left frame: ``X_cam = rotation @ (X - centre)``.
    """
    n, offset = PLANE_NORMAL, PLANE_OFFSET_M
    e1 = np.cross(n, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    directions = cam.pixel_directions() @ rotation  # rows: rotation.T @ d, left frame
    s = (offset - n @ centre_m) / (directions @ n)
    hits = centre_m + s[:, None] * directions - n * offset
    half = texture.shape[0] / 2.0
    coords = [hits @ e2 / 1e-3 + half, hits @ e1 / 1e-3 + half]
    image = ndimage.map_coordinates(texture, coords, order=3, mode="constant", cval=np.nan)
    return image.reshape(cam.height_px, cam.width_px).astype(np.float32)


def test_end_to_end_plane_from_a_rendered_pair():
    texture = smooth_texture((1500, 1500), 4.0, seed=6)  # 1 mm texels, features of ~2-3 px in the images
    left = render_plane(LEFT, np.eye(3), np.zeros(3), texture)
    right = render_plane(RIGHT, RIG_ROTATION, RIG_CENTRE_M, texture)
    rect = rectify(EXACT)
    left_r, right_r = rect.apply(left, right)
    depth = plane_depth_rectified(rect)
    truth = rect.focal_px * rect.baseline_m / depth
    disparity = zncc_disparity(left_r, right_r, min_disparity_px=int(truth.min()) - 6, num_disparities=NUM_D)
    valid = np.isfinite(disparity)
    assert valid.mean() > 0.7  # the left ~60 columns have no partner (disparity 56-67 px)
    err = disparity[valid] - truth[valid]
    rms_px = float(np.sqrt(np.mean(err**2)))
    assert rms_px <= ZNCC_SLANTED_RMS_PX
    points = disparity_to_points(disparity, rect)
    fit = fit_plane_ransac(points, threshold_m=0.01)
    angle_deg = math.degrees(math.acos(min(1.0, float(fit.normal @ PLANE_NORMAL))))
    assert angle_deg <= STEREO_PLANE_NORMAL_DEG
    assert abs(fit.offset_m - PLANE_OFFSET_M) <= STEREO_PLANE_OFFSET_M
    # Depth noise predicted from the disparity noise: dZ = Z^2 / (f B) dd.
    z = depth[valid]
    predicted_m = rms_px * np.sqrt(np.mean((z**2 / (rect.focal_px * rect.baseline_m)) ** 2))
    # The plane residual is that depth noise, seen along the normal rather than along z.
    assert abs(fit.rmse_m / predicted_m - 1.0) <= STEREO_PLANE_RMSE_RELATIVE


# =============================================================================== bad input
def test_bad_input_names_the_parameter():
    left, right, board = board_views(3)
    image = np.zeros((20, 30), np.float32)
    cases = [
        (lambda: calibrate_stereo(left[:2], right[:2], board, left=LEFT, right=RIGHT), "at least 3 views, got 2"),
        (lambda: calibrate_stereo(left, right[:2], board, left=LEFT, right=RIGHT), "same views"),
        (lambda: calibrate_stereo(left, right, board[:-1], left=LEFT, right=RIGHT), r"corners_left\[0\] must have"),
        (lambda: calibrate_stereo(left, right, board, left=LEFT.K, right=RIGHT), "left must be a PinholeCamera"),
        (
            lambda: StereoCalibration(left=LEFT, right=RIGHT, rotation=2 * np.eye(3), translation_m=[0.1, 0, 0]),
            "rotation must be a proper rotation",
        ),
        (
            lambda: StereoCalibration(left=LEFT, right=RIGHT, rotation=np.eye(3), translation_m=[0, 0, 0]),
            "translation_m must not be zero",
        ),
        (
            lambda: StereoCalibration(left=LEFT, right=RIGHT, rotation=np.eye(3), translation_m=[0.1, np.nan, 0]),
            r"translation_m\[1\] must be finite",
        ),
        (lambda: rectify(EXACT, alpha=1.5), "alpha must lie in"),
        (lambda: rectify(EXACT, size=(0, 10)), r"size\[0\] must be positive"),
        (
            lambda: rectify(StereoCalibration(left=LEFT, right=RIGHT, rotation=np.eye(3), translation_m=[0.1, 0, 0])),
            "right camera towards \\+x",
        ),
        (
            lambda: rectify(StereoCalibration(left=LEFT, right=RIGHT, rotation=np.eye(3), translation_m=[0, -0.1, 0])),
            "horizontal rig",
        ),
        (lambda: rectify(EXACT).apply(image, image), r"left_image must have shape \(240, 320\)"),
        (lambda: zncc_disparity(image, image, min_disparity_px=0, num_disparities=8, window_px=4), "window_px"),
        (lambda: zncc_disparity(image, image, min_disparity_px=0, num_disparities=2), "num_disparities must be >= 3"),
        (lambda: zncc_disparity(image, image, min_disparity_px=0.5, num_disparities=8), "min_disparity_px must be"),
        (lambda: zncc_disparity(image, image[:, :-1], min_disparity_px=0, num_disparities=8), "same shape"),
        (
            lambda: zncc_disparity(image[..., None], image, min_disparity_px=0, num_disparities=8),
            r"left must be a grey",
        ),
        (
            lambda: zncc_disparity(image, image, min_disparity_px=0, num_disparities=8, left_right_max_diff_px=-1),
            "left_right_max_diff_px must be non-negative",
        ),
        (lambda: sgbm_disparity(image, image, min_disparity_px=0, num_disparities=16, mode="fast"), "mode must be"),
        (lambda: sgbm_disparity(image, image, min_disparity_px=0, num_disparities=16, p1=10, p2=5), "p2 must be"),
        (lambda: disparity_to_points(image, rectify(EXACT)), r"disparity must have the rectified shape"),
        (lambda: disparity_to_depth(np.zeros((240, 320)), EXACT), "rectification must be a Rectification"),
    ]
    for call, message in cases:
        with pytest.raises(ParameterError, match=message):
            call()


def test_calibrate_stereo_takes_one_board_per_view():
    """Boards of two sizes: each view with its own board points gives the exact rig; the wrong size
    for half of them does not."""
    left, right, board = board_views(3)
    # Three more views, of a board with half-size squares at about half the distance.
    gx, gy = np.meshgrid(np.arange(9), np.arange(6))
    half = np.stack([gx.ravel(), gy.ravel()], axis=1) * 0.0125
    rng = np.random.default_rng(5)
    views_l, views_r = list(left), list(right)
    for _ in range(3):
        rot = rotation_from_euler_xyz(tuple(rng.uniform(-0.4, 0.4, 3)))
        centre = np.array([0.06 + rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02), rng.uniform(0.3, 0.45)])
        points = np.concatenate([half - half.mean(axis=0), np.zeros((len(half), 1))], axis=1) @ rot.T + centre
        views_l.append(LEFT.project(points))
        views_r.append(RIGHT.project(points @ RIG_ROTATION.T + RIG_TRANSLATION_M))
    boards = [board] * 3 + [half] * 3
    cal = calibrate_stereo(views_l, views_r, boards, left=LEFT, right=RIGHT)
    assert rotation_angle_rad(cal.rotation, RIG_ROTATION) <= STEREO_CALIB_ROTATION_RAD
    assert np.max(np.abs(cal.translation_m - RIG_TRANSLATION_M)) <= STEREO_CALIB_TRANSLATION_M
    wrong = calibrate_stereo(views_l, views_r, [board] * 6, left=LEFT, right=RIGHT)
    assert wrong.rms_px > 100 * STEREO_CALIB_RMS_PX
    with pytest.raises(ParameterError, match="one view per board_points_m"):
        calibrate_stereo(views_l, views_r, boards[:5], left=LEFT, right=RIGHT)
