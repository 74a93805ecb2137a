"""The light-field camera with a real main lens: validation, micro-image geometry, object-space rays."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from lfrefract import camera_preset
from lfrefract.errors import ParameterError
from lfrefract.optics.lens import lens_preset
from lfrefract.optics.real_lens import RealLensCamera


@pytest.fixture(scope="module")
def tiny_dg() -> RealLensCamera:
    return RealLensCamera.from_preset(camera_preset("tiny"), "double-gauss")


def test_preset_matches_the_cameras_first_order_data(tiny_dg):
    fo = tiny_dg.first_order
    assert math.isclose(fo.efl_m, tiny_dg.camera.focal_length_m, rel_tol=1e-12)
    assert math.isclose(fo.f_number, tiny_dg.camera.f_number, rel_tol=1e-12)


def test_refuses_a_lens_scaled_to_another_camera():
    camera = camera_preset("tiny")
    with pytest.raises(ParameterError, match="effective focal length"):
        RealLensCamera(camera=camera, lens=lens_preset("double-gauss", focal_length_m=7e-3, f_number=2.2))
    with pytest.raises(ParameterError, match="f-number"):
        RealLensCamera(camera=camera, lens=lens_preset("double-gauss", focal_length_m=6e-3, f_number=2.8))


def test_refuses_a_lens_reaching_back_to_the_mla():
    camera = camera_preset("tiny")
    # The double Gauss's rear vertex is 1.7 mm behind its rear principal plane: an MLA 1.5 mm behind
    # the principal plane would sit inside the lens.
    short = replace(camera, lens_to_mla_m=1.5e-3, f_number=8.0)  # image side f/2, the MLA's
    lens = lens_preset("double-gauss", focal_length_m=short.focal_length_m, f_number=short.f_number)
    with pytest.raises(ParameterError, match="at or behind the MLA"):
        RealLensCamera(camera=short, lens=lens)


def test_micro_image_scale_uses_the_exit_pupil(tiny_dg):
    d = tiny_dg.first_order.exit_pupil_z_m + tiny_dg.camera.lens_to_mla_m
    assert tiny_dg.exit_pupil_distance_m == pytest.approx(d)
    assert tiny_dg.micro_image_scale == pytest.approx((d + tiny_dg.camera.mla.focal_length_m) / d)
    # Paraxially the image-side cone is the thin lens's (object at infinity, focused at infinity).
    assert tiny_dg.image_side_f_number == pytest.approx(tiny_dg.camera.image_side_f_number, rel=1e-9)


def test_chief_rays_of_micro_image_centres_aim_at_the_entrance_pupil(tiny_dg):
    """A pixel at its micro-image centre sees through the exit pupil's centre, so its object-space
    ray is a chief ray of the lens: near the axis it points back at the entrance pupil's centre."""
    camera = tiny_dg.camera
    idx = np.array([[0, 0], [1, 0], [0, 1], [-1, 1], [2, -1]])
    uv = tiny_dg.micro_image_centres_px(idx)
    rays = tiny_dg.rays_through_lenses(uv)
    assert rays.in_aperture.all()
    np.testing.assert_array_equal(rays.lens_indices, idx)
    off_axis = np.hypot(rays.directions_cam[:, 0], rays.directions_cam[:, 1]) > 1e-9
    assert off_axis.sum() == 4
    o, d = rays.origins_cam[off_axis], rays.directions_cam[off_axis]
    # Closest approach to the axis, backwards along the ray, lies at the entrance pupil (within the
    # pupil aberration of these near-axis chief rays, < 1 % of the 4 mm pupil-to-front distance).
    s = -(o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]) / (d[:, 0] ** 2 + d[:, 1] ** 2)
    z_cross = o[:, 2] + s * d[:, 2]
    np.testing.assert_allclose(z_cross, tiny_dg.first_order.entrance_pupil_z_m, atol=4e-5)
    assert camera.lens_to_mla_m > 0


def test_chief_rays_cover_every_pixel_with_nan_where_vignetted(tiny_dg):
    rays = tiny_dg.chief_rays()
    n = tiny_dg.camera.sensor.width_px * tiny_dg.camera.sensor.height_px
    assert rays.origins_cam.shape == (n, 3)
    assert 0.3 < rays.in_aperture.mean() < 0.9
    assert np.all(np.isfinite(rays.origins_cam[rays.in_aperture]))
    assert np.all(np.isnan(rays.origins_cam[~rays.in_aperture]))
    # Rays leave the front surface into the scene.
    assert np.all(rays.directions_cam[rays.in_aperture, 2] > 0)
    assert np.all(rays.origins_cam[rays.in_aperture, 2] <= tiny_dg.extent_z_m[1] + 1e-12)


def test_round_trips_through_a_dict(tiny_dg):
    again = RealLensCamera.from_dict(tiny_dg.to_dict())
    assert again == tiny_dg
    with pytest.raises(ParameterError, match="unknown"):
        RealLensCamera.from_dict({**tiny_dg.to_dict(), "extra": 1})


@pytest.mark.parametrize("lens_name", ["double-gauss", "wide-angle"])
def test_paraxial_limit_is_the_thin_lens_of_the_same_first_order_data(lens_name):
    """Near the axis a real lens maps a ray at its rear principal plane (z = 0) to the thin lens's
    ray, moved to the front principal plane: same height there, same direction. The difference
    falls as the cube of the heights and angles (third-order aberrations): 10x smaller ones give a
    difference about 1000x smaller, so the relative difference vanishes in the paraxial limit."""
    real = RealLensCamera.from_preset(camera_preset("tiny"), lens_name)
    camera = real.camera
    rng = np.random.default_rng(3)
    errors = []
    for scale in (1.0, 0.1):
        # The axial microlens: pixel offsets from its micro-image centre set the heights on the main
        # lens, offsets on the MLA the field; both shrink together.
        n = 400
        uv = real.micro_image_centres_px(np.zeros((n, 2), dtype=np.int64)) + scale * rng.uniform(-1.0, 1.0, (n, 2))
        offsets = scale * 0.3 * camera.mla.pitch_m * rng.uniform(-1.0, 1.0, (n, 2))
        thin = camera.rays_through_lenses(uv, lens_offsets_m=offsets)
        thick = real.rays_through_lenses(uv, lens_offsets_m=offsets)
        assert thin.in_aperture.all()
        assert thick.in_aperture.all()
        np.testing.assert_array_equal(thin.lens_indices, thick.lens_indices)
        z_h = real.first_order.front_principal_z_m
        o, d = thick.origins_cam, thick.directions_cam
        at_h = o + ((z_h - o[:, 2]) / d[:, 2])[:, None] * d
        height_err = np.abs(at_h[:, :2] - thin.origins_cam[:, :2]).max()
        direction_err = np.abs(d - thin.directions_cam).max()
        errors.append((height_err, direction_err))
    (h1, d1), (h2, d2) = errors
    assert h1 < 2e-5
    assert d1 < 2e-3
    assert h2 < h1 / 300, errors
    assert d2 < d1 / 300, errors
