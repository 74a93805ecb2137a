"""Sub-aperture views: their centre of projection and direction agree with the captured-ray model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lfrefract import ParameterError, camera_preset, virtual_camera_for
from lfrefract.views import naive_view, subaperture_centre_m, subaperture_view
from tests.tolerances import SENSOR_VS_NUMPY_DIRECTION, SENSOR_VS_NUMPY_ORIGIN_M

TINY = camera_preset("tiny")


@pytest.mark.parametrize("lens_to_mla_m", [6e-3, 6.3e-3])
@pytest.mark.parametrize("offset_px", [(0.0, 0.0), (2.5, -1.0), (-2.0, 2.0)])
def test_subaperture_rays_share_a_centre_and_land_where_the_view_puts_them(lens_to_mla_m, offset_px):
    camera = dataclasses.replace(TINY, lens_to_mla_m=lens_to_mla_m)
    idx = camera.lens_indices_on_sensor()
    rays = camera.rays_through_lenses(camera.micro_image_centres_px(idx) + np.asarray(offset_px))
    # Every ray of the view passes the main lens at one point ...
    np.testing.assert_allclose(
        rays.origins_cam - subaperture_centre_m(camera, offset_px), 0.0, atol=SENSOR_VS_NUMPY_ORIGIN_M
    )
    # ... and a raw image lit only in one micro-image puts that lens where its ray points.
    output = virtual_camera_for(camera)
    lens = len(idx) // 2
    raw = np.zeros((camera.sensor.height_px, camera.sensor.width_px), dtype=np.float32)
    centre = np.round(camera.micro_image_centres_px(idx[lens : lens + 1])[0]).astype(int)
    raw[centre[1] - 4 : centre[1] + 5, centre[0] - 4 : centre[0] + 5] = 1.0
    view = np.nan_to_num(subaperture_view(camera, raw, offset_px, output=output))
    peak = np.array(np.unravel_index(np.argmax(view), view.shape))[::-1]
    expected = output.project(rays.directions_cam[lens : lens + 1])[0]
    assert np.all(np.abs(peak - expected) <= 1.0)  # the nearest output pixel to the lens's position
    d = output.pixel_directions(expected[None])[0]
    np.testing.assert_allclose(d, rays.directions_cam[lens], atol=SENSOR_VS_NUMPY_DIRECTION)


def test_the_central_subaperture_view_is_the_naive_central_view():
    raw = np.random.default_rng(0).random((TINY.sensor.height_px, TINY.sensor.width_px, 3)).astype(np.float32)
    np.testing.assert_array_equal(subaperture_view(TINY, raw, (0.0, 0.0)), naive_view(TINY, raw, kind="central"))
    np.testing.assert_array_equal(subaperture_centre_m(TINY, (0.0, 0.0)), 0.0)


def test_offsets_that_reach_the_rim_are_refused():
    raw = np.zeros((TINY.sensor.height_px, TINY.sensor.width_px), dtype=np.float32)
    with pytest.raises(ParameterError, match="reaches the micro-image rim"):
        subaperture_view(TINY, raw, (TINY.micro_image_radius_px, 0.0))
    with pytest.raises(ParameterError, match="offset_px"):
        subaperture_view(TINY, raw, (np.nan, 0.0))
    with pytest.raises(ParameterError, match="raw must have shape"):
        subaperture_view(TINY, raw[:-1], (0.0, 0.0))
