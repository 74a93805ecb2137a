"""Refraction-free synthesis geometry: chessboard corners at two depths behind a straight and a tilted port.

The synthesized image must be a central projection with the warp map's ``K`` at every depth, so
corners found in it land on the pinhole projections of the board's ground-truth 3D corners. The
conventional central view (no refraction handling), resampled onto the same ``K``, does not: the
port magnifies (0 deg) and also deflects (tilted) what it sees, so the same check misses by
several pixels there.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
import pytest

from lfrefract.synthesis import WarpMap, build_warp_map
from lfrefract.views import naive_view
from simulator import assets
from simulator.config import Chessboard, SceneConfig
from simulator.job import render_raw
from simulator.scene import check_geometry
from tests.simulator.scenes import chessboard_corners_world, scene
from tests.tolerances import NAIVE_CORNER_RMS_MIN_PX, SYNTH_CORNER_RMS_PX

pytestmark = pytest.mark.render

# The tiny preset with twice its focal length and sensor: the same 44 deg field, MLA and f-numbers,
# four times the microlenses (7655). Its refraction-free image (2 px per lens) is 188 x 141 px with
# f = 240 px, so a 7 x 5 board at 9 px per square fits inside the exact coverage behind a tilted
# port, which the larger aperture keeps wide (the tiny preset's image is 92 x 69 px, too small for
# a board the detector finds reliably).
CAMERA = {
    "name": "tiny-2x",
    "focal_length_m": 0.012,
    "lens_to_mla_m": 0.012,
    "f_number": 2.2,
    "mla": {"grid": "hex", "pitch_m": 100e-6, "focal_length_m": 200e-6, "rotation_rad": 0.0, "offset_m": [0.0, 0.0]},
    "sensor": {"width_px": 960, "height_px": 720, "pixel_pitch_m": 10e-6},
}

# Port tilts (tilt_x_deg, tilt_y_deg): straight, and 26.8 deg in all (like the reference port's
# 26.6 deg) about both axes. Each comes with the line of sight (x / z, y / z) of the board's centre,
# chosen to keep the board inside the exact coverage (at least 17 / 2 px from its edge) (the tilted port turns the
# covered field up and to the right).
TILTS = {(0.0, 0.0): (0.0, 0.0), (25.0, 10.0): (0.16, -0.125)}
DEPTHS_M = (0.15, 0.6)
SQUARES = (7, 5)
PX_PER_SQUARE = 9.0  # at the board's centre, in the refraction-free image
SLANT_XYZ_DEG = [-10.0, -15.0, 5.0]  # not fronto-parallel: its depth varies by +-6.6 % across it
# In the water, in front of the camera and off its axis, so that neither board is lit at grazing incidence.
LIGHTS = [
    {"type": "point", "position_m": [-0.08, -0.1, 0.05], "intensity_w_sr": 0.05},
    {"type": "point", "position_m": [0.1, 0.04, 0.05], "intensity_w_sr": 0.05},
]


def _port(tilt: tuple[float, float]) -> dict:
    """12 mm away, 4 mm of glass (as in test_synthesis_render), air / glass 1.5 / water 1.333."""
    return {
        "distance_m": 0.012,
        "thickness_m": 0.004,
        "tilt_x_deg": tilt[0],
        "tilt_y_deg": tilt[1],
        "n_air": 1.0,
        "n_glass": 1.5,
        "n_water": 1.333,
    }


def _scene(tilt: tuple[float, float], depth_m: float, focal_px: float) -> SceneConfig:
    direction = np.array([*TILTS[tilt], 1.0])
    board = {
        "type": "chessboard",
        "position_m": (depth_m * direction).tolist(),
        "rotation_xyz_deg": SLANT_XYZ_DEG,
        "squares": list(SQUARES),
        "square_size_m": PX_PER_SQUARE * depth_m / focal_px,
    }
    config = scene(port=_port(tilt), objects=[board], lights=LIGHTS, spp=16, seed=0, camera=CAMERA)
    check_geometry(config)
    return config


@functools.cache
def _warp_map(tilt: tuple[float, float]) -> WarpMap:
    config = scene(port=_port(tilt), objects=[], lights=LIGHTS, camera=CAMERA)
    return build_warp_map(config.camera, config.port)


def _board_points_world(board: Chessboard, n: int = 21) -> np.ndarray:
    """An n x n grid over the whole board, margin included (world frame)."""
    w, h = assets.chessboard_size_m(
        squares=board.squares, square_size_m=board.square_size_m, margin_squares=board.margin_squares
    )
    xx, yy = np.meshgrid(np.linspace(-w / 2, w / 2, n), np.linspace(-h / 2, h / 2, n))
    return board.placement.to_world(np.stack([xx.ravel(), yy.ravel(), np.zeros(n * n)], axis=1))


def _corners(image: np.ndarray) -> np.ndarray | None:
    """Inner corners (N, 2) that OpenCV's sector-based detector finds, or None."""
    grey = np.nan_to_num(image.mean(axis=2))  # the naive view is NaN outside the lenses' hull
    white = np.percentile(grey, 99)
    gray8 = (np.clip(grey / white, 0.0, 1.0) * 255).astype(np.uint8)
    pattern = (SQUARES[0] - 1, SQUARES[1] - 1)
    found, corners = cv2.findChessboardCornersSB(gray8, pattern, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if not found:
        return None
    # Refine on the saddle point within 7 x 7 px (less than a 9 px square): the sector-based
    # detector's own estimate leans towards the board's edge on blurred images (0.2 px RMS).
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    return cv2.cornerSubPix(gray8, corners, (3, 3), (-1, -1), criteria).reshape(-1, 2)


def _rms_px(found: np.ndarray, expected: np.ndarray) -> float:
    # The detector may report the grid from either end (7 x 5 squares look the same after a half turn).
    return min(float(np.sqrt(np.mean(np.sum((found - e) ** 2, axis=1)))) for e in (expected, expected[::-1]))


@pytest.mark.parametrize("depth_m", DEPTHS_M)
@pytest.mark.parametrize("tilt", list(TILTS), ids=lambda t: f"tilt{t[0]:g},{t[1]:g}")
def test_corners_in_synthesized_image_at_pinhole_projection(mi, tilt, depth_m):
    warp = _warp_map(tilt)
    K = warp.output
    config = _scene(tilt, depth_m, K.focal_px)
    board = config.objects[0]
    # The whole board lies inside the exact coverage: every pixel of it is synthesized from rays the
    # camera recorded, none from the stand-ins of the field-of-view limitation.
    uv = np.round(K.project(_board_points_world(board))).astype(int)
    assert np.all((uv >= 0) & (uv < [K.width_px, K.height_px]))
    assert np.all(warp.exact[uv[:, 1], uv[:, 0]])
    expected = K.project(chessboard_corners_world(board))

    raw = render_raw(mi, config, progress=False)
    synthesized = _corners(warp.apply(raw))
    assert synthesized is not None, "no chessboard found in the synthesized image"
    assert _rms_px(synthesized, expected) < SYNTH_CORNER_RMS_PX

    # The conventional central view on the same K: the board is found, in the wrong place.
    naive = _corners(naive_view(config.camera, raw, output=K))
    assert naive is not None, "no chessboard found in the naive view"
    assert _rms_px(naive, expected) > NAIVE_CORNER_RMS_MIN_PX
