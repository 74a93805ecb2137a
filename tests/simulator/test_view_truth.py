"""Ground-truth disparity of sub-aperture view stacks (simulator.view_truth) against planes at known depth."""

from __future__ import annotations

import configparser
import dataclasses

import numpy as np
import pytest

from lfrefract import PinholeCamera, Pose, camera_preset, virtual_camera_for
from lfrefract.errors import ParameterError
from lfrefract.formats.viewstack import _hci_parameters
from lfrefract.optics.forward import project_through_port
from lfrefract.optics.port import FlatPort
from lfrefract.optics.real_lens import RealLensCamera
from lfrefract.synthesis.views import subaperture_centre_m, subaperture_slope_shift, subaperture_stack
from simulator import groundtruth
from simulator.scene import build_scene
from simulator.view_truth import ViewDisparity, stack_spacing_px, view_disparity, view_stack_disparity
from tests.simulator.scenes import port, scene
from tests.tolerances import (
    FLOAT64_GEOMETRY_M,
    FLOAT64_UNIT,
    VIEW_TRUTH_EDGE_M,
    VIEW_TRUTH_PARAXIAL_RELATIVE,
    VIEW_TRUTH_RELATIVE,
)

DEPTH_M = 0.3


def _plane(size_m=(3.0, 3.0), position_m=(0.0, 0.0, DEPTH_M)) -> dict:
    return {"type": "textured_plane", "position_m": list(position_m), "size_m": list(size_m), "texture_px": 64}


def _stack_of_ones(camera, output, grid, spacing_px=None):
    raw = np.ones((camera.sensor.height_px, camera.sensor.width_px), dtype=np.float32)
    return subaperture_stack(camera, raw, grid=grid, spacing_px=spacing_px, output=output)


def _hci_disparity(cfg_text: str, depth_m: np.ndarray) -> np.ndarray:
    """The benchmark's depth2disp (evaluation-toolkit, scenes/base_scene.py) on a parameters.cfg:
    ``B f max(W, H) / sensor * (1 / depth - 1 / focus)``, taken at its limit for ``focus_distance_m = inf``
    (the formula evaluated literally there is inf / inf)."""
    cfg = configparser.ConfigParser()
    cfg.read_string(cfg_text)
    baseline_mm = cfg.getfloat("extrinsics", "baseline_mm")
    focus_m = cfg.getfloat("extrinsics", "focus_distance_m")
    focal_mm = cfg.getfloat("intrinsics", "focal_length_mm")
    sensor_mm = cfg.getfloat("intrinsics", "sensor_size_mm")
    max_res = max(cfg.getint("intrinsics", "image_resolution_x_px"), cfg.getint("intrinsics", "image_resolution_y_px"))
    f = baseline_mm / 1000.0 * focal_mm * max_res
    return f / sensor_mm * (1.0 / depth_m - 1.0 / focus_m)


def test_a_view_pixel_is_the_ray_from_the_view_centre_along_k_inverse_p_even_off_the_focal_plane():
    """The model the truth rests on, against the views' own resampling: the sub-aperture ray through a
    lens (sensor point at its micro-image centre plus the view's offset, through the lens centre, bent
    by the thin main lens) starts at the view's centre and has the slope of the pixel where the view
    puts that lens, K (c / f' + slope shift, 1), also with f' != f (where the shift is not zero)."""
    camera = dataclasses.replace(camera_preset("tiny"), lens_to_mla_m=0.0063)
    idx = camera.lens_indices_on_sensor()[::37]
    for offset in [(1.3, -0.7), (-2.0, 2.0)]:
        rays = camera.rays_through_lenses(camera.micro_image_centres_px(idx) + np.asarray(offset))
        assert rays.in_aperture.all()
        np.testing.assert_allclose(
            rays.origins_cam,
            np.broadcast_to(subaperture_centre_m(camera, offset), rays.origins_cam.shape),
            atol=FLOAT64_GEOMETRY_M,
        )
        shift = np.asarray(subaperture_slope_shift(camera, *offset))
        assert np.all(np.abs(shift) > 1e-4)
        slopes = camera.mla.centres_m(idx) / camera.lens_to_mla_m + shift  # views.resampling_matrix's
        np.testing.assert_allclose(rays.directions_cam[:, :2] / rays.directions_cam[:, 2:], slopes, atol=FLOAT64_UNIT)


