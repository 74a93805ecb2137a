"""The method registry and projectors (lfrefract.methods), without rendering.

The render-based comparison of the methods is tests/simulator/test_approx_baseline.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfrefract import FlatPort, ParameterError, PinholeCamera, camera_preset, virtual_camera_for
from lfrefract.calibration import ApproxCalibration
from lfrefract.calibration.approx import INTRINSIC_NAMES
from lfrefract.methods import (
    METHODS,
    ApproxProjector,
    CalibrationViews,
    CentralProjector,
    ConventionalView,
    NaiveProjector,
    ProposedDistortionProjector,
    ProposedProjector,
    build_projector,
    conventional_image,
)
from lfrefract.synthesis.views import finite_pixels, naive_view, subaperture_view
from lfrefract.synthesis.warp_map import build_warp_map
from tests.tolerances import FLOAT32_WEIGHT_SUM


@pytest.fixture(scope="module")
def camera():
    return camera_preset("tiny")


@pytest.fixture(scope="module")
def raw(camera):
    return np.random.default_rng(0).random((camera.sensor.height_px, camera.sensor.width_px, 3), dtype=np.float32)


@pytest.fixture(scope="module")
def port():
    return FlatPort.from_degrees(distance_m=0.012, thickness_m=0.004, tilt_x_deg=15.0)


@pytest.fixture(scope="module")
def warp(camera, port):
    return build_warp_map(camera, port)


def _identity_calibration(view: PinholeCamera, **changes) -> ApproxCalibration:
    """A calibration whose undistortion onto ``view`` is the identity."""
    fields = {
        "K": view.K,
        "dist_coeffs": np.zeros(5),
        "image_size": (view.width_px, view.height_px),
        "pattern": (6, 4),
        "square_size_m": 0.01,
        "depth_m": 0.2,
        "view_depths_m": np.full(3, 0.2),
        "rms_px": 0.1,
        "view_rms_px": np.full(3, 0.1),
        "intrinsic_std": np.zeros(len(INTRINSIC_NAMES)),
    }
    return ApproxCalibration(**{**fields, **changes})


@pytest.mark.parametrize(
    "view",
    [None, PinholeCamera(focal_px=230.0, cx_px=40.3, cy_px=30.1, width_px=90, height_px=70)],
    ids=["default", "zoomed"],
)
def test_conventional_view_is_the_central_naive_view(camera, raw, view):
    expected = naive_view(camera, raw, output=view, kind="central")
    conventional = ConventionalView(camera, view if view is not None else virtual_camera_for(camera))
    image = conventional.apply(raw)
    assert image.dtype == np.float32
    assert np.array_equal(np.isnan(image), np.isnan(expected))
    assert np.nanmax(np.abs(image - expected)) < FLOAT32_WEIGHT_SUM
    assert np.array_equal(conventional_image(camera, raw, view=view), expected, equal_nan=True)
    grey = conventional.apply(raw[..., 1])
    assert grey.shape == image.shape[:2]
    assert np.allclose(grey, image[..., 1], equal_nan=True)


def test_conventional_view_leaves_unrecorded_pixels_out(camera, raw):
    """A board capture's NaN (unrecorded) pixels: with ``recorded`` each micro-image's sample is weighed
    over its recorded pixels, as in the sub-aperture views, instead of one NaN spoiling it. Here one
    pixel of every centre's bilinear footprint is NaN."""
    conventional = ConventionalView(camera, virtual_camera_for(camera))
    whole = conventional.apply(raw)
    u, v = np.floor(camera.micro_image_centres_px(camera.lens_indices_on_sensor())).astype(int).T
    inside = (u >= 0) & (v >= 0) & (u < raw.shape[1]) & (v < raw.shape[0])
    holed = raw.copy()
    holed[v[inside], u[inside], 1] = np.nan
    assert np.all(np.isnan(conventional.apply(holed)[..., 1]))  # every lens's green sample spoilt
    recorded = finite_pixels(holed)
    image = conventional.apply(holed, recorded=recorded)
    assert np.array_equal(np.isnan(image), np.isnan(whole))
    expected = subaperture_view(camera, holed, (0.0, 0.0), recorded=recorded)
    assert np.nanmax(np.abs(image - expected)) < FLOAT32_WEIGHT_SUM
    assert finite_pixels(raw) is None  # nothing to leave out


def test_conventional_view_checks_the_raw_shape(camera, raw):
    with pytest.raises(ParameterError, match="raw must have shape"):
        ConventionalView(camera, virtual_camera_for(camera)).apply(raw[:-1])


def test_registry_names_every_method():
    assert set(METHODS) == {"naive", "approx", "proposed", "proposed+distortion", "depth-aware"}


def test_proposed_is_the_warp_map_with_nan_where_unfilled(camera, port, raw, warp):
    projector = build_projector("proposed", camera, port, warp=warp)
    assert isinstance(projector, ProposedProjector)
    assert isinstance(projector, CentralProjector)
    assert projector.name == "proposed"
    assert projector.output == warp.output
    image = projector.apply(raw)
    filled = warp.filled
    assert not filled.all()  # the tilted port leaves part of the image without rays
    assert np.array_equal(image[filled], warp.apply(raw)[filled])
    assert np.all(np.isnan(image[~filled]))
    data = projector.to_dict()
    assert data["method"] == "proposed"
    assert data["warp_map_key"] == warp.key


