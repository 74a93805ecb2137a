"""The camera's ray model and the port refined together (lfrefract.calibration.joint), and the
covariance a camera calibration carries for it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfrefract import FlatPort, ParameterError, PinholeCamera, Pose
from lfrefract.calibration.joint import (
    INVALID_PORT_RESIDUAL_PX,
    TILT_LIMIT_RAD,
    _JointProblem,
    calibrate_port_and_camera,
)
from lfrefract.calibration.port import BoardView
from lfrefract.optics.ray_correction import CorrectionEstimate, RayCorrection, apply_correction
from tests.tolerances import HELD_BACK_NOISE_FACTOR, JOINT_DISTANCE_M, JOINT_NORMAL_DEG

CAMERA = PinholeCamera(focal_px=600.0, cx_px=399.5, cy_px=299.5, width_px=800, height_px=600)
TRUE = RayCorrection(pupil_scale=0.985, slope_scale=1.0, k1=0.08, k2=0.1, pupil_drift_m=-0.006)
PORT = FlatPort.from_degrees(distance_m=0.015, thickness_m=0.004, tilt_x_deg=20.0, tilt_y_deg=-3.0)
#: Aperture points the corners are seen from (the centre and four 3 mm off it), metres.
APERTURE_M = np.array([[0.0, 0.0], [0.003, 0.0], [-0.003, 0.0], [0.0, 0.003], [0.0, -0.003]])
#: The in-air estimate's standard deviations, and its error: 1.3 sigma in pupil scale, 1 in drift.
PRIOR_STD = np.array([0.003, 0.0015, 0.02, 0.05, 0.002])
PRIOR = CorrectionEstimate(
    correction=RayCorrection.from_vector(TRUE.vector() + np.array([0.004, -0.001, 0.01, 0.0, 0.002])),
    covariance=np.diag(PRIOR_STD**2),
)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(a @ b)))


def _views(n: int, noise_px: float, seed: int, *, grid: tuple[int, int] = (7, 5)) -> list[BoardView]:
    """``n`` boards at random poses 0.15-0.35 m away, each seen from every aperture point at a
    ``grid`` (columns, rows) of pixels around its centre; the board points are where the true rays
    land on the board."""
    rng = np.random.default_rng(seed)
    uu, vv = np.meshgrid(np.linspace(-60.0, 60.0, grid[0]), np.linspace(-45.0, 45.0, grid[1]))
    grid = np.stack([uu.ravel(), vv.ravel()], axis=1)
    a = np.repeat(APERTURE_M, len(grid), axis=0)
    views = []
    while len(views) < n:
        pose = Pose.from_euler_xyz_deg(
            rng.uniform(-30, 30, 3) * [1, 1, 0.3],
            [rng.uniform(-0.08, 0.08), rng.uniform(-0.06, 0.06), rng.uniform(0.15, 0.35)],
        )
        position, rotation = np.asarray(pose.position_m), np.asarray(pose.rotation)
        pixels = np.tile(CAMERA.project(position[None])[0] + grid, (len(APERTURE_M), 1))
        if not np.all((pixels > 0) & (pixels < [CAMERA.width_px - 1, CAMERA.height_px - 1])):
            continue
        x = np.column_stack([pixels, np.ones(len(pixels))]) @ np.linalg.inv(CAMERA.K).T
        trace = PORT.trace_from_air(*apply_correction(TRUE.vector(), a, x[:, :2] / x[:, 2:3]))
        q, w = trace.exit_points_cam, trace.directions_cam
        s = ((position - q) @ rotation[:, 2]) / (w @ rotation[:, 2])
        board = ((q + s[:, None] * w) - position) @ rotation
        noisy = pixels + rng.normal(scale=noise_px, size=pixels.shape)
        views.append(BoardView(corners_px=noisy, board_points_m=board[:, :2], centres_m=np.c_[a, np.zeros(len(a))]))
    return views


def test_the_refinement_finds_the_port_that_the_in_air_model_misses():
    result = calibrate_port_and_camera(CAMERA, _views(6, 0.02, seed=1), prior=PRIOR, thickness_m=PORT.thickness_m)
    sequential, joint = result.sequential.port, result.port.port
    # On the in-air model the port is off by far more than the bounds; refined, within them.
    assert _angle_deg(sequential.normal, PORT.normal) > 2 * JOINT_NORMAL_DEG
    assert abs(sequential.distance_m - PORT.distance_m) > 4 * JOINT_DISTANCE_M
    assert _angle_deg(joint.normal, PORT.normal) < JOINT_NORMAL_DEG
    assert abs(joint.distance_m - PORT.distance_m) < JOINT_DISTANCE_M
    # The ray model moved towards the truth, by the prior's measure.
    inverse = np.linalg.inv(PRIOR.covariance)
    before = TRUE.vector() - PRIOR.correction.vector()
    after = TRUE.vector() - result.correction.correction.vector()
    assert after @ inverse @ after < 0.1 * (before @ inverse @ before)
    assert result.prior_chi2 == pytest.approx(before @ inverse @ before, rel=0.5)
    # The refined covariance is tighter than the prior's: the underwater boards said something.
    assert np.all(result.correction.std < PRIOR_STD)
    assert result.port.rms_px < result.sequential.rms_px
    # The held-back check keeps it: boards left out of the fit are predicted to their noise (0.02 px
    # in the image, n_air / n_water of it as the port's geometric residual), on the in-air model not.
    check, noise_px = result.check, 0.02 / 1.333
    assert result.accepted
    assert check.kept == "joint"
    assert check.folds == 5
    assert result.port is result.joint_port
    assert result.correction is result.joint_correction
    assert check.joint_rms_px < HELD_BACK_NOISE_FACTOR * noise_px < check.in_air_rms_px / HELD_BACK_NOISE_FACTOR
    assert check.in_air_rms_px - check.joint_rms_px > 2 * check.standard_error_px
    assert len(check.board_joint_rms_px) == 6
    assert max(check.board_joint_rms_px) < HELD_BACK_NOISE_FACTOR * noise_px
    data = result.to_dict()
    assert data["in_air_correction"] == PRIOR.correction.to_dict()
    assert data["correction"] == result.correction.correction.to_dict()
    assert data["kept"] == "joint"
    assert data["held_back"]["joint_rms_px"] == check.joint_rms_px


def test_a_refinement_that_does_not_predict_held_back_boards_better_is_rejected():
    # The in-air model is the truth: the joint fit moves it within its covariance to fit the boards'
    # noise, and predicts boards it did not see no better. The port on the in-air model is kept.
    truth = CorrectionEstimate(correction=TRUE, covariance=PRIOR.covariance)
    result = calibrate_port_and_camera(
        CAMERA, _views(4, 0.02, seed=2, grid=(4, 3)), prior=truth, thickness_m=PORT.thickness_m
    )
    check = result.check
    assert not result.accepted
    assert check.kept == "in-air"
    assert check.folds == 4  # one board held back in each
    assert result.port is result.sequential
    assert result.correction is truth
    assert result.joint_correction.correction != TRUE  # the joint fit moved it; not kept
    assert check.in_air_rms_px - check.joint_rms_px <= check.standard_error_px
    assert check.joint_rms_px >= check.in_air_rms_px  # fitted to noise, it predicts worse than the truth
    assert "with the in-air model" in check.reason
    assert "standard error" in check.reason
    assert _angle_deg(result.port.port.normal, PORT.normal) < JOINT_NORMAL_DEG
    data = result.to_dict()
    assert data["kept"] == "in-air"
    assert data["held_back"]["reason"] == check.reason


def test_fewer_than_four_boards_keep_the_in_air_model():
    # A fold's fits would rest on two boards: the check does not run, and what is not checked is not kept.
    result = calibrate_port_and_camera(
        CAMERA, _views(3, 0.02, seed=1, grid=(4, 3)), prior=PRIOR, thickness_m=PORT.thickness_m
    )
    assert not result.accepted
    assert result.port is result.sequential
    assert result.correction is PRIOR
    assert result.check.folds == 0
    assert result.check.in_air_rms_px is None
    assert "needs at least 4 boards, got 3" in result.check.reason


def test_a_step_to_no_port_costs_much_and_does_not_fail():
    # The solver (unbounded Levenberg-Marquardt) tried a negative distance on a benchmark's straight port:
    # building that port raised ParameterError out of the fit. Such a step must cost a lot instead.
    views = _views(2, 0.0, seed=3)
    problem = _JointProblem(CAMERA, views, PORT)
    x = np.concatenate([TRUE.vector(), [PORT.tilt_x_rad, PORT.tilt_y_rad, PORT.distance_m], np.zeros(12)])
    assert np.all(np.isfinite(problem.residuals_px(x)))
    for bad in ({7: -0.02}, {7: 0.0}, {5: TILT_LIMIT_RAD}, {6: -1.2 * TILT_LIMIT_RAD}):
        y = x.copy()
        for index, value in bad.items():
            y[index] = value
        residuals = problem.residuals_px(y)
        assert residuals.shape == (2 * sum(len(v.corners_px) for v in views),)
        assert np.all(residuals == INVALID_PORT_RESIDUAL_PX)


def test_bad_input_is_refused():
    views = _views(2, 0.0, seed=2)
    with pytest.raises(ParameterError, match="prior must be a CorrectionEstimate"):
        calibrate_port_and_camera(CAMERA, views, prior=PRIOR.correction, thickness_m=0.004)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="camera must be a PinholeCamera"):
        calibrate_port_and_camera(None, views, prior=PRIOR, thickness_m=0.004)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="views must be BoardView"):
        calibrate_port_and_camera(CAMERA, [*views, "x"], prior=PRIOR, thickness_m=0.004)  # type: ignore[list-item]


def test_a_correction_estimate_round_trips_and_refuses_a_bad_covariance():
    data = PRIOR.covariance_to_dict()
    np.testing.assert_array_equal(CorrectionEstimate.covariance_from_dict(data), PRIOR.covariance)
    np.testing.assert_allclose(PRIOR.std, PRIOR_STD)
    with pytest.raises(ParameterError, match="parameters must be"):
        CorrectionEstimate.covariance_from_dict({**data, "parameters": data["parameters"][::-1]})
    with pytest.raises(ParameterError, match="5 rows of 5"):
        CorrectionEstimate.covariance_from_dict({**data, "matrix": data["matrix"][:4]})
    with pytest.raises(ParameterError, match=r"matrix\[0\]\[0\]"):
        CorrectionEstimate.covariance_from_dict({**data, "matrix": [["a"] * 5, *data["matrix"][1:]]})
    skew = PRIOR.covariance.copy()
    skew[0, 1] = 1e-6
    for bad, match in ((np.eye(4), "5 x 5"), (skew, "symmetric"), (-np.eye(5), "positive definite")):
        with pytest.raises(ParameterError, match=match):
            CorrectionEstimate(correction=TRUE, covariance=bad)
    with pytest.raises(ParameterError, match="correction must be a RayCorrection"):
        CorrectionEstimate(correction=TRUE.vector(), covariance=np.eye(5))  # type: ignore[arg-type]
    assert not PRIOR.covariance.flags.writeable
