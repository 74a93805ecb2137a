"""Sub-aperture views: their centre of projection and direction agree with the captured-ray model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lfrefract import ParameterError, camera_preset, virtual_camera_for
from lfrefract.synthesis.views import naive_view, subaperture_centre_m, subaperture_view
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


# =============================================================================== unrecorded pixels, memory (issue 12)
def _holed(fraction: float, *, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A textured RGB raw image with NaN in channel 0 of ``fraction`` of its pixels, and the recorded mask."""
    rng = np.random.default_rng(seed)
    raw = (0.4 + 0.2 * rng.random((TINY.sensor.height_px, TINY.sensor.width_px, 3))).astype(np.float32)
    holes = rng.random(raw.shape[:2]) < fraction
    raw[holes, 0] = np.nan
    return raw, ~holes


@pytest.mark.parametrize("view", ["central", "full", "subaperture"])
def test_unrecorded_pixels_get_no_weight_and_recorded_ones_keep_theirs(view):
    from tests.tolerances import FLOAT32_WEIGHT_SUM, MASKED_VIEW_EXTRA_NAN_FRACTION

    def render(raw, recorded=None):
        if view == "subaperture":
            return subaperture_view(TINY, raw, (1.5, -1.0), recorded=recorded)
        return naive_view(TINY, raw, kind=view, recorded=recorded)

    raw, recorded = _holed(0.03)
    clean = np.where(np.isnan(raw), 0.5, raw)
    # NaN spread before: one NaN raw pixel made its lens's sample NaN, and that every pixel of its triangles.
    assert np.isnan(render(raw)).any(axis=2).mean() > 0.25
    masked = render(raw, recorded)
    extra = np.isnan(masked).any(axis=2) & ~np.isnan(render(clean)).any(axis=2)
    assert extra.mean() <= MASKED_VIEW_EXTRA_NAN_FRACTION
    # Pixels that no masked raw pixel reaches (the view of the hole indicator is 0 there) are unchanged.
    reach = render(np.repeat((~recorded).astype(np.float32)[..., None], 3, axis=2))[..., 0]
    untouched = reach == 0
    assert untouched.sum() >= 20  # the full view averages ~80 raw pixels per lens: few pixels are untouched
    np.testing.assert_allclose(masked[untouched], render(clean)[untouched], rtol=FLOAT32_WEIGHT_SUM)
    # A recorded mask of all True is the unmasked result itself.
    np.testing.assert_array_equal(render(clean, np.ones_like(recorded)), render(clean))
    # A uniform field stays uniform: the weights are renormalised over the recorded pixels.
    flat = np.where(np.isnan(raw), np.nan, 0.5).astype(np.float32)
    values = render(flat, recorded)
    np.testing.assert_allclose(values[~np.isnan(values)], 0.5, rtol=FLOAT32_WEIGHT_SUM)


def test_a_recorded_mask_of_the_wrong_shape_or_type_is_refused():
    raw, recorded = _holed(0.0)
    with pytest.raises(ParameterError, match=r"recorded must be a bool array of shape \(360, 480\), got float64"):
        naive_view(TINY, raw, recorded=recorded.astype(float))
    with pytest.raises(
        ParameterError, match=r"recorded must be a bool array of shape \(360, 480\), got bool \(10, 10\)"
    ):
        subaperture_view(TINY, raw, (0.0, 0.0), recorded=np.ones((10, 10), bool))


def test_a_view_beyond_the_memory_is_refused_before_it_is_allocated(monkeypatch):
    import lfrefract._memory
    from lfrefract import PinholeCamera
    from lfrefract.synthesis.views import naive_view_bytes

    huge = PinholeCamera(focal_px=3e4, cx_px=3e4, cy_px=3e4, width_px=60_000, height_px=60_000)
    raw, _ = _holed(0.0)
    estimate = naive_view_bytes(TINY, huge, kind="central", channels=3)
    assert estimate > 3.6e9 * 600  # the resampling alone: 600 bytes per output pixel
    for call in (lambda: naive_view(TINY, raw, output=huge), lambda: subaperture_view(TINY, raw, (0, 0), output=huge)):
        with pytest.raises(ParameterError, match=r"of 60000 x 60000 px needs about .* TiB of memory .* available"):
            call()
    # The default view fits; with no memory available it is refused too, naming the figures.
    monkeypatch.setattr(lfrefract._memory, "available_memory", lambda: (1000, "test"))
    with pytest.raises(
        ParameterError, match=r"a full view of 92 x 69 px needs about .* more than the 1000 B available \(test\)"
    ):
        naive_view(TINY, raw, kind="full")
