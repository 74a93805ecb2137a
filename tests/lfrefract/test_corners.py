"""Chessboard corners located in the 4D light field (lfrefract.calibration.corners), on raw images
computed from the captured-ray model: every pixel's chief ray refracted by the port onto a board
with a smooth chessboard texture, so the exact corner tracks are known."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfrefract import FlatPort, ParameterError, Pose, camera_preset, virtual_camera_for
from lfrefract.calibration import corners as corners_module
from lfrefract.calibration.approx import detect_chessboard
from lfrefract.calibration.corners import light_field_corners
from lfrefract.calibration.port import board_view_from_light_field, project_through_port
from lfrefract.synthesis.views import finite_pixels, subaperture_view
from tests.tolerances import LF_CORNER_ANALYTIC_PX

CAMERA = camera_preset("tiny")
VIEW = virtual_camera_for(CAMERA)  # 92 x 69 px, f = 120 px
PATTERN = (6, 4)
PORT = FlatPort.from_degrees(distance_m=0.012, thickness_m=0.004, tilt_x_deg=20.0, tilt_y_deg=-10.0)


def _board(port: FlatPort, depth_m: float, rotation_deg, px_per_square: float) -> tuple[Pose, float]:
    """A board centred on the optical axis's refracted line at ``depth_m``, about ``px_per_square``."""
    trace = port.trace_from_air(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]))
    start, direction = trace.exit_points_cam[0], trace.directions_cam[0]
    centre = start + direction * (depth_m - start[2]) / direction[2]
    return Pose.from_euler_xyz_deg(rotation_deg, centre), px_per_square * depth_m / (1.333 * VIEW.focal_px)


def _corners_world(pose: Pose, square_m: float) -> np.ndarray:
    jj, ii = np.mgrid[0 : PATTERN[1], 0 : PATTERN[0]]
    local = np.stack([ii.ravel() - (PATTERN[0] - 1) / 2, jj.ravel() - (PATTERN[1] - 1) / 2], axis=1) * square_m
    return pose.to_world(np.c_[local, np.zeros(len(local))])


def _raw(port: FlatPort, pose: Pose, square_m: float, *, bounded: bool = False) -> np.ndarray:
    """Each pixel's chief ray through ``port`` onto the board plane, where the texture
    ``0.5 + 0.4 tanh(3 cos(pi x / s)) tanh(3 cos(pi y / s))`` has its X-junctions at the inner corners
    (point-symmetric about each, like a blurred chessboard); ``bounded``: white (0.9) beyond the
    board's squares (one more than :data:`PATTERN` each way), so that OpenCV finds the board."""
    rays = CAMERA.captured_rays()
    trace = port.trace_from_air(rays.origins_cam, rays.directions_cam)
    rotation, centre = np.asarray(pose.rotation), np.asarray(pose.position_m)
    normal = rotation[:, 2]
    along = ((centre - trace.exit_points_cam) @ normal) / (trace.directions_cam @ normal)
    local = (trace.exit_points_cam + along[:, None] * trace.directions_cam - centre) @ rotation
    x, y = local[:, 0] / square_m, local[:, 1] / square_m
    value = 0.5 + 0.4 * np.tanh(3.0 * np.cos(math.pi * x)) * np.tanh(3.0 * np.cos(math.pi * y))
    if bounded:
        value = np.where((np.abs(x) < (PATTERN[0] + 1) / 2) & (np.abs(y) < (PATTERN[1] + 1) / 2), value, 0.9)
    return np.where(rays.in_aperture, value, 0.0).reshape(CAMERA.sensor.height_px, CAMERA.sensor.width_px)


