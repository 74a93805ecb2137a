"""Stereo rig experiments' common parts: captures, chessboards and the methods' calibrated rigs.

``planes`` and ``objects`` render a rig (:mod:`simulator.rig`) in front of chessboards and their
objects, turn every capture into central projections by each method of :data:`METHOD_NAMES`, and
calibrate and rectify the rig on each method's own images (:func:`calibrated_methods`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lfrefract import ParameterError, virtual_camera_for
from lfrefract.calibration.approx import detect_chessboard
from lfrefract.formats.exr import read_exr
from lfrefract.formats.jsonio import read_json
from lfrefract.methods import CalibrationViews, build_projector
from lfrefract.stereo.geometry import Rectification, StereoCalibration, calibrate_stereo, rectify
from lfrefract.stereo.matching import sgbm_disparity, zncc_disparity
from lfrefract.synthesis.warp_map import WarpMap, build_warp_map
from simulator.boards import chessboard_corners_world
from simulator.config import Chessboard, Placement, read_toml
from simulator.rig import RigConfig, embedded_rigs, parse_rig
from simulator.rig_render import render_rig

__all__ = [
    "BOARD_OFFSETS",
    "MATCHERS",
    "METHOD_NAMES",
    "SQUARES",
    "Capture",
    "RigSetup",
    "aim",
    "calibrated_methods",
    "chessboards",
    "exact_coverage",
    "grey",
    "match",
    "render_capture",
    "render_captures",
    "rig_data",
    "warp_maps",
]

#: Methods compared, in table order.
METHOD_NAMES = ("approx far", "approx near", "proposed", "proposed+distortion", "ideal")

#: Stereo matchers run on every method's rectified pair: the paper's NCC cost
#: (:func:`lfrefract.stereo.matching.zncc_disparity`) and OpenCV's semi-global matcher
#: (:func:`lfrefract.stereo.matching.sgbm_disparity`), whose smoothness terms hold up better at depth edges.
MATCHERS = ("zncc", "sgbm")


@dataclass(frozen=True)
class RigSetup:
    """What a rig experiment renders at one scale.

    Attributes
    ----------
    rig : str
        The embedded rig (``scenes/rigs/``) whose wall and cameras are used; its objects, lights and
        render settings are replaced by the experiment's.
    calibration_depths_m : (float, float)
        Near and far chessboard depths (the approximation baseline's two calibrations).
    px_per_square : float
        Chessboard squares in the views at their depth, pixels (about).
    spp : int
        Samples per pixel.
    """

    rig: str
    calibration_depths_m: tuple[float, float]
    px_per_square: float
    spp: int


#: Chessboard squares (columns, rows) and where the calibration boards sit: offsets from the rig's
#: line of sight as fractions of the depth, and their rotations (perspective fixes the focal length).
SQUARES = (7, 5)
BOARD_OFFSETS = ((-0.07, -0.05), (0.07, -0.05), (-0.07, 0.05), (0.07, 0.05), (0.0, 0.0), (0.0, -0.06))
BOARD_ROTATIONS_DEG = ((-20, 15, 5), (15, -20, -5), (20, 20, 10), (-15, -15, 0), (0, 0, 20), (25, 0, -10))
LIGHTS = [
    {"type": "point", "position_m": [-0.2, -0.25, 0.1], "intensity_w_sr": 0.4},
    {"type": "point", "position_m": [0.25, -0.1, 0.08], "intensity_w_sr": 0.35},
]


def rig_data(setup: RigSetup, objects: list[dict]) -> dict:
    """The rig file's wall and cameras with the experiment's lights, render settings and ``objects``."""
    data = read_toml(embedded_rigs()[setup.rig], "rig")
    data.update(name=f"experiment-{setup.rig}", render={"spp": setup.spp, "seed": 0}, light=LIGHTS, object=objects)
    return data


def aim(rig: RigConfig, depth_m: float) -> np.ndarray:
    """World point at ``z = depth_m`` on the mean refracted line of sight of the cameras' axes."""
    points = []
    for camera in rig.cameras:
        scene = camera.scene
        trace = scene.port.trace_from_air(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]))
        pose = scene.pose
        start = pose.to_world(trace.exit_points_cam)[0]
        direction = np.asarray(pose.rotation) @ trace.directions_cam[0]
        points.append(start + direction * (depth_m - start[2]) / direction[2])
    return np.mean(points, axis=0)


def square_size_m(rig: RigConfig, setup: RigSetup, depth_m: float) -> float:
    view = virtual_camera_for(rig.cameras[0].scene.camera)
    water = rig.wall.n_water / rig.wall.n_air
    return setup.px_per_square * depth_m / (water * view.focal_px)


