"""The light-field camera model: microlens lattice, sensor, captured rays, presets, validation.

Expected values are derived here from first-order optics (similar triangles and the thin-lens
equation) and from the lattice definition in the module docstring, in physical units.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lfrefract import LightFieldCamera, MicrolensArray, ParameterError, SensorGeometry, camera_preset
from lfrefract.optics import camera as camera_module
from lfrefract.optics.presets import PRESETS
from tests.tolerances import (
    CELL_INNER_FRACTION,
    CELL_MOMENT_RELATIVE,
    FLOAT64_GEOMETRY_M,
    FLOAT64_PIXEL_PX,
    FLOAT64_RELATIVE,
    FLOAT64_UNIT,
    QUOTED_LENS_COUNT_RELATIVE,
    QUOTED_PX_PER_LENS,
    VIGNETTING_FRACTION,
)

SQRT3 = math.sqrt(3.0)


# =============================================================================== independent helpers
def lattice_centres(grid: str, pitch: float, rotation: float, offset, idx: np.ndarray) -> np.ndarray:
    """Image-plane lens centres from the definition: offset + R(rotation) (i a1 + j a2)."""
    idx = np.asarray(idx, dtype=np.float64).reshape(-1, 2)
    a1 = np.array([pitch, 0.0])
    a2 = np.array([pitch / 2.0, pitch * SQRT3 / 2.0]) if grid == "hex" else np.array([0.0, pitch])
    local = idx[:, :1] * a1 + idx[:, 1:] * a2
    c, s = math.cos(rotation), math.sin(rotation)
    return np.asarray(offset) + local @ np.array([[c, s], [-s, c]])  # rows rotated by R


def brute_nearest(grid, pitch, rotation, offset, points, window=22):
    """Indices (N, 2) and distances (N,) of the nearest lens centre, by exhaustive search."""
    ii, jj = np.meshgrid(np.arange(-window, window + 1), np.arange(-window, window + 1))
    cand = np.stack([ii.ravel(), jj.ravel()], axis=1)
    centres = lattice_centres(grid, pitch, rotation, offset, cand)
    d2 = np.sum((np.asarray(points)[:, None, :] - centres[None, :, :]) ** 2, axis=2)
    best = np.argmin(d2, axis=1)
    return cand[best], np.sqrt(d2[np.arange(len(best)), best])


def tiny_like(
    *, lens_to_mla_m=6e-3, focal_length_m=6e-3, f_number=2.2, rotation_rad=0.0, offset_m=(0.0, 0.0), grid="hex"
) -> LightFieldCamera:
    """The tiny preset's optics, with the parameters under test changed."""
    return LightFieldCamera(
        focal_length_m=focal_length_m,
        lens_to_mla_m=lens_to_mla_m,
        f_number=f_number,
        mla=MicrolensArray(
            grid=grid, pitch_m=100e-6, focal_length_m=200e-6, rotation_rad=rotation_rad, offset_m=offset_m
        ),
        sensor=SensorGeometry(width_px=480, height_px=360, pixel_pitch_m=10e-6),
    )


def camera_frame_lens_xy(camera: LightFieldCamera, idx) -> np.ndarray:
    """Camera-frame (x, y) of lens centres: image-plane coordinates rotated by 180 degrees."""
    m = camera.mla
    return -lattice_centres(m.grid, m.pitch_m, m.rotation_rad, m.offset_m, idx)


def sensor_xy_of_pixels(camera: LightFieldCamera, uv) -> np.ndarray:
    """Camera-frame (x, y) of raw pixel positions (OpenCV pixel centres, sensor centred on the axis)."""
    s = camera.sensor
    centre = np.array([(s.width_px - 1) / 2.0, (s.height_px - 1) / 2.0])
    return -(np.asarray(uv, dtype=np.float64) - centre) * s.pixel_pitch_m


def expected_micro_image_centres_px(camera: LightFieldCamera, idx) -> np.ndarray:
    """Where the chief ray from the main-lens centre through each lens centre meets the sensor.

    Similar triangles: the line from (0, 0, 0) through the lens centre at z = -f' reaches
    z = -(f' + f_mla) at (f' + f_mla) / f' times the lens centre's distance from the axis.
    """
    m, s = camera.mla, camera.sensor
    scale = (camera.lens_to_mla_m + m.focal_length_m) / camera.lens_to_mla_m
    img = lattice_centres(m.grid, m.pitch_m, m.rotation_rad, m.offset_m, idx) * scale
    return img / s.pixel_pitch_m + np.array([(s.width_px - 1) / 2.0, (s.height_px - 1) / 2.0])


def distance_point_to_lines(point, origins, directions) -> np.ndarray:
    return np.linalg.norm(np.cross(np.asarray(point) - origins, directions), axis=1)


