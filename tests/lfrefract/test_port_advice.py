"""The port calibration's advice: what its views leave poorly determined, and which views fix it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lfrefract import FlatPort, ParameterError
from lfrefract.calibration.advice import advise_port_views
from lfrefract.calibration.camera import corrected_view
from lfrefract.calibration.port import (
    BoardView,
    PortCalibration,
    PortUndeterminedError,
    calibrate_port,
    normal_std_deg,
    project_through_port,
)
from lfrefract.optics.camera_model import CameraModel
from lfrefract.optics.presets import camera_preset
from lfrefract.optics.ray_correction import RayCorrection
from tests.lfrefract.test_port_calibration import CAMERA, _angle_deg
from tests.tolerances import ADVICE_MODEL_PART_FACTOR, ADVICE_PREDICTION_FACTOR

TRUE = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.01, tilt_x_deg=20.0, tilt_y_deg=10.0)
NOISE_PX = 0.4
LOOSE = {"thickness_m": 0.01, "max_normal_std_deg": 90.0, "max_distance_std_m": 1.0}
#: 9 x 6 inner corners of 20 mm squares: small enough that boards turned 30 deg fit whole (outer
#: squares and all) in the 800 x 600 px view (f = 600 px) at 0.3 m, where the advice places them.
SQUARE_M = 0.02
XX, YY = np.meshgrid((np.arange(9) - 4.0) * SQUARE_M, (np.arange(6) - 2.5) * SQUARE_M)
BOARD = np.stack([XX.ravel(), YY.ravel()], axis=1)


def _outline() -> np.ndarray:
    """The outer squares' corners of :data:`BOARD` (its inner-corner grid one square further out on every
    side), a point per square along each edge, board frame (metres)."""
    lo, hi = BOARD.min(axis=0) - SQUARE_M, BOARD.max(axis=0) + SQUARE_M
    xs = np.arange(lo[0], hi[0] + SQUARE_M / 2, SQUARE_M)
    ys = np.arange(lo[1], hi[1] + SQUARE_M / 2, SQUARE_M)
    edges = [np.c_[xs, np.full_like(xs, y)] for y in (lo[1], hi[1])]
    return np.concatenate(edges + [np.c_[np.full_like(ys, x), ys] for x in (lo[0], hi[0])])


def _in_view(port: FlatPort, points: np.ndarray, turn_deg, centre_m) -> bool:
    """Whether board points (board frame) turned ``turn_deg`` about x then y and centred at ``centre_m``
    all appear inside the view through ``port``."""
    rotation = Rotation.from_euler("xy", turn_deg, degrees=True).as_matrix()
    uv = project_through_port(CAMERA, port, np.c_[points, np.zeros(len(points))] @ rotation.T + centre_m)
    return bool(np.all(np.isfinite(uv)) and np.all((uv >= 0) & (uv <= [CAMERA.width_px - 1, CAMERA.height_px - 1])))


def _view(turn_deg, centre_m, rng: np.random.Generator) -> BoardView | None:
    """The board turned ``turn_deg`` about x then y from facing the camera, centred at ``centre_m``,
    seen through the true port with :data:`NOISE_PX` of corner noise; None unless its outer squares are
    all in view (as a detector needs them)."""
    if not _in_view(TRUE, _outline(), turn_deg, centre_m):
        return None
    rotation = Rotation.from_euler("xy", turn_deg, degrees=True).as_matrix()
    uv = project_through_port(CAMERA, TRUE, np.c_[BOARD, np.zeros(len(BOARD))] @ rotation.T + centre_m)
    return BoardView(corners_px=uv + rng.normal(scale=NOISE_PX, size=uv.shape), board_points_m=BOARD)


def _alike(n: int, rng: np.random.Generator) -> list[BoardView]:
    """Views as a hurried user takes them: boards facing the camera near the middle, 0.40-0.45 m away."""
    views: list[BoardView] = []
    while len(views) < n:
        found = _view(rng.uniform(-5, 5, 2), [*rng.uniform(-0.03, 0.03, 2), rng.uniform(0.40, 0.45)], rng)
        if found is not None:
            views.append(found)
    return views


@pytest.fixture(scope="module")
def frontal() -> tuple[list[BoardView], PortCalibration]:
    """Four views as a hurried user takes them and the port calibrated from them (shared: a calibration
    takes seconds)."""
    views = _alike(4, np.random.default_rng(1))
    return views, calibrate_port(CAMERA, views, **LOOSE)


def test_views_that_leave_the_port_poorly_determined_get_advice_that_determines_it(frontal):
    views, before = frontal
    rng = np.random.default_rng(11)
    advice = advise_port_views(CAMERA, before, views, target_normal_std_deg=0.1, target_distance_std_m=1e-3)
    assert "normal" in advice.poorly_determined
    assert advice.normal_std_deg == before.normal_std_deg > 0.1
    assert len(advice.views) == 3
    predicted = [v.normal_std_deg for v in advice.views]
    assert predicted == sorted(predicted, reverse=True)
    assert predicted[0] < advice.normal_std_deg
    assert len({(tuple(v.centre_m.round(6)), v.turn_deg) for v in advice.views}) == 3  # three distinct views
    assert advice.lines()[0].startswith("the views leave the normal")
    assert not any("camera model" in line for line in advice.lines())  # none given: no camera model's part
    # Taking the advice: the port is known about as well as predicted, and better than with as many
    # more views like the first ones.
    added = [_view(v.turn_deg, v.centre_m, rng) for v in advice.views]
    assert all(v is not None for v in added)
    advised = calibrate_port(CAMERA, views + added, **LOOSE)
    alike = calibrate_port(CAMERA, views + _alike(3, rng), **LOOSE)
    ratio = advised.normal_std_deg / advice.views[-1].normal_std_deg
    assert 1 / ADVICE_PREDICTION_FACTOR < ratio < ADVICE_PREDICTION_FACTOR
    assert advised.normal_std_deg < 0.8 * alike.normal_std_deg
    assert advised.distance_std_m < 0.8 * alike.distance_std_m
    # Its stated uncertainty covers its error.
    assert _angle_deg(advised.port.normal, TRUE.normal) < 3 * advised.normal_std_deg
    assert abs(advised.port.distance_m - TRUE.distance_m) < 3 * advised.distance_std_m


def test_every_advised_board_is_seen_whole_with_its_outer_squares(frontal):
    # A detector finds a board only with its outer squares in view (OpenCV's needs each outer square's
    # whole outline): frontal boards at 0.40-0.45 m leave nearer, turned boards as the most informative
    # candidates, many of them with their inner corners in view and their outer squares not.
    views, calibration = frontal
    advice = advise_port_views(CAMERA, calibration, views, target_normal_std_deg=0.1, target_distance_std_m=1e-3)
    assert len(advice.views) == 3
    for view in advice.views:
        assert _in_view(calibration.port, _outline(), view.turn_deg, view.centre_m), view.description
    assert advice.views[-1].normal_std_deg < 0.6 * advice.normal_std_deg


def test_boards_that_fit_nowhere_whole_get_no_view_and_say_so(frontal):
    # The same corners on a board four times as large: its outer squares leave the view at every place.
    views, calibration = frontal
    large = [BoardView(corners_px=v.corners_px, board_points_m=4 * v.board_points_m) for v in views]
    advice = advise_port_views(CAMERA, calibration, large)
    assert advice.poorly_determined
    assert advice.views == ()
    assert "no board like these fits whole in the view" in advice.lines()[1]


def _model_calibration(model: CameraModel, views: list[BoardView]) -> PortCalibration:
    """The port from ``views`` on ``model``'s rays, its uncertainty propagated (as ``calibrate port --camera``)."""
    moved = [[corrected_view(v, m, CAMERA) for v in views] for m in model.spread_corrections()]
    corrected = [corrected_view(v, model.correction, CAMERA) for v in views]
    return calibrate_port(CAMERA, corrected, model_views=moved, **LOOSE)


