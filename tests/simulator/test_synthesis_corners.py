"""Refraction-free synthesis geometry: chessboard corners at two depths behind a straight and a tilted port.

The synthesized image must be a central projection with the warp map's ``K`` at every depth, so
corners found in it land on the pinhole projections of the board's ground-truth 3D corners. The
conventional central view (no refraction handling), resampled onto the same ``K``, does not: the
port magnifies (0 deg) and also deflects (tilted) what it sees, so the same check misses by
several pixels there.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from lfrefract.synthesis.views import naive_view
from lfrefract.synthesis.warp_map import PAPER_K, SynthesisOptions, WarpMap, build_warp_map
from simulator import boards
from simulator.boards import chessboard_corners_world
from simulator.config import SceneConfig
from simulator.job import render_raw
from tests.tolerances import NAIVE_CORNER_RMS_MIN_PX, SYNTH_CORNER_RMS_PX

pytestmark = pytest.mark.render

# The camera (tiny-2x: the tiny preset with twice its focal length and sensor, 188 x 141 px
# refraction-free image with f = 240 px), the 7 x 5 board at 9 px per square and the port (12 mm
# away, 4 mm glass) come from simulator/boards.py, shared with test_approx_baseline:
# the board fits inside the exact coverage behind a tilted port, which the larger aperture keeps
# wide (the tiny preset's image is 92 x 69 px, too small for a board the detector finds reliably).

# Port tilts (tilt_x_deg, tilt_y_deg): straight, and 26.8 deg in all (like the reference port's
# 26.6 deg) about both axes. Each comes with the line of sight (x / z, y / z) of the board's centre,
# chosen to keep the board inside the exact coverage (at least 17 / 2 px from its edge) (the tilted port turns the
# covered field up and to the right).
TILTS = {(0.0, 0.0): (0.0, 0.0), (25.0, 10.0): (0.16, -0.125)}
DEPTHS_M = (0.15, 0.6)


def _scene(tilt: tuple[float, float], depth_m: float, focal_px: float) -> SceneConfig:
    return boards.board_scene(tilt, boards.slanted_board(depth_m, TILTS[tilt], focal_px))


@functools.cache
def _warp_map(tilt: tuple[float, float]) -> WarpMap:
    config = boards.empty_scene(tilt)
    # The paper's k, at which the tolerances were measured (the default is 8).
    return build_warp_map(config.camera, config.port, options=SynthesisOptions(k=PAPER_K))


@pytest.mark.parametrize("depth_m", DEPTHS_M)
@pytest.mark.parametrize("tilt", list(TILTS), ids=lambda t: f"tilt{t[0]:g},{t[1]:g}")
def test_corners_in_synthesized_image_at_pinhole_projection(mi, tilt, depth_m):
    warp = _warp_map(tilt)
    K = warp.output
    config = _scene(tilt, depth_m, K.focal_px)
    board = config.objects[0]
    # The whole board lies inside the exact coverage: every pixel of it is synthesized from rays the
    # camera recorded, none from the stand-ins of the field-of-view limitation.
    uv = np.round(K.project(boards.board_points_world(board))).astype(int)
    assert np.all((uv >= 0) & (uv < [K.width_px, K.height_px]))
    assert np.all(warp.exact[uv[:, 1], uv[:, 0]])
    expected = K.project(chessboard_corners_world(board))

    raw = render_raw(mi, config, progress=False)
    synthesized = boards.find_corners(warp.apply(raw))
    assert synthesized is not None, "no chessboard found in the synthesized image"
    assert boards.corner_rms_px(synthesized, expected) < SYNTH_CORNER_RMS_PX

    # The conventional central view on the same K: the board is found, in the wrong place.
    naive = boards.find_corners(naive_view(config.camera, raw, output=K))
    assert naive is not None, "no chessboard found in the naive view"
    assert boards.corner_rms_px(naive, expected) > NAIVE_CORNER_RMS_MIN_PX