@pytest.mark.parametrize(
    ("port", "depth_m", "rotation_deg"),
    [
        (PORT, 0.2, (20.0, -15.0, 5.0)),
        (PORT, 0.5, (-10.0, 25.0, -5.0)),
        (FlatPort.from_degrees(distance_m=0.012, thickness_m=0.004), 0.3, (0.0, 0.0, 10.0)),
    ],
)
def test_corner_tracks_follow_the_exact_refracted_projection(port, depth_m, rotation_deg):
    pose, square = _board(port, depth_m, rotation_deg, px_per_square=12.0)
    world = _corners_world(pose, square)
    expected = project_through_port(VIEW, port, world)
    start = expected + np.random.default_rng(0).normal(scale=0.3, size=expected.shape)
    tracks = light_field_corners(
        CAMERA, _raw(port, pose, square), start, pattern=PATTERN, square_size_m=square, view=VIEW
    )
    assert tracks.ok.all()
    assert np.sqrt(np.mean(np.sum((tracks.centre_px - expected) ** 2, axis=1))) < LF_CORNER_ANALYTIC_PX
    # Seen from near the rim of the usable aperture, where the parallax is largest (0.2-0.6 px here).
    reach = 0.9 * CAMERA.usable_aperture_radius_m(0.71)
    for a in ((reach, 0.0), (0.0, -reach), (-0.7 * reach, 0.7 * reach)):
        seen = project_through_port(VIEW, port, world, centre_m=(*a, 0.0))
        assert np.min(np.linalg.norm(seen - expected, axis=1)) > 5 * LF_CORNER_ANALYTIC_PX
        error = np.sqrt(np.mean(np.sum((tracks.at(a) - seen) ** 2, axis=1)))
        assert error < 2 * LF_CORNER_ANALYTIC_PX, (a, error)
    assert np.all(tracks.centre_std_px < LF_CORNER_ANALYTIC_PX)


def test_corners_are_fitted_alike_in_chunks_and_unrecorded_pixels_are_no_samples(monkeypatch):
    # A board of more corners than a chunk (an Illum board of 9 x 7 inner corners has 63, a larger one more)
    # is fitted chunk by chunk on the samples and k-d tree shared by every capture of the camera.
    pose, square = _board(PORT, 0.3, (10.0, -5.0, 0.0), px_per_square=12.0)
    expected = project_through_port(VIEW, PORT, _corners_world(pose, square))
    raw = _raw(PORT, pose, square)
    whole = light_field_corners(CAMERA, raw, expected, pattern=PATTERN, square_size_m=square, view=VIEW)
    monkeypatch.setattr(corners_module, "_CHUNK", 5)
    chunked = light_field_corners(CAMERA, raw, expected, pattern=PATTERN, square_size_m=square, view=VIEW)
    np.testing.assert_allclose(chunked.centre_px, whole.centre_px, atol=1e-9)
    assert chunked.ok.all()
    # A NaN pixel (unrecorded) inside a corner's window is left out of that corner's samples.
    rays = CAMERA.captured_rays()
    seen = VIEW.project(rays.directions_cam)
    near = np.flatnonzero(rays.in_aperture & (np.linalg.norm(seen - expected[7], axis=1) < 1.5))
    holed = raw.copy().ravel()
    holed[near[::2]] = np.nan
    # The first sample of all unrecorded too (the padding of the fit's sample rows once took its value).
    holed[corners_module._light_field_samples(CAMERA, VIEW, corners_module.RIM_MARGIN_PX).pixel[0]] = np.nan
    with_holes = light_field_corners(
        CAMERA, holed.reshape(raw.shape), expected, pattern=PATTERN, square_size_m=square, view=VIEW
    )
    assert with_holes.ok.all()
    assert with_holes.samples[7] < whole.samples[7]
    np.testing.assert_array_equal(np.delete(with_holes.samples, 7), np.delete(whole.samples, 7))
    assert np.linalg.norm(with_holes.centre_px[7] - whole.centre_px[7]) < LF_CORNER_ANALYTIC_PX


def test_corners_without_contrast_are_flagged():
    pose, square = _board(PORT, 0.3, (0.0, 0.0, 0.0), px_per_square=12.0)
    start = project_through_port(VIEW, PORT, _corners_world(pose, square))
    flat = np.full((CAMERA.sensor.height_px, CAMERA.sensor.width_px), 0.5)
    tracks = light_field_corners(CAMERA, flat, start, pattern=PATTERN, square_size_m=square, view=VIEW)
    assert not tracks.ok.any()