def test_the_camera_models_part_falls_with_the_advised_views_as_predicted():
    # The views are the thin lens's; the camera model is the thin lens with an uncertainty in the focal
    # length (0.05 %), the radial term k1 (0.005) and the pupil's drift (1 mm): with four frontal boards
    # it is confounded with the port (0.26 deg, 2.5 mm), with boards turned it is not.
    spread = [[0, 5e-4, 0, 0, 0], [0, 0, 5e-3, 0, 0], [0, 0, 0, 0, 1e-3]]
    model = CameraModel(camera=camera_preset("tiny"), correction=RayCorrection(), spread=spread)
    rng = np.random.default_rng(1)
    views = _alike(4, rng)
    before = _model_calibration(model, views)
    part = before.covariance_parts["camera_model"]
    assert normal_std_deg(before.port, part) > 0.2
    assert math.sqrt(part[2, 2]) > 2e-3
    with pytest.raises(ParameterError, match="camera_model must be that model"):
        advise_port_views(CAMERA, before, views)
    advice = advise_port_views(CAMERA, before, views, camera_model=model)
    assert advice.camera_model_normal_deg == pytest.approx(normal_std_deg(before.port, part), rel=1e-12)
    last = advice.views[-1]
    assert last.camera_model_normal_deg < 0.4 * advice.camera_model_normal_deg
    assert last.camera_model_distance_m < 0.5 * advice.camera_model_distance_m
    # Below the targets with the advised views, the camera model is not named as a limit; with a
    # stricter distance target it is.
    assert last.camera_model_normal_deg < 0.1
    assert last.camera_model_distance_m < 1e-3
    assert not any("camera model" in line for line in advice.lines())
    strict = advise_port_views(CAMERA, before, views, camera_model=model, target_distance_std_m=0.5e-3)
    assert strict.views[-1].camera_model_distance_m > 0.5e-3
    assert "the camera model's own uncertainty still leaves" in strict.lines()[-1]
    # Taking the advice: the refitted port's camera model part and its stated uncertainty are as predicted.
    added = [_view(v.turn_deg, v.centre_m, rng) for v in advice.views]
    assert all(v is not None for v in added)
    after = _model_calibration(model, views + added)
    refit = after.covariance_parts["camera_model"]
    for predicted, found in (
        (last.camera_model_normal_deg, normal_std_deg(after.port, refit)),
        (last.camera_model_distance_m, math.sqrt(refit[2, 2])),
    ):
        assert 1 / ADVICE_MODEL_PART_FACTOR < predicted / found < ADVICE_MODEL_PART_FACTOR
    for predicted, found in ((last.normal_std_deg, after.normal_std_deg), (last.distance_std_m, after.distance_std_m)):
        assert 1 / ADVICE_PREDICTION_FACTOR < predicted / found < ADVICE_PREDICTION_FACTOR


