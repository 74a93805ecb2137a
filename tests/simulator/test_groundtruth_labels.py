"""Ground-truth labels: surface normals and instance ids of the ideal image, depth and microlens of
every raw pixel, against analytic geometry in physical units (numpy ray/plane intersections, the
core's port trace), independent of Mitsuba."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lfrefract import PinholeCamera, Pose
from lfrefract.errors import ParameterError
from lfrefract.optics.real_lens import RealLensCamera
from simulator import groundtruth
from simulator.config import Chessboard, Disc, SceneConfig, TexturedPlane
from simulator.geometry import plane_size_m
from simulator.scene import build_scene
from tests.simulator.scenes import port, scene
from tests.tolerances import (
    DEPTH_FLOAT32_RELATIVE,
    FLOAT64_PIXEL_PX,
    LABEL_EDGE_MARGIN_RELATIVE,
    LABEL_NORMAL_FLOAT32,
    RAW_DEPTH_FLOAT32_RELATIVE,
)

pytestmark = pytest.mark.render

PINHOLE = PinholeCamera(focal_px=150.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120)

#: A camera pose away from the identity (rotated on all three axes, shifted), so that a label left
#: in the world frame, or rotated the wrong way, shows.
POSE = Pose.from_euler_xyz_deg((8.0, 25.0, -6.0), (-0.25, 0.05, 0.1))


def _plane(position_m, rotation_xyz_deg=(0.0, 0.0, 0.0), size_m=(3.0, 3.0)) -> dict:
    return {
        "type": "textured_plane",
        "position_m": list(position_m),
        "rotation_xyz_deg": list(rotation_xyz_deg),
        "size_m": list(size_m),
        "texture_px": 64,
    }


def _in_front(pose: Pose, point_cam) -> list[float]:
    """World position of a camera-frame point."""
    return pose.to_world(np.asarray([point_cam], dtype=np.float64))[0].tolist()


def _analytic_hits(config: SceneConfig, origins_cam: np.ndarray, directions_cam: np.ndarray):
    """First object along each camera-frame ray by numpy ray/plane intersection.

    Returns instance ids (N,) (0: none), camera-frame z (N,) (+inf: none), the camera-frame unit
    normal (N, 3) of the object hit (NaN: none, not yet oriented), and ``near_edge`` (N,): the ray
    passes within :data:`LABEL_EDGE_MARGIN_RELATIVE` of its distance from some object's rim.
    """
    n = len(origins_cam)
    ids = np.zeros(n, dtype=np.uint16)
    best_t = np.full(n, np.inf)
    normal = np.full((n, 3), np.nan)
    near_edge = np.zeros(n, dtype=bool)
    to_cam = np.linalg.inv(config.pose.matrix)
    for i, obj in enumerate(config.objects):
        m = to_cam @ obj.placement.matrix
        rot, centre = m[:3, :3], m[:3, 3]
        axis = rot[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((centre - origins_cam) @ axis) / (directions_cam @ axis)
        local = (origins_cam + t[:, None] * directions_cam - centre) @ rot
        if isinstance(obj, (TexturedPlane, Chessboard)):
            half_w, half_h = (s / 2.0 for s in plane_size_m(obj))
            inset = np.minimum(half_w - np.abs(local[:, 0]), half_h - np.abs(local[:, 1]))
        elif isinstance(obj, Disc):
            inset = obj.radius_m - np.hypot(local[:, 0], local[:, 1])
        else:
            raise TypeError(type(obj))
        ahead = np.isfinite(t) & (t > 0)
        near_edge |= ahead & (np.abs(inset) <= LABEL_EDGE_MARGIN_RELATIVE * t)
        hit = ahead & (inset >= 0) & (t < best_t)
        best_t[hit], ids[hit], normal[hit] = t[hit], i + 1, axis
    z = np.where(np.isfinite(best_t), origins_cam[:, 2] + best_t * directions_cam[:, 2], np.inf)
    return ids, z, normal, near_edge


def _facing(normal: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) turned to face rays of ``directions`` (N, 3)."""
    return normal * np.where(np.sum(normal * directions, axis=1) > 0, -1.0, 1.0)[:, None]


