"""Underwater chessboard scenes for the corner tests (synthesis geometry, approximation baseline).

The tiny preset's refraction-free image (92 x 69 px) is too small for a board the detector finds
reliably, so these tests use :data:`CAMERA`, the tiny preset with twice its focal length and
sensor: the same 44 deg field, MLA and f-numbers, four times the microlenses (7655). Its
refraction-free image (2 px per lens) is 188 x 141 px with f = 240 px.
"""

from __future__ import annotations

import numpy as np

from lfrefract.calibration.approx import detect_chessboard
from lfrefract.pinhole import PinholeCamera
from simulator import assets
from simulator.config import Chessboard, SceneConfig
from simulator.scene import check_geometry
from tests.simulator.scenes import scene

CAMERA = {
    "name": "tiny-2x",
    "focal_length_m": 0.012,
    "lens_to_mla_m": 0.012,
    "f_number": 2.2,
    "mla": {"grid": "hex", "pitch_m": 100e-6, "focal_length_m": 200e-6, "rotation_rad": 0.0, "offset_m": [0.0, 0.0]},
    "sensor": {"width_px": 960, "height_px": 720, "pixel_pitch_m": 10e-6},
}

#: Squares (columns, rows) of the test board; its detector pattern is one less each way.
SQUARES = (7, 5)
PATTERN = (SQUARES[0] - 1, SQUARES[1] - 1)

# In the water, in front of the camera and off its axis, so that no board is lit at grazing incidence.
LIGHTS = [
    {"type": "point", "position_m": [-0.08, -0.1, 0.05], "intensity_w_sr": 0.05},
    {"type": "point", "position_m": [0.1, 0.04, 0.05], "intensity_w_sr": 0.05},
]


def port(tilt: tuple[float, float]) -> dict:
    """A port table with tilt ``(tilt_x_deg, tilt_y_deg)``: 12 mm away, 4 mm of glass (as in
    test_synthesis_render), air / glass 1.5 / water 1.333."""
    return {
        "distance_m": 0.012,
        "thickness_m": 0.004,
        "tilt_x_deg": tilt[0],
        "tilt_y_deg": tilt[1],
        "n_air": 1.0,
        "n_glass": 1.5,
        "n_water": 1.333,
    }


def board(position_m, rotation_xyz_deg, square_size_m: float) -> dict:
    """A :data:`SQUARES` chessboard object table."""
    return {
        "type": "chessboard",
        "position_m": [float(x) for x in position_m],
        "rotation_xyz_deg": [float(a) for a in rotation_xyz_deg],
        "squares": list(SQUARES),
        "square_size_m": float(square_size_m),
    }


def board_scene(tilt: tuple[float, float], board_table: dict, *, spp: int = 16, seed: int = 0) -> SceneConfig:
    """One board behind the port of ``tilt``, seen by :data:`CAMERA` (checked geometry)."""
    config = scene(port=port(tilt), objects=[board_table], lights=LIGHTS, spp=spp, seed=seed, camera=CAMERA)
    check_geometry(config)
    return config


def empty_scene(tilt: tuple[float, float]) -> SceneConfig:
    """Camera and port only (for warp maps)."""
    return scene(port=port(tilt), objects=[], lights=LIGHTS, camera=CAMERA)


# Test boards: slanted, not fronto-parallel (their depth varies by +-6.6 % across them), at
# PX_PER_SQUARE pixels per square at the board's centre in the refraction-free image.
SLANT_XYZ_DEG = (-10.0, -15.0, 5.0)
PX_PER_SQUARE = 9.0


def slanted_board(depth_m: float, direction: tuple[float, float], focal_px: float) -> dict:
    """A slanted test board centred on the line of sight ``(x / z, y / z) = direction`` at ``depth_m``,
    with :data:`PX_PER_SQUARE` pixels per square in a pinhole image of ``focal_px``."""
    position = depth_m * np.array([*direction, 1.0])
    return board(position, SLANT_XYZ_DEG, PX_PER_SQUARE * depth_m / focal_px)


# Calibration views of the approximation baseline: where each board's centre appears in the
# conventional (central) view, as fractions of its size from the centre, and the board's
# rotation. The targets spread the corners over most of the view and the +-15-25 deg turns give
# the perspective that fixes the focal length.
CALIBRATION_TARGETS = ((-0.22, -0.2), (0.22, -0.2), (-0.22, 0.2), (0.22, 0.2), (0.0, 0.0), (0.0, -0.22))
CALIBRATION_ROTATIONS_DEG = ((-20, 15, 5), (15, -20, -5), (20, 20, 10), (-15, -15, 0), (0, 0, 20), (25, 0, -10))
# Pixels per square in the conventional view (the port magnifies about n_water times).
CALIBRATION_PX_PER_SQUARE = 10.0


def calibration_boards(tilt: tuple[float, float], depth_m: float, view: PinholeCamera) -> list[dict]:
    """Board tables for the calibration views at ``depth_m`` behind the port of ``tilt``.

    Each board's centre is where the refracted line of sight of its target pixel of the
    conventional view ``view`` (a pinhole in air at the main-lens centre) reaches ``z = depth_m``,
    so the board is seen there whatever the port.
    """
    flat_port = empty_scene(tilt).port
    square = CALIBRATION_PX_PER_SQUARE * depth_m / (flat_port.n_water / flat_port.n_air * view.focal_px)
    tables = []
    for (fu, fv), rotation in zip(CALIBRATION_TARGETS, CALIBRATION_ROTATIONS_DEG, strict=True):
        uv = np.array([[view.cx_px + fu * view.width_px, view.cy_px + fv * view.height_px]])
        line = view.pixel_directions(uv)
        trace = flat_port.trace_from_air(np.zeros_like(line), line)
        start, direction = trace.exit_points_cam[0], trace.directions_cam[0]
        tables.append(board(start + direction * (depth_m - start[2]) / direction[2], rotation, square))
    return tables


def board_points_world(board: Chessboard, n: int = 21) -> np.ndarray:
    """An n x n grid over the whole board, margin included (world frame)."""
    w, h = assets.chessboard_size_m(
        squares=board.squares, square_size_m=board.square_size_m, margin_squares=board.margin_squares
    )
    xx, yy = np.meshgrid(np.linspace(-w / 2, w / 2, n), np.linspace(-h / 2, h / 2, n))
    return board.placement.to_world(np.stack([xx.ravel(), yy.ravel(), np.zeros(n * n)], axis=1))


def find_corners(image: np.ndarray) -> np.ndarray | None:
    """Inner corners (N, 2) of the :data:`SQUARES` board that OpenCV finds, or None.

    The core's detector (``findChessboardCornersSB`` refined by ``cornerSubPix`` within 7 x 7 px,
    less than a 9 px square); NaN counts as black.
    """
    return detect_chessboard(image, PATTERN)


def corner_rms_px(found: np.ndarray, expected: np.ndarray) -> float:
    """RMS distance (px) of found corners from expected ones, in the better of the two orders.

    The detector may report the grid from either end (7 x 5 squares look the same after a half turn).
    """
    return min(float(np.sqrt(np.mean(np.sum((found - e) ** 2, axis=1)))) for e in (expected, expected[::-1]))
