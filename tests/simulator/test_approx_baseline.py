"""The approximation baseline (paper section 3.1) against the proposed synthesis, on rendered chessboards.

A pinhole plus radial-tangential distortion calibrated from underwater board views at one depth
(0.2 m) undistorts the conventional image (the central view) well near that depth, and worse far
from it (0.6 m), the more so behind a tilted port; the refraction-free synthesis stays sub-pixel
at both depths. The error measured is the RMS distance between the corners found in a method's
image and the projections, with that image's ``K`` from the main-lens centre, of the board's
ground-truth 3D corners. The calibration is given the calibration boards' 3D corners, so its
pinhole sits at the camera centre in the camera's orientation (``corners_cam``): what is left is
the approximation's own error, not the calibration's frame ambiguity.
"""

from __future__ import annotations

import functools

import pytest

from lfrefract.methods import build_projector
from simulator import boards
from simulator.boards import DIRECTIONS, STRAIGHT, TILTED, chessboard_corners_world
from simulator.job import render_raw
from tests.tolerances import (
    APPROX_FAR_OVER_NEAR_STRAIGHT_MIN,
    APPROX_FAR_OVER_NEAR_TILTED_MIN,
    APPROX_NEAR_RMS_PX,
    APPROX_TILTED_OVER_STRAIGHT_FAR_MIN,
    SYNTH_CORNER_RMS_PX,
)

pytestmark = pytest.mark.render

CALIBRATION_DEPTH_M = 0.2
NEAR_M, FAR_M = CALIBRATION_DEPTH_M, 0.6
# The port tilts STRAIGHT and TILTED (0 and 26.8 deg in all) and the test board's line of sight
# behind each, DIRECTIONS, come from simulator/boards.py (shared with benchmarks/bench_approx.py).
FAR_OVER_NEAR_MIN = {STRAIGHT: APPROX_FAR_OVER_NEAR_STRAIGHT_MIN, TILTED: APPROX_FAR_OVER_NEAR_TILTED_MIN}


@functools.cache
def _errors(mi, tilt: tuple[float, float]) -> dict[tuple[str, float], float]:
    """Corner RMS (px) of each method at the near and far test depths behind the port of ``tilt``."""
    config = boards.empty_scene(tilt)
    camera, port = config.camera, config.port
    views = boards.calibration_views(mi, tilt, CALIBRATION_DEPTH_M)
    proposed = build_projector("proposed", camera, port)
    projectors = {
        "approx": build_projector("approx", camera, port, calibration=views),
        "proposed": proposed,
        "proposed+distortion": build_projector(
            "proposed+distortion", camera, port, calibration=views, warp=proposed.warp
        ),
    }
    errors = {}
    for depth_m in (NEAR_M, FAR_M):
        config = boards.board_scene(tilt, boards.slanted_board(depth_m, DIRECTIONS[tilt], proposed.output.focal_px))
        raw = render_raw(mi, config, progress=False)
        ground_truth = chessboard_corners_world(config.objects[0])
        for name, projector in projectors.items():
            # Every method's image is a central projection from the main-lens centre with its K.
            assert projector.output == proposed.output
            found = boards.find_corners(projector.apply(raw))
            assert found is not None, f"{name}: no chessboard found at {depth_m} m behind a {tilt} deg port"
            errors[name, depth_m] = boards.corner_rms_px(found, projector.output.project(ground_truth))
    return errors


@pytest.mark.parametrize("tilt", [STRAIGHT, TILTED], ids=["tilt0", "tilt26.8"])
def test_approx_is_good_near_its_calibration_depth_and_worse_far_from_it(mi, tilt):
    errors = _errors(mi, tilt)
    assert errors["approx", NEAR_M] < APPROX_NEAR_RMS_PX
    assert errors["approx", FAR_M] >= FAR_OVER_NEAR_MIN[tilt] * errors["approx", NEAR_M]


def test_tilted_port_makes_approx_worse(mi):
    straight, tilted = _errors(mi, STRAIGHT), _errors(mi, TILTED)
    assert tilted["approx", FAR_M] >= APPROX_TILTED_OVER_STRAIGHT_FAR_MIN * straight["approx", FAR_M]


@pytest.mark.parametrize("method", ["proposed", "proposed+distortion"])
@pytest.mark.parametrize("tilt", [STRAIGHT, TILTED], ids=["tilt0", "tilt26.8"])
def test_proposed_stays_subpixel_at_both_depths(mi, tilt, method):
    errors = _errors(mi, tilt)
    assert errors[method, NEAR_M] < SYNTH_CORNER_RMS_PX
    assert errors[method, FAR_M] < SYNTH_CORNER_RMS_PX
