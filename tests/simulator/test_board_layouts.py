"""The calibration boards' layouts (simulator.boards): the outer ring stays in view.

The pipeline experiment calibrates the camera on in-air boards and the port on underwater boards of
both rings; a board whose corners leave the view cannot be located, so each board's inner corners are
checked to lie inside the refraction-free view it was laid out for, with a margin: through the port
from the main-lens centre for the port boards, straight for the in-air ones.
"""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import camera_preset, virtual_camera_for
from lfrefract.calibration.port import project_through_port
from lfrefract.optics.pinhole import PinholeCamera
from simulator import boards
from tests.tolerances import BOARD_CORNER_MARGIN_SQUARES

VIEW = virtual_camera_for(camera_preset(boards.CAMERA))
#: The Illum's refraction-free view (1078 x 748 px), where the boards are sized by the view's width.
ILLUM_VIEW = virtual_camera_for(camera_preset("illum"))
#: The pipeline's wall as the left camera of the default rig sees it (20 deg), and a steeper one.
TILTS_DEG = ((20.0, -3.0), (25.0, 10.0))


def _inside(uv: np.ndarray, view: PinholeCamera) -> bool:
    """All pixels (N, 2) at least the margin inside the view."""
    margin = BOARD_CORNER_MARGIN_SQUARES * boards.board_px_per_square(view)
    size = np.array([view.width_px - 1, view.height_px - 1])
    return bool(np.all(np.isfinite(uv)) and np.all(uv >= margin) and np.all(uv <= size - margin))


@pytest.mark.parametrize("view", [VIEW, ILLUM_VIEW], ids=["tiny-2x", "illum"])
@pytest.mark.parametrize("tilt_deg", TILTS_DEG)
def test_the_outer_ring_adds_ten_port_boards_after_the_inner_ten_all_in_view(tilt_deg, view):
    inner = boards.port_boards(tilt_deg, view)
    both = boards.port_boards(tilt_deg, view, outer_ring=True)
    assert len(inner) == 10
    assert len(both) == 20
    assert both[:10] == inner
    port = boards.empty_scene(tilt_deg).port
    seen = []  # each board's inner corners in the view, through the port
    for table in both:
        board = boards.board_scene(tilt_deg, table).objects[0]  # the table as the scene parser reads it
        seen.append(project_through_port(view, port, boards.chessboard_corners_world(board)))
        assert _inside(seen[-1], view), table
    # Each outer board is seen farther from the view's centre than its inner twin (but the one on the axis).
    centre = np.array([view.cx_px, view.cy_px])
    off_axis = [i for i, target in enumerate(boards.PORT_TARGETS) if target != (0.0, 0.0)]
    for i in off_axis:
        outer, inner_twin = seen[10 + i].mean(axis=0), seen[i].mean(axis=0)
        assert np.linalg.norm(outer - centre) > np.linalg.norm(inner_twin - centre) + 5.0, i


@pytest.mark.parametrize("view", [VIEW, ILLUM_VIEW], ids=["tiny-2x", "illum"])
def test_the_outer_ring_adds_ten_in_air_boards_in_view(view):
    inner = boards.in_air_boards(view)
    both = boards.in_air_boards(view, outer_ring=True)
    assert both[:10] == inner
    assert len(both) == 20
    for table in both:
        board = boards.in_air_board_scene(table).objects[0]
        assert _inside(view.project(boards.chessboard_corners_world(board)), view), table


@pytest.mark.parametrize("view", [VIEW, ILLUM_VIEW], ids=["tiny-2x", "illum"])
def test_the_boards_span_a_good_part_of_the_view(view):
    """On the Illum's view the boards' 14 px squares made each board 9 % of the view's width, a few
    degrees across: too small for a calibration to tell the focal length from the distance."""
    for table in boards.in_air_boards(view, outer_ring=True):
        board = boards.in_air_board_scene(table).objects[0]
        uv = view.project(boards.chessboard_corners_world(board))
        # Inner corners span 5 of the 7 squares' widths (less by the board's turn, at most 30 deg).
        assert np.ptp(uv[:, 0]) >= boards.BOARD_MIN_VIEW_FRACTION * view.width_px * 5 / 7 * np.cos(np.radians(35))
    assert boards.board_px_per_square(VIEW) == boards.PORT_PX_PER_SQUARE  # the tiny cameras' boards as before
