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

from lfrefract import virtual_camera_for
from lfrefract.methods import CalibrationViews, build_projector
from simulator.job import render_raw
from tests.simulator import chessboards as cb
from tests.simulator.scenes import chessboard_corners_world
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
STRAIGHT, TILTED = (0.0, 0.0), (25.0, 10.0)  # (tilt_x_deg, tilt_y_deg): 0 and 26.8 deg in all
# The test board's line of sight (x / z, y / z): off the axis (the approximation's radial error
# grows with the distance from the image centre) and inside the synthesis's exact coverage, which
# the tilted port turns up and to the right.
DIRECTIONS = {STRAIGHT: (0.1, -0.06), TILTED: (0.16, -0.125)}
FAR_OVER_NEAR_MIN = {STRAIGHT: APPROX_FAR_OVER_NEAR_STRAIGHT_MIN, TILTED: APPROX_FAR_OVER_NEAR_TILTED_MIN}


@functools.cache
def _errors(mi, tilt: tuple[float, float]) -> dict[tuple[str, float], float]:
    """Corner RMS (px) of each method at the near and far test depths behind the port of ``tilt``."""
    camera = cb.empty_scene(tilt).camera
    boards = cb.calibration_boards(tilt, CALIBRATION_DEPTH_M, virtual_camera_for(camera))
    configs = [cb.board_scene(tilt, table) for table in boards]
    views = CalibrationViews(
        raws=[render_raw(mi, c, progress=False) for c in configs],
        pattern=cb.PATTERN,
        square_size_m=boards[0]["square_size_m"],
        corners_cam=[chessboard_corners_world(c.objects[0]) for c in configs],
    )
    port = configs[0].port
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
        config = cb.board_scene(tilt, cb.slanted_board(depth_m, DIRECTIONS[tilt], proposed.output.focal_px))
        raw = render_raw(mi, config, progress=False)
        ground_truth = chessboard_corners_world(config.objects[0])
        for name, projector in projectors.items():
            # Every method's image is a central projection from the main-lens centre with its K.
            assert projector.output == proposed.output
            found = cb.find_corners(projector.apply(raw))
            assert found is not None, f"{name}: no chessboard found at {depth_m} m behind a {tilt} deg port"
            errors[name, depth_m] = cb.corner_rms_px(found, projector.output.project(ground_truth))
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
