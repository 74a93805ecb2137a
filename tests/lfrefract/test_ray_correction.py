"""The ray correction of the thin-lens model (lfrefract.optics.ray_correction)."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract.errors import ParameterError
from lfrefract.optics.presets import camera_preset
from lfrefract.optics.ray_correction import PARAMETERS, RayCorrection


def _thin_rays():
    camera = camera_preset("tiny")
    rays = camera.captured_rays()
    keep = rays.in_aperture
    a = rays.origins_cam[keep, :2]
    t = rays.directions_cam[keep, :2] / rays.directions_cam[keep, 2:3]
    return rays, a, t


def test_the_identity_gives_back_the_thin_lens_rays():
    rays, a, t = _thin_rays()
    origins, directions = RayCorrection().apply(a, t)
    np.testing.assert_allclose(origins[:, :2], a, atol=1e-15)
    np.testing.assert_allclose(origins[:, 2], 0.0)
    np.testing.assert_allclose(directions, rays.directions_cam[rays.in_aperture], atol=1e-12)


def test_a_ray_passes_through_its_scaled_aperture_point_on_its_drifted_pupil_plane():
    _, a, t = _thin_rays()
    correction = RayCorrection(pupil_scale=1.1, slope_scale=0.97, k1=0.2, k2=-0.1, pupil_drift_m=-0.006)
    origins, directions = correction.apply(a, t)
    slopes = directions[:, :2] / directions[:, 2:3]
    r2 = np.sum(t * t, axis=1, keepdims=True)
    np.testing.assert_allclose(slopes, 0.97 * t * (1 + 0.2 * r2 - 0.1 * r2 * r2), rtol=1e-12)
    pupil_z = -0.006 * np.sum(slopes * slopes, axis=1, keepdims=True)
    at_pupil = origins[:, :2] + slopes * pupil_z  # the ray where it crosses z = d |t'|^2
    np.testing.assert_allclose(at_pupil, 1.1 * a, atol=1e-15)
    assert np.ptp(pupil_z) > 1e-4  # the field spreads the pupil planes: the term is exercised


def test_it_round_trips_and_an_earlier_file_without_the_drift_reads_as_no_drift():
    correction = RayCorrection(pupil_scale=1.01, slope_scale=0.99, k1=0.1, k2=0.05, pupil_drift_m=0.002)
    assert RayCorrection.from_dict(correction.to_dict()) == correction
    assert list(correction.to_dict()) == list(PARAMETERS)
    earlier = {"pupil_scale": 1.01, "slope_scale": 0.99, "k1": 0.1, "k2": 0.05}
    assert RayCorrection.from_dict(earlier).pupil_drift_m == 0.0


@pytest.mark.parametrize(
    ("data", "named"),
    [
        ({"pupil_scale": 1.0, "slope_scale": 1.0, "k1": 0.0}, "k2"),
        ({"pupil_scale": 1.0, "slope_scale": 1.0, "k1": 0.0, "k2": 0.0, "drift": 0.0}, "drift"),
        ({"pupil_scale": 1.0, "slope_scale": 1.0, "k1": 0.0, "k2": 0.0, "pupil_drift_m": 0.7}, "pupil_drift_m"),
        ({"pupil_scale": 3.0, "slope_scale": 1.0, "k1": 0.0, "k2": 0.0}, "pupil_scale"),
    ],
)
def test_a_bad_correction_is_refused_naming_the_key(data, named):
    with pytest.raises(ParameterError, match=named):
        RayCorrection.from_dict(data)
