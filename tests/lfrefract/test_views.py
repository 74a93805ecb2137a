"""Sub-aperture views: their centre of projection and direction agree with the captured-ray model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lfrefract import ParameterError, camera_preset, virtual_camera_for
from lfrefract.synthesis.views import naive_view, subaperture_centre_m, subaperture_view
from tests.tolerances import (
    RESAMPLING_REPRODUCTION_PX,
    RESAMPLING_WEIGHT_ROUNDOFF,
    SENSOR_VS_NUMPY_DIRECTION,
    SENSOR_VS_NUMPY_ORIGIN_M,
)

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
    from lfrefract.synthesis.views import RESAMPLING_BYTES_PER_PIXEL, naive_view_bytes

    huge = PinholeCamera(focal_px=3e4, cx_px=3e4, cy_px=3e4, width_px=60_000, height_px=60_000)
    raw, _ = _holed(0.0)
    estimate = naive_view_bytes(TINY, huge, kind="central", channels=3)
    assert estimate > 3.6e9 * RESAMPLING_BYTES_PER_PIXEL  # the resampling alone
    for call in (lambda: naive_view(TINY, raw, output=huge), lambda: subaperture_view(TINY, raw, (0, 0), output=huge)):
        with pytest.raises(ParameterError, match=r"of 60000 x 60000 px needs about .* GiB of memory .* available"):
            call()
    # The default view fits; with no memory available it is refused too, naming the figures.
    monkeypatch.setattr(lfrefract._memory, "available_memory", lambda: (1000, "test"))
    with pytest.raises(
        ParameterError, match=r"a full view of 92 x 69 px needs about .* more than the 1000 B available \(test\)"
    ):
        naive_view(TINY, raw, kind="full")


# =============================================================================== the resampling's bounded work
def _all_candidates_weights(positions: np.ndarray, width: int, height: int):
    """The resampling's weights as first written: every triangle tested against a square of candidate
    pixels as wide as the largest triangle's box (the reference the bounded rasterisation must equal)."""
    from scipy.spatial import Delaunay

    simplices = Delaunay(positions).simplices
    corners = positions[simplices]
    e0, e1 = corners[:, 0] - corners[:, 2], corners[:, 1] - corners[:, 2]
    det = e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0]
    scale = np.max(np.abs(positions)) + 1.0
    proper = np.abs(det) > 1e-12 * scale**2
    proper &= np.all(corners.max(axis=1) >= 0, axis=1) & np.all(corners.min(axis=1) <= [width - 1, height - 1], axis=1)
    simplices, corners, e0, e1, det = simplices[proper], corners[proper], e0[proper], e1[proper], det[proper]
    inverse = np.stack([np.stack([e1[:, 1], -e1[:, 0]], 1), np.stack([-e0[:, 1], e0[:, 0]], 1)], 1) / det[:, None, None]
    lo = np.clip(np.ceil(corners.min(axis=1)).astype(np.int64), 0, [width - 1, height - 1])
    hi = np.clip(np.floor(corners.max(axis=1)).astype(np.int64), 0, [width - 1, height - 1])
    span = int(max((hi - lo).max(initial=0), 0)) + 1
    oy, ox = np.mgrid[0:span, 0:span]
    candidates = lo[:, None, :] + np.stack([ox.ravel(), oy.ravel()], axis=1)[None]
    bary = np.einsum("mij,msj->msi", inverse, candidates - corners[:, None, 2])
    weights = np.concatenate([bary, 1.0 - bary.sum(axis=2, keepdims=True)], axis=2)
    tol = 100 * np.finfo(np.float64).eps
    inside = np.all(weights >= -tol, axis=2) & np.all(candidates <= hi[:, None, :], axis=2)
    tri, cand = np.nonzero(inside)
    pixel = candidates[tri, cand, 1] * width + candidates[tri, cand, 0]
    pixel, first = np.unique(pixel, return_index=True)
    return pixel, simplices[tri[first]], weights[tri[first], cand[first]]


def _lens_positions(camera, output, correction=None, shift=(0.0, 0.0)) -> np.ndarray:
    slopes = camera.mla.centres_m(camera.lens_indices_on_sensor()) / camera.lens_to_mla_m + np.asarray(shift)
    if correction is not None:
        slopes = correction.slopes(slopes)
    return output.focal_px * slopes + np.array([output.cx_px, output.cy_px])


