"""The pipeline with estimated parameters: the MLA calibrated from a white image, the port from
ten rendered chessboard captures (light-field corners), then synthesis.

Issue 4 asks that the refraction-free image's corner error with estimated parameters stay within
1.5 x the error with ground-truth parameters.
"""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import camera_preset
from lfrefract.calibration import calibrate_mla
from lfrefract.synthesis.warp_map import build_warp_map
from simulator import boards
from simulator.boards import DIRECTIONS, TILTED, chessboard_corners_world
from simulator.config import RenderSettings, embedded_scenes, load_scene
from simulator.job import render_raw
from tests.tolerances import ESTIMATED_OVER_TRUE_CORNER_RMS

pytestmark = pytest.mark.render

TILT = TILTED  # 26.8 deg in all
DIRECTION = DIRECTIONS[TILT]  # inside the exact coverage behind this port (test_synthesis_corners)


def test_synthesis_with_the_calibrated_mla_and_port_matches_ground_truth_parameters(mi, port_from_renders):
    camera = camera_preset(boards.CAMERA)
    white_scene = load_scene(embedded_scenes()["white"]).with_overrides(
        camera=camera, render=RenderSettings(spp=16, seed=3)
    )
    estimated = calibrate_mla(render_raw(mi, white_scene, progress=False)).calibrated_camera(camera)
    assert estimated != camera  # estimated, not copied: it differs in the last digits
    port = port_from_renders(TILT)  # shared with test_port_calibration_render
    assert port.calibration.port != port.truth
    truth_map = build_warp_map(camera, port.truth)
    estimated_map = build_warp_map(estimated, port.calibration.port, output=truth_map.output)
    for depth_m in (0.15, 0.6):
        config = boards.board_scene(TILT, boards.slanted_board(depth_m, DIRECTION, truth_map.output.focal_px))
        raw = render_raw(mi, config, progress=False)
        expected = truth_map.output.project(chessboard_corners_world(config.objects[0]))
        errors = []
        for warp in (truth_map, estimated_map):
            corners = boards.find_corners(warp.apply(raw))
            assert corners is not None
            errors.append(boards.corner_rms_px(corners, expected))
        assert errors[1] <= ESTIMATED_OVER_TRUE_CORNER_RMS * errors[0], (depth_m, errors)
        assert np.isfinite(errors).all()