# ----------------------------------------------------------------------------- ideal-image labels
def test_slanted_plane_under_a_pose_gives_its_normal_and_depth_in_the_camera_frame(mi):
    plane = _plane(_in_front(POSE, (0.02, -0.01, 0.5)), rotation_xyz_deg=(20.0, 0.0, 10.0))
    config = scene(port=None, objects=[plane]).with_overrides(pose=POSE)
    built = build_scene(mi, config, port_geometry=False)
    labels = groundtruth.surface_labels(mi, built, config, PINHOLE)
    h, w = PINHOLE.height_px, PINHOLE.width_px
    assert labels.depth_m.shape == labels.instance_id.shape == (h, w)
    assert labels.normal_cam.shape == (h, w, 3)
    assert (labels.depth_m.dtype, labels.normal_cam.dtype, labels.instance_id.dtype) == (
        np.float32,
        np.float32,
        np.uint16,
    )
    # The depth is the depth map's, bit for bit.
    np.testing.assert_array_equal(labels.depth_m, groundtruth.depth_map(mi, built, PINHOLE, config.pose))

    d = PINHOLE.pixel_directions()
    ids, z, normal, _ = _analytic_hits(config, np.zeros_like(d), d)
    assert np.all(ids == 1)  # the 3 m plane fills the view
    np.testing.assert_array_equal(labels.instance_id, np.ones((h, w), dtype=np.uint16))
    np.testing.assert_allclose(labels.depth_m.ravel(), z, rtol=DEPTH_FLOAT32_RELATIVE)
    expected = _facing(normal, d)
    # The plane's normal in the camera frame: R^T times its world normal, towards the camera.
    world_normal = config.objects[0].placement.matrix[:3, 2]
    np.testing.assert_allclose(np.abs(expected[0]), np.abs(np.asarray(POSE.rotation).T @ world_normal), atol=1e-12)
    assert expected[0] @ np.array([0.0, 0.0, 1.0]) < 0  # it faces the camera
    np.testing.assert_allclose(labels.normal_cam.reshape(-1, 3), expected, atol=LABEL_NORMAL_FLOAT32)