@pytest.mark.parametrize(
    ("correction", "shift", "size"),
    [(None, (0.0, 0.0), None), (None, (0.003, -0.002), (150, 110)), (-0.05, (0.0, 0.0), None), (0.05, (0, 0), None)],
    ids=["thin", "shifted-larger", "barrel", "pincushion"],
)
def test_the_bounded_resampling_equals_the_all_candidates_one(correction, shift, size):
    """On the tiny camera (the pincushion's long hull triangles lie outside its image) the bounded
    rasterisation finds the same pixels, triangles and weights as testing every candidate."""
    from lfrefract.optics.ray_correction import RayCorrection
    from lfrefract.synthesis.views import _linear_weights

    output = virtual_camera_for(TINY)
    if size is not None:
        w, h = size  # finer pixels: 1.6 times the focal length
        output = dataclasses.replace(
            output, focal_px=1.6 * output.focal_px, width_px=w, height_px=h, cx_px=w / 2, cy_px=h / 2
        )
    ray_correction = None if correction is None else RayCorrection(k1=correction)
    positions = _lens_positions(TINY, output, ray_correction, shift)
    got = _linear_weights(positions, output.width_px, output.height_px)
    want = _all_candidates_weights(positions, output.width_px, output.height_px)
    assert len(got[0]) > 0.9 * output.width_px * output.height_px
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    np.testing.assert_array_equal(got[2], want[2])