@pytest.mark.render
def test_in_air_the_disparity_is_focal_times_baseline_over_depth_in_every_view(mi):
    # An output wider than the lenses' hull, so that some pixels of every view are not recorded.
    config = scene(port=None, objects=[_plane()])
    output = PinholeCamera(focal_px=120.0, cx_px=55.5, cy_px=44.0, width_px=112, height_px=89)
    truth = view_stack_disparity(mi, build_scene(mi, config, port_geometry=False), config, output, grid=3)
    assert isinstance(truth, ViewDisparity)
    assert truth.disparity_x_px.shape == truth.disparity_y_px.shape == (3, 3, 89, 112)
    assert truth.disparity_x_px.dtype == np.float32
    camera = config.camera
    # The docstring's formula from the camera's parameters: b = s * pixel pitch * f' / f_mla.
    spacing = stack_spacing_px(camera, 3)
    baseline = spacing * camera.sensor.pixel_pitch_m * camera.lens_to_mla_m / camera.mla.focal_length_m
    expected = output.focal_px * baseline / DEPTH_M
    assert truth.baseline_m == pytest.approx(baseline, rel=1e-12)
    # NaN exactly where the views are (outside the lenses' hull), and nowhere else: the plane fills the view.
    views = _stack_of_ones(camera, output, 3).views
    assert 0.05 < np.isnan(views).mean() < 0.5
    for maps in (truth.disparity_x_px, truth.disparity_y_px):
        np.testing.assert_array_equal(np.isnan(maps), np.isnan(views))
        np.testing.assert_allclose(maps[np.isfinite(maps)], expected, rtol=VIEW_TRUTH_RELATIVE)


@pytest.mark.render
def test_in_air_the_disparity_is_the_one_parameters_cfg_implies_from_depth(mi):
    """The benchmark's own depth -> disparity conversion, on the parameters.cfg that this project writes
    for the same stack, applied to each view's depth map (traced from the view's centre)."""
    slanted = {**_plane(position_m=(0.02, -0.01, 0.4)), "rotation_xyz_deg": [20.0, -30.0, 0.0]}
    config = scene(port=None, objects=[slanted])
    mitsuba_scene = build_scene(mi, config, port_geometry=False)
    output = virtual_camera_for(config.camera)
    truth = view_stack_disparity(mi, mitsuba_scene, config, output, grid=3, spacing_px=1.5)
    cfg = _hci_parameters(_stack_of_ones(config.camera, output, 3, spacing_px=1.5))
    assert "focus_distance_m = inf" in cfg
    for r, c in [(1, 1), (0, 2), (2, 0)]:
        depth = groundtruth.depth_map(mi, mitsuba_scene, output, Pose(position_m=tuple(truth.centres_m[r, c])))
        assert np.ptp(depth) > 0.1  # slanted: the disparity varies
        expected = _hci_disparity(cfg, depth.astype(np.float64))
        np.testing.assert_allclose(truth.disparity_x_px[r, c], expected, rtol=VIEW_TRUTH_RELATIVE)
        np.testing.assert_allclose(truth.disparity_y_px[r, c], expected, rtol=VIEW_TRUTH_RELATIVE)
    assert np.all(truth.disparity_x_px > 0)  # near points move left in the view to the right


@pytest.mark.render
def test_behind_a_straight_port_the_disparity_is_the_same_in_every_view_but_grows_with_the_field(mi):
    """A port parallel to the main lens: moving the centre along it moves the whole set-up, so each view
    sees the fronto-parallel plane as the central view does (the same maps). Refraction is not a central
    projection: the displacement grows from the apparent-depth value f b / (d + t n_air / n_glass +
    w n_air / n_water) on the axis towards the edges, and differently along and across the field."""
    config = scene(port=port(0.0), objects=[_plane()])
    output = virtual_camera_for(config.camera)
    truth = view_stack_disparity(mi, build_scene(mi, config, port_geometry=False), config, output, grid=3)
    dx, dy = truth.disparity_x_px, truth.disparity_y_px
    assert np.isfinite(dx).all()
    assert np.isfinite(dy).all()
    for r in range(3):
        for c in range(3):
            np.testing.assert_allclose(dx[r, c], dx[1, 1], rtol=VIEW_TRUTH_RELATIVE)
            np.testing.assert_allclose(dy[r, c], dy[1, 1], rtol=VIEW_TRUTH_RELATIVE)
    p = config.port
    water_m = DEPTH_M - p.distance_m - p.thickness_m
    apparent_m = p.distance_m + p.thickness_m * p.n_air / p.n_glass + water_m * p.n_air / p.n_water
    axis = output.focal_px * truth.baseline_m / apparent_m
    u0, v0 = int(output.cx_px), int(output.cy_px)  # cy is a pixel centre, cx half a pixel off
    np.testing.assert_allclose(dx[1, 1, v0, u0 : u0 + 2], axis, rtol=VIEW_TRUTH_PARAXIAL_RELATIVE)
    np.testing.assert_allclose(dy[1, 1, v0, u0 : u0 + 2], axis, rtol=VIEW_TRUTH_PARAXIAL_RELATIVE)
    assert dx[1, 1].min() == pytest.approx(axis, rel=VIEW_TRUTH_PARAXIAL_RELATIVE)
    # Along the middle row the horizontal disparity grows towards both edges (10 % at the tiny view's
    # 21 deg half field); the vertical one, across the field there, grows less.
    row = dx[1, 1, v0]
    assert row[0] > 1.05 * axis
    assert row[-1] > 1.05 * axis
    assert np.all(np.diff(row[u0 + 1 :]) > 0)
    assert np.all(np.diff(row[: u0 + 1]) < 0)
    assert dy[1, 1, v0, 0] < row[0] - 0.01 * axis


