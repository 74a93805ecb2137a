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
from simulator import boards
from tests.tolerances import BOARD_CORNER_MARGIN_SQUARES

VIEW = virtual_camera_for(camera_preset(boards.CAMERA))
#: The pipeline's wall as the left camera of the default rig sees it (20 deg), and a steeper one.
TILTS_DEG = ((20.0, -3.0), (25.0, 10.0))


def _inside(uv: np.ndarray) -> bool:
    """All pixels (N, 2) at least the margin inside the view."""
    margin = BOARD_CORNER_MARGIN_SQUARES * boards.PORT_PX_PER_SQUARE
    size = np.array([VIEW.width_px - 1, VIEW.height_px - 1])
    return bool(np.all(np.isfinite(uv)) and np.all(uv >= margin) and np.all(uv <= size - margin))


@pytest.mark.parametrize("tilt_deg", TILTS_DEG)
def test_the_outer_ring_adds_ten_port_boards_after_the_inner_ten_all_in_view(tilt_deg):
    inner = boards.port_boards(tilt_deg, VIEW)
    both = boards.port_boards(tilt_deg, VIEW, outer_ring=True)
    assert len(inner) == 10
    assert len(both) == 20
    assert both[:10] == inner
    port = boards.empty_scene(tilt_deg).port
    seen = []  # each board's inner corners in the view, through the port
    for table in both:
        board = boards.board_scene(tilt_deg, table).objects[0]  # the table as the scene parser reads it
        seen.append(project_through_port(VIEW, port, boards.chessboard_corners_world(board)))
        assert _inside(seen[-1]), table
    # Each outer board is seen farther from the view's centre than its inner twin (but the one on the axis).
    centre = np.array([VIEW.cx_px, VIEW.cy_px])
    off_axis = [i for i, target in enumerate(boards.PORT_TARGETS) if target != (0.0, 0.0)]
    for i in off_axis:
        outer, inner_twin = seen[10 + i].mean(axis=0), seen[i].mean(axis=0)
        assert np.linalg.norm(outer - centre) > np.linalg.norm(inner_twin - centre) + 5.0, i


def test_the_outer_ring_adds_ten_in_air_boards_in_view():
    inner = boards.in_air_boards(VIEW)
    both = boards.in_air_boards(VIEW, outer_ring=True)
    assert both[:10] == inner
    assert len(both) == 20
    for table in both:
        board = boards.in_air_board_scene(table).objects[0]
        assert _inside(VIEW.project(boards.chessboard_corners_world(board))), table