def _check_linear_reproduction(positions, pixel, corners, weights, width):
    """Barycentric weights reproduce every inside pixel's own coordinates from its triangle's vertices."""
    assert np.all(weights >= -RESAMPLING_WEIGHT_ROUNDOFF)
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, rtol=0, atol=RESAMPLING_WEIGHT_ROUNDOFF)
    mixed = np.einsum("pi,pij->pj", weights, positions[corners])
    uv = np.stack([pixel % width, pixel // width], axis=1)
    np.testing.assert_allclose(mixed, uv, rtol=0, atol=RESAMPLING_REPRODUCTION_PX)


def test_a_calibrated_cameras_distorted_lens_field_is_resampled_within_its_memory_estimate():
    """A calibration's pincushion (k1 = 0.05) bows the sides of tiny-2x's lens field in: Delaunay fills
    the hull with slivers as wide as the 188 x 141 px image, and giving every triangle the widest one's
    box of candidates asked for 6.8 GiB. The resampling stays within resampling_bytes, and is right."""
    import tracemalloc

    from lfrefract.optics.camera_model import CameraModel
    from lfrefract.optics.ray_correction import RayCorrection
    from lfrefract.synthesis.views import resampling_bytes, resampling_matrix

    camera = camera_preset("tiny-2x")
    output = virtual_camera_for(camera)
    correction = RayCorrection(k1=0.05)
    positions = _lens_positions(camera, output, correction)
    model = CameraModel(camera=camera, correction=correction)  # built before the memory is traced
    tracemalloc.start()
    try:
        _, matrix, inside = resampling_matrix(model, output)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    pixels = output.width_px * output.height_px
    assert peak < resampling_bytes(lenses=len(positions), pixels=pixels)
    assert inside.sum() > 0.9 * pixels
    pixels_uv = np.argwhere(inside.reshape(output.height_px, -1))[:, ::-1]
    np.testing.assert_allclose(matrix[inside] @ positions, pixels_uv, rtol=0, atol=RESAMPLING_REPRODUCTION_PX)


def test_triangles_larger_than_the_image_take_work_of_their_pixels_only():
    """Thousands of lenses in one corner and three far away: every triangle reaching the far ones
    covers a large part of the 1000 x 1000 px image (the all-candidates method asked for 4000 x 10^6
    candidates). The bounded rasterisation's memory stays within resampling_bytes, every pixel is found
    once, and its weights reproduce its coordinates."""
    import tracemalloc

    from lfrefract.synthesis.views import _linear_weights, resampling_bytes

    rng = np.random.default_rng(3)
    cluster = 5.0 + 40.0 * rng.random((2000, 2))
    far = np.array([[-5e4, -5e4], [5e4, -4e4], [-3e4, 6e4]])
    positions = np.concatenate([cluster, far])
    tracemalloc.start()
    try:
        pixel, corners, weights = _linear_weights(positions, 1000, 1000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < resampling_bytes(lenses=len(positions), pixels=10**6)
    np.testing.assert_array_equal(pixel, np.arange(10**6))
    _check_linear_reproduction(positions, pixel, corners, weights, 1000)


def test_a_resampling_beyond_the_memory_is_refused_by_every_caller(monkeypatch):
    """The resampling checks its own estimate, so the conventional view of ``calibrate approx`` and
    the baselines (built without naive_view's check) refuse before allocating too."""
    import lfrefract._memory
    from lfrefract.methods import ConventionalView

    monkeypatch.setattr(lfrefract._memory, "available_memory", lambda: (1000, "test"))
    with pytest.raises(
        ParameterError,
        match=r"resampling 1907 lenses onto a 92 x 69 px image needs about .* more than the 1000 B available \(test\)",
    ):
        ConventionalView(TINY, virtual_camera_for(TINY))


# =============================================================================== results with no value (issue 36)
def _looking_away(shift_px: float = 1e4):
    """tiny's default view with its principal point ``shift_px`` off: no lens lands in it."""
    from lfrefract import PinholeCamera

    output = virtual_camera_for(TINY)
    return PinholeCamera(
        focal_px=output.focal_px,
        cx_px=output.cx_px + shift_px,
        cy_px=output.cy_px,
        width_px=output.width_px,
        height_px=output.height_px,
    )


def _every_view(raw, recorded=None, output=None):
    """Each way the core makes a view, as a callable."""
    from lfrefract.methods import ConventionalView
    from lfrefract.synthesis.views import subaperture_stack

    return {
        "central": lambda: naive_view(TINY, raw, output=output, recorded=recorded),
        "full": lambda: naive_view(TINY, raw, output=output, kind="full", recorded=recorded),
        "subaperture": lambda: subaperture_view(TINY, raw, (1.5, -1.0), output=output, recorded=recorded),
        "stack": lambda: subaperture_stack(TINY, raw, grid=3, output=output, recorded=recorded),
        "conventional": lambda: ConventionalView(TINY, output or virtual_camera_for(TINY)).apply(
            raw, recorded=recorded
        ),
    }


@pytest.mark.parametrize("view", ["central", "full", "subaperture", "stack", "conventional"])
def test_a_view_whose_output_sees_no_lens_is_refused_naming_its_geometry(view):
    """An output geometry whose principal point is 10 000 px off holds no lens: every pixel was NaN, and
    ``naive`` and ``views`` wrote such images with exit status 0."""
    raw, _ = _holed(0.0)
    with pytest.raises(
        ParameterError, match=r"no value anywhere: no pixel of the 92 x 69 px output .*cx 1\.005e\+04.* lenses"
    ):
        _every_view(raw, output=_looking_away())[view]()


@pytest.mark.parametrize("view", ["central", "full", "subaperture", "stack", "conventional"])
def test_a_view_whose_every_raw_pixel_is_masked_is_refused_naming_the_mask(view):
    """``--nonfinite mask`` on an all-NaN raw image left every lens without a recorded pixel: all NaN, exit 0."""
    raw = np.full((TINY.sensor.height_px, TINY.sensor.width_px, 3), np.nan, dtype=np.float32)
    recorded = np.zeros(raw.shape[:2], dtype=bool)
    with pytest.raises(
        ParameterError, match=r"no value anywhere: .*raw pixels masked as unrecorded .*--nonfinite mask"
    ):
        _every_view(raw, recorded)[view]()
    # One recorded micro-image is a result (NaN elsewhere), not refused.
    centre = np.round(TINY.micro_image_centres_px(TINY.lens_indices_on_sensor()[900:901])[0]).astype(int)
    raw[centre[1] - 4 : centre[1] + 5, centre[0] - 4 : centre[0] + 5] = 0.5
    recorded = np.isfinite(raw).all(axis=2)
    result = _every_view(raw, recorded)[view]()
    assert np.isfinite(getattr(result, "views", result)).any()
