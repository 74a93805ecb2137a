"""The scene's geometry in numpy (simulator.geometry): every object type registers its own shape,
the checks use it, and none of it needs Mitsuba."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from lfrefract import ParameterError
from simulator import assets, geometry
from simulator.config import OBJECT_TYPES, Bowl, Chessboard, Disc, Figurine, Placement, TexturedPlane
from tests.simulator.scenes import port, scene

PLACE = Placement(position_m=(0.01, -0.02, 0.4), rotation_xyz_deg=(10.0, -20.0, 5.0))


def test_every_object_type_registers_its_sample_points():
    registered = set(geometry.local_sample_points.registry) - {object}
    assert registered == set(OBJECT_TYPES.values())


def test_a_type_without_geometry_is_named():
    class Cone:
        placement = PLACE

    with pytest.raises(TypeError, match=r"local_sample_points: no geometry registered for scene object type Cone"):
        geometry.object_sample_points(Cone())
    with pytest.raises(TypeError, match=r"plane_size_m: no geometry registered .* Disc"):
        geometry.plane_size_m(Disc(placement=PLACE, radius_m=0.05))


def test_plane_sample_points_are_the_placed_corners():
    plane = TexturedPlane(placement=PLACE, size_m=(0.3, 0.2))
    expected = PLACE.to_world(np.array([[-0.15, -0.1, 0.0], [0.15, -0.1, 0.0], [0.15, 0.1, 0.0], [-0.15, 0.1, 0.0]]))
    np.testing.assert_allclose(geometry.object_sample_points(plane), expected, rtol=0, atol=1e-15)


def test_a_chessboard_carries_its_size_checked_once():
    board = Chessboard(placement=PLACE, squares=(8, 6), square_size_m=0.025, margin_squares=1.5)
    size = assets.chessboard_size_m(squares=(8, 6), square_size_m=0.025, margin_squares=1.5)
    assert board.board_size_m == size == geometry.plane_size_m(board)
    assert (board.board_size_m[0], board.board_size_m[1]) == pytest.approx((0.275, 0.225), rel=1e-15)


def test_disc_outline_lies_on_its_rim():
    disc = Disc(placement=PLACE, radius_m=0.05)
    points = geometry.object_sample_points(disc)
    assert points.shape == (geometry.DISC_OUTLINE_POINTS, 3)
    local = (points - PLACE.position_m) @ PLACE.matrix[:3, :3]
    np.testing.assert_allclose(np.hypot(local[:, 0], local[:, 1]), 0.05, rtol=1e-12)
    np.testing.assert_allclose(local[:, 2], 0.0, atol=1e-15)


@pytest.mark.parametrize(
    "obj",
    [
        Bowl(placement=PLACE, radius_m=0.05, depth_m=0.03, texture_seed=3),
        Figurine(placement=PLACE, height_m=0.08, seed=2, texture_seed=4),
    ],
)
def test_procedural_meshes_are_cached_read_only_and_placed(obj):
    v = geometry.local_mesh(obj)[0]
    assert geometry.local_mesh(obj)[0] is v  # cached: the sweep's checks do not rebuild it
    assert not v.flags.writeable
    world_v, _, world_n = geometry.world_mesh(obj)
    np.testing.assert_allclose(world_v, PLACE.to_world(v), rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(world_n, axis=1), 1.0, rtol=1e-6)
    uv = geometry.wrapped_texcoords(obj)
    assert uv.shape == (len(v), 2)
    assert uv[:, 0].min() >= 0.0
    assert uv[:, 0].max() <= 1.0
    assert uv[:, 1].min() == 0.0


def test_check_geometry_names_an_object_on_the_camera_side():
    config = scene(port=port(), objects=[{"type": "disc", "position_m": [0.0, 0.0, 0.015], "radius_m": 0.01}])
    with pytest.raises(ParameterError, match=r"object\[0\] \(disc\) reaches the camera side of the port"):
        geometry.check_geometry(config)
    ok = scene(port=port(), objects=[{"type": "disc", "position_m": [0.0, 0.0, 0.3], "radius_m": 0.01}])
    assert geometry.check_geometry(ok)["port_clearance_m"] > 0.0


def test_geometry_needs_no_mitsuba():
    code = (
        "import sys, simulator.geometry\n"
        "print(','.join(sorted(m for m in sys.modules if m.split('.')[0] in ('mitsuba', 'drjit'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_a_chessboards_squares_have_one_check_and_one_message():
    # The scene's check and the asset generators' were two, with two messages for one mistake.
    message = r"squares must be \(columns, rows\), a list of 2 integers, got 8"
    with pytest.raises(ParameterError, match=message):
        Chessboard(placement=PLACE, squares=8, square_size_m=0.02)
    for func in (assets.chessboard_size_m, assets.chessboard_inner_corners):
        with pytest.raises(ParameterError, match=message):
            func(squares=8, square_size_m=0.02)
    with pytest.raises(ParameterError, match=message):
        assets.chessboard_texture(squares=8, texels_per_square=4)


def test_a_chessboard_builds_its_texture_and_corners_from_its_checked_layout():
    board = Chessboard(placement=PLACE, squares=(5, 4), square_size_m=0.02, margin_squares=0.5, texels_per_square=8)
    assert board.layout == assets.ChessboardLayout(squares=(5, 4), margin_squares=0.5)
    np.testing.assert_array_equal(
        board.texture(), assets.chessboard_texture(squares=(5, 4), texels_per_square=8, margin_squares=0.5)
    )
    np.testing.assert_array_equal(
        board.inner_corners_local_m(),
        assets.chessboard_inner_corners(squares=(5, 4), square_size_m=0.02, margin_squares=0.5),
    )


def test_every_object_type_registers_a_mitsuba_shape_and_a_mesh_where_it_has_one():
    from simulator import scene

    assert set(scene._shape.registry) - {object} == set(OBJECT_TYPES.values())
    assert set(geometry.local_mesh.registry) - {object} == {Bowl, Figurine}
    assert set(geometry.texture_wrap.registry) - {object} == {Bowl, Figurine}
    assert set(geometry.plane_size_m.registry) - {object} == {TexturedPlane, Chessboard}
