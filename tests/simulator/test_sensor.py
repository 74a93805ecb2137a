"""The Mitsuba sensors against the numpy camera models: two independent implementations agree."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfrefract import FlatPort, LightFieldCamera, MicrolensArray, PinholeCamera, Pose, SensorGeometry, camera_preset
from lfrefract.errors import ParameterError
from lfrefract.optics.lens import lens_preset
from lfrefract.optics.real_lens import RealLensCamera
from simulator.sensor import pinhole_sensor_dict, plenoptic_sensor_dict
from tests.tolerances import (
    SENSOR_VS_NUMPY_DIRECTION,
    SENSOR_VS_NUMPY_ORIGIN_M,
    SENSOR_VS_NUMPY_PIXEL_PX,
    SENSOR_VS_NUMPY_PORT_POINT_M,
    SENSOR_VS_NUMPY_REAL_LENS_DIRECTION,
    SENSOR_VS_NUMPY_REAL_LENS_ORIGIN_M,
    SENSOR_VS_NUMPY_WEIGHT_RELATIVE,
)

CAMERAS = {
    "tiny": camera_preset("tiny"),
    "square-rotated-offset": LightFieldCamera(
        focal_length_m=5e-3,
        lens_to_mla_m=5.2e-3,  # focused closer than infinity
        f_number=2.0,
        mla=MicrolensArray(
            grid="square", pitch_m=80e-6, focal_length_m=150e-6, rotation_rad=0.03, offset_m=(13e-6, -21e-6)
        ),
        sensor=SensorGeometry(width_px=200, height_px=150, pixel_pitch_m=8e-6),
    ),
    "hex-rotated": LightFieldCamera(
        focal_length_m=9.993e-3,
        lens_to_mla_m=9.993e-3,
        f_number=2.0,
        mla=MicrolensArray(grid="hex", pitch_m=20e-6, focal_length_m=36e-6, rotation_rad=-0.002, offset_m=(3e-6, 5e-6)),
        sensor=SensorGeometry(width_px=1000, height_px=700, pixel_pitch_m=1.4e-6),
    ),
}
POSE = Pose.from_euler_xyz_deg((5.0, -12.0, 3.0), (0.1, -0.2, 0.05))


def _arrays(vec) -> np.ndarray:
    return np.asarray(vec, dtype=np.float64).T


def _sample_random_paths(mi, sensor, camera, *, seed: int, count: int = 4000):
    """Sample ``count`` paths at random film and aperture positions; return their inputs and rays."""
    w, h = camera.sensor.width_px, camera.sensor.height_px
    rng = np.random.default_rng(seed)
    uv = rng.uniform([-0.5, -0.5], [w - 0.5, h - 0.5], size=(count, 2))
    aperture = rng.uniform(0.0, 1.0, size=(count, 2))
    position = mi.Point2f(((uv[:, 0] + 0.5) / w).astype(np.float32), ((uv[:, 1] + 0.5) / h).astype(np.float32))
    ray, weight = sensor.sample_ray(0.0, 0.5, position, mi.Point2f(aperture[:, 0], aperture[:, 1]))
    return uv, aperture, ray, weight


@pytest.mark.parametrize("name", sorted(CAMERAS))
@pytest.mark.parametrize("pose", [Pose(), POSE], ids=["identity", "posed"])
def test_plenoptic_sensor_matches_numpy_rays(mi, name, pose):
    camera = CAMERAS[name]
    sensor = mi.load_dict(plenoptic_sensor_dict(mi, camera, pose, spp=1))
    uv, aperture, ray, weight = _sample_random_paths(mi, sensor, camera, seed=1)

    expected = camera.rays_through_lenses(uv, lens_offsets_m=camera.mla.cell_offsets_m(aperture))
    origins_world = pose.to_world(expected.origins_cam)
    directions_world = expected.directions_cam @ np.asarray(pose.rotation).T
    inside = _arrays(weight)[:, 0] > 0
    # Paths within float32 round-off of the aperture rim may be classified either way.
    rim = np.abs(np.linalg.norm(expected.origins_cam[:, :2], axis=1) - camera.aperture_radius_m) < 1e-8
    assert np.array_equal(inside[~rim], expected.in_aperture[~rim])
    assert 0.3 < inside.mean() < 0.95  # both vignetted and unvignetted paths are compared
    ok = inside & expected.in_aperture
    np.testing.assert_allclose(_arrays(ray.o)[ok], origins_world[ok], atol=SENSOR_VS_NUMPY_ORIGIN_M)
    np.testing.assert_allclose(_arrays(ray.d)[ok], directions_world[ok], atol=SENSOR_VS_NUMPY_DIRECTION)
    # Vignetted paths cost no traversal: they are given a zero-length ray.
    assert np.all(np.asarray(ray.maxt)[~inside] == 0.0)


def test_chief_rays_of_micro_image_centres_pass_through_lens_centre(mi, tiny):
    """The aperture sample that maps to the lens centre, at micro-image centres: rays from (0,0,0)."""
    sensor = mi.load_dict(plenoptic_sensor_dict(mi, tiny, Pose(), spp=1))
    centres = tiny.micro_image_centres_px(tiny.lens_indices_on_sensor())
    w, h = tiny.sensor.width_px, tiny.sensor.height_px
    position = mi.Point2f((centres[:, 0] + 0.5) / w, (centres[:, 1] + 0.5) / h)
    zero = np.zeros(len(centres), dtype=np.float32)
    ray, weight = sensor.sample_ray(0.0, 0.5, position, mi.Point2f(zero, zero))
    assert np.all(_arrays(weight) > 0)
    np.testing.assert_allclose(_arrays(ray.o), 0.0, atol=SENSOR_VS_NUMPY_ORIGIN_M)


def test_pinhole_sensor_matches_opencv_projection(mi):
    pinhole = PinholeCamera(focal_px=321.5, cx_px=101.25, cy_px=70.5, width_px=200, height_px=150)
    sensor = mi.load_dict(pinhole_sensor_dict(mi, pinhole, POSE, spp=1))
    rng = np.random.default_rng(2)
    uv = rng.uniform([-0.5, -0.5], [199.5, 149.5], size=(2000, 2))
    position = mi.Point2f((uv[:, 0] + 0.5) / 200, (uv[:, 1] + 0.5) / 150)
    ray, _ = sensor.sample_ray(0.0, 0.5, position, mi.Point2f(0.5, 0.5))
    origins = np.broadcast_to(_arrays(ray.o), (len(uv), 3))
    np.testing.assert_allclose(origins, np.tile(POSE.position_m, (len(uv), 1)), atol=SENSOR_VS_NUMPY_ORIGIN_M)
    d_cam = _arrays(ray.d) @ np.asarray(POSE.rotation)
    # Project a point along the ray with the OpenCV model: it lands on the sampled pixel.
    np.testing.assert_allclose(pinhole.project(d_cam), uv, atol=SENSOR_VS_NUMPY_PIXEL_PX)


def test_band_crop_maps_back_to_full_film(mi, tiny):
    """A sample in a crop window (band) gives the ray of the same full-film position."""
    w, h = tiny.sensor.width_px, tiny.sensor.height_px
    crop = (0, 100, w, 37)
    full = mi.load_dict(plenoptic_sensor_dict(mi, tiny, Pose(), spp=1))
    band = mi.load_dict(plenoptic_sensor_dict(mi, tiny, Pose(), spp=1, crop=crop))
    rng = np.random.default_rng(3)
    s = rng.uniform(0, 1, size=(500, 2))
    full_pos = mi.Point2f(s[:, 0], (crop[1] + s[:, 1] * crop[3]) / h)
    a = mi.Point2f(0.2, 0.7)
    ray_full, _ = full.sample_ray(0.0, 0.5, full_pos, a)
    ray_band, _ = band.sample_ray(0.0, 0.5, mi.Point2f(s[:, 0], s[:, 1]), a)
    np.testing.assert_allclose(_arrays(ray_band.d), _arrays(ray_full.d), atol=SENSOR_VS_NUMPY_DIRECTION)
    assert not math.isclose(float(np.asarray(ray_band.d)[1].mean()), 0.0, abs_tol=1e-3)  # not a trivial band


@pytest.mark.parametrize("thickness_m", [0.0, 0.008])
def test_plenoptic_sensor_refracts_through_port_like_numpy(mi, tiny, thickness_m):
    """The ``sensor`` port model: rays leave the water face as lfrefract's port trace says."""
    port = FlatPort.from_degrees(distance_m=0.015, thickness_m=thickness_m, tilt_x_deg=28.0, tilt_y_deg=-9.0)
    sensor = mi.load_dict(plenoptic_sensor_dict(mi, tiny, POSE, spp=1, port=port))
    uv, aperture, ray, weight = _sample_random_paths(mi, sensor, tiny, seed=4)

    air = tiny.rays_through_lenses(uv, lens_offsets_m=tiny.mla.cell_offsets_m(aperture))
    water = port.trace_from_air(air.origins_cam, air.directions_cam)
    ok = air.in_aperture & water.valid & (_arrays(weight)[:, 0] > 0)
    assert ok.mean() > 0.5
    np.testing.assert_allclose(
        _arrays(ray.o)[ok], POSE.to_world(water.exit_points_cam[ok]), atol=SENSOR_VS_NUMPY_PORT_POINT_M
    )
    directions_world = water.directions_cam @ np.asarray(POSE.rotation).T
    np.testing.assert_allclose(_arrays(ray.d)[ok], directions_world[ok], atol=SENSOR_VS_NUMPY_DIRECTION)
    expected_weight = water.transmittance * port.radiance_scale
    np.testing.assert_allclose(_arrays(weight)[ok, 0], expected_weight[ok], rtol=SENSOR_VS_NUMPY_WEIGHT_RELATIVE)
    assert np.all(_arrays(weight)[~air.in_aperture] == 0.0)