def all_pixels(camera: LightFieldCamera) -> np.ndarray:
    vv, uu = np.mgrid[0 : camera.sensor.height_px, 0 : camera.sensor.width_px]
    return np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)


# =============================================================================== lattice
def test_lattice_basis_centres_and_cell_area():
    hex_mla = MicrolensArray(grid="hex", pitch_m=2e-5, focal_length_m=4e-5)
    np.testing.assert_allclose(
        hex_mla.centres_m([[0, 0], [1, 0], [0, 1], [-1, 1], [2, -3]]),
        [[0, 0], [2e-5, 0], [1e-5, SQRT3 * 1e-5], [-1e-5, SQRT3 * 1e-5], [4e-5 - 3e-5, -3 * SQRT3 * 1e-5]],
        rtol=0,
        atol=FLOAT64_GEOMETRY_M,
    )
    assert hex_mla.cell_area_m2 == pytest.approx(SQRT3 / 2.0 * (2e-5) ** 2, rel=FLOAT64_RELATIVE)
    assert hex_mla.f_number == pytest.approx(2.0, rel=FLOAT64_RELATIVE)
    # Rotating by 90 degrees (from +xi towards +eta) and shifting: lens (1, 0) sits at offset + (0, pitch).
    sq = MicrolensArray(
        grid="square", pitch_m=1e-4, focal_length_m=2e-4, rotation_rad=math.pi / 2, offset_m=(3e-5, -1e-5)
    )
    np.testing.assert_allclose(
        sq.centres_m([[1, 0], [0, 1]]), [[3e-5, 9e-5], [-7e-5, -1e-5]], rtol=0, atol=FLOAT64_GEOMETRY_M
    )
    assert sq.cell_area_m2 == pytest.approx(1e-8, rel=FLOAT64_RELATIVE)


lattice_params = st.fixed_dictionaries(
    {
        "grid": st.sampled_from(["hex", "square"]),
        "pitch": st.floats(min_value=1e-6, max_value=1e-3),
        "rotation": st.floats(min_value=-math.pi, max_value=math.pi),
        "offset_frac": st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)),
        "seed": st.integers(0, 2**32 - 1),
    }
)


@settings(max_examples=60, deadline=None)
@given(p=lattice_params)
def test_nearest_indices_agrees_with_brute_force(p):
    pitch = p["pitch"]
    offset = (p["offset_frac"][0] * pitch, p["offset_frac"][1] * pitch)
    mla = MicrolensArray(
        grid=p["grid"], pitch_m=pitch, focal_length_m=2 * pitch, rotation_rad=p["rotation"], offset_m=offset
    )
    rng = np.random.default_rng(p["seed"])
    points = np.asarray(offset) + rng.uniform(-8 * pitch, 8 * pitch, size=(400, 2))
    got = mla.nearest_indices(points)
    assert got.dtype == np.int64
    assert got.shape == (400, 2)
    want_idx, want_dist = brute_nearest(p["grid"], pitch, p["rotation"], offset, points)
    got_dist = np.linalg.norm(lattice_centres(p["grid"], pitch, p["rotation"], offset, got) - points, axis=1)
    # Equal distances (ties on a cell border) may pick either lens; otherwise the same lens.
    np.testing.assert_allclose(got_dist, want_dist, rtol=0, atol=FLOAT64_UNIT * pitch)
    differ = np.any(got != want_idx, axis=1)
    assert differ.mean() < 0.01  # random points hardly ever sit on a cell border

    # Lattice points themselves, and points a little off them, map to their own index.
    idx = rng.integers(-6, 7, size=(100, 2))
    centres = lattice_centres(p["grid"], pitch, p["rotation"], offset, idx)
    np.testing.assert_array_equal(mla.nearest_indices(centres), idx)
    jitter = rng.uniform(-0.2 * pitch, 0.2 * pitch, size=(100, 2))
    np.testing.assert_array_equal(mla.nearest_indices(centres + jitter), idx)


def test_nearest_indices_in_blocks_as_in_one(monkeypatch):
    # A full sensor is handled in blocks of points; a block boundary must not change any answer.
    mla = camera_preset("illum").mla
    points = np.random.default_rng(3).uniform(-40 * mla.pitch_m, 40 * mla.pitch_m, size=(1000, 2))
    whole = mla.nearest_indices(points)
    monkeypatch.setattr(camera_module, "_NEAREST_CHUNK", 7)
    np.testing.assert_array_equal(mla.nearest_indices(points), whole)
    assert mla.nearest_indices(np.zeros((0, 2))).shape == (0, 2)


