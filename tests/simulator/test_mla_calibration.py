"""MLA calibration from rendered white images against the camera's ground truth (issue 4).

Three tiny cameras (1907 lenses on 480 x 360 px): the preset (hexagonal, unrotated, on axis), a
hexagonal MLA rotated 0.1 rad and offset, focused closer (f' != f, so the micro-image scale differs
from the preset's), and a square MLA rotated -0.2 rad and offset. 64 spp each.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from lfrefract import MicrolensArray, camera_preset
from lfrefract.calibration import LENS_STATUS, calibrate_mla
from simulator.config import RenderSettings, embedded_scenes, load_scene
from simulator.job import render_raw
from tests.tolerances import (
    MLA_FITTED_CENTRE_MAX_PX,
    MLA_FITTED_CENTRE_RMS_PX,
    MLA_MEASURED_CENTRE_MAX_PX,
    MLA_MEASURED_CENTRE_RMS_PX,
    MLA_OFFSET_PX,
    MLA_PITCH_PX,
    MLA_ROTATION_RAD,
)

pytestmark = pytest.mark.render

_TINY = camera_preset("tiny")
CAMERAS = {
    "hex": _TINY,
    "hex-rotated-offset": dataclasses.replace(
        _TINY,
        lens_to_mla_m=6.2e-3,
        mla=MicrolensArray(
            grid="hex", pitch_m=100e-6, focal_length_m=200e-6, rotation_rad=0.1, offset_m=(23e-6, -41e-6)
        ),
    ),
    "square-rotated-offset": dataclasses.replace(
        _TINY,
        mla=MicrolensArray(
            grid="square", pitch_m=100e-6, focal_length_m=200e-6, rotation_rad=-0.2, offset_m=(37e-6, 12e-6)
        ),
    ),
}


@pytest.fixture(scope="module", params=list(CAMERAS))
def calibrated(request, mi):
    """(camera, calibration, the camera's lattice index of each calibrated lens)."""
    camera = CAMERAS[request.param]
    config = load_scene(embedded_scenes()["white"]).with_overrides(camera=camera, render=RenderSettings(spp=64, seed=0))
    calibration = calibrate_mla(render_raw(mi, config, progress=False))  # RGB: channels averaged
    return camera, calibration, camera.lens_indices_for_pixels(calibration.centres_px)


def test_lattice_and_implied_mla(calibrated):
    camera, cal, true_idx = calibrated
    assert cal.grid == camera.mla.grid
    assert cal.pitch_px == pytest.approx(camera.micro_image_pitch_px, abs=MLA_PITCH_PX)
    period = math.pi / 3 if cal.grid == "hex" else math.pi / 2
    rotation_error = (cal.rotation_rad - camera.mla.rotation_rad + period / 2) % period - period / 2
    assert abs(rotation_error) < MLA_ROTATION_RAD
    # The physical MLA from the micro-image lattice (sensor pixel pitch, f' and f_mla known).
    mla = cal.calibrated_camera(camera).mla
    px_per_m = camera.micro_image_scale / camera.sensor.pixel_pitch_m  # lens-plane metres -> sensor px
    assert mla.grid == camera.mla.grid
    assert mla.pitch_m == pytest.approx(camera.mla.pitch_m, abs=MLA_PITCH_PX / px_per_m)
    # Lens (0, 0) of the calibration is the camera's lens true_idx - cal.indices (one shift for all).
    shift = true_idx - cal.indices
    assert np.all(shift == shift[0])
    offset_error = np.linalg.norm(np.subtract(mla.offset_m, camera.mla.centres_m(shift[:1])[0]))
    assert offset_error * px_per_m < MLA_OFFSET_PX


def test_every_micro_image_centre(calibrated):
    camera, cal, true_idx = calibrated
    assert {tuple(r) for r in true_idx} == {tuple(r) for r in camera.lens_indices_on_sensor()}
    truth = camera.micro_image_centres_px(true_idx)
    fitted = np.linalg.norm(cal.centres_px - truth, axis=1)
    assert np.sqrt(np.mean(fitted**2)) < MLA_FITTED_CENTRE_RMS_PX
    assert fitted.max() < MLA_FITTED_CENTRE_MAX_PX
    used = cal.used
    measured = np.linalg.norm(cal.measured_px[used] - truth[used], axis=1)
    assert np.sqrt(np.mean(measured**2)) < MLA_MEASURED_CENTRE_RMS_PX
    assert measured.max() < MLA_MEASURED_CENTRE_MAX_PX
    # Radiance is uniform and nothing vignettes a disc here: every micro-image whose window lies on
    # the sensor is used (bar rare noise outliers), and the quality figure is the measured error.
    counts = cal.status_counts()
    assert counts["dim"] == 0
    assert counts["outlier"] <= 2
    assert counts["used"] > 0.9 * len(cal.indices)
    assert cal.residual_rms_px == pytest.approx(np.sqrt(np.mean(measured**2)), rel=0.1)
    edge = cal.status == LENS_STATUS.index("edge")
    half = cal.window_radius_px + 0.5
    h, w = camera.sensor.height_px, camera.sensor.width_px
    near_border = (
        (truth[:, 0] < half) | (truth[:, 0] > w - 1 - half) | (truth[:, 1] < half) | (truth[:, 1] > h - 1 - half)
    )
    assert np.all(near_border[edge])