def test_instance_ids_follow_the_config_order_with_occlusion(mi):
    """A backdrop, a chessboard in front of it and ten discs: ids 1..12 where each is seen, 0 off them.

    Twelve shapes: Mitsuba lists them in another order than the config's (and not the same one
    from run to run), so ids must come from the shapes' names.
    """
    backdrop = _plane((-0.15, 0.0, 0.8), rotation_xyz_deg=(0.0, 15.0, 0.0), size_m=(0.6, 0.5))
    board = {
        "type": "chessboard",
        "position_m": [0.08, 0.05, 0.5],
        "rotation_xyz_deg": [-10.0, 0.0, 5.0],
        "squares": [6, 4],
        "square_size_m": 0.03,
    }
    discs = [
        {
            "type": "disc",
            "position_m": [-0.2 + 0.1 * (k % 5), -0.12 + 0.07 * (k // 5), 0.6 - 0.02 * k],
            "rotation_xyz_deg": [0.0, -30.0 + 6.0 * k, 0.0],
            "radius_m": 0.025,
        }
        for k in range(10)
    ]
    config = scene(port=None, objects=[backdrop, board, *discs])
    labels = groundtruth.surface_labels(mi, build_scene(mi, config, port_geometry=False), config, PINHOLE)
    d = PINHOLE.pixel_directions()
    ids, z, normal, near_edge = _analytic_hits(config, np.zeros_like(d), d)
    keep = ~near_edge
    assert keep.mean() > 0.97
    assert set(np.unique(ids[keep])) == set(range(len(config.objects) + 1))  # each object seen, and background
    got = labels.instance_id.ravel()
    np.testing.assert_array_equal(got[keep], ids[keep])
    np.testing.assert_allclose(labels.depth_m.ravel()[keep], z[keep], rtol=DEPTH_FLOAT32_RELATIVE)
    seen = keep & (ids > 0)
    np.testing.assert_allclose(
        labels.normal_cam.reshape(-1, 3)[seen], _facing(normal, d)[seen], atol=LABEL_NORMAL_FLOAT32
    )
    assert np.all(np.isnan(labels.normal_cam.reshape(-1, 3)[got == groundtruth.BACKGROUND_ID]))
    assert np.all(np.isinf(labels.depth_m.ravel()[got == groundtruth.BACKGROUND_ID]))
    table = groundtruth.instance_table(config)
    assert [e["id"] for e in table] == list(range(1, 13))
    assert [e["object_index"] for e in table] == list(range(12))
    assert [e["type"] for e in table] == ["textured_plane", "chessboard"] + ["disc"] * 10


def test_mesh_normals_are_unit_and_face_the_camera(mi):
    """A bowl (a mesh with vertex normals): the interpolated shading normal, unit, on the camera's side."""
    bowl = {"type": "bowl", "position_m": [0.0, 0.0, 0.35], "radius_m": 0.06, "depth_m": 0.04}
    config = scene(port=None, objects=[bowl])
    labels = groundtruth.surface_labels(mi, build_scene(mi, config, port_geometry=False), config, PINHOLE)
    normal = labels.normal_cam.reshape(-1, 3).astype(np.float64)
    hit = labels.instance_id.ravel() == 1
    assert 0.1 < hit.mean() < 0.9
    assert np.array_equal(np.isfinite(labels.depth_m.ravel()), hit)
    np.testing.assert_allclose(np.linalg.norm(normal[hit], axis=1), 1.0, atol=LABEL_NORMAL_FLOAT32)
    assert np.all(np.sum(normal[hit] * PINHOLE.pixel_directions()[hit], axis=1) <= 0.0)
    assert np.all(np.isnan(normal[~hit]))
    # Inside a bowl opening towards the camera the normals turn towards its axis: left of the axis
    # they point right (+x), right of it left; smooth, so they take many values, not one per facet.
    # (The outermost two columns on either side see the rim, 4 mm of wall edge-on.)
    centre_v = int(PINHOLE.cy_px)
    row = labels.normal_cam[centre_v]
    cols = np.flatnonzero(labels.instance_id[centre_v] == 1)[2:-2]
    quarter = len(cols) // 4
    assert row[cols[:quarter], 0].min() > 0.3
    assert row[cols[-quarter:], 0].max() < -0.3
    assert len(np.unique(row[cols, 0])) > len(cols) // 2


def test_a_scene_with_port_faces_is_refused(mi):
    config = scene(port=port(20.0), objects=[_plane((0.0, 0.0, 0.5))])
    with pytest.raises(ParameterError, match="port_face_0"):
        groundtruth.surface_labels(mi, build_scene(mi, config, port_geometry=True), config, PINHOLE)


# ----------------------------------------------------------------------------- raw-pixel truth
def _micro_image_centres_px(config: SceneConfig, scale: float) -> np.ndarray:
    """Micro-image centres (M, 2), raw pixels, of a lattice reaching well past the sensor, from the
    conventions (docs/conventions.md) alone."""
    cam = config.camera
    mla = cam.mla
    a1 = np.array([1.0, 0.0])
    a2 = np.array([0.5, math.sqrt(3.0) / 2.0]) if mla.grid == "hex" else np.array([0.0, 1.0])
    c, s = math.cos(mla.rotation_rad), math.sin(mla.rotation_rad)
    rot = np.array([[c, -s], [s, c]])
    reach = int(max(cam.sensor.size_m) / mla.pitch_m) + 4
    ii, jj = np.meshgrid(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1))
    lattice = mla.pitch_m * (ii.reshape(-1, 1) * a1 + jj.reshape(-1, 1) * a2) @ rot.T + np.asarray(mla.offset_m)
    centre = np.array([(cam.sensor.width_px - 1) / 2.0, (cam.sensor.height_px - 1) / 2.0])
    return scale * lattice / cam.sensor.pixel_pitch_m + centre


def _raw_pixels(config: SceneConfig) -> np.ndarray:
    sensor = config.camera.sensor
    vv, uu = np.mgrid[0 : sensor.height_px, 0 : sensor.width_px]
    return np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)


