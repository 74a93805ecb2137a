"""Underwater chessboard set-ups: boards placed behind a tilted port, rendered and calibrated from.

The set-ups that the corner tests (synthesis geometry, approximation baseline, port calibration),
``benchmarks/bench_approx.py`` and ``docs/make_figures.py`` share, so that they measure the same
boards:

* the camera :data:`CAMERA` (the ``tiny-2x`` preset: the tiny camera with twice its focal length
  and sensor; its refraction-free image is 188 x 141 px with f = 240 px, where the tiny preset's
  92 x 69 px is too small for a board the detector finds reliably) behind a port 12 mm away with
  4 mm of glass (:func:`port_table`), lit by :data:`LIGHTS`;
* a :data:`SQUARES` chessboard (7 x 5 squares, :data:`PATTERN` inner corners), placed as a slanted
  test board on a line of sight (:func:`slanted_board`), as six views at one depth for the
  approximation baseline (:func:`calibration_boards`, :func:`calibration_views`) or as ten views
  from 0.15 to 0.35 m for port calibration (:func:`port_boards`, :func:`port_from_renders`; twenty
  with the outer ring, :data:`OUTER_RING_SCALE`);
* the boards' ground truth (:func:`chessboard_corners_world`) and the corner error measures
  (:func:`find_corners`, :func:`corner_rms_px`).

Frames and units: metres and the camera frame of ``docs/conventions.md`` (OpenCV's: +x right, +y
down, +z forward from the main-lens centre). Every scene here has the identity camera pose, so
world points are camera-frame points. A port tilt is the pair ``(tilt_x_deg, tilt_y_deg)`` of the
scene's ``[port]`` table, degrees (docs/conventions.md says how they turn the port's normal). Pixels
are OpenCV's ``(u, v)`` with pixel centres at integers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from lfrefract.calibration.advice import AdvisedView
from lfrefract.calibration.approx import detect_chessboard
from lfrefract.calibration.port import (
    PortCalibration,
    board_view_from_light_field,
    calibrate_port,
    project_through_port,
)
from lfrefract.errors import ParameterError
from lfrefract.methods import CalibrationViews
from lfrefract.optics.lens import LensPrescription
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort
from lfrefract.synthesis.views import subaperture_view
from simulator.backend import load_mitsuba
from simulator.config import Chessboard, SceneConfig, parse_scene
from simulator.geometry import check_geometry
from simulator.job import render_raw

__all__ = [
    "BOARD_MIN_VIEW_FRACTION",
    "CALIBRATION_PX_PER_SQUARE",
    "CALIBRATION_ROTATIONS_DEG",
    "CALIBRATION_TARGETS",
    "CAMERA",
    "DIRECTIONS",
    "LIGHTS",
    "OUTER_RING_SCALE",
    "PATTERN",
    "PORT_DEPTHS_M",
    "PORT_PX_PER_SQUARE",
    "PORT_ROTATIONS_DEG",
    "PORT_SPP",
    "PORT_TARGETS",
    "PX_PER_SQUARE",
    "SLANT_XYZ_DEG",
    "SQUARES",
    "STRAIGHT",
    "TILTED",
    "PortFromRenders",
    "advised_board_table",
    "aligned_errors_px",
    "board_points_world",
    "board_px_per_square",
    "board_scene",
    "board_table",
    "boards_at_targets",
    "calibration_boards",
    "calibration_views",
    "chessboard_corners_world",
    "corner_rms_px",
    "empty_scene",
    "find_corners",
    "port_boards",
    "port_from_renders",
    "port_table",
    "slanted_board",
]

#: The camera preset of every scene here ("tiny-2x": the tiny preset at twice its size).
CAMERA = "tiny-2x"

#: Squares (columns, rows) of the board; its detector pattern :data:`PATTERN` is one less each way.
SQUARES = (7, 5)
#: Inner corners (columns, rows) of the board: OpenCV's ``patternSize``.
PATTERN = (SQUARES[0] - 1, SQUARES[1] - 1)

#: Point lights (position in metres, intensity in W/sr): in the water, in front of the camera and
#: off its axis, so that no board is lit at grazing incidence.
LIGHTS = [
    {"type": "point", "position_m": [-0.08, -0.1, 0.05], "intensity_w_sr": 0.05},
    {"type": "point", "position_m": [0.1, 0.04, 0.05], "intensity_w_sr": 0.05},
]

#: Port tilts ``(tilt_x_deg, tilt_y_deg)`` of the approximation baseline's comparison: straight,
#: and 26.8 deg in all (like the reference port's 26.6 deg) about both axes.
STRAIGHT, TILTED = (0.0, 0.0), (25.0, 10.0)
#: The slanted test board's line of sight ``(x / z, y / z)`` behind each of :data:`STRAIGHT` and
#: :data:`TILTED`: off the axis (the approximation's radial error grows with the distance from the
#: image centre) and inside the synthesis's exact coverage, which the tilted port turns up and to
#: the right.
DIRECTIONS = {STRAIGHT: (0.1, -0.06), TILTED: (0.16, -0.125)}

#: The slanted test board's rotation (x, y, z Euler angles, degrees): not fronto-parallel, its depth
#: varies by +-6.6 % across it.
SLANT_XYZ_DEG = (-10.0, -15.0, 5.0)
#: Pixels per square of the slanted test board at its centre in the refraction-free image.
PX_PER_SQUARE = 9.0

#: Calibration views of the approximation baseline: where each board's centre appears in the
#: conventional (central) view, as fractions of its width and height from its centre. They spread
#: the corners over most of the view.
CALIBRATION_TARGETS = ((-0.22, -0.2), (0.22, -0.2), (-0.22, 0.2), (0.22, 0.2), (0.0, 0.0), (0.0, -0.22))
#: The calibration boards' rotations (x, y, z Euler angles, degrees): the +-15-25 deg turns give
#: the perspective that fixes the focal length.
CALIBRATION_ROTATIONS_DEG = ((-20, 15, 5), (15, -20, -5), (20, 20, 10), (-15, -15, 0), (0, 0, 20), (25, 0, -10))
#: Pixels per square of the calibration boards in the conventional view (the port magnifies about
#: n_water times).
CALIBRATION_PX_PER_SQUARE = 10.0

#: Port calibration views: ten boards over the field (fractions of the view from its centre, as
#: :data:`CALIBRATION_TARGETS`). Refraction's departure from a central camera grows with the angle
#: of view and with nearness.
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
#: Pixels per square of the port calibration boards in the conventional view: large squares (the
#: board spans half of the tiny-2x view, all of the tiny one) put more raw pixels around every corner.
PORT_PX_PER_SQUARE = 14.0
#: The least part of the view's width a port or in-air calibration board's squares span
#: (:func:`board_px_per_square`). The tiny cameras' views are small enough that
#: :data:`PORT_PX_PER_SQUARE` gives more; on an Illum-sized view (1078 px) 14 px squares made a board
#: 9 % of the view's width, a few degrees across, whose perspective cannot tell the focal length
#: from the board's distance (docs/calibration.md, "What the boards determine").
BOARD_MIN_VIEW_FRACTION = 0.4
#: Depths (camera-frame z, metres) of the port calibration boards' centres, from 0.15 to 0.35 m.
PORT_DEPTHS_M = (0.15, 0.35, 0.25, 0.2, 0.3, 0.18, 0.28, 0.22, 0.33, 0.16)
#: The port calibration boards' rotations (x, y, z Euler angles, degrees): turned 15-30 deg about
#: both axes, which fixes each board's pose.
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
#: The outer ring of port and in-air calibration boards (``outer_ring=True`` of :func:`port_boards`
#: and :func:`in_air_boards`): ten more boards at :data:`PORT_TARGETS` this many times farther from the
#: view's centre (their edges reach the view's), at the same depths, turned the other way about x and
#: y. They reach the field's edge, where refraction departs most from a central camera and a real
#: lens's distortion is largest. Measured on the pipeline experiment (double Gauss, tiny sensor, 20 deg
#: wall; docs/experiments.md): the port normal 0.17 / 0.23 deg from the truth with the ten inner boards,
#: 0.07 / 0.12 deg with both rings (left / right camera), once the camera was calibrated on both rings too.
OUTER_RING_SCALE = 1.6
#: Samples per pixel of the port calibration renders (:func:`port_from_renders`).
PORT_SPP = 32

_SOURCE = "<simulator.boards>"


def port_table(tilt_deg: tuple[float, float]) -> dict:
    """The ``[port]`` table of every scene here.

    Parameters
    ----------
    tilt_deg : (float, float)
        ``(tilt_x_deg, tilt_y_deg)``, degrees.

    Returns
    -------
    dict
        A port 12 mm from the main-lens centre with 4 mm of glass, indices air 1.0 / glass 1.5 /
        water 1.333.
    """
    return {
        "distance_m": 0.012,
        "thickness_m": 0.004,
        "tilt_x_deg": tilt_deg[0],
        "tilt_y_deg": tilt_deg[1],
        "n_air": 1.0,
        "n_glass": 1.5,
        "n_water": 1.333,
    }


def board_table(position_m, rotation_xyz_deg, square_size_m: float) -> dict:
    """A :data:`SQUARES` chessboard ``[[object]]`` table (one square of margin).

    Parameters
    ----------
    position_m : sequence of 3 float
        The board's centre (margin included), world frame, metres.
    rotation_xyz_deg : sequence of 3 float
        The board's rotation, x, y, z Euler angles, degrees (zero: facing the camera, upright).
    square_size_m : float
        Edge of a square, metres.
    """
    return {
        "type": "chessboard",
        "position_m": [float(x) for x in position_m],
        "rotation_xyz_deg": [float(a) for a in rotation_xyz_deg],
        "squares": list(SQUARES),
        "square_size_m": float(square_size_m),
    }


def advised_board_table(view: AdvisedView, square_size_m: float) -> dict:
    """A :data:`SQUARES` chessboard table at a view a port calibration's advice names
    (:func:`lfrefract.calibration.advice.advise_port_views`), in the frame of the advice's camera.

    The advice turns a board facing the camera by extrinsic rotations about x then y
    (:attr:`~lfrefract.calibration.advice.AdvisedView.turn_deg`) and puts the centre of its
    inner-corner grid at :attr:`~lfrefract.calibration.advice.AdvisedView.centre_m`; a
    :class:`simulator.config.Placement` turns extrinsically about x, y, z and places the board's
    centre, which its even margin makes the centre of its inner corners. So the table's rotation is
    ``(turn_x, turn_y, 0)`` and its position the advised centre.

    Parameters
    ----------
    view : AdvisedView
        One of :attr:`lfrefract.calibration.advice.PortAdvice.views`.
    square_size_m : float
        Edge of a square, metres: the advice's board is like the calibration's board seen nearest its
        depth, so give that board's.

    Returns
    -------
    dict
        The ``[[object]]`` table (:func:`board_table`), in the camera frame (OpenCV axes, metres).
    """
    if not isinstance(view, AdvisedView):
        raise ParameterError(f"view must be an AdvisedView, got {view!r}")
    return board_table(view.centre_m, (*view.turn_deg, 0.0), square_size_m)


def _scene(tilt_deg: tuple[float, float], objects: list[dict], lights: Sequence[dict], spp: int, seed: int):
    data = {
        "name": "boards",
        "camera": {"preset": CAMERA},
        "render": {"spp": spp, "seed": seed},
        "light": list(lights),
        "object": objects,
        "port": port_table(tilt_deg),
    }
    return parse_scene(data, source=_SOURCE)


def board_scene(
    tilt_deg: tuple[float, float],
    board: dict,
    *,
    spp: int = 16,
    seed: int = 0,
    lights: Sequence[dict] | None = None,
) -> SceneConfig:
    """One board behind the port of ``tilt_deg``, seen by :data:`CAMERA`, its geometry checked.

    Parameters
    ----------
    tilt_deg : (float, float)
        ``(tilt_x_deg, tilt_y_deg)`` of the port (:func:`port_table`), degrees.
    board : dict
        The board's ``[[object]]`` table (:func:`board_table`).
    spp, seed : int
        Samples per pixel and seed of the render.
    lights : sequence of dict, optional
        ``[[light]]`` tables; default :data:`LIGHTS`.

    Raises
    ------
    ParameterError
        If the board crosses the port or the camera (:func:`simulator.geometry.check_geometry`).
    """
    config = _scene(tilt_deg, [board], LIGHTS if lights is None else lights, spp, seed)
    check_geometry(config)
    return config


def empty_scene(tilt_deg: tuple[float, float]) -> SceneConfig:
    """:data:`CAMERA` and the port of ``tilt_deg`` (degrees), no object: for warp maps and the port."""
    return _scene(tilt_deg, [], LIGHTS, 16, 0)


def slanted_board(depth_m: float, direction: tuple[float, float], focal_px: float) -> dict:
    """The slanted test board (:data:`SLANT_XYZ_DEG`) on a line of sight.

    Parameters
    ----------
    depth_m : float
        Camera-frame z of the board's centre, metres.
    direction : (float, float)
        The line of sight ``(x / z, y / z)`` of the board's centre (e.g. :data:`DIRECTIONS`).
    focal_px : float
        Focal length of the pinhole image (the refraction-free image) that the board is sized for,
        pixels: its squares are :data:`PX_PER_SQUARE` pixels there at the centre.

    Returns
    -------
    dict
        The board's ``[[object]]`` table.
    """
    position = depth_m * np.array([*direction, 1.0])
    return board_table(position, SLANT_XYZ_DEG, PX_PER_SQUARE * depth_m / focal_px)


def calibration_boards(tilt_deg: tuple[float, float], depth_m: float, view: PinholeCamera) -> list[dict]:
    """The approximation baseline's six calibration boards at one depth behind the port of ``tilt_deg``.

    Boards at :data:`CALIBRATION_TARGETS` turned by :data:`CALIBRATION_ROTATIONS_DEG`, with
    :data:`CALIBRATION_PX_PER_SQUARE` pixels per square (:func:`boards_at_targets`).

    Parameters
    ----------
    tilt_deg : (float, float)
        ``(tilt_x_deg, tilt_y_deg)`` of the port, degrees.
    depth_m : float
        Camera-frame z of every board's centre, metres.
    view : PinholeCamera
        The refraction-free view of :data:`CAMERA` (:func:`lfrefract.virtual_camera_for`).

    Returns
    -------
    list of dict
        ``[[object]]`` tables.
    """
    depths = [depth_m] * len(CALIBRATION_TARGETS)
    return boards_at_targets(empty_scene(tilt_deg).port, view, CALIBRATION_TARGETS, depths, CALIBRATION_ROTATIONS_DEG)


def port_boards(
    tilt_deg: tuple[float, float] | FlatPort, view: PinholeCamera, *, outer_ring: bool = False
) -> list[dict]:
    """The ten port calibration boards behind the port of ``tilt_deg`` (degrees), or behind a port.

    Boards at :data:`PORT_TARGETS` and :data:`PORT_DEPTHS_M`, turned by :data:`PORT_ROTATIONS_DEG`,
    with :func:`board_px_per_square` pixels per square (:func:`boards_at_targets`); ``view`` as in
    :func:`calibration_boards`. ``tilt_deg`` may be the port itself (a rig camera's wall, in its
    frame); the tables are then in that camera's frame. ``outer_ring``: ten more after them, the
    outer ring of :data:`OUTER_RING_SCALE`.
    """
    port = tilt_deg if isinstance(tilt_deg, FlatPort) else empty_scene(tilt_deg).port
    targets, depths, rotations = _ring_layout(outer_ring)
    return boards_at_targets(port, view, targets, depths, rotations, px_per_square=board_px_per_square(view))


def board_px_per_square(view: PinholeCamera) -> float:
    """Pixels per square of the port and in-air calibration boards in ``view``: :data:`PORT_PX_PER_SQUARE`,
    or more where that would make a board (:data:`SQUARES` wide) span less than
    :data:`BOARD_MIN_VIEW_FRACTION` of the view's width."""
    return max(PORT_PX_PER_SQUARE, BOARD_MIN_VIEW_FRACTION * view.width_px / SQUARES[0])