@pytest.mark.render
@pytest.mark.parametrize(("r", "c"), [(1, 1), (0, 2)])
def test_behind_a_tilted_port_the_disparity_is_the_displacement_of_the_plane_between_neighbours(mi, r, c):
    """The oracle: each pixel's ray traced through the port in float64, met with the analytic plane, and
    that point projected into the neighbouring views through the port. The plane covers part of the view,
    so the NaN mask is where its ray misses the plane."""
    size, centre = (0.12, 0.1), (0.03, 0.02, DEPTH_M)
    config = scene(port=port(25.0, 10.0), objects=[_plane(size, centre)])
    output = virtual_camera_for(config.camera)
    truth = view_stack_disparity(mi, build_scene(mi, config, port_geometry=False), config, output, grid=3)
    p, b = config.port, truth.baseline_m
    view_centre = truth.centres_m[r, c]
    trace = p.trace_from_air(
        np.broadcast_to(view_centre, (output.width_px * output.height_px, 3)), output.pixel_directions()
    )
    assert trace.valid.all()
    along = (DEPTH_M - trace.exit_points_cam[:, 2]) / trace.directions_cam[:, 2]
    points = trace.exit_points_cam + along[:, None] * trace.directions_cam
    inside = np.abs(points[:, :2] - centre[:2]) <= np.asarray(size) / 2
    on_plane = inside.all(axis=1)
    edge = np.min(np.abs(np.abs(points[:, :2] - centre[:2]) - np.asarray(size) / 2), axis=1) < VIEW_TRUTH_EDGE_M
    assert 0.2 < on_plane.mean() < 0.9
    assert edge.sum() <= 2
    dx, dy = truth.disparity_x_px[r, c].ravel(), truth.disparity_y_px[r, c].ravel()
    np.testing.assert_array_equal(np.isfinite(dx)[~edge], on_plane[~edge])
    np.testing.assert_array_equal(np.isfinite(dy), np.isfinite(dx))
    seen = on_plane & np.isfinite(dx)
    uv = np.stack(np.meshgrid(np.arange(output.width_px), np.arange(output.height_px)), axis=-1).reshape(-1, 2)
    right = project_through_port(p, output, view_centre + np.array([b, 0.0, 0.0]), points[seen])
    below = project_through_port(p, output, view_centre + np.array([0.0, b, 0.0]), points[seen])
    expected_x, expected_y = uv[seen, 0] - right[:, 0], uv[seen, 1] - below[:, 1]
    np.testing.assert_allclose(dx[seen], expected_x, rtol=VIEW_TRUTH_RELATIVE)
    np.testing.assert_allclose(dy[seen], expected_y, rtol=VIEW_TRUTH_RELATIVE)
    # Not one central camera's shifts: the two directions disagree by far more than the tolerance, and
    # neither is the in-air value.
    assert np.max(np.abs(expected_x - expected_y) / expected_x) > 0.05
    assert np.all(expected_x > 1.1 * output.focal_px * b / DEPTH_M)


