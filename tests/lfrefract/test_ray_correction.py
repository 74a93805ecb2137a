"""The ray correction of the thin-lens model (lfrefract.optics.ray_correction)."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract.errors import ParameterError
from lfrefract.optics.presets import camera_preset
from lfrefract.optics.ray_correction import PARAMETERS, RayCorrection
from tests.tolerances import FLOAT64_GEOMETRY_M, FLOAT64_UNIT


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


def test_thin_lens_rays_inverts_the_correction_from_any_point_on_the_ray():
    _, a, t = _thin_rays()
    correction = RayCorrection(pupil_scale=1.02, slope_scale=0.98, k1=0.12, k2=0.08, pupil_drift_m=-0.006)
    origins, directions = correction.apply(a, t)
    along_m = np.linspace(0.0, 0.05, len(a))[:, None]  # points up to 50 mm in front of the lens
    twin_a, twin_t, found = correction.thin_lens_rays(origins + along_m * directions, 3.0 * directions)
    assert found.all()
    np.testing.assert_allclose(twin_a, a, rtol=0, atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_allclose(twin_t, t, rtol=0, atol=FLOAT64_UNIT)


def test_a_ray_beyond_the_fold_of_the_radial_terms_has_no_thin_lens_ray():
    """k1 = -10: s rho (1 + k1 rho^2) peaks at slope 0.122 (rho = 0.183); steeper rays have no twin."""
    correction = RayCorrection(k1=-10.0)
    slopes = np.array([[0.05, 0.0], [0.0, -0.1], [0.2, 0.0], [0.08, 0.08]])
    directions = np.column_stack([slopes, np.ones(4)])
    twin_a, twin_t, found = correction.thin_lens_rays(np.zeros((4, 3)), directions)
    np.testing.assert_array_equal(found, [True, True, False, True])
    assert np.isnan(twin_a[2]).all()
    assert np.isnan(twin_t[2]).all()
    back = correction.slopes(twin_t[found])
    np.testing.assert_allclose(back, slopes[found], rtol=0, atol=FLOAT64_UNIT)
