"""A port calibration's advised view as a board in a scene (simulator.boards.advised_board_table).

The advice (lfrefract.calibration.advice.advise_port_views) gives each view to add as a pose in the
camera frame: the centre of the board's inner-corner grid and its turn, extrinsic rotations about x
then y of a board facing the camera. The measurement of the advice on renders
(benchmarks/measure_port_advice.py) renders a board there; its corners must be where the advice put
them, or the renders measure another view than the advised one.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lfrefract import FlatPort, ParameterError, camera_preset, virtual_camera_for
from lfrefract.calibration.advice import AdvisedView, advise_port_views
from lfrefract.calibration.port import BoardView, calibrate_port, project_through_port
from simulator import boards
from simulator.config import Chessboard, Placement
from tests.tolerances import FLOAT64_GEOMETRY_M

VIEW = virtual_camera_for(camera_preset(boards.CAMERA))
#: The pipeline's left camera's wall at the tiny scale, roughly (20 / 7 deg, 20 mm; 4 mm of glass).
PORT = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.004, tilt_x_deg=20.0, tilt_y_deg=7.0)
#: Projection through the port is solved by Gauss-Newton on the pixel (project_through_port), to
#: convergence: its pixels agree with the forward trace far below a thousandth of a pixel.
PROJECTION_PX = 1e-6


def _chessboard(table: dict) -> Chessboard:
    placement = Placement(position_m=tuple(table["position_m"]), rotation_xyz_deg=tuple(table["rotation_xyz_deg"]))
    return Chessboard(placement=placement, squares=tuple(table["squares"]), square_size_m=table["square_size_m"])


def _grid(square_m: float) -> np.ndarray:
    """The inner-corner grid as the calibration's board views hold it: centred, row by row, x fastest."""
    cols, rows = boards.PATTERN
    jj, ii = np.mgrid[0:rows, 0:cols]
    return np.stack([ii.ravel() - (cols - 1) / 2, jj.ravel() - (rows - 1) / 2], axis=1) * square_m


def _advised_corners(advised: AdvisedView, square_m: float) -> np.ndarray:
    """The inner corners (N, 3) of the advice's board: its grid turned about x then y (extrinsic) from
    facing the camera, at the advised centre; camera frame, metres."""
    turn = Rotation.from_euler("xy", advised.turn_deg, degrees=True)
    grid = _grid(square_m)
    return turn.apply(np.column_stack([grid, np.zeros(len(grid))])) + advised.centre_m


def test_an_advised_view_placed_as_a_board_has_its_corners_where_the_advice_put_them():
    # Four of the pipeline's port boards with 0.02 px of corner noise (their renders' residual): a calibration
    # whose advice names views.
    rng = np.random.default_rng(0)
    tables = boards.port_boards(PORT, VIEW)[:4]
    views = []
    for table in tables:
        uv = project_through_port(VIEW, PORT, boards.chessboard_corners_world(_chessboard(table)))
        views.append(
            BoardView(
                corners_px=uv + rng.normal(scale=0.02, size=uv.shape), board_points_m=_grid(table["square_size_m"])
            )
        )
    calibration = calibrate_port(VIEW, views, thickness_m=PORT.thickness_m, max_normal_std_deg=90.0)
    advice = advise_port_views(VIEW, calibration, views, target_normal_std_deg=0.01, count=2)
    assert len(advice.views) == 2
    square = tables[0]["square_size_m"]
    for advised in advice.views:
        corners = boards.chessboard_corners_world(_chessboard(boards.advised_board_table(advised, square)))
        np.testing.assert_allclose(corners, _advised_corners(advised, square), rtol=0.0, atol=FLOAT64_GEOMETRY_M)
        # Seen through the calibrated port, its centre is where the advice says and it is in view.
        centre_px = project_through_port(VIEW, calibration.port, corners.mean(axis=0, keepdims=True))[0]
        np.testing.assert_allclose(centre_px, advised.image_px, rtol=0.0, atol=PROJECTION_PX)
        uv = project_through_port(VIEW, calibration.port, corners)
        assert np.all((uv >= 0.0) & (uv <= [VIEW.width_px - 1, VIEW.height_px - 1]))
    # Turned about both axes, the order of the turns counts (about y then x would move the corners by
    # centimetres here).
    both = dataclasses.replace(advice.views[0], turn_deg=(-30.0, 30.0))
    corners = boards.chessboard_corners_world(_chessboard(boards.advised_board_table(both, square)))
    np.testing.assert_allclose(corners, _advised_corners(both, square), rtol=0.0, atol=FLOAT64_GEOMETRY_M)
    swapped = Rotation.from_euler("yx", both.turn_deg[::-1], degrees=True)
    assert np.abs(swapped.apply(np.c_[_grid(square), np.zeros(len(corners))]) + both.centre_m - corners).max() > 1e-4


def test_an_advised_board_needs_an_advised_view():
    with pytest.raises(ParameterError, match="view must be an AdvisedView"):
        boards.advised_board_table({"centre_m": [0.0, 0.0, 0.3]}, 0.01)  # type: ignore[arg-type]