def test_a_port_known_to_its_targets_gets_no_advice_and_a_camera_model_part_without_shifts_is_held():
    rng = np.random.default_rng(2)
    views = _alike(4, rng)
    result = calibrate_port(CAMERA, views, **LOOSE)
    none = advise_port_views(CAMERA, result, views, target_normal_std_deg=10.0, target_distance_std_m=0.1)
    assert none.poorly_determined == ()
    assert none.views == ()
    assert none.lines() == []
    # A camera model's part given without how the model moves the views (no shifts): held as it is.
    held = np.diag([math.radians(0.3) ** 2, math.radians(0.3) ** 2, 2e-3**2])
    parts = {**result.covariance_parts, "camera_model": held}
    with_model = type(result)(**{**vars(result), "covariance": result.covariance + held, "covariance_parts": parts})
    advice = advise_port_views(CAMERA, with_model, views)
    assert advice.camera_model_normal_deg == pytest.approx(0.3, rel=0.05)
    assert all(v.normal_std_deg > 0.29 for v in advice.views)
    assert all(v.camera_model_normal_deg == advice.camera_model_normal_deg for v in advice.views)
    assert "the camera model's own uncertainty still leaves +- 0.30" in advice.lines()[-1]


def test_bad_input_names_the_parameter():
    rng = np.random.default_rng(3)
    views = _alike(3, rng)
    result = calibrate_port(CAMERA, views, **LOOSE)
    with pytest.raises(ParameterError, match="target_normal_std_deg"):
        advise_port_views(CAMERA, result, views, target_normal_std_deg=0.0)
    with pytest.raises(ParameterError, match="count"):
        advise_port_views(CAMERA, result, views, count=0)
    with pytest.raises(ParameterError, match="views must be the calibration's 3"):
        advise_port_views(CAMERA, result, views[:2])
    with pytest.raises(ParameterError, match="camera_model must be a CameraModel"):
        advise_port_views(CAMERA, result, views, camera_model="tiny")  # type: ignore[arg-type]


def test_a_refused_port_carries_its_fit_and_gets_advice():
    rng = np.random.default_rng(4)
    views = _alike(3, rng)
    with pytest.raises(PortUndeterminedError, match="the views do not determine the port") as refused:
        calibrate_port(CAMERA, views, thickness_m=0.01, max_normal_std_deg=0.01)
    advice = advise_port_views(CAMERA, refused.value.calibration, views)
    assert advice.normal_std_deg == refused.value.calibration.normal_std_deg > 0.01
    assert advice.views
    assert advice.views[-1].normal_std_deg < advice.normal_std_deg
