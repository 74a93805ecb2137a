"""The camera's ray-model fit (lfrefract.calibration.camera.calibrate_camera) on synthetic board light
fields: what it does when the boards do not determine the slope scale.

The synthetic camera departs from the five-parameter model by a field-curvature term (the slopes gain
``c |t|^2 a``, which a real lens has and the model lacks), so the fit leaves a residual that every
corner of a capture shares. Small boards (24 corners spanning a few degrees) then let the slope scale
trade against the boards' distances; large ones do not.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lfrefract import camera_preset, virtual_camera_for
from lfrefract.calibration import calibrate_camera
from lfrefract.calibration.camera import HELD_SLOPE_SCALE_STD
from lfrefract.calibration.port import BoardView
from lfrefract.errors import CalibrationError
from lfrefract.formats.capture import camera_model_from_option
from lfrefract.formats.jsonio import write_json
from tests.tolerances import CAMERA_CAL_BOARD_DEPTH_RELATIVE, CAMERA_CAL_FREE_SLOPE_SCALE

CAMERA = camera_preset("illum")
VIEW = virtual_camera_for(CAMERA)
# The synthetic camera: pupil and slope scales, radial terms, and the field curvature the model lacks.
PUPIL, SLOPE, K1, K2, CURVATURE_PER_M = 1.04, 1.0, 0.07, 0.1, 3.0
CORNER_NOISE_PX = 0.02


def _slopes_through(points_cam: np.ndarray, aperture_m: np.ndarray) -> np.ndarray:
    """The thin-lens slopes (N, 2) whose synthetic-camera rays from ``aperture_m`` (N, 2) pass ``points_cam`` (N, 3)."""
    target = (points_cam[:, :2] - PUPIL * aperture_m) / points_cam[:, 2:3]
    t = target / SLOPE
    for _ in range(40):  # a contraction: the distortion and curvature terms are small
        r2 = np.sum(t * t, axis=1, keepdims=True)
        t = (target - CURVATURE_PER_M * r2 * aperture_m) / (SLOPE * (1.0 + K1 * r2 + K2 * r2 * r2))
    return t


def _board_views(*, square_at_015_m: float, seed: int = 1) -> tuple[list[BoardView], np.ndarray]:
    """Twelve boards of 6 x 4 corners at 0.15-0.35 m over the field, seen from 12 aperture points.

    Returns the views and each board centre's true depth (m)."""
    rng = np.random.default_rng(seed)
    axis = np.linspace(-1.8e-3, 1.8e-3, 4)
    aperture = np.array([(x, y) for x in axis for y in axis if x * x + y * y <= (1.9e-3) ** 2])
    gx, gy = np.meshgrid(np.arange(6) - 2.5, np.arange(4) - 1.5)
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    views, depths = [], []
    for k in range(12):
        depth = 0.15 + 0.2 * k / 11
        centre = np.array([rng.uniform(-0.3, 0.3) * depth, rng.uniform(-0.2, 0.2) * depth, depth])
        rotation = Rotation.from_euler("xyz", rng.uniform(-20, 20, 3) * [1, 1, 0.25], degrees=True).as_matrix()
        board = grid * square_at_015_m * depth / 0.15
        corners = np.column_stack([board, np.zeros(len(board))]) @ rotation.T + centre
        a = np.repeat(aperture, len(corners), axis=0)
        t = _slopes_through(np.tile(corners, (len(aperture), 1)), a)
        pixels = np.column_stack([t, np.ones(len(t))]) @ VIEW.K.T
        views.append(
            BoardView(
                corners_px=pixels[:, :2] + rng.normal(0.0, CORNER_NOISE_PX, (len(t), 2)),
                board_points_m=np.tile(board, (len(aperture), 1)),
                centres_m=np.column_stack([a, np.zeros(len(a))]),
            )
        )
        depths.append(depth)
    return views, np.array(depths)


def _depth_ratios(calibration, views: list[BoardView], depths: np.ndarray) -> np.ndarray:
    """Each fitted board centre's depth over its true depth."""
    ratios = []
    for pose, view, depth in zip(calibration.poses, views, depths, strict=True):
        rotation = Rotation.from_rotvec(pose[:3]).as_matrix()
        centre = np.mean(view.board_points_m, axis=0)
        ratios.append((rotation @ np.array([*centre, 0.0]) + pose[3:])[2] / depth)
    return np.array(ratios)


def test_small_boards_hold_the_slope_scale_and_keep_their_distances():
    """Boards 2.1 mm a square at 0.15 m (5 deg across): fitted freely, the slope scale went to 0.979
    (its Jacobian spread 0.0095, inside the check then) and every board 2.1-3.5 % too far."""
    views, depths = _board_views(square_at_015_m=2.1e-3)
    calibration = calibrate_camera(CAMERA, views, view=VIEW)
    ratios = _depth_ratios(calibration, views, depths)
    assert abs(np.mean(ratios) - 1.0) < CAMERA_CAL_BOARD_DEPTH_RELATIVE, ratios
    assert calibration.held == ("slope_scale",)
    assert calibration.correction.slope_scale == 1.0
    assert calibration.clustered_std[1] == 0.0
    written = calibration.to_dict()
    assert written["held"] == ["slope_scale"]
    assert written["correction_std"]["slope_scale"] == pytest.approx(HELD_SLOPE_SCALE_STD)


def test_large_boards_determine_the_slope_scale(tmp_path):
    """Boards six times larger (30 deg across) determine the slope scale: fitted, not held."""
    views, depths = _board_views(square_at_015_m=6 * 2.1e-3)
    calibration = calibrate_camera(CAMERA, views, view=VIEW)
    assert calibration.held == ()
    assert abs(calibration.correction.slope_scale - SLOPE) < CAMERA_CAL_FREE_SLOPE_SCALE
    assert calibration.to_dict()["held"] == []
    # Its file gives back its camera model, bit for bit (JSON keeps every float64).
    write_json(tmp_path / "camera.json", calibration.to_dict())
    read, model = camera_model_from_option(tmp_path / "camera.json"), calibration.model
    assert (read.camera, read.correction) == (model.camera, model.correction)
    assert np.array_equal(read.covariance, model.covariance)
    assert np.array_equal(read.spread, model.spread)
    ratios = _depth_ratios(calibration, views, depths)
    assert abs(np.mean(ratios) - 1.0) < CAMERA_CAL_BOARD_DEPTH_RELATIVE, ratios


def test_one_capture_repeated_is_refused_naming_the_two():
    """The same capture three times met the minimum of three and gave k1 -0.44, k2 -0.95 (truth 0.07,
    0.1) with a slope scale fitted, not held: its clustered spread was 1e-6, the captures agreeing
    perfectly. Two captures of one pose (corners 0.02 px apart) are refused the same way."""
    views, _ = _board_views(square_at_015_m=2.1e-3)
    with pytest.raises(CalibrationError, match=r"views\[0\] and views\[1\] show the board in the same pose"):
        calibrate_camera(CAMERA, [views[0], views[0], views[0]], view=VIEW)
    rng = np.random.default_rng(5)
    again = BoardView(
        corners_px=views[1].corners_px + rng.normal(0.0, CORNER_NOISE_PX, views[1].corners_px.shape),
        board_points_m=views[1].board_points_m,
        centres_m=views[1].centres_m,
    )
    with pytest.raises(CalibrationError, match=r"views\[1\] and views\[3\] show the board in the same pose"):
        calibrate_camera(CAMERA, [*views[:3], again], view=VIEW)
