"""Underwater chessboard scenes for the corner tests (synthesis geometry, approximation baseline,
port calibration from renders).

The tiny preset's refraction-free image (92 x 69 px) is too small for a board the detector finds
reliably, so these tests use :data:`CAMERA`, the ``tiny-2x`` preset: the tiny camera with twice its
focal length and sensor. Its refraction-free image (2 px per lens) is 188 x 141 px with f = 240 px.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from lfrefract.calibration.approx import detect_chessboard
from lfrefract.calibration.port import (
    PortCalibration,
    board_view_from_light_field,
    calibrate_port,
    project_through_port,
)
from lfrefract.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.port import FlatPort
from lfrefract.views import subaperture_view
from simulator import assets
from simulator.backend import load_mitsuba
from simulator.config import Chessboard, SceneConfig
from simulator.job import render_raw
from simulator.scene import check_geometry
from tests.simulator.scenes import chessboard_corners_world, scene

#: The tiny preset at twice its size (the "tiny-2x" preset), as a scene's camera.
CAMERA = "tiny-2x"

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


def board_scene(
    tilt: tuple[float, float], board_table: dict, *, spp: int = 16, seed: int = 0, lights: list[dict] = LIGHTS
) -> SceneConfig:
    """One board behind the port of ``tilt``, seen by :data:`CAMERA` (checked geometry)."""
    config = scene(port=port(tilt), objects=[board_table], lights=lights, spp=spp, seed=seed, camera=CAMERA)
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
    """Board tables for the approximation baseline's calibration views at ``depth_m`` behind the
    port of ``tilt`` (:data:`CALIBRATION_TARGETS`, :data:`CALIBRATION_ROTATIONS_DEG`)."""
    depths = [depth_m] * len(CALIBRATION_TARGETS)
    return boards_at_targets(tilt, view, CALIBRATION_TARGETS, depths, CALIBRATION_ROTATIONS_DEG)


# Port calibration views: ten boards over the field and from 0.15 to 0.35 m, turned 15-30 deg
# about both axes (refraction's departure from a central camera grows with the angle of view
# and with nearness, and the turns fix each board's pose).
PORT_TARGETS = (
    (-0.15, -0.15),
    (0.15, -0.15),
    (-0.15, 0.15),
    (0.15, 0.15),
    (0.0, 0.0),
    (-0.15, 0.0),
    (0.15, 0.0),
    (0.0, -0.15),
    (0.0, 0.15),
    (0.08, 0.08),
)
# Large squares (the board spans two thirds of the view): more raw pixels around every corner.
PORT_PX_PER_SQUARE = 14.0
PORT_DEPTHS_M = (0.15, 0.35, 0.25, 0.2, 0.3, 0.18, 0.28, 0.22, 0.33, 0.16)
PORT_ROTATIONS_DEG = (
    (20, 20, 5),
    (-20, 25, -5),
    (25, -20, 0),
    (-25, -15, 10),
    (30, 0, 0),
    (0, 30, -10),
    (-15, -25, 5),
    (25, 15, 0),
    (-20, 20, -5),
    (15, -30, 0),
)


def port_boards(tilt: tuple[float, float], view: PinholeCamera) -> list[dict]:
    """Board tables for port calibration behind the port of ``tilt`` (:data:`PORT_TARGETS`)."""
    return boards_at_targets(
        tilt, view, PORT_TARGETS, PORT_DEPTHS_M, PORT_ROTATIONS_DEG, px_per_square=PORT_PX_PER_SQUARE
    )


def boards_at_targets(
    tilt, view: PinholeCamera, targets, depths_m, rotations_deg, *, px_per_square: float = CALIBRATION_PX_PER_SQUARE
) -> list[dict]:
    """Board tables behind the port of ``tilt``, one per target.

    Board ``i``'s centre is where the refracted line of sight of target pixel ``i`` of the
    conventional view ``view`` (a pinhole in air at the main-lens centre; targets as fractions of
    its size from its centre) reaches ``z = depths_m[i]``, so the board is seen there whatever the
    port; its squares are about ``px_per_square`` pixels in that view.
    """
    flat_port = empty_scene(tilt).port
    tables = []
    for (fu, fv), depth, rotation in zip(targets, depths_m, rotations_deg, strict=True):
        square = px_per_square * depth / (flat_port.n_water / flat_port.n_air * view.focal_px)
        uv = np.array([[view.cx_px + fu * view.width_px, view.cy_px + fv * view.height_px]])
        line = view.pixel_directions(uv)
        trace = flat_port.trace_from_air(np.zeros_like(line), line)
        start, direction = trace.exit_points_cam[0], trace.directions_cam[0]
        tables.append(board(start + direction * (depth - start[2]) / direction[2], rotation, square))
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


def aligned_errors_px(found: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """Found minus expected corners (N, 2), pixels, in the better of the two orders.

    The detector may report the grid from either end (7 x 5 squares look the same after a half turn).
    """
    return min((found - e for e in (expected, expected[::-1])), key=lambda d: float(np.sum(d**2)))


def corner_rms_px(found: np.ndarray, expected: np.ndarray) -> float:
    """RMS distance (px) of found corners from expected ones, in the better of the two orders."""
    return float(np.sqrt(np.mean(np.sum(aligned_errors_px(found, expected) ** 2, axis=1))))


# Port calibration from renders (tests/simulator/test_port_calibration_render.py and the pipeline
# with estimated parameters): samples per pixel of the board renders.
PORT_SPP = 32


@dataclass(frozen=True)
class PortFromRenders:
    """A port calibrated from the :func:`port_boards` renders behind the port of one tilt.

    ``light_field_errors_px`` and ``central_errors_px`` (N, 2): the light-field corners (seen from
    the main-lens centre) and OpenCV's corners in the central view, minus the exact refracted
    projection of the boards' corners, all boards.
    """

    calibration: PortCalibration
    truth: FlatPort
    view: PinholeCamera
    light_field_errors_px: np.ndarray
    central_errors_px: np.ndarray

    @property
    def light_field_rms_px(self) -> float:
        return float(np.sqrt(np.mean(np.sum(self.light_field_errors_px**2, axis=1))))

    @property
    def central_rms_px(self) -> float:
        return float(np.sqrt(np.mean(np.sum(self.central_errors_px**2, axis=1))))

    @property
    def normal_error_deg(self) -> float:
        cos = float(np.clip(self.calibration.port.normal @ self.truth.normal, -1.0, 1.0))
        return math.degrees(math.acos(cos))

    @property
    def distance_error_m(self) -> float:
        return self.calibration.port.distance_m - self.truth.distance_m


@functools.cache
def port_from_renders(tilt: tuple[float, float]) -> PortFromRenders:
    """Render the ten :func:`port_boards` behind the port of ``tilt`` (:data:`PORT_SPP`), locate their
    corners in the light field, and calibrate the port (once per tilt per test session)."""
    mi = load_mitsuba("llvm_ad_rgb")
    truth = empty_scene(tilt).port
    camera = empty_scene(tilt).camera
    view = virtual_camera_for(camera)
    views, light_field, central = [], [], []
    for seed, table in enumerate(port_boards(tilt, view)):
        config = board_scene(tilt, table, spp=PORT_SPP, seed=seed)
        raw = render_raw(mi, config, progress=False)
        found = board_view_from_light_field(
            camera, raw, pattern=PATTERN, square_size_m=table["square_size_m"], view=view
        )
        assert found is not None, seed
        assert found.central.sum() == PATTERN[0] * PATTERN[1], seed
        views.append(found)
        expected = project_through_port(view, truth, chessboard_corners_world(config.objects[0]))
        central_view = find_corners(subaperture_view(camera, raw, (0.0, 0.0), output=view))
        light_field.append(aligned_errors_px(found.corners_px[found.central], expected))
        central.append(aligned_errors_px(central_view, expected))
    calibration = calibrate_port(
        view, views, thickness_m=truth.thickness_m, n_air=truth.n_air, n_glass=truth.n_glass, n_water=truth.n_water
    )
    return PortFromRenders(
        calibration=calibration,
        truth=truth,
        view=view,
        light_field_errors_px=np.concatenate(light_field),
        central_errors_px=np.concatenate(central),
    )