def _ring_layout(outer_ring: bool) -> tuple[list, list, list]:
    """Targets, depths and rotations (degrees) of the port and in-air boards: :data:`PORT_TARGETS`
    and, with ``outer_ring``, the outer ring after them (:data:`OUTER_RING_SCALE`)."""
    targets, depths, rotations = list(PORT_TARGETS), list(PORT_DEPTHS_M), list(PORT_ROTATIONS_DEG)
    if outer_ring:
        targets += [(OUTER_RING_SCALE * u, OUTER_RING_SCALE * v) for u, v in PORT_TARGETS]
        depths += PORT_DEPTHS_M
        rotations += [(-x, -y, z) for x, y, z in PORT_ROTATIONS_DEG]
    return targets, depths, rotations


def boards_at_targets(
    port: FlatPort,
    view: PinholeCamera,
    targets: Sequence[tuple[float, float]],
    depths_m: Sequence[float],
    rotations_deg: Sequence[Sequence[float]],
    *,
    px_per_square: float = CALIBRATION_PX_PER_SQUARE,
) -> list[dict]:
    """Boards behind ``port``, each seen where it is aimed at, whatever the port.

    Board ``i``'s centre is where the refracted line of sight of target pixel ``i`` of ``view`` (a
    pinhole in air at the main-lens centre) reaches ``z = depths_m[i]``.

    Parameters
    ----------
    port : FlatPort
        The port, camera frame (e.g. ``empty_scene(tilt_deg).port``).
    view : PinholeCamera
        The view the targets are given in.
    targets : sequence of (float, float)
        Where each board's centre appears, as fractions of ``view``'s width and height from its
        principal point.
    depths_m : sequence of float
        Camera-frame z of each board's centre, metres.
    rotations_deg : sequence of (float, float, float)
        Each board's rotation, x, y, z Euler angles, degrees.
    px_per_square : float
        Pixels per square in the conventional view (``view``'s focal length times
        ``n_water / n_air``) at each board's centre depth.

    Returns
    -------
    list of dict
        ``[[object]]`` tables, one per target.
    """
    flat_port = port
    tables = []
    for (fu, fv), depth, rotation in zip(targets, depths_m, rotations_deg, strict=True):
        square = px_per_square * depth / (flat_port.n_water / flat_port.n_air * view.focal_px)
        uv = np.array([[view.cx_px + fu * view.width_px, view.cy_px + fv * view.height_px]])
        line = view.pixel_directions(uv)
        trace = flat_port.trace_from_air(np.zeros_like(line), line)
        start, direction = trace.exit_points_cam[0], trace.directions_cam[0]
        tables.append(board_table(start + direction * (depth - start[2]) / direction[2], rotation, square))
    return tables