def midpoint_grid(n: int) -> np.ndarray:
    g = (np.arange(n) + 0.5) / n
    s0, s1 = np.meshgrid(g, g, indexing="ij")
    return np.stack([s0.ravel(), s1.ravel()], axis=1)


@pytest.mark.parametrize("grid", ["hex", "square"])
@pytest.mark.parametrize(("rotation", "offset"), [(0.0, (0.0, 0.0)), (0.3, (2.5e-5, -4e-5)), (-2.0, (1e-4, 1e-4))])
def test_cell_offsets_fill_the_cell_uniformly(grid, rotation, offset):
    pitch = 1e-4
    mla = MicrolensArray(grid=grid, pitch_m=pitch, focal_length_m=2e-4, rotation_rad=rotation, offset_m=offset)
    samples = midpoint_grid(300)  # 300 is a multiple of 3: each hexagon rhombus gets a full midpoint grid
    off = mla.cell_offsets_m(samples)
    assert off.shape == (samples.shape[0], 2)

    # Inside the cell: the nearest lens to centre + offset is that lens (exhaustive search).
    lens = np.array([[3, -2]])
    centre = lattice_centres(grid, pitch, rotation, offset, lens)[0]
    idx, _ = brute_nearest(grid, pitch, rotation, offset, centre + off[::7], window=8)
    np.testing.assert_array_equal(idx, np.broadcast_to(lens, idx.shape))

    # Uniform: zero mean, and the second moment of the cell about its centre.
    np.testing.assert_allclose(off.mean(axis=0), 0.0, rtol=0, atol=FLOAT64_UNIT * pitch)
    # Regular hexagon of circumradius R = pitch / sqrt(3): six equilateral triangles with a vertex at
    # the centre, E|r|^2 = R^2 / 3 + R^2 / 12 = 5 R^2 / 12 = 5 pitch^2 / 36. Square of side p: 2 p^2 / 12.
    second = 5.0 * pitch**2 / 36.0 if grid == "hex" else pitch**2 / 6.0
    cov = off.T @ off / off.shape[0]
    assert np.trace(cov) == pytest.approx(second, rel=CELL_MOMENT_RELATIVE)
    # Both cells have an isotropic inertia tensor.
    np.testing.assert_allclose(cov, np.eye(2) * second / 2.0, rtol=0, atol=CELL_MOMENT_RELATIVE * second)

    # Uniform, not just the right moments: a concentric half-size cell holds a quarter of the samples.
    c, s = math.cos(rotation), math.sin(rotation)
    local = off @ np.array([[c, -s], [s, c]])  # undo the rotation: rows times R
    if grid == "hex":
        # Edges of the hexagon (vertices along +-eta) have outward normals at 0, 60, 120 deg,
        # inradius pitch / 2; the half-size hexagon has inradius pitch / 4.
        normals = np.array([[math.cos(a), math.sin(a)] for a in np.radians([0.0, 60.0, 120.0])])
        inner = np.all(np.abs(local @ normals.T) <= pitch / 4.0, axis=1)
        outer = np.all(np.abs(local @ normals.T) <= pitch / 2.0 * (1 + 1e-12), axis=1)
        assert np.max(np.linalg.norm(local, axis=1)) == pytest.approx(pitch / SQRT3, rel=0.01)
    else:
        inner = np.all(np.abs(local) <= pitch / 4.0, axis=1)
        outer = np.all(np.abs(local) <= pitch / 2.0 * (1 + 1e-12), axis=1)
    assert outer.all()
    assert inner.mean() == pytest.approx(0.25, abs=CELL_INNER_FRACTION)


