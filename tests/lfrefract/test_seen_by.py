"""Raw pixels recording a point through an aperture point (lfrefract.optics.seen_by), against the camera model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfrefract.errors import ParameterError
from lfrefract.optics.port import FlatPort
from lfrefract.optics.presets import camera_preset
from lfrefract.optics.seen_by import SeenBy, pixels_seeing_points
from tests.tolerances import FLOAT64_GEOMETRY_M, SEEN_BY_MISS_M

CAMERA = camera_preset("tiny")
PORT = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.005, tilt_x_deg=12.0, tilt_y_deg=-8.0)
R = CAMERA.aperture_radius_m
AXIS_POINT = np.array([0.0, 0.0, 0.5])
LENS_CENTRE = np.zeros(2)
APERTURE = np.array([[0.0, 0.0], [0.8 * R, 0.0], [0.0, -0.5 * R], [-0.6 * R, 0.6 * R], [0.3 * R, 0.9 * R]])


def _points(rng: np.random.Generator, count: int) -> np.ndarray:
    """Points 0.2-1 m away, within about +-11 deg of the axis (inside the tiny camera's field in water)."""
    z = rng.uniform(0.2, 1.0, count)
    t = rng.uniform(-0.2, 0.2, (count, 2))
    return np.concatenate([t * z[:, None], z[:, None]], axis=1)


def _miss(origins: np.ndarray, directions: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance from each point to its ray (unit directions), metres."""
    rel = points - origins
    along = np.sum(rel * directions, axis=1, keepdims=True)
    return np.linalg.norm(rel - along * directions, axis=1)


def _round_trip(seen: SeenBy, port: FlatPort | None, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The exact paths of the valid entries, traced out by the camera (and the port): (miss, aperture error)."""
    v = seen.valid
    n_idx, m_idx = np.nonzero(v)
    rays = CAMERA.rays_through_lenses(seen.uv_px[v], lens_offsets_m=seen.lens_offset_m[v])
    np.testing.assert_array_equal(rays.lens_indices, seen.lens_index[v])
    assert np.all(rays.in_aperture)
    aperture_error = np.max(np.abs(rays.origins_cam[:, :2] - APERTURE[m_idx]))
    np.testing.assert_array_equal(rays.origins_cam[:, 2], 0.0)
    if port is None:
        return _miss(rays.origins_cam, rays.directions_cam, points[n_idx]), aperture_error
    trace = port.trace_from_air(rays.origins_cam, rays.directions_cam)
    assert np.all(trace.valid)
    return _miss(trace.exit_points_cam, trace.directions_cam, points[n_idx]), aperture_error


@pytest.mark.parametrize("port", [PORT, None], ids=["tilted-port", "no-port"])
def test_round_trip_through_the_camera_and_port(port: FlatPort | None) -> None:
    rng = np.random.default_rng(7)
    points = _points(rng, 400)
    seen = pixels_seeing_points(CAMERA, port, points, APERTURE)
    assert seen.uv_px.shape == (400, 5, 2)
    assert seen.lens_index.shape == (400, 5, 2)
    assert seen.valid.shape == (400, 5)
    assert seen.lens_index.dtype == np.int64
    assert seen.valid.mean() > 0.9
    miss, aperture_error = _round_trip(seen, port, points)
    assert np.max(miss) <= SEEN_BY_MISS_M
    assert aperture_error <= FLOAT64_GEOMETRY_M
    # The positions lie on the sensor, under the lens the camera assigns them to.
    uv = seen.uv_px[seen.valid]
    assert np.all(uv >= -0.5)
    assert np.all(uv[:, 0] <= CAMERA.sensor.width_px - 0.5)
    assert np.all(uv[:, 1] <= CAMERA.sensor.height_px - 0.5)
    np.testing.assert_array_equal(CAMERA.lens_indices_for_pixels(uv), seen.lens_index[seen.valid])


def test_chief_ray_pixel_starts_at_the_aperture_point() -> None:
    rng = np.random.default_rng(8)
    points = _points(rng, 300)
    seen = pixels_seeing_points(CAMERA, PORT, points, APERTURE)
    v = seen.valid
    _, m_idx = np.nonzero(v)
    rays = CAMERA.captured_rays(seen.uv_chief_px[v])  # sub-pixel positions: the model is continuous
    np.testing.assert_allclose(rays.origins_cam[:, :2], APERTURE[m_idx], rtol=0, atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_array_equal(rays.lens_indices, seen.lens_index[v])
    assert np.all(rays.in_aperture)
    # The two positions differ by the lens offset scaled by f_mla / f' (module docstring), a fraction
    # of a pixel: at most pitch / sqrt(3) (hexagonal cell's circumradius) on the MLA.
    offset = seen.lens_offset_m[v]
    assert np.all(np.linalg.norm(offset, axis=1) <= CAMERA.mla.pitch_m / math.sqrt(3.0) * (1 + 1e-9))
    shift_px = -offset * CAMERA.mla.focal_length_m / CAMERA.lens_to_mla_m / CAMERA.sensor.pixel_pitch_m
    np.testing.assert_allclose(seen.uv_chief_px[v] - seen.uv_px[v], shift_px, rtol=0, atol=1e-9)


def test_index_matched_port_is_straight_rays() -> None:
    """A port whose media all have index 1 bends nothing: the same pixels as no port."""
    rng = np.random.default_rng(9)
    points = _points(rng, 200)
    flat = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.005, tilt_x_deg=12.0, n_glass=1.0, n_water=1.0)
    with_port = pixels_seeing_points(CAMERA, flat, points, APERTURE)
    without = pixels_seeing_points(CAMERA, None, points, APERTURE)
    np.testing.assert_array_equal(with_port.valid, without.valid)
    np.testing.assert_array_equal(with_port.lens_index, without.lens_index)
    np.testing.assert_allclose(with_port.uv_px, without.uv_px, rtol=0, atol=1e-6)
    # A real port moves the pixels (refraction), by far more than that.
    real = pixels_seeing_points(CAMERA, PORT, points, APERTURE)
    both = real.valid & without.valid
    assert np.max(np.abs(real.uv_px[both] - without.uv_px[both])) > 1.0


def test_invalid_cases_are_flagged() -> None:
    points = np.array(
        [
            [0.0, 0.0, 0.5],  # visible on the axis
            [0.0, 0.0, 0.021],  # inside the glass (the air-side face is 2 cm away, 5 mm thick)
            [0.001, 0.0, 0.01],  # between the camera and the port, in the air
            [0.0, 0.0, -0.3],  # behind the camera
            [3.0, 0.0, 0.5],  # far outside the field of view: off the sensor
        ]
    )
    aperture = np.array([[0.0, 0.0], [1.01 * R, 0.0], [0.5 * R, 0.5 * R]])
    for port in (PORT, None):
        seen = pixels_seeing_points(CAMERA, port, points, aperture)
        expected = np.zeros((5, 3), dtype=bool)
        expected[0, [0, 2]] = True  # the aperture point at 1.01 R is outside the aperture
        # Without a port the points 1-2 cm in front of the lens are ordinary points in the air.
        rows = [0, 1, 2, 3, 4] if port is not None else [0, 3, 4]
        np.testing.assert_array_equal(seen.valid[rows], expected[rows])
        assert np.all(np.isnan(seen.uv_px[~seen.valid]))
        assert np.all(np.isnan(seen.uv_chief_px[~seen.valid]))
        assert np.all(np.isnan(seen.lens_offset_m[~seen.valid]))
        assert np.all(seen.lens_index[~seen.valid] == -1)
        assert np.all(np.isfinite(seen.uv_px[seen.valid]))


def test_rim_margin_shrinks_the_usable_aperture() -> None:
    margin = 1.0
    usable = CAMERA.usable_aperture_radius_m(margin)
    aperture = np.array([[0.99 * usable, 0.0], [1.01 * usable, 0.0]])
    seen = pixels_seeing_points(CAMERA, PORT, AXIS_POINT, aperture, rim_margin_px=margin)
    np.testing.assert_array_equal(seen.valid, [[True, False]])
    assert pixels_seeing_points(CAMERA, PORT, AXIS_POINT, aperture).valid.all()


def test_single_point_and_aperture_point() -> None:
    seen = pixels_seeing_points(CAMERA, None, AXIS_POINT, LENS_CENTRE)
    assert seen.uv_px.shape == (1, 1, 2)
    # On the axis through the lens centre: the micro-image centre of the lens on the axis.
    np.testing.assert_array_equal(seen.lens_index[0, 0], CAMERA.mla.nearest_indices(np.zeros((1, 2)))[0])
    centre = CAMERA.micro_image_centres_px(seen.lens_index[0])[0]
    scale = CAMERA.mla.focal_length_m / CAMERA.lens_to_mla_m / CAMERA.sensor.pixel_pitch_m
    offset_px = seen.lens_offset_m[0, 0] * scale
    np.testing.assert_allclose(seen.uv_px[0, 0], centre + offset_px, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((None, PORT, [[0, 0, 1.0]], [[0, 0.0]]), "camera must be a LightFieldCamera"),
        ((CAMERA, "port", [[0, 0, 1.0]], [[0, 0.0]]), "port must be a FlatPort or None"),
        ((CAMERA, PORT, [[0, 0]], [[0, 0.0]]), "points_cam must have shape"),
        ((CAMERA, PORT, [[0, 0, np.nan]], [[0, 0.0]]), "points_cam must be finite"),
        ((CAMERA, PORT, [[0, 0, 1.0]], [[0, 0, 0.0]]), "aperture_points_m must have shape"),
        ((CAMERA, PORT, [[0, 0, 1.0]], [[np.inf, 0.0]]), "aperture_points_m must be finite"),
    ],
)
def test_bad_inputs_raise(args: tuple, message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        pixels_seeing_points(*args)


@pytest.mark.parametrize("margin", [-1.0, 1e6, float("nan")])
def test_bad_rim_margin_raises(margin: float) -> None:
    with pytest.raises(ParameterError, match="rim_margin_px"):
        pixels_seeing_points(CAMERA, PORT, AXIS_POINT, LENS_CENTRE, rim_margin_px=margin)