def test_plenoptic_sensor_reports_tir_as_zero_weight(mi, tiny):
    """Paths the port totally internally reflects carry nothing and are not traced."""
    port = FlatPort.from_degrees(distance_m=0.02, tilt_x_deg=35.0, n_air=1.5, n_glass=1.5, n_water=1.0)
    sensor = mi.load_dict(plenoptic_sensor_dict(mi, tiny, Pose(), spp=1, port=port))
    w, h = tiny.sensor.width_px, tiny.sensor.height_px
    uv = np.stack(np.meshgrid(np.arange(0, w, 3), np.arange(0, h, 3)), axis=-1).reshape(-1, 2).astype(float)
    position = mi.Point2f((uv[:, 0] + 0.5) / w, (uv[:, 1] + 0.5) / h)
    ray, weight = sensor.sample_ray(0.0, 0.5, position, mi.Point2f(0.0, 0.0))  # hex cell centre: chief rays
    air = tiny.captured_rays(uv)
    tir = port.trace_from_air(air.origins_cam, air.directions_cam).tir & air.in_aperture
    assert 0.05 < tir.mean() < 0.95
    assert np.all(_arrays(weight)[tir] == 0.0)
    assert np.all(np.asarray(ray.maxt)[tir] == 0.0)


REAL_LENS_CAMERAS = {
    "tiny": camera_preset("tiny"),
    "square-rotated-offset": CAMERAS["square-rotated-offset"],
}