def test_naive_projector(camera, port, raw):
    projector = build_projector("naive", camera, port)
    assert isinstance(projector, NaiveProjector)
    assert isinstance(projector, CentralProjector)
    assert projector.output == virtual_camera_for(camera)
    assert np.array_equal(projector.apply(raw), ConventionalView(camera, projector.output).apply(raw), equal_nan=True)
    assert projector.to_dict()["method"] == "naive"


def test_approx_with_identity_calibration_is_the_conventional_image(camera, raw):
    view = virtual_camera_for(camera)
    projector = ApproxProjector(
        conventional=ConventionalView(camera, view), calibration=_identity_calibration(view), output=view
    )
    assert isinstance(projector, CentralProjector)
    assert projector.name == "approx"
    assert projector.depth_m == 0.2
    image = projector.apply(raw)
    expected = conventional_image(camera, raw)
    both = np.isfinite(image) & np.isfinite(expected)
    # Bilinear interpolation at the pixel centres returns the pixels; a NaN neighbour spreads by
    # one pixel at most.
    assert both.mean() > 0.9
    assert np.allclose(image[both], expected[both], atol=FLOAT32_WEIGHT_SUM)
    # Its plain-data form reads back, given the camera.
    back = ApproxProjector.from_dict(projector.to_dict(), camera)
    assert back.to_dict() == projector.to_dict()
    assert np.array_equal(back.apply(raw), image, equal_nan=True)


def test_approx_undistorts_onto_the_chosen_output(camera, raw):
    view = virtual_camera_for(camera)
    output = PinholeCamera(focal_px=view.focal_px / 2, cx_px=22.0, cy_px=17.0, width_px=45, height_px=35)
    turn = 0.02  # rad about y: the model looks 0.02 rad to the right of the camera
    rotation = np.array([[math.cos(turn), 0, math.sin(turn)], [0, 1, 0], [-math.sin(turn), 0, math.cos(turn)]])
    calibration = _identity_calibration(view, rotation=rotation, known_corners=True)
    projector = ApproxProjector(conventional=ConventionalView(camera, view), calibration=calibration, output=output)
    assert projector.apply(raw).shape == (35, 45, 3)
    # A camera-frame direction lands where the output K puts it.
    direction = np.array([[0.05, -0.03, 1.0]])
    source = calibration.project(direction)
    assert np.allclose(calibration.undistort_points(source, output), output.project(direction), atol=1e-6)


def test_proposed_distortion_with_identity_calibration_is_proposed(camera, port, raw, warp):
    projector = ProposedDistortionProjector(warp, _identity_calibration(warp.output))
    assert isinstance(projector, CentralProjector)
    assert projector.output == warp.output
    image = projector.apply(raw)
    proposed = ProposedProjector(warp).apply(raw)
    both = np.isfinite(image) & np.isfinite(proposed)
    assert np.allclose(image[both], proposed[both], atol=FLOAT32_WEIGHT_SUM)
    data = projector.to_dict()
    assert data["method"] == "proposed+distortion"
    assert data["calibration_depth_m"] == 0.2


def test_bad_method_input(camera, port, raw, warp):
    with pytest.raises(ParameterError, match="name must be one of"):
        build_projector("exact", camera, port)
    with pytest.raises(ParameterError, match="method 'approx' needs calibration views"):
        build_projector("approx", camera, port)
    with pytest.raises(ParameterError, match="method 'proposed\\+distortion' needs calibration views"):
        build_projector("proposed+distortion", camera, port, warp=warp)
    with pytest.raises(ParameterError, match="need the port"):
        build_projector("proposed", camera)
    with pytest.raises(ParameterError, match="camera must be a LightFieldCamera"):
        build_projector("proposed", "tiny", port)
    other = PinholeCamera(focal_px=100.0, cx_px=10.0, cy_px=10.0, width_px=21, height_px=21)
    with pytest.raises(ParameterError, match="differs from the warp map's"):
        build_projector("proposed", camera, port, warp=warp, output=other)
    view = virtual_camera_for(camera)
    with pytest.raises(ParameterError, match="the conventional view is 92 x 69 px but the calibration is for 21 x 21"):
        ApproxProjector(
            conventional=ConventionalView(camera, view), calibration=_identity_calibration(other), output=view
        )
    with pytest.raises(ParameterError, match="warp map's output is 92 x 69 px"):
        ProposedDistortionProjector(warp, _identity_calibration(other))
    with pytest.raises(ParameterError, match="warp must be a WarpMap"):
        ProposedProjector("map")
    with pytest.raises(ParameterError, match=r"corners_cam must have one array per raw image \(2\), got 1"):
        CalibrationViews(
            raws=[np.zeros((2, 2))] * 2, pattern=(6, 4), square_size_m=0.01, corners_cam=[np.ones((24, 3))]
        )
    with pytest.raises(ParameterError, match="method must be one of"):
        ApproxProjector.from_dict({"method": "proposed", "calibration": {}, "view": {}, "output": {}}, camera)