def chessboards(rig: RigConfig, setup: RigSetup, depth_m: float) -> list[dict]:
    centre = aim(rig, depth_m)
    square = square_size_m(rig, setup, depth_m)
    return [
        {
            "type": "chessboard",
            "position_m": (centre + depth_m * np.array([dx, dy, 0.0])).tolist(),
            "rotation_xyz_deg": list(rotation),
            "squares": list(SQUARES),
            "square_size_m": square,
        }
        for (dx, dy), rotation in zip(BOARD_OFFSETS, BOARD_ROTATIONS_DEG, strict=True)
    ]


@dataclass(frozen=True)
class Capture:
    """One rendered rig capture on disk; images are read when asked for (an Illum raw image is
    0.5 GB, and the experiment has thirty)."""

    folder: Path

    def raw(self, camera: str) -> np.ndarray:
        return read_exr(self.folder / camera / "raw.exr", role="raw")

    def ideal(self, camera: str) -> np.ndarray:
        return read_exr(self.folder / camera / "ideal.exr", role="ideal")


def render_capture(setup: RigSetup, objects: list[dict], folder: Path) -> Capture:
    """Render the rig with ``objects`` into ``folder`` (kept if it already holds this very rig)."""
    rig = parse_rig(rig_data(setup, objects))
    meta = folder / "meta.json"
    if not (meta.is_file() and read_json(meta).get("objects") == objects):
        render_rig(rig, folder, progress=False, write_previews=False, overwrite=True, metadata={"objects": objects})
    return Capture(folder)


def inner_corners_world(table: dict) -> np.ndarray:
    """Inner corners (N, 3) of a chessboard table of :func:`chessboards` in the world frame, in the
    board's order (:func:`simulator.boards.chessboard_corners_world`)."""
    placement = Placement(position_m=table["position_m"], rotation_xyz_deg=table["rotation_xyz_deg"])
    board = Chessboard(placement=placement, squares=table["squares"], square_size_m=table["square_size_m"])
    return chessboard_corners_world(board)


def board_points_m(square: float) -> np.ndarray:
    cols, rows = SQUARES[0] - 1, SQUARES[1] - 1
    jj, ii = np.mgrid[0:rows, 0:cols]
    return np.stack([ii.ravel(), jj.ravel()], axis=1) * square