@pytest.mark.render
def test_the_camera_pose_carries_the_rays_into_the_world(mi):
    """The same plane in the camera frame, once with the identity pose and once with the camera (and the
    plane with it) turned and moved in the world: the same maps."""
    angles, position = (10.0, -20.0, 5.0), (0.1, -0.2, 0.3)
    pose = Pose.from_euler_xyz_deg(angles, position)
    local = np.array([0.0, 0.0, DEPTH_M])
    world = np.asarray(pose.rotation) @ local + np.asarray(position)
    fixed = scene(port=port(25.0, 10.0), objects=[_plane()])
    moved = dataclasses.replace(
        scene(port=port(25.0, 10.0), objects=[{**_plane(position_m=tuple(world)), "rotation_xyz_deg": list(angles)}]),
        pose=pose,
    )
    a = view_stack_disparity(mi, build_scene(mi, fixed, port_geometry=False), fixed, grid=3)
    b = view_stack_disparity(mi, build_scene(mi, moved, port_geometry=False), moved, grid=3)
    assert np.isfinite(a.disparity_x_px).all()
    np.testing.assert_allclose(b.disparity_x_px, a.disparity_x_px, rtol=VIEW_TRUTH_RELATIVE)
    np.testing.assert_allclose(b.disparity_y_px, a.disparity_y_px, rtol=VIEW_TRUTH_RELATIVE)


@pytest.mark.render
def test_one_view_at_a_time_gives_the_stack_s_maps(mi):
    config = scene(port=port(20.0, -5.0), objects=[_plane()])
    mitsuba_scene = build_scene(mi, config, port_geometry=False)
    truth = view_stack_disparity(mi, mitsuba_scene, config, grid=5)
    dx, dy = view_disparity(mi, mitsuba_scene, config, row=4, column=1, grid=5)
    np.testing.assert_array_equal(dx, truth.disparity_x_px[4, 1])
    np.testing.assert_array_equal(dy, truth.disparity_y_px[4, 1])
    assert truth.spacing_px == _stack_of_ones(config.camera, virtual_camera_for(config.camera), 5).spacing_px


@pytest.mark.render
def test_bad_requests_are_refused(mi):
    config = scene(port=port(20.0), objects=[_plane()])
    mitsuba_scene = build_scene(mi, config, port_geometry=False)
    with pytest.raises(ParameterError, match="grid must be an odd integer"):
        view_stack_disparity(mi, mitsuba_scene, config, grid=4)
    with pytest.raises(ParameterError, match=r"spacing_px=5\.0 puts the corner views"):
        view_stack_disparity(mi, mitsuba_scene, config, grid=9, spacing_px=5.0)
    with pytest.raises(ParameterError, match="column must be an integer in"):
        view_disparity(mi, mitsuba_scene, config, row=0, column=3, grid=3)
    with pytest.raises(ParameterError, match="output must be a PinholeCamera"):
        view_stack_disparity(mi, mitsuba_scene, config, "ideal", grid=3)
    lens = RealLensCamera.from_preset(config.camera, "double-gauss").lens
    with_lens = dataclasses.replace(config, lens=lens, port=port_far())
    with pytest.raises(ParameterError, match="not a pinhole's rays"):
        view_stack_disparity(mi, mitsuba_scene, with_lens, grid=3)


def port_far() -> FlatPort:
    """The tests' port, 40 mm away: clear of a real main lens."""
    return FlatPort.from_dict({**port(20.0), "distance_m": 0.04})


def test_the_memory_estimate_covers_the_lenses_of_the_resampling(monkeypatch):
    """The estimate took 1.5 x the resampling's bytes per pixel and nothing per lens: the Illum's 233 000
    lenses (350 MB of triangulation) onto a 10 x 10 px view passed it, and the stack's result was allocated
    before the resampling refused. The estimate is lfrefract's resampling_bytes, its lens term included."""
    import lfrefract._memory
    from lfrefract.synthesis.views import lens_count, resampling_bytes
    from simulator.view_truth import view_disparity_bytes

    config = scene(port=port(20.0), objects=[_plane()], camera="illum")
    small = PinholeCamera(focal_px=10.0, cx_px=4.5, cy_px=4.5, width_px=10, height_px=10)
    lenses = resampling_bytes(lenses=lens_count(config.camera), pixels=100)
    assert view_disparity_bytes(config.camera, small, 3) >= lenses > 3e8
    monkeypatch.setattr(lfrefract._memory, "available_memory", lambda: (2 * 10**8, "test"))
    for call in (
        lambda: view_stack_disparity(None, None, config, small, grid=3),
        lambda: view_disparity(None, None, config, small, row=0, column=0, grid=3),
    ):
        with pytest.raises(ParameterError, match=r"the disparity of a (3 x 3 stack of )?10 x 10 px views? needs about"):
            call()