def chessboard_corners_world(board: Chessboard) -> np.ndarray:
    """A chessboard object's inner corners, world frame, metres: ground truth.

    Parameters
    ----------
    board : Chessboard
        The object (``SceneConfig.objects``).

    Returns
    -------
    ndarray, float64, shape ((columns - 1) * (rows - 1), 3)
        In the order of :func:`simulator.assets.chessboard_inner_corners` (row by row from the
        top-left corner, x fastest: OpenCV's order for pattern size ``(columns - 1, rows - 1)`` on an
        upright board). With an identity camera pose (every scene here) these are camera-frame points.
    """
    local = board.inner_corners_local_m()
    return board.placement.to_world(np.concatenate([local, np.zeros((len(local), 1))], axis=1))


def board_points_world(board: Chessboard, *, n: int = 21) -> np.ndarray:
    """An ``n`` x ``n`` grid over the whole board, margin included.

    Returns
    -------
    ndarray, float64, shape (n * n, 3)
        World-frame points, metres.
    """
    w, h = board.board_size_m
    xx, yy = np.meshgrid(np.linspace(-w / 2, w / 2, n), np.linspace(-h / 2, h / 2, n))
    return board.placement.to_world(np.stack([xx.ravel(), yy.ravel(), np.zeros(n * n)], axis=1))