def find_corners(image: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """The detector's corners in a canonical order: the first one the top-left one (the board is
    turned by less than 90 deg in every view), so that both cameras list them alike."""
    found = detect_chessboard(image, pattern)
    if found is not None and found[0].sum() > found[-1].sum():
        found = found[::-1].copy()
    return found


def grey(image: np.ndarray) -> np.ndarray:
    return image.mean(axis=2) if image.ndim == 3 else image


def match(matcher: str, left: np.ndarray, right: np.ndarray, *, min_disparity_px: int, num_disparities: int):
    """Disparity (H, W) of a rectified pair (grey or RGB, NaN where missing) by one of :data:`MATCHERS`."""
    if matcher == "zncc":
        return zncc_disparity(
            grey(left), grey(right), min_disparity_px=min_disparity_px, num_disparities=num_disparities
        )
    if matcher == "sgbm":
        return sgbm_disparity(
            grey(left), grey(right), min_disparity_px=min_disparity_px, num_disparities=num_disparities
        )
    raise ParameterError(f"matcher must be one of {MATCHERS}, got {matcher!r}")


def warp_maps(rig: RigConfig) -> dict[str, WarpMap]:
    """Each camera's warp map (:func:`lfrefract.synthesis.warp_map.build_warp_map`) with the default options."""
    return {c.name: build_warp_map(c.scene.camera, c.scene.port) for c in rig.cameras}


def exact_coverage(points_left: np.ndarray, rig: RigConfig, warps: dict[str, WarpMap]) -> np.ndarray:
    """Whether each point (N, 3; the first camera's frame, metres) is seen by exact pixels of every camera.

    A point is inside when it projects, in every camera's refraction-free view (true pose,
    ``warps[name].output``), onto a pixel whose necessary rays that camera records
    (:attr:`WarpMap.exact`): there the synthesis is exact, elsewhere it approximates. The region
    belongs to the set-up, not to a method, so every method is measured on the same points.
    """
    points_left = np.asarray(points_left, dtype=np.float64).reshape(-1, 3)
    world = rig.cameras[0].scene.pose.to_world(points_left)
    inside = np.ones(len(points_left), dtype=bool)
    for camera in rig.cameras:
        warp = warps[camera.name]
        points = camera.scene.pose.to_camera(world)
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.rint(warp.output.project(points))
        ok = (points[:, 2] > 0) & np.isfinite(uv).all(axis=1)
        ok &= (uv[:, 0] >= 0) & (uv[:, 0] < warp.output.width_px) & (uv[:, 1] >= 0) & (uv[:, 1] < warp.output.height_px)
        col, row = np.where(ok, uv[:, 0], 0).astype(np.int64), np.where(ok, uv[:, 1], 0).astype(np.int64)
        inside &= ok & warp.exact[row, col]
    return inside


def calibrated_methods(
    base: RigConfig,
    setup: RigSetup,
    boards: dict[float, list[Capture]],
    *,
    progress: bool,
    warps: dict[str, WarpMap] | None = None,
) -> Iterator[tuple[str, Callable, Rectification, StereoCalibration, int]]:
    """For each method of :data:`METHOD_NAMES`: its projection ``project(camera, capture)`` of a
    capture into a central image, and the rig calibrated and rectified on its own images of the
    chessboard captures ``boards`` (depth -> six captures of :func:`chessboards`), with the number of
    board views found in both images.

    The approximation's camera model is calibrated per camera on the boards at one depth
    (``approx far`` / ``approx near``), with the boards' true corners fixing the model's frame (as
    tests/simulator/test_approx_baseline.py does: a free OpenCV fit of boards at one depth trades
    the focal length against the board distances and the principal point against the port's
    deflection, and its undistorted images leave the frame); ``proposed+distortion`` fits its
    residual distortion on the farthest boards. The rig is calibrated on every board given: the
    approximation's camera model belongs to one depth, the rig's pose to none (boards at one depth
    left the baseline a few per cent off on the small rig's 188 px images). ``warps``: the cameras'
    warp maps if already built (:func:`warp_maps`).
    """
    names = [c.name for c in base.cameras]
    pattern = (SQUARES[0] - 1, SQUARES[1] - 1)
    depths = sorted(boards)
    near, far = depths[0], depths[-1]
    squares = {d: square_size_m(base, setup, d) for d in depths}
    cameras = {c.name: c.scene for c in base.cameras}
    warps = warp_maps(base) if warps is None else warps

    def calibration(name: str, depth: float) -> CalibrationViews:
        pose = cameras[name].pose
        corners = [pose.to_camera(inner_corners_world(table)) for table in chessboards(base, setup, depth)]
        return CalibrationViews(
            raws=[b.raw(name) for b in boards[depth]],
            pattern=pattern,
            square_size_m=squares[depth],
            corners_cam=corners,
        )

    for method in tqdm(METHOD_NAMES, desc="methods (synthesis, stereo)", disable=not progress):
        if method == "ideal":
            outputs = {n: warps[n].output for n in names}

            def project(name, capture):
                return capture.ideal(name)
        else:
            projectors = {}
            for n in names:
                scene = cameras[n]
                if method.startswith("approx"):
                    depth = far if method.endswith("far") else near
                    projectors[n] = build_projector("approx", scene.camera, calibration=calibration(n, depth))
                elif method == "proposed":
                    projectors[n] = build_projector("proposed", scene.camera, scene.port, warp=warps[n])
                else:
                    projectors[n] = build_projector(
                        method, scene.camera, scene.port, warp=warps[n], calibration=calibration(n, far)
                    )
            outputs = {n: projectors[n].output for n in names}

            def project(name, capture, projectors=projectors):
                return projectors[name].apply(capture.raw(name))

        found = [
            (find_corners(project("left", b), pattern), find_corners(project("right", b), pattern), squares[depth])
            for depth in depths
            for b in boards[depth]
        ]
        pairs = [(lft, rgt, square) for lft, rgt, square in found if lft is not None and rgt is not None]
        stereo = calibrate_stereo(
            [p[0] for p in pairs],
            [p[1] for p in pairs],
            [board_points_m(p[2]) for p in pairs],
            left=outputs["left"],
            right=outputs["right"],
        )
        yield method, project, rectify(stereo), stereo, len(pairs)


def render_captures(setup: RigSetup, jobs: list[tuple[str, list[dict]]], work: Path, *, progress: bool) -> dict:
    """Render each ``(name, objects)`` of ``jobs`` into ``work / name`` (reusing matching renders);
    ``{name: Capture}``."""
    return {
        name: render_capture(setup, objects, work / name)
        for name, objects in tqdm(jobs, desc="rendering the rig", unit="capture", disable=not progress)
    }