@pytest.mark.parametrize("lens_name", ["double-gauss", "wide-angle"])
@pytest.mark.parametrize("name", sorted(REAL_LENS_CAMERAS))
def test_plenoptic_sensor_traces_real_lens_like_numpy(mi, name, lens_name):
    """The Dr.Jit trace through every surface of a real lens agrees with the numpy twin
    (:class:`lfrefract.optics.real_lens.RealLensCamera`, built on :func:`lfrefract.optics.lens.trace_lens`)."""
    real = RealLensCamera.from_preset(REAL_LENS_CAMERAS[name], lens_name)
    camera = real.camera
    sensor = mi.load_dict(plenoptic_sensor_dict(mi, camera, POSE, spp=1, lens=real.lens))
    uv, aperture, ray, weight = _sample_random_paths(mi, sensor, camera, seed=7)

    expected = real.rays_through_lenses(uv, lens_offsets_m=camera.mla.cell_offsets_m(aperture))
    inside = _arrays(weight)[:, 0] > 0
    # Paths within float32 round-off of a clear aperture may be classified either way: compare
    # the classification where the numpy trace is clear of every rim by 1e-7 of the aperture.
    agree = inside == expected.in_aperture
    assert agree.mean() > 0.995, agree.mean()
    assert 0.1 < inside.mean() < 0.95  # both vignetted and unvignetted paths are compared
    ok = inside & expected.in_aperture
    np.testing.assert_allclose(
        _arrays(ray.o)[ok], POSE.to_world(expected.origins_cam[ok]), atol=SENSOR_VS_NUMPY_REAL_LENS_ORIGIN_M
    )
    directions_world = expected.directions_cam @ np.asarray(POSE.rotation).T
    np.testing.assert_allclose(_arrays(ray.d)[ok], directions_world[ok], atol=SENSOR_VS_NUMPY_REAL_LENS_DIRECTION)
    np.testing.assert_array_equal(_arrays(weight)[ok, 0], 1.0)
    assert np.all(np.asarray(ray.maxt)[~inside] == 0.0)


def test_plenoptic_sensor_refuses_a_lens_of_another_focal_length(mi, tiny):
    lens = lens_preset("double-gauss", focal_length_m=1.1 * tiny.focal_length_m, f_number=tiny.f_number)
    with pytest.raises(ParameterError, match="effective focal length"):
        plenoptic_sensor_dict(mi, tiny, Pose(), spp=1, lens=lens)


def test_stopped_real_lens_paths_get_finite_zero_length_rays(mi, tiny):
    """Paths that miss a sphere would carry NaN from the quadratic: the ray handed to Mitsuba is finite."""
    real = RealLensCamera.from_preset(tiny, "wide-angle")
    sensor = mi.load_dict(plenoptic_sensor_dict(mi, tiny, Pose(), spp=1, lens=real.lens))
    _, _, ray, weight = _sample_random_paths(mi, sensor, tiny, seed=11)
    stopped = _arrays(weight)[:, 0] == 0
    assert stopped.mean() > 0.5
    assert np.all(np.isfinite(_arrays(ray.o)))
    assert np.all(np.isfinite(_arrays(ray.d)))
    assert np.all(np.asarray(ray.maxt)[stopped] == 0.0)