def _check_lens_rows(config: SceneConfig, truth: groundtruth.RawPixelTruth, scale: float) -> None:
    """Each pixel's lens-table row is the lens of the nearest micro-image centre (-1: not on the table)."""
    cam = config.camera
    table = groundtruth.lens_table(cam, config.lens)
    uv = _raw_pixels(config)
    lattice = _micro_image_centres_px(config, scale)
    dist, nearest = cKDTree(lattice).query(uv)
    rows = truth.lens_row.ravel()
    assert truth.lens_row.dtype == np.int32
    on = rows >= 0
    own = np.linalg.norm(uv[on] - table["micro_image_centre_px"][rows[on]], axis=1)
    # The table's centre is the nearest one (ties within round-off), within the lattice cell's
    # circumradius (pitch / sqrt(3) for the hexagonal cell, pitch / sqrt(2) for the square one).
    np.testing.assert_allclose(own, dist[on], atol=FLOAT64_PIXEL_PX)
    pitch_px = cam.mla.pitch_m * scale / cam.sensor.pixel_pitch_m
    assert own.max() <= pitch_px / (math.sqrt(3.0) if cam.mla.grid == "hex" else math.sqrt(2.0))
    # Every lens on the table has pixels; a pixel off the table is one whose nearest centre lies
    # beyond the outermost pixel centres.
    assert set(np.unique(rows[on])) == set(range(len(table["lens_index"])))
    assert 0 < (~on).mean() < 0.05
    off_centre = lattice[nearest[~on]]
    w, h = cam.sensor.width_px, cam.sensor.height_px
    outside = (off_centre[:, 0] < 0) | (off_centre[:, 0] > w - 1) | (off_centre[:, 1] < 0) | (off_centre[:, 1] > h - 1)
    assert np.all(outside)


def test_raw_depth_of_a_fronto_parallel_plane_without_port(mi, tiny):
    """Every recorded pixel sees the plane at its depth; NaN exactly outside the main-lens aperture."""
    depth = 0.45
    config = scene(port=None, objects=[_plane((0.0, 0.0, depth))])
    truth = groundtruth.raw_pixel_truth(mi, build_scene(mi, config, port_geometry=False), config)
    assert truth.depth_m.shape == truth.lens_row.shape == (tiny.sensor.height_px, tiny.sensor.width_px)
    assert truth.depth_m.dtype == np.float32
    # A pixel's chief ray passes the aperture iff the pixel lies within the micro-image radius
    # (the aperture's image, R f_mla / f') of its micro-image centre.
    dist, _ = cKDTree(_micro_image_centres_px(config, tiny.micro_image_scale)).query(_raw_pixels(config))
    radius_px = tiny.aperture_radius_m * tiny.mla.focal_length_m / tiny.lens_to_mla_m / tiny.sensor.pixel_pitch_m
    clear = np.abs(dist - radius_px) > FLOAT64_PIXEL_PX
    recorded = np.isfinite(truth.depth_m.ravel())
    np.testing.assert_array_equal(recorded[clear], dist[clear] <= radius_px)
    assert np.all(np.isnan(truth.depth_m.ravel()[~recorded]))
    assert 0.6 < recorded.mean() < 0.8  # the disc / hexagon area ratio, 0.70
    np.testing.assert_allclose(truth.depth_m.ravel()[recorded], depth, rtol=RAW_DEPTH_FLOAT32_RELATIVE)
    _check_lens_rows(config, truth, tiny.micro_image_scale)


def _expected_raw(config: SceneConfig, optics):
    """The analytic raw-pixel depth: the core's chief rays, the core's port trace, numpy planes."""
    rays = optics.chief_rays() if isinstance(optics, RealLensCamera) else optics.captured_rays()
    n = len(rays.in_aperture)
    z = np.full(n, np.nan)
    near_edge = np.zeros(n, dtype=bool)
    ok = rays.in_aperture.copy()
    assert config.port is not None
    trace = config.port.trace_from_air(rays.origins_cam[ok], rays.directions_cam[ok])
    tir = np.zeros(n, dtype=bool)
    tir[ok] = trace.tir
    ok[ok] = trace.valid
    _, z[ok], _, near_edge[ok] = _analytic_hits(
        config, trace.exit_points_cam[trace.valid], trace.directions_cam[trace.valid]
    )
    return z, ok, near_edge, tir


