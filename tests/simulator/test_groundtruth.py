"""Ground truth: depth maps against analytic planes, chessboard corners in the ideal image."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from lfrefract import PinholeCamera, Pose
from simulator import assets, groundtruth
from simulator.boards import chessboard_corners_world
from simulator.scene import build_scene
from tests.simulator.scenes import port, scene
from tests.tolerances import DEPTH_FLOAT32_RELATIVE, IDEAL_CHESSBOARD_RMS_PX

pytestmark = pytest.mark.render

BIG = PinholeCamera(focal_px=520.0, cx_px=199.5, cy_px=149.5, width_px=400, height_px=300)


def test_depth_of_slanted_plane_matches_plane_equation(mi):
    rotation = (20.0, -25.0, 0.0)
    plane = {
        "type": "textured_plane",
        "position_m": [0.02, -0.01, 0.5],
        "rotation_xyz_deg": list(rotation),
        "size_m": [3.0, 3.0],
        "texture_px": 64,
    }
    config = scene(port=port(20.0), objects=[plane])
    depth = groundtruth.depth_map(mi, build_scene(mi, config, port_geometry=False), BIG, Pose())
    obj = config.objects[0]
    normal = obj.placement.matrix[:3, 2]
    centre = np.asarray(obj.placement.position_m)
    d = BIG.pixel_directions()
    expected_z = (normal @ centre) / (d @ normal) * d[:, 2]
    assert np.all(np.isfinite(depth))
    np.testing.assert_allclose(depth.ravel(), expected_z, rtol=DEPTH_FLOAT32_RELATIVE)


def test_depth_is_inf_where_nothing_is_hit(mi):
    small = {"type": "disc", "position_m": [0.0, 0.0, 0.3], "radius_m": 0.01}
    config = scene(port=None, objects=[small])
    depth = groundtruth.depth_map(mi, build_scene(mi, config, port_geometry=False), BIG, Pose())
    assert np.isinf(depth[0, 0])
    assert depth[0, 0] > 0
    assert depth[150, 200] == pytest.approx(0.3, rel=DEPTH_FLOAT32_RELATIVE)


def test_chessboard_corners_in_ideal_image_at_pinhole_projection(mi):
    """Pins texture orientation, object placement, K and the pixel-centre convention at once."""
    board = {
        "type": "chessboard",
        "position_m": [0.01, 0.005, 0.45],
        "rotation_xyz_deg": [15.0, -20.0, 5.0],
        "squares": [8, 6],
        "square_size_m": 0.025,
    }
    config = scene(port=port(25.0), objects=[board])
    truth = groundtruth.compute(
        mi, build_scene(mi, config, port_geometry=False), config, BIG, spp=64, seed=0, progress=False
    )
    gray = (np.clip(truth.ideal.mean(axis=2) / truth.ideal.max(), 0, 1) * 255).astype(np.uint8)
    found, corners = cv2.findChessboardCorners(gray, (7, 5))
    assert found
    corners = cv2.cornerSubPix(
        gray, corners, (5, 5), (-1, -1), (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    ).reshape(-1, 2)
    obj = config.objects[0]
    expected = BIG.project(chessboard_corners_world(obj))
    # OpenCV may report the grid from either end; compare with the matching order.
    rms = min(np.sqrt(np.mean(np.sum((corners - e) ** 2, axis=1))) for e in (expected, expected[::-1]))
    assert rms < IDEAL_CHESSBOARD_RMS_PX
    # The grid alone is symmetric under a half turn; the squares' colours are not: the top-left
    # square (column 0, row 0 inside the margin) is black, its right neighbour white.
    w, h = assets.chessboard_size_m(squares=(8, 6), square_size_m=0.025, margin_squares=obj.margin_squares)
    margin = obj.margin_squares * 0.025
    centres_local = np.array(
        [
            [-w / 2 + margin + 0.0125, -h / 2 + margin + 0.0125, 0.0],
            [-w / 2 + margin + 0.0375, -h / 2 + margin + 0.0125, 0.0],
        ]
    )
    u, v = np.round(BIG.project(obj.placement.to_world(centres_local))).astype(int).T
    black, white = gray[v[0], u[0]], gray[v[1], u[1]]
    assert black < 0.3 * white


def test_lens_table_lists_every_micro_image_on_the_sensor(tiny):
    table = groundtruth.lens_table(tiny)
    centres = table["micro_image_centre_px"]
    assert len(centres) == len(table["lens_index"]) == len(table["lens_centre_m"])
    assert centres[:, 0].min() >= -0.5
    assert centres[:, 0].max() <= tiny.sensor.width_px - 0.5
    assert centres[:, 1].min() >= -0.5
    assert centres[:, 1].max() <= tiny.sensor.height_px - 0.5
    # Every pixel's own lens (well inside the sensor) is in the table.
    uv = np.stack(np.meshgrid(np.arange(20, 460, 7), np.arange(20, 340, 7)), axis=-1).reshape(-1, 2)
    own = {tuple(i) for i in tiny.lens_indices_for_pixels(uv)}
    assert own <= {tuple(i) for i in table["lens_index"]}


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_user_mesh_is_placed_and_scaled(mi, tmp_path, suffix):
    """A user mesh file (a 2 x 2 square, scaled to 0.2 m and placed at z = 0.4 m) lands in the depth map."""
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    path = tmp_path / f"square{suffix}"
    if suffix == ".ply":
        assets.write_ply(path, vertices, faces)
    else:
        lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
        path.write_text("\n".join(lines) + "\n")
    mesh = {"type": "mesh", "path": path.name, "position_m": [0.05, 0.0, 0.4], "scale": 0.1}
    config = scene(port=None, objects=[mesh], base_dir=tmp_path)
    depth = groundtruth.depth_map(mi, build_scene(mi, config, port_geometry=False), BIG, Pose())
    hit = np.isfinite(depth)
    np.testing.assert_allclose(depth[hit], 0.4, rtol=DEPTH_FLOAT32_RELATIVE)
    # The square spans x in [-0.05, 0.15] m at z = 0.4 m: its image columns follow from K.
    cols = np.flatnonzero(hit.any(axis=0))
    expected = BIG.project(np.array([[-0.05, 0.0, 0.4], [0.15, 0.0, 0.4]]))[:, 0]
    assert abs(cols.min() - expected[0]) <= 1
    assert abs(cols.max() - expected[1]) <= 1


def test_lens_table_of_a_real_lens_holds_every_lens_whose_own_micro_image_is_on_the_sensor():
    """With the double Gauss on the Illum the micro-images lie nearer the axis than the thin lens's
    (about its exit pupil): the table chose by the thin lens's and left 432 edge lenses out."""
    from lfrefract.optics.presets import camera_preset
    from lfrefract.optics.real_lens import RealLensCamera
    from simulator.groundtruth import lens_table

    camera = camera_preset("illum")
    real = RealLensCamera.from_preset(camera, "double-gauss")
    table = lens_table(camera, real.lens)
    # Every candidate of a generous superset (a 10 % smaller scale reaches further out) whose real
    # micro-image centre lies within the outermost pixel centres.
    candidates = camera.lens_indices_on_sensor(micro_image_scale=0.9 * real.micro_image_scale)
    px = real.micro_image_centres_px(candidates)
    width, height = camera.sensor.width_px, camera.sensor.height_px
    inside = (px[:, 0] >= 0) & (px[:, 0] <= width - 1) & (px[:, 1] >= 0) & (px[:, 1] <= height - 1)
    assert {tuple(i) for i in table["lens_index"]} == {tuple(i) for i in candidates[inside]}
    assert np.array_equal(table["micro_image_centre_px"], real.micro_image_centres_px(table["lens_index"]))
