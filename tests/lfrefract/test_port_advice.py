"""The port calibration's advice: what its views leave poorly determined, and which views fix it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lfrefract import FlatPort, ParameterError
from lfrefract.calibration.advice import advise_port_views
from lfrefract.calibration.port import BoardView, PortUndeterminedError, calibrate_port, project_through_port
from tests.lfrefract.test_port_calibration import BOARD, CAMERA, _angle_deg

TRUE = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.01, tilt_x_deg=20.0, tilt_y_deg=10.0)
NOISE_PX = 0.4
LOOSE = {"thickness_m": 0.01, "max_normal_std_deg": 90.0, "max_distance_std_m": 1.0}


def _view(turn_deg, centre_m, rng: np.random.Generator) -> BoardView | None:
    """The board turned ``turn_deg`` about x then y from facing the camera, centred at ``centre_m``,
    seen through the true port with :data:`NOISE_PX` of corner noise; None if not seen whole."""
    rotation = Rotation.from_euler("xy", turn_deg, degrees=True).as_matrix()
    uv = project_through_port(CAMERA, TRUE, np.c_[BOARD, np.zeros(len(BOARD))] @ rotation.T + centre_m)
    inside = np.all(np.isfinite(uv)) and np.all((uv >= 0) & (uv <= [CAMERA.width_px - 1, CAMERA.height_px - 1]))
    return (
        BoardView(corners_px=uv + rng.normal(scale=NOISE_PX, size=uv.shape), board_points_m=BOARD) if inside else None
    )


def _alike(n: int, rng: np.random.Generator) -> list[BoardView]:
    """Views as a hurried user takes them: boards facing the camera near the middle, 0.40-0.45 m away."""
    views: list[BoardView] = []
    while len(views) < n:
        found = _view(rng.uniform(-5, 5, 2), [*rng.uniform(-0.03, 0.03, 2), rng.uniform(0.40, 0.45)], rng)
        if found is not None:
            views.append(found)
    return views


@pytest.mark.parametrize("seed", [1])
def test_views_that_leave_the_port_poorly_determined_get_advice_that_determines_it(seed):
    rng = np.random.default_rng(seed)
    views = _alike(4, rng)
    before = calibrate_port(CAMERA, views, **LOOSE)
    advice = advise_port_views(CAMERA, before, views, target_normal_std_deg=0.1, target_distance_std_m=1e-3)
    assert "normal" in advice.poorly_determined
    assert advice.normal_std_deg == before.normal_std_deg > 0.1
    assert len(advice.views) == 3
    predicted = [v.normal_std_deg for v in advice.views]
    assert predicted == sorted(predicted, reverse=True)
    assert predicted[0] < advice.normal_std_deg
    assert len({(tuple(v.centre_m.round(6)), v.turn_deg) for v in advice.views}) == 3  # three distinct views
    assert advice.lines()[0].startswith("the views leave the normal")
    # Taking the advice: the port is known at least about as well as predicted, and better than with
    # as many more views like the first ones.
    added = [_view(v.turn_deg, v.centre_m, rng) for v in advice.views]
    assert all(v is not None for v in added)
    advised = calibrate_port(CAMERA, views + added, **LOOSE)
    alike = calibrate_port(CAMERA, views + _alike(3, rng), **LOOSE)
    assert advised.normal_std_deg < 1.25 * advice.views[-1].normal_std_deg  # the prediction is conservative
    assert advised.normal_std_deg < 0.8 * alike.normal_std_deg
    assert advised.distance_std_m < 0.8 * alike.distance_std_m
    # Its stated uncertainty covers its error.
    assert _angle_deg(advised.port.normal, TRUE.normal) < 3 * advised.normal_std_deg
    assert abs(advised.port.distance_m - TRUE.distance_m) < 3 * advised.distance_std_m


def test_a_port_known_to_its_targets_gets_no_advice_and_the_camera_models_floor_is_named():
    rng = np.random.default_rng(2)
    views = _alike(4, rng)
    result = calibrate_port(CAMERA, views, **LOOSE)
    none = advise_port_views(CAMERA, result, views, target_normal_std_deg=10.0, target_distance_std_m=0.1)
    assert none.poorly_determined == ()
    assert none.views == ()
    assert none.lines() == []
    # A camera model whose own uncertainty exceeds the target: no view reduces that part.
    floor = np.diag([math.radians(0.3) ** 2, math.radians(0.3) ** 2, 2e-3**2])
    parts = {**result.covariance_parts, "camera_model": floor}
    with_model = type(result)(**{**vars(result), "covariance": result.covariance + floor, "covariance_parts": parts})
    advice = advise_port_views(CAMERA, with_model, views)
    assert advice.camera_model_floor_normal_deg == pytest.approx(0.3, rel=0.05)
    assert all(v.normal_std_deg > 0.29 for v in advice.views)
    assert "camera model's own uncertainty" in advice.lines()[-1]


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


def test_a_refused_port_carries_its_fit_and_gets_advice():
    rng = np.random.default_rng(4)
    views = _alike(3, rng)
    with pytest.raises(PortUndeterminedError, match="the views do not determine the port") as refused:
        calibrate_port(CAMERA, views, thickness_m=0.01, max_normal_std_deg=0.01)
    advice = advise_port_views(CAMERA, refused.value.calibration, views)
    assert advice.normal_std_deg == refused.value.calibration.normal_std_deg > 0.01
    assert advice.views
    assert advice.views[-1].normal_std_deg < advice.normal_std_deg