@pytest.mark.parametrize(
    "port_table",
    [
        port(tilt_x_deg=25.0, tilt_y_deg=-10.0, thickness_m=0.006),
        # A camera in a dense medium (n 2.0) behind a bare interface into n 1.0, tilted 30 deg:
        # the critical angle is 30 deg, so part of the view is totally internally reflected.
        {"distance_m": 0.02, "tilt_x_deg": 30.0, "n_air": 2.0, "n_water": 1.0},
    ],
    ids=["glass", "tir"],
)
def test_raw_depth_through_a_tilted_port_under_a_pose(mi, tiny, port_table):
    """A slanted plane that fills part of the view: the analytically traced ray's hit, +inf past
    the plane, NaN where vignetted or totally reflected."""
    plane = _plane(_in_front(POSE, (0.03, 0.02, 0.4)), rotation_xyz_deg=(30.0, 10.0, 0.0), size_m=(0.2, 0.15))
    config = scene(port=port_table, objects=[plane]).with_overrides(pose=POSE)
    truth = groundtruth.raw_pixel_truth(mi, build_scene(mi, config, port_geometry=False), config)
    z, recorded, near_edge, tir = _expected_raw(config, tiny)
    got = truth.depth_m.ravel().astype(np.float64)
    np.testing.assert_array_equal(np.isnan(got), ~recorded)
    if port_table.get("n_air") == 2.0:
        assert 0.05 < tir.mean() < 0.6  # some of the view reflected, not all
    keep = recorded & ~near_edge
    assert np.isinf(z[keep]).any()
    assert np.isfinite(z[keep]).any()
    np.testing.assert_array_equal(np.isinf(got[keep]), np.isinf(z[keep]))
    seen = keep & np.isfinite(z)
    np.testing.assert_allclose(got[seen], z[seen], rtol=RAW_DEPTH_FLOAT32_RELATIVE)
    # The port matters: straight rays would miss the plane, or hit it elsewhere, at most of these pixels.
    straight = tiny.captured_rays()
    _, z_straight, _, _ = _analytic_hits(config, straight.origins_cam, straight.directions_cam)
    assert np.mean(~np.isclose(z_straight[seen], z[seen], rtol=100 * RAW_DEPTH_FLOAT32_RELATIVE)) > 0.5


def test_raw_truth_with_a_real_lens(mi, tiny):
    """The double Gauss: its chief rays leave its front surface; its micro-images are the exit pupil's."""
    plane = _plane((0.0, 0.0, 0.5), rotation_xyz_deg=(0.0, 20.0, 0.0))
    config = scene(port=port(15.0, 5.0), objects=[plane])
    real = RealLensCamera.from_preset(tiny, "double-gauss")
    config = config.with_overrides(lens=real.lens)
    truth = groundtruth.raw_pixel_truth(mi, build_scene(mi, config, port_geometry=False), config)
    z, recorded, _, _ = _expected_raw(config, real)
    got = truth.depth_m.ravel().astype(np.float64)
    np.testing.assert_array_equal(np.isnan(got), ~recorded)
    assert 0.2 < recorded.mean() < 0.8
    assert np.all(np.isfinite(z[recorded]))
    np.testing.assert_allclose(got[recorded], z[recorded], rtol=RAW_DEPTH_FLOAT32_RELATIVE)
    _check_lens_rows(config, truth, real.micro_image_scale)


def test_raw_truth_does_not_depend_on_the_block_size(mi, tiny):
    config = scene(
        port=port(20.0), objects=[_plane((0.02, 0.0, 0.4), rotation_xyz_deg=(0.0, 0.0, 0.0), size_m=(0.2, 0.2))]
    )
    built = build_scene(mi, config, port_geometry=False)
    whole = groundtruth.raw_pixel_truth(mi, built, config)
    rows = groundtruth.raw_pixel_truth(mi, built, config, max_block_pixels=3 * tiny.sensor.width_px + 7)
    one = groundtruth.raw_pixel_truth(mi, built, config, max_block_pixels=1)  # one row at a time
    for other in (rows, one):
        np.testing.assert_array_equal(other.depth_m, whole.depth_m)
        np.testing.assert_array_equal(other.lens_row, whole.lens_row)
    for bad in (0, -5, 2.5, True):
        with pytest.raises(ParameterError, match="max_block_pixels"):
            groundtruth.raw_pixel_truth(mi, built, config, max_block_pixels=bad)