def test_bad_input_is_rejected_with_the_parameter_named():
    raw = np.zeros((CAMERA.sensor.height_px, CAMERA.sensor.width_px))
    corners = np.zeros((24, 2))
    with pytest.raises(ParameterError, match="corners_px"):
        light_field_corners(CAMERA, raw, corners[:20], pattern=PATTERN, square_size_m=0.01, view=VIEW)
    with pytest.raises(ParameterError, match="window_squares"):
        light_field_corners(CAMERA, raw, corners, pattern=PATTERN, square_size_m=0.01, view=VIEW, window_squares=1.0)
    with pytest.raises(ParameterError, match="square_size_m"):
        light_field_corners(CAMERA, raw, corners, pattern=PATTERN, square_size_m=-1.0, view=VIEW)
    with pytest.raises(ParameterError, match="raw"):
        light_field_corners(CAMERA, raw[:10], corners, pattern=PATTERN, square_size_m=0.01, view=VIEW)


def test_a_board_view_leaves_unrecorded_pixels_out_of_the_central_view():
    """A board capture's NaN (unrecorded: what its white does not light) spoiled every micro-image
    sample whose bilinear footprint held one: on an Illum in-air board at the field's edge the
    central view lost the board's white border and the board was not found, though its light-field
    corners were all located. Here one pixel of every centre's footprint is NaN."""
    pose, square = _board(PORT, 0.3, (10.0, -5.0, 0.0), px_per_square=10.0)
    raw = _raw(PORT, pose, square, bounded=True)
    kwargs = {"pattern": PATTERN, "square_size_m": square, "view": VIEW}
    whole = board_view_from_light_field(CAMERA, raw, **kwargs)
    assert whole is not None
    assert np.count_nonzero(whole.central) == PATTERN[0] * PATTERN[1]
    centres = CAMERA.micro_image_centres_px(CAMERA.lens_indices_on_sensor())
    u, v = np.floor(centres).astype(int).T
    inside = (u >= 0) & (v >= 0) & (u < raw.shape[1]) & (v < raw.shape[0])
    holed = raw.copy()
    holed[v[inside], u[inside]] = np.nan
    found = board_view_from_light_field(CAMERA, holed, **kwargs)
    assert found is not None
    assert np.count_nonzero(found.central) == PATTERN[0] * PATTERN[1]
    moved = np.linalg.norm(found.corners_px[found.central] - whole.corners_px[whole.central], axis=1)
    assert np.max(moved) < LF_CORNER_ANALYTIC_PX


@pytest.mark.parametrize("cut", ["dark", "unrecorded"])
def test_a_board_the_view_cuts_gives_the_corners_it_shows(cut):
    """A board reaching past what the lens lights (a Petzval's image circle at tiny-2x cut 17 of
    20 calibration boards, which were all left out): its lattice of seen corners is located, each
    corner where the exact refracted projection puts it, at its place on the board up to a rigid
    motion of the board (which the pose absorbs)."""
    pose, square = _board(PORT, 0.3, (10.0, -5.0, 0.0), px_per_square=10.0)
    raw = _raw(PORT, pose, square, bounded=True)
    raw[:, int(0.55 * raw.shape[1]) :] = 0.0 if cut == "dark" else np.nan
    kwargs = {"pattern": PATTERN, "square_size_m": square, "view": VIEW}
    central = subaperture_view(CAMERA, raw, (0.0, 0.0), output=VIEW, recorded=finite_pixels(raw))
    assert detect_chessboard(central, PATTERN) is None  # the whole board is not seen
    found = board_view_from_light_field(CAMERA, raw, **kwargs)
    assert found is not None
    world = _corners_world(pose, square)
    expected = project_through_port(VIEW, PORT, world)
    seen = found.corners_px[found.central]
    distance = np.linalg.norm(seen[:, None] - expected[None], axis=2)
    nearest = distance.argmin(axis=1)
    assert len(set(nearest)) == len(seen) >= 9
    assert len(seen) < PATTERN[0] * PATTERN[1]
    assert np.sqrt(np.mean(distance.min(axis=1) ** 2)) < LF_CORNER_ANALYTIC_PX
    jj, ii = np.mgrid[0 : PATTERN[1], 0 : PATTERN[0]]
    local = np.stack([ii.ravel(), jj.ravel()], axis=1)[nearest] * square
    board = found.board_points_m[found.central]
    pairs = np.linalg.norm(board[:, None] - board[None], axis=2)
    np.testing.assert_allclose(pairs, np.linalg.norm(local[:, None] - local[None], axis=2), atol=1e-12)