def find_corners(image: np.ndarray, *, canonical: bool = False) -> np.ndarray | None:
    """The inner corners of the :data:`SQUARES` board that OpenCV finds in an image.

    The core's detector (:func:`lfrefract.calibration.approx.detect_chessboard`:
    ``findChessboardCornersSB`` refined by ``cornerSubPix`` within 7 x 7 px, less than a 9 px
    square); NaN counts as black.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
    canonical : bool
        Put the corners in one order whichever end the detector started from: the first corner
        the top-left one (smaller ``u + v`` than the last; right for a board turned by less than
        90 deg), so that two views of one board (a stereo pair) list them alike.

    Returns
    -------
    ndarray, float64, shape (24, 2), or None
        Pixels ``(u, v)`` in the detector's order (or the canonical one); None if the board is not found.
    """
    found = detect_chessboard(image, PATTERN)
    if canonical and found is not None and found[0].sum() > found[-1].sum():
        found = found[::-1].copy()
    return found


def aligned_errors_px(found: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """Found minus expected corners, in the better of the two orders.

    The detector may report the grid from either end (7 x 5 squares look the same after a half turn).

    Parameters
    ----------
    found, expected : ndarray, shape (N, 2)
        Corner pixels ``(u, v)``.

    Returns
    -------
    ndarray, shape (N, 2)
        Pixels.
    """
    return min((found - e for e in (expected, expected[::-1])), key=lambda d: float(np.sum(d**2)))


def corner_rms_px(found: np.ndarray, expected: np.ndarray) -> float:
    """RMS distance (pixels) of found corners from expected ones (N, 2), in the better of the two orders."""
    return float(np.sqrt(np.mean(np.sum(aligned_errors_px(found, expected) ** 2, axis=1))))


def calibration_views(
    mi: ModuleType, tilt_deg: tuple[float, float], depth_m: float, *, seed: int = 0
) -> CalibrationViews:
    """Render the six :func:`calibration_boards` at ``depth_m`` behind the port of ``tilt_deg``.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set (:func:`simulator.backend.load_mitsuba`).
    tilt_deg : (float, float)
        ``(tilt_x_deg, tilt_y_deg)`` of the port, degrees.
    depth_m : float
        Camera-frame z of the boards' centres, metres.
    seed : int
        Seed of every render (16 spp).

    Returns
    -------
    CalibrationViews
        The raw images, with the boards' inner corners in the camera frame (metres) as
        ``corners_cam``, for :func:`lfrefract.methods.build_projector`.
    """
    camera = empty_scene(tilt_deg).camera
    boards = calibration_boards(tilt_deg, depth_m, virtual_camera_for(camera))
    configs = [board_scene(tilt_deg, table, seed=seed) for table in boards]
    return CalibrationViews(
        raws=[render_raw(mi, c, progress=False) for c in configs],
        pattern=PATTERN,
        square_size_m=boards[0]["square_size_m"],
        corners_cam=[chessboard_corners_world(c.objects[0]) for c in configs],
    )


@dataclass(frozen=True)
class PortFromRenders:
    """A port calibrated from the :func:`port_boards` renders behind the port of one tilt.

    Attributes
    ----------
    calibration : PortCalibration
        :func:`lfrefract.calibration.port.calibrate_port`'s result.
    truth : FlatPort
        The port the boards were rendered behind.
    view : PinholeCamera
        The refraction-free view the corners are expressed in.
    light_field_errors_px, central_errors_px : ndarray, shape (N, 2)
        The light-field corners (seen from the main-lens centre) and OpenCV's corners in the central
        view, minus the exact refracted projection of the boards' corners into ``view``, all boards,
        pixels.
    """

    calibration: PortCalibration
    truth: FlatPort
    view: PinholeCamera
    light_field_errors_px: np.ndarray
    central_errors_px: np.ndarray

    @property
    def light_field_rms_px(self) -> float:
        """RMS of :attr:`light_field_errors_px`, pixels."""
        return float(np.sqrt(np.mean(np.sum(self.light_field_errors_px**2, axis=1))))

    @property
    def central_rms_px(self) -> float:
        """RMS of :attr:`central_errors_px`, pixels."""
        return float(np.sqrt(np.mean(np.sum(self.central_errors_px**2, axis=1))))

    @property
    def normal_error_deg(self) -> float:
        """Angle between the estimated and the true port normal, degrees."""
        cos = float(np.clip(self.calibration.port.normal @ self.truth.normal, -1.0, 1.0))
        return math.degrees(math.acos(cos))

    @property
    def distance_error_m(self) -> float:
        """Estimated minus true port distance, metres."""
        return self.calibration.port.distance_m - self.truth.distance_m


def port_from_renders(
    tilt_deg: tuple[float, float], *, mi: ModuleType | None = None, spp: int = PORT_SPP
) -> PortFromRenders:
    """Render the ten :func:`port_boards`, locate their corners in the light field, calibrate the port.

    Board ``i`` is rendered with seed ``i``. The thickness and indices of the port are given to
    the calibration; its normal and distance are estimated. About a minute per tilt on 2 cores.

    Parameters
    ----------
    tilt_deg : (float, float)
        ``(tilt_x_deg, tilt_y_deg)`` of the port, degrees.
    mi : module, optional
        Mitsuba with a variant set; default ``load_mitsuba("llvm_ad_rgb")`` (the variant of the
        figures in docs/calibration.md).
    spp : int
        Samples per pixel of the renders.

    Raises
    ------
    RuntimeError
        If a board, or one of its corners, is not found in a render.
    """
    if mi is None:
        mi = load_mitsuba("llvm_ad_rgb")
    truth = empty_scene(tilt_deg).port
    camera = empty_scene(tilt_deg).camera
    view = virtual_camera_for(camera)
    views, light_field, central = [], [], []
    for seed, table in enumerate(port_boards(tilt_deg, view)):
        config = board_scene(tilt_deg, table, spp=spp, seed=seed)
        raw = render_raw(mi, config, progress=False)
        where = f"port calibration board {seed} behind a port tilted {tilt_deg} deg"
        found = board_view_from_light_field(
            camera, raw, pattern=PATTERN, square_size_m=table["square_size_m"], view=view
        )
        if found is None:
            raise RuntimeError(f"{where}: the board is not found in the central view")
        if found.central.sum() != PATTERN[0] * PATTERN[1]:
            missing = PATTERN[0] * PATTERN[1] - int(found.central.sum())
            raise RuntimeError(f"{where}: {missing} corner(s) not located in the light field")
        views.append(found)
        expected = project_through_port(view, truth, chessboard_corners_world(config.objects[0]))
        central_view = find_corners(subaperture_view(camera, raw, (0.0, 0.0), output=view))
        if central_view is None:
            raise RuntimeError(f"{where}: the board is not found in the central view")
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


def in_air_board_scene(
    board: dict, *, lens: str | LensPrescription = "thin", spp: int = 16, seed: int = 0, camera: str = CAMERA
) -> SceneConfig:
    """One board in air (``medium = "air"``, no port) before the camera with main lens ``lens``.

    Parameters
    ----------
    board : dict
        The board's ``[[object]]`` table (:func:`board_table`).
    lens : str or LensPrescription
        ``"thin"``, a lens preset (``lfsim lenses``) or a design (a lens file's), scaled and stopped
        to the camera (:func:`simulator.config.main_lens`).
    spp, seed : int
        Samples per pixel and seed of the render.
    camera : str
        The camera's preset (default :data:`CAMERA`).
    """
    data = {
        "name": "in-air-boards",
        "medium": "air",
        "camera": {"preset": camera, "lens": lens},
        "render": {"spp": spp, "seed": seed},
        "light": list(LIGHTS),
        "object": [board],
    }
    config = parse_scene(data, source=_SOURCE)
    check_geometry(config)
    return config


def in_air_boards(view: PinholeCamera, *, outer_ring: bool = False) -> list[dict]:
    """The camera calibration's ten boards in air: :data:`PORT_TARGETS` at :data:`PORT_DEPTHS_M`,
    turned by :data:`PORT_ROTATIONS_DEG`, :func:`board_px_per_square` pixels per square in ``view``
    (the refraction-free view of :data:`CAMERA`; so their squares differ, 9-20 mm on it), each centred on
    its target's line of sight. ``outer_ring``: ten more after them, the outer ring of
    :data:`OUTER_RING_SCALE` (the lens's distortion is calibrated where the port boards see)."""
    k_inverse = np.linalg.inv(view.K)
    px_per_square = board_px_per_square(view)
    tables = []
    for (fx, fy), depth, rotation in zip(*_ring_layout(outer_ring), strict=True):
        sight = k_inverse @ np.array([view.K[0, 2] + fx * view.width_px, view.K[1, 2] + fy * view.height_px, 1.0])
        square = px_per_square * depth / view.K[0, 0]
        tables.append(board_table(depth * sight / sight[2], rotation, square))
    return tables