def test_cell_offsets_documented_centre_samples():
    hex_mla = MicrolensArray(grid="hex", pitch_m=1e-4, focal_length_m=2e-4, rotation_rad=0.4)
    sq = MicrolensArray(grid="square", pitch_m=1e-4, focal_length_m=2e-4, rotation_rad=0.4)
    np.testing.assert_allclose(hex_mla.cell_offsets_m([[0.0, 0.0]]), [[0.0, 0.0]], atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_allclose(sq.cell_offsets_m([[0.5, 0.5]]), [[0.0, 0.0]], atol=FLOAT64_GEOMETRY_M)
    # Square corner sample (0, 0) is the cell corner (-p/2, -p/2), rotated by 0.4 rad.
    c, s = math.cos(0.4), math.sin(0.4)
    np.testing.assert_allclose(
        sq.cell_offsets_m([[0.0, 0.0]]), [[-5e-5 * c + 5e-5 * s, -5e-5 * s - 5e-5 * c]], atol=FLOAT64_GEOMETRY_M
    )


# =============================================================================== sensor
def test_sensor_pixel_conventions():
    s = SensorGeometry(width_px=480, height_px=360, pixel_pitch_m=1e-5)
    assert s.size_m == pytest.approx((4.8e-3, 3.6e-3), rel=FLOAT64_RELATIVE)
    assert s.centre_px == (239.5, 179.5)
    np.testing.assert_allclose(
        s.pixels_to_image_plane([[239.5, 179.5], [479.0, 179.5], [0.0, 0.0]]),
        [[0.0, 0.0], [239.5e-5, 0.0], [-239.5e-5, -179.5e-5]],
        rtol=0,
        atol=FLOAT64_GEOMETRY_M,
    )
    uv = np.array([[12.25, 300.0], [0.0, 359.0]])
    np.testing.assert_allclose(s.image_plane_to_pixels(s.pixels_to_image_plane(uv)), uv, atol=FLOAT64_PIXEL_PX)


# =============================================================================== optics
def test_derived_optics_of_tiny():
    cam = camera_preset("tiny")
    # f = f' = 6 mm at f/2.2, pitch 100 um, f_mla 200 um, 10 um pixels.
    assert cam.aperture_radius_m == pytest.approx(6e-3 / 4.4, rel=FLOAT64_RELATIVE)
    assert cam.image_side_f_number == pytest.approx(2.2, rel=FLOAT64_RELATIVE)
    assert cam.mla_z_m == -6e-3
    assert cam.sensor_z_m == pytest.approx(-6.2e-3, rel=FLOAT64_RELATIVE)
    assert cam.micro_image_scale == pytest.approx(6.2 / 6.0, rel=FLOAT64_RELATIVE)
    assert cam.micro_image_pitch_px == pytest.approx(10.0 * 6.2 / 6.0, rel=FLOAT64_RELATIVE)
    # The aperture (radius 1.364 mm) seen from the sensor through a microlens: radius * f_mla / f'.
    assert cam.micro_image_radius_px == pytest.approx(6e-3 / 4.4 * 200e-6 / 6e-3 / 1e-5, rel=FLOAT64_RELATIVE)


@pytest.mark.parametrize(
    "camera",
    [
        camera_preset("tiny"),
        tiny_like(rotation_rad=0.05, offset_m=(2e-5, -3.5e-5)),
        tiny_like(grid="square", lens_to_mla_m=6.3e-3, rotation_rad=-0.02),
    ],
    ids=["tiny", "rotated-offset", "square-refocused"],
)
def test_micro_image_centre_chief_rays_pass_the_lens_centre(camera):
    idx = camera.lens_indices_on_sensor()
    uv = expected_micro_image_centres_px(camera, idx)
    np.testing.assert_allclose(camera.micro_image_centres_px(idx), uv, rtol=0, atol=FLOAT64_PIXEL_PX)
    rays = camera.rays_through_lenses(uv)
    np.testing.assert_array_equal(rays.lens_indices, idx)
    # The pixel at a micro-image centre sees along the line through the lens centre and the
    # main-lens centre: it leaves the main lens at the origin ...
    np.testing.assert_allclose(rays.origins_cam, 0.0, rtol=0, atol=FLOAT64_GEOMETRY_M)
    assert rays.in_aperture.all()
    # ... undeviated, along the line from the lens centre (x, y, -f') through the origin.
    lens_xy = camera_frame_lens_xy(camera, idx)
    expected = np.concatenate([-lens_xy, np.full((len(idx), 1), camera.lens_to_mla_m)], axis=1)
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(rays.directions_cam, expected, rtol=0, atol=FLOAT64_UNIT)


def test_micro_image_offsets_grow_towards_the_edge():
    # docs/design.md: the micro-image centre is offset from the lens centre by about c * f_mla / f'.
    cam = camera_preset("tiny")
    idx = cam.lens_indices_on_sensor()
    lens_px = lattice_centres("hex", 1e-4, 0.0, (0, 0), idx) / 1e-5 + np.array([239.5, 179.5])
    shift = np.linalg.norm(cam.micro_image_centres_px(idx) - lens_px, axis=1)
    c_px = np.linalg.norm(lattice_centres("hex", 1e-4, 0.0, (0, 0), idx), axis=1) / 1e-5
    np.testing.assert_allclose(shift, c_px * 200e-6 / 6e-3, rtol=0, atol=FLOAT64_PIXEL_PX)
    # presets.py: "up to 8 px away from their lens centres at the edge" (left/right edge, central row).
    assert 7.0 < shift[idx[:, 1] == 0].max() < 8.0


def test_lens_indices_on_sensor_matches_exhaustive_search():
    cam = tiny_like(rotation_rad=0.1, offset_m=(3e-5, 1e-5))
    got = cam.lens_indices_on_sensor()
    ii, jj = np.meshgrid(np.arange(-60, 61), np.arange(-60, 61))
    cand = np.stack([ii.ravel(), jj.ravel()], axis=1)
    uv = expected_micro_image_centres_px(cam, cand)
    on = (uv[:, 0] >= 0) & (uv[:, 0] <= 479) & (uv[:, 1] >= 0) & (uv[:, 1] <= 359)
    want = cand[on]
    want = want[np.lexsort((want[:, 0], want[:, 1]))]
    np.testing.assert_array_equal(got, want)


def test_lens_indices_for_pixels_is_the_nearest_micro_image_centre():
    cam = tiny_like(rotation_rad=-0.07, offset_m=(-2e-5, 4e-5))
    rng = np.random.default_rng(7)
    uv = rng.uniform([0, 0], [479, 359], size=(600, 2))
    got = cam.lens_indices_for_pixels(uv)
    ii, jj = np.meshgrid(np.arange(-45, 46), np.arange(-30, 31))
    cand = np.stack([ii.ravel(), jj.ravel()], axis=1)
    centres = expected_micro_image_centres_px(cam, cand)
    d = np.linalg.norm(uv[:, None, :] - centres[None], axis=2)
    best = d.min(axis=1)
    got_d = np.linalg.norm(uv - expected_micro_image_centres_px(cam, got), axis=1)
    np.testing.assert_allclose(got_d, best, rtol=0, atol=FLOAT64_PIXEL_PX)


def test_raw_image_is_upright():
    # A raw pixel at the top left looks up (-y) and left (-x) into the scene.
    cam = camera_preset("tiny")
    rays = cam.captured_rays(np.array([[30.0, 30.0], [450.0, 330.0]]))
    assert rays.directions_cam[0, 0] < 0
    assert rays.directions_cam[0, 1] < 0
    assert rays.directions_cam[1, 0] > 0
    assert rays.directions_cam[1, 1] > 0
    assert np.all(rays.directions_cam[:, 2] > 0)


def test_captured_rays_geometry_for_every_pixel_of_tiny():
    cam = camera_preset("tiny")
    uv = all_pixels(cam)
    rays = cam.captured_rays()
    assert rays.origins_cam.shape == (480 * 360, 3)
    # The default pixel order is row-major.
    np.testing.assert_array_equal(rays.lens_indices, cam.lens_indices_for_pixels(uv))
    # From the pixel centre s (z = -(f' + f_mla)) through the lens centre c (z = -f'), straight on to
    # the main lens (z = 0): h = c + (c - s) f' / f_mla.
    c = camera_frame_lens_xy(cam, rays.lens_indices)
    s = sensor_xy_of_pixels(cam, uv)
    hit = c + (c - s) * (6e-3 / 200e-6)
    np.testing.assert_allclose(rays.origins_cam[:, :2], hit, rtol=0, atol=FLOAT64_GEOMETRY_M)
    np.testing.assert_array_equal(rays.origins_cam[:, 2], 0.0)
    # Vignetting: blocked exactly when the hit lies outside the aperture of radius f / (2N).
    r = np.linalg.norm(hit, axis=1)
    radius = 6e-3 / (2 * 2.2)
    clear = np.abs(r - radius) > FLOAT64_GEOMETRY_M
    np.testing.assert_array_equal(rays.in_aperture[clear], r[clear] <= radius)
    # f' = f: the MLA plane is conjugate to infinity, so all rays through one lens centre leave
    # parallel to the undeviated chief ray through the main-lens centre, direction (-x, -y, f').
    expected = np.concatenate([-c, np.full((len(c), 1), 6e-3)], axis=1)
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(rays.directions_cam, expected, rtol=0, atol=FLOAT64_UNIT)
    np.testing.assert_allclose(np.linalg.norm(rays.directions_cam, axis=1), 1.0, rtol=0, atol=FLOAT64_UNIT)


def test_vignetting_fraction_of_tiny_is_disc_over_cell():
    cam = camera_preset("tiny")
    fraction = cam.captured_rays().in_aperture.mean()
    # Micro-image: the aperture (radius f / 2N) imaged by a microlens from distance f' onto the
    # sensor f_mla behind it: radius (f / 2N) f_mla / f'. Cells: the lens lattice (hexagonal, area
    # sqrt(3)/2 p^2) scaled by (f' + f_mla) / f' onto the sensor.
    disc_radius = 6e-3 / 4.4 * 200e-6 / 6e-3
    cell_pitch = 100e-6 * 6.2 / 6.0
    expected = math.pi * disc_radius**2 / (SQRT3 / 2.0 * cell_pitch**2)
    assert expected == pytest.approx(0.7019, abs=1e-4)
    assert fraction == pytest.approx(expected, abs=VIGNETTING_FRACTION)


@pytest.mark.parametrize("lens_to_mla_m", [6.3e-3, 5.7e-3])
def test_rays_through_one_lens_meet_at_its_conjugate_point(lens_to_mla_m):
    f = 6e-3
    cam = tiny_like(lens_to_mla_m=lens_to_mla_m, rotation_rad=0.03)
    rays = cam.captured_rays()
    # Thin lens 1/f = 1/z_o + 1/z_i with z_i = f': the lens centre's conjugate point at
    # z_o = f f' / (f' - f) (negative: a virtual point behind the lens), on the undeviated chief ray.
    z_o = f * lens_to_mla_m / (lens_to_mla_m - f)
    for lens in ([0, 0], [20, -15], [-22, 18], [5, 19]):
        mine = np.all(rays.lens_indices == lens, axis=1)
        assert 60 < mine.sum() < 150  # about one micro-image cell of 10.3^2 * 0.87 px
        c = camera_frame_lens_xy(cam, [lens])[0]
        conjugate = np.array([-c[0] * z_o / lens_to_mla_m, -c[1] * z_o / lens_to_mla_m, z_o])
        dist = distance_point_to_lines(conjugate, rays.origins_cam[mine], rays.directions_cam[mine])
        np.testing.assert_allclose(dist, 0.0, atol=FLOAT64_GEOMETRY_M)
        # and the lines really fan out: they are not all the same line
        assert np.ptp(rays.origins_cam[mine, 0]) > 1e-3


@pytest.mark.parametrize("lens_to_mla_m", [6e-3, 6.3e-3])
def test_beam_from_one_sensor_point_focuses_on_the_focal_plane(lens_to_mla_m):
    # The sensor is at the microlens focal plane: all paths from one sensor point leave the
    # microlens parallel (slope (c - s) / f_mla), and a parallel beam focuses at z = f on the
    # main lens's focal plane, at f times its slope.
    f = 6e-3
    cam = tiny_like(lens_to_mla_m=lens_to_mla_m)
    uv = np.array([[100.3, 77.9]])
    idx = cam.lens_indices_for_pixels(uv)
    offsets = cam.mla.cell_offsets_m(midpoint_grid(9))
    rays = cam.rays_through_lenses(np.repeat(uv, len(offsets), axis=0), lens_offsets_m=offsets)
    np.testing.assert_array_equal(rays.lens_indices, np.repeat(idx, len(offsets), axis=0))
    c = camera_frame_lens_xy(cam, idx)[0]
    s = sensor_xy_of_pixels(cam, uv)[0]
    slope = (c - s) / 200e-6
    focus = np.array([f * slope[0], f * slope[1], f])
    dist = distance_point_to_lines(focus, rays.origins_cam, rays.directions_cam)
    np.testing.assert_allclose(dist, 0.0, atol=FLOAT64_GEOMETRY_M)
    # Where each path meets the main lens: through (c + offset) at z = -f' with that slope.
    through = c - offsets  # image-plane offsets are rotated by 180 degrees in the camera frame
    np.testing.assert_allclose(rays.origins_cam[:, :2], through + slope * lens_to_mla_m, atol=FLOAT64_GEOMETRY_M)


def test_rays_through_lenses_bad_input():
    cam = camera_preset("tiny")
    with pytest.raises(ParameterError, match=re.escape("lens_offsets_m must have one row per uv row (2), got 3 rows")):
        cam.rays_through_lenses(np.zeros((2, 2)), lens_offsets_m=np.zeros((3, 2)))
    with pytest.raises(ParameterError, match=re.escape("uv must be finite, got a row [1.0, nan]")):
        cam.rays_through_lenses([[1.0, float("nan")]])
    with pytest.raises(ParameterError, match=re.escape("uv must have shape (N, 2), got shape (4, 3)")):
        cam.captured_rays(np.zeros((4, 3)))


# =============================================================================== presets
def test_illum_preset():
    cam = camera_preset("illum")
    assert cam.name == "illum"
    assert (cam.sensor.width_px, cam.sensor.height_px) == (7728, 5368)
    assert cam.sensor.pixel_pitch_m == 1.4e-6
    assert cam.mla.grid == "hex"
    assert cam.mla.pitch_m == 20e-6
    assert cam.mla.focal_length_m == 36e-6
    assert cam.focal_length_m == cam.lens_to_mla_m == 9.993e-3
    assert cam.f_number == 2.0
    px_per_lens = 20.0 / 1.4 * (9.993 + 0.036) / 9.993
    assert cam.micro_image_pitch_px == pytest.approx(px_per_lens, rel=FLOAT64_RELATIVE)
    assert cam.micro_image_pitch_px == pytest.approx(14.3, abs=QUOTED_PX_PER_LENS)
    idx = cam.lens_indices_on_sensor()
    rows = np.unique(idx[:, 1])
    per_row = np.bincount(idx[:, 1] - idx[:, 1].min())
    assert len(rows) == pytest.approx(434, rel=QUOTED_LENS_COUNT_RELATIVE)
    assert per_row.max() == pytest.approx(541, rel=QUOTED_LENS_COUNT_RELATIVE)


def test_f01_preset():
    cam = camera_preset("f01")
    assert (cam.sensor.width_px, cam.sensor.height_px) == (3280, 3280)
    assert cam.sensor.pixel_pitch_m == 1.4e-6
    assert cam.mla.pitch_m == 14e-6
    assert cam.mla.grid == "hex"
    assert cam.focal_length_m == 6.84e-3
    assert cam.f_number == 1.92
    assert cam.micro_image_pitch_px == pytest.approx(10.0 * (6.84 + 0.025) / 6.84, rel=FLOAT64_RELATIVE)


def test_tiny_preset_is_small():
    cam = camera_preset("tiny")
    assert cam.sensor.width_px * cam.sensor.height_px <= 480 * 360
    assert cam.mla.grid == "hex"
    assert len(cam.lens_indices_on_sensor()) < 5000


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_focus_at_infinity_and_do_not_overlap(name):
    cam = camera_preset(name)
    assert cam.name == name
    assert cam.lens_to_mla_m == cam.focal_length_m
    # Image-side f-number f' / (f / N) at or above the microlens f-number f_mla / pitch.
    assert cam.lens_to_mla_m / (cam.focal_length_m / cam.f_number) >= cam.mla.focal_length_m / cam.mla.pitch_m
    # So a micro-image (diameter) fits in its cell pitch.
    assert 2 * cam.micro_image_radius_px <= cam.micro_image_pitch_px


def test_unknown_preset():
    with pytest.raises(
        ParameterError, match=re.escape("camera preset must be one of ['illum', 'f01', 'tiny', 'tiny-2x'], got 'x3'")
    ):
        camera_preset("x3")


# =============================================================================== validation
def test_f_number_below_the_microlens_f_number_is_rejected():
    # MLA f/2 (200 um / 100 um); main lens f = f' at f/1.8 sends an f/1.8 cone: micro-images overlap.
    with pytest.raises(ParameterError, match=r"f_number=1\.8 .*below the microlens f-number 2\b.*overlap"):
        tiny_like(f_number=1.8)
    # Exactly matched f-numbers tile the sensor and are accepted.
    assert tiny_like(f_number=2.0).image_side_f_number == pytest.approx(2.0, rel=FLOAT64_RELATIVE)
    # Moving the MLA back raises the image-side f-number f' N / f above the MLA's: accepted.
    assert tiny_like(f_number=1.8, lens_to_mla_m=6.7e-3).image_side_f_number > 2.0


@pytest.mark.parametrize(
    ("factory", "pattern"),
    [
        (
            lambda: MicrolensArray(grid="hex", pitch_m=-1e-5, focal_length_m=1e-5),
            "mla.pitch_m must be positive, got -1e-05",
        ),
        (
            lambda: MicrolensArray(grid="tri", pitch_m=1e-5, focal_length_m=1e-5),
            "mla.grid must be one of ['hex', 'square'], got 'tri'",
        ),
        (
            lambda: MicrolensArray(grid="hex", pitch_m=1e-5, focal_length_m=float("nan")),
            "mla.focal_length_m must be finite, got nan",
        ),
        (
            lambda: MicrolensArray(grid="hex", pitch_m=1e-5, focal_length_m=1e-5, rotation_rad=float("inf")),
            "mla.rotation_rad must be finite, got inf",
        ),
        (
            lambda: MicrolensArray(grid="hex", pitch_m=1e-5, focal_length_m=1e-5, offset_m=(0.0,)),
            "mla.offset_m must have 2 entries, got (0.0,)",
        ),
        (
            lambda: MicrolensArray(grid="hex", pitch_m=1e-5, focal_length_m=1e-5, offset_m=(0.0, float("nan"))),
            "mla.offset_m[1] must be finite, got nan",
        ),
        (
            lambda: SensorGeometry(width_px=0, height_px=10, pixel_pitch_m=1e-6),
            "sensor.width_px must be positive, got 0",
        ),
        (
            lambda: SensorGeometry(width_px=10, height_px=True, pixel_pitch_m=1e-6),
            "sensor.height_px must be an integer, got True",
        ),
        (
            lambda: SensorGeometry(width_px=10.0, height_px=10, pixel_pitch_m=1e-6),
            "sensor.width_px must be an integer, got 10.0",
        ),
        (
            lambda: SensorGeometry(width_px=10, height_px=10, pixel_pitch_m=0.0),
            "sensor.pixel_pitch_m must be positive, got 0.0",
        ),
        (lambda: tiny_like(focal_length_m=float("nan")), "focal_length_m must be finite, got nan"),
        (lambda: tiny_like(lens_to_mla_m=-6e-3), "lens_to_mla_m must be positive, got -0.006"),
        (lambda: tiny_like(f_number=0), "f_number must be positive, got 0"),
        (lambda: tiny_like(f_number=False), "f_number must be a real number, got False"),
    ],
)
def test_bad_camera_parameters_are_named(factory, pattern):
    with pytest.raises(ParameterError, match=re.escape(pattern)):
        factory()


def test_camera_parts_must_have_the_right_types():
    good = camera_preset("tiny")
    with pytest.raises(ParameterError, match=re.escape("mla must be a MicrolensArray, got {'grid': 'hex'}")):
        dataclasses.replace(good, mla={"grid": "hex"})
    with pytest.raises(ParameterError, match="sensor must be a SensorGeometry, got None"):
        dataclasses.replace(good, sensor=None)


def test_camera_dict_round_trip_and_unknown_keys():
    cam = tiny_like(rotation_rad=0.01, offset_m=(1e-6, -2e-6))
    data = cam.to_dict()
    assert data["mla"]["offset_m"] == [1e-6, -2e-6]
    assert LightFieldCamera.from_dict(data) == cam
    with pytest.raises(ParameterError, match=r"unknown key\(s\) in camera: \['zoom'\]"):
        LightFieldCamera.from_dict({**data, "zoom": 2})
    with pytest.raises(ParameterError, match=r"unknown key\(s\) in camera.mla: \['pitch'\]"):
        LightFieldCamera.from_dict({**data, "mla": {**data["mla"], "pitch": 1}})
    with pytest.raises(ParameterError, match=r"unknown key\(s\) in camera.sensor: \['bits'\]"):
        LightFieldCamera.from_dict({**data, "sensor": {**data["sensor"], "bits": 12}})


# =============================================================================== hostile sidecars (issue 12)
@pytest.mark.parametrize(
    ("data", "message"),
    [
        ("tiny", "camera must be a table (a JSON object) of camera parameters, got 'tiny'"),
        (["tiny"], "camera must be a table"),
        (None, "camera must be a table"),
        ({"mla": "hex"}, "camera.mla must be a table (a JSON object), got 'hex'"),
        ({"sensor": [480, 360]}, "camera.sensor must be a table (a JSON object), got [480, 360]"),
        ({"mla": {"offset_m": 5}}, "mla.offset_m must be a sequence of 2 numbers, got 5"),
        ({"mla": {"offset_m": "ab"}}, "mla.offset_m"),
        ({"mla": {"grid": ["hex"]}}, "mla.grid must be"),
        ({"sensor": {"width_px": "480"}}, "sensor.width_px must be an integer, got '480'"),
        ({"focal_length_m": [0.006]}, "focal_length_m must be a real number, got [0.006]"),
        ({"name": 7}, "name must be a string, got 7"),
    ],
)
def test_camera_from_dict_of_the_wrong_types_is_a_parameter_error(data, message):
    # A meta.json's camera with values of the wrong type gave ValueError/TypeError from dict() and
    # tuple(); every one is a ParameterError naming the key.
    good = camera_preset("tiny").to_dict()
    if isinstance(data, dict):
        data = {**good, **{k: ({**good[k], **v} if isinstance(v, dict) else v) for k, v in data.items()}}
    with pytest.raises(ParameterError, match=re.escape(message)):
        LightFieldCamera.from_dict(data)


def test_sensor_sizes_are_bounded():
    from lfrefract.optics.camera import MAX_IMAGE_SIDE_PX

    assert MAX_IMAGE_SIDE_PX == 65536
    SensorGeometry(width_px=65536, height_px=16, pixel_pitch_m=1e-6)
    with pytest.raises(ParameterError, match=re.escape("sensor.width_px must be at most 65536 px, got 200000")):
        SensorGeometry(width_px=200_000, height_px=16, pixel_pitch_m=1e-6)
    # A warp map indexes raw pixels with int32.
    with pytest.raises(ParameterError, match=re.escape("at most 2147483647 pixels (int32 raw indices)")):
        SensorGeometry(width_px=65536, height_px=32768, pixel_pitch_m=1e-6)
    SensorGeometry(width_px=65536, height_px=32767, pixel_pitch_m=1e-6)
