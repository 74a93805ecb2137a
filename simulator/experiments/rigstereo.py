"""Stereo rig experiments' common parts: the rig, its captures, the chessboards and the methods' rigs.

``planes`` and ``objects`` render a rig (:mod:`simulator.rig`) in front of chessboards and their
objects, hand the captures to each method of the registry (:mod:`simulator.experiments.methods`)
and, for the methods that make central images, calibrate and rectify the rig on each method's own
images (:func:`prepare_methods`).

Scenes are built from the typed scene objects of :mod:`simulator.config` (:class:`Chessboard`,
:class:`TexturedPlane`, ...): :func:`experiment_rig` is the embedded rig with the experiment's
lights, render settings and options, :func:`with_objects` puts objects in front of it. Frames and
units: metres; the world frame of the rig file; a camera's frame is OpenCV's (docs/conventions.md).
"""

from __future__ import annotations

import dataclasses
import json
import math
import traceback
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lfrefract.errors import ParameterError
from lfrefract.formats.capture import DEPTH_NAME, IDEAL_NAME, RAW_NAME
from lfrefract.formats.exr import read_exr
from lfrefract.methods import CalibrationViews
from lfrefract.optics.pinhole import virtual_camera_for
from lfrefract.optics.port import FlatPort
from lfrefract.stereo.geometry import Rectification, StereoCalibration, calibrate_stereo, rectify
from lfrefract.stereo.matching import sgbm_disparity, zncc_disparity
from lfrefract.synthesis.warp_map import PAPER_K, SynthesisOptions, WarpMap, build_warp_map
from simulator.boards import CALIBRATION_ROTATIONS_DEG, PATTERN, SQUARES, chessboard_corners_world, find_corners
from simulator.config import Chessboard, Placement, PointLight, RenderSettings, SceneObject, main_lens
from simulator.experiments import ExperimentOptions, named_options
from simulator.experiments.kept import kept_render
from simulator.experiments.methods import (
    BUILTIN_METHODS,
    CentralImages,
    DepthMaps,
    MethodCamera,
    MethodRig,
    Shot,
    check_result,
    method_factories,
)
from simulator.rig import RigCamera, RigConfig, Wall, load_rig
from simulator.rig_render import render_rig

__all__ = [
    "BOARD_OFFSETS",
    "LIGHTS",
    "MATCHERS",
    "METHOD_NAMES",
    "WALL_OPTIONS",
    "Capture",
    "PreparedMethod",
    "RigSetup",
    "aim",
    "board_points_m",
    "calibrate_method_rig",
    "capture_signature",
    "chessboards",
    "exact_coverage",
    "experiment_rig",
    "grey",
    "match",
    "prepare_methods",
    "render_capture",
    "render_captures",
    "rig_setup",
    "square_size_m",
    "wall_with_options",
    "warp_maps",
    "with_objects",
]

#: The built-in methods, in table order (the registry, :func:`~simulator.experiments.methods.method_names`,
#: is what an experiment runs).
METHOD_NAMES = tuple(BUILTIN_METHODS)

#: Stereo matchers run on every method's rectified pair: the paper's NCC cost
#: (:func:`lfrefract.stereo.matching.zncc_disparity`) and OpenCV's semi-global matcher
#: (:func:`lfrefract.stereo.matching.sgbm_disparity`), whose smoothness terms hold up better at depth edges.
MATCHERS = ("zncc", "sgbm")

#: Where the calibration boards sit: offsets of their centres from the rig's line of sight as
#: fractions of the depth (their rotations are :data:`simulator.boards.CALIBRATION_ROTATIONS_DEG`:
#: the perspective that fixes the focal length).
BOARD_OFFSETS = ((-0.07, -0.05), (0.07, -0.05), (-0.07, 0.05), (0.07, 0.05), (0.0, 0.0), (0.0, -0.06))

#: The rig experiments' lights: two point lights in the water, in front of the rig and off its axis
#: (world frame, metres; W/sr), brighter than the single-camera board scenes' (the rig's objects
#: are up to 1.5 m away).
LIGHTS = (
    PointLight(position_m=(-0.2, -0.25, 0.1), intensity_w_sr=(0.4, 0.4, 0.4)),
    PointLight(position_m=(0.25, -0.1, 0.08), intensity_w_sr=(0.35, 0.35, 0.35)),
)


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


def rig_setup(rig: RigConfig) -> str:
    """The set-up of a rig figure in one line: the cameras, their baseline and the wall (tilt from the
    world's +z, glass, distance from the world origin, water).

    Parameters
    ----------
    rig : RigConfig

    Returns
    -------
    str
        E.g. ``"default-rig: two tiny-2x cameras 60 mm apart behind a wall tilted 20 deg (4 mm glass,
        15 mm from the rig's origin, water n = 1.333)"``.
    """
    names = [camera.scene.camera.name for camera in rig.cameras]
    counts = {1: "one", 2: "two", 3: "three", 4: "four"}
    if len(set(names)) == 1:
        cameras = f"{counts.get(len(names), len(names))} {names[0]} camera{'s' if len(names) > 1 else ''}"
    else:
        cameras = " and ".join(f"{camera.name} ({name})" for camera, name in zip(rig.cameras, names, strict=True))
    if len(rig.cameras) > 1:
        cameras += f" {np.linalg.norm(rig.relative_pose(1)[1]) * 1e3:.3g} mm apart"
    wall = rig.wall
    tilt = np.degrees(np.arccos(np.clip(wall.normal[2], -1.0, 1.0)))
    return (
        f"{rig.name}: {cameras} behind a wall tilted {tilt:.3g} deg ({wall.thickness_m * 1e3:.3g} mm glass, "
        f"{wall.distance_m * 1e3:.3g} mm from the rig's origin, water n = {wall.n_water:.4g})"
    )


def experiment_rig(setup: RigSetup, options: ExperimentOptions | None = None) -> RigConfig:
    """The embedded rig ``setup.rig`` with the experiment's lights (:data:`LIGHTS`), render settings
    (``setup.spp``, seed 0), no objects, and the options that apply: ``camera`` replaces every
    camera's optics; ``lens`` its main lens (scaled and stopped to the camera); ``port_distance_m``
    / ``thickness_m`` move the wall's air-side plane / change its glass, ``port_tilt_x_deg`` /
    ``port_tilt_y_deg`` turn it (:func:`wall_with_options`), ``n_glass`` / ``n_water`` set its indices
    (each camera's port follows from its pose).

    Raises
    ------
    ParameterError
        If the options make an impossible rig (a camera on the water side of the moved wall, a
        wall without glass).
    """
    rig = load_rig(setup.rig)
    options = options if options is not None else ExperimentOptions()
    names = ("port_distance_m", "thickness_m", *WALL_OPTIONS, "camera", "lens")
    with named_options(options, *names):
        return _rig_with_options(rig, setup, options)


#: The :class:`ExperimentOptions` fields that turn a rig's wall or change its indices.
WALL_OPTIONS = ("port_tilt_x_deg", "port_tilt_y_deg", "n_glass", "n_water")


def wall_with_options(wall: Wall, options: ExperimentOptions) -> Wall:
    """``wall`` as ``options`` change it: ``port_distance_m`` (its air-side plane's offset from the
    world origin), ``thickness_m``, ``n_glass``, ``n_water``, and its tilts ``port_tilt_x_deg`` /
    ``port_tilt_y_deg`` (degrees; the normal ``R_y(tilt_y) R_x(tilt_x) (0, 0, 1)`` in the world frame,
    the port's convention; a tilt not given keeps the wall's own, ``FlatPort.from_normal``'s inverse).
    The very ``wall`` where none is given.

    Raises
    ------
    ParameterError
        For a wall the options make impossible (no glass, an index out of range).
    """
    changes: dict = {
        key: value
        for key, value in (
            ("distance_m", options.port_distance_m),
            ("thickness_m", options.thickness_m),
            ("n_glass", options.n_glass),
            ("n_water", options.n_water),
        )
        if value is not None
    }
    if options.port_tilt_x_deg is not None or options.port_tilt_y_deg is not None:
        own = FlatPort.from_normal(np.asarray(wall.normal), distance_m=1.0)
        tilts = {
            "tilt_x_deg": math.degrees(own.tilt_x_rad) if options.port_tilt_x_deg is None else options.port_tilt_x_deg,
            "tilt_y_deg": math.degrees(own.tilt_y_rad) if options.port_tilt_y_deg is None else options.port_tilt_y_deg,
        }
        changes["normal"] = tuple(FlatPort.from_degrees(distance_m=1.0, **tilts).normal.tolist())
    return dataclasses.replace(wall, **changes) if changes else wall


def _rig_with_options(rig: RigConfig, setup: RigSetup, options: ExperimentOptions) -> RigConfig:
    wall = wall_with_options(rig.wall, options)
    changes = wall is not rig.wall
    cameras = []
    for camera in rig.cameras:
        scene = camera.scene
        optics = scene.camera if options.camera is None else options.camera
        lens = scene.lens if options.lens is None else main_lens(options.lens, optics)
        scene = scene.with_overrides(
            name=f"experiment-{setup.rig}-{camera.name}",
            camera=optics,
            lens=lens,
            port=wall.port_for(scene.pose) if changes else scene.port,
            lights=LIGHTS,
            objects=(),
            # The ideal images at the raw images' spp: the experiments compare the two at equal noise.
            render=RenderSettings(spp=setup.spp, ideal_spp=setup.spp, seed=0),
        )
        cameras.append(RigCamera(camera.name, scene))
    return dataclasses.replace(rig, name=f"experiment-{setup.rig}", wall=wall, cameras=tuple(cameras))


def with_objects(rig: RigConfig, objects: Sequence[SceneObject]) -> RigConfig:
    """``rig`` with ``objects`` (typed scene objects, world frame) in front of every camera."""
    objects = tuple(objects)
    cameras = tuple(RigCamera(c.name, c.scene.with_overrides(objects=objects)) for c in rig.cameras)
    return dataclasses.replace(rig, cameras=cameras)


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
    """Edge of a chessboard square at ``depth_m`` that appears ``setup.px_per_square`` px wide (about)."""
    view = virtual_camera_for(rig.cameras[0].scene.camera)
    water = rig.wall.n_water / rig.wall.n_air
    return setup.px_per_square * depth_m / (water * view.focal_px)


def chessboards(rig: RigConfig, setup: RigSetup, depth_m: float) -> tuple[Chessboard, ...]:
    """The six calibration boards at ``depth_m`` (:data:`BOARD_OFFSETS`, :data:`SQUARES` squares)."""
    centre = aim(rig, depth_m)
    square = square_size_m(rig, setup, depth_m)
    return tuple(
        Chessboard(
            placement=Placement(
                position_m=tuple(centre + depth_m * np.array([dx, dy, 0.0])),
                rotation_xyz_deg=tuple(float(a) for a in rotation),
            ),
            squares=SQUARES,
            square_size_m=square,
        )
        for (dx, dy), rotation in zip(BOARD_OFFSETS, CALIBRATION_ROTATIONS_DEG, strict=True)
    )


@dataclass(frozen=True)
class Capture:
    """One rendered rig capture on disk (a :class:`~simulator.experiments.methods.Shot`); images
    are read when asked for (an Illum raw image is 0.5 GB, and the experiment has thirty)."""

    folder: Path

    def raw(self, camera: str) -> np.ndarray:
        """Camera ``camera``'s raw lenslet image."""
        return read_exr(self.folder / camera / RAW_NAME, role="raw")

    def ideal(self, camera: str) -> np.ndarray:
        """Ground truth: its refraction-free image."""
        return read_exr(self.folder / camera / IDEAL_NAME, role="ideal")

    def depth(self, camera: str) -> np.ndarray:
        """Ground truth: camera z along each pixel of its ideal image, metres (``inf``: no surface)."""
        return read_exr(self.folder / camera / DEPTH_NAME, role="depth")


def _signature(rig: RigConfig) -> list:
    """What a capture of ``rig`` depends on, as plain JSON data (each camera's whole scene)."""
    scenes = [{k: v for k, v in c.scene.to_dict().items() if k != "source"} for c in rig.cameras]
    return json.loads(json.dumps({"wall": rig.wall.to_dict(), "scenes": scenes}))


def capture_signature(rig: RigConfig, *, write_lfr: bool = False) -> dict:
    """What a kept capture of ``rig`` (:func:`render_capture`) is recorded and reused by, as plain JSON
    data: the wall and each camera's whole scene (its port among them), and ``write_lfr``."""
    return {"rig": _signature(rig), "lfr": write_lfr}


def render_capture(rig: RigConfig, folder: Path, *, write_lfr: bool = False) -> Capture:
    """Render ``rig`` into ``folder``, kept if it already holds a render of this very rig (the same
    wall and scenes: cameras, ports, objects, lights, render settings, sensors) with its files as they
    were rendered (:func:`simulator.experiments.kept.kept_render`: sizes and SHA-256s).
    ``write_lfr``: every camera also writes its Lytro file (its scene needs a ``[sensor]``)."""
    signature = capture_signature(rig, write_lfr=write_lfr)
    kept_render(
        folder,
        signature,
        lambda: render_rig(
            rig,
            folder,
            progress=False,
            write_previews=False,
            overwrite=True,
            metadata={"experiment_rig": signature},
            write_lfr=write_lfr,
        ),
    )
    return Capture(folder)


def render_captures(
    rig: RigConfig,
    jobs: Sequence[tuple[str, Sequence[SceneObject]]],
    work: Path,
    *,
    progress: bool,
    write_lfr: bool = False,
    desc: str = "rendering the rig",
) -> dict[str, Capture]:
    """Render ``rig`` with each ``(name, objects)`` of ``jobs`` into ``work / name`` (reusing
    matching renders); ``{name: Capture}``. ``write_lfr``: as :func:`render_capture`."""
    return {
        name: render_capture(with_objects(rig, objects), Path(work) / name, write_lfr=write_lfr)
        for name, objects in tqdm(jobs, desc=desc, unit="capture", disable=not progress)
    }


def board_points_m(square: float) -> np.ndarray:
    """The board's inner corners in its own plane, ``(x, y)`` (N, 2), metres, in the canonical order of
    :func:`simulator.boards.find_corners`."""
    cols, rows = PATTERN
    jj, ii = np.mgrid[0:rows, 0:cols]
    return np.stack([ii.ravel(), jj.ravel()], axis=1) * square


def grey(image: np.ndarray) -> np.ndarray:
    """Channel mean of an (H, W, C) image; an (H, W) image as it is."""
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
    """Each camera's warp map (:func:`lfrefract.synthesis.warp_map.build_warp_map`) with the paper's options.

    The rig experiments reproduce the paper's set-up, so they average :data:`PAPER_K` (32) rays rather
    than the synthesis's default (8, which scores better on images; docs/synthesis.md, "Choosing k").
    """
    options = SynthesisOptions(k=PAPER_K)
    return {c.name: build_warp_map(c.scene.camera, c.scene.port, options=options) for c in rig.cameras}


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


@dataclass(frozen=True, eq=False)
class PreparedMethod:
    """A method set up for the rig: its images and calibrated rig, its depth maps, or its error.

    Attributes
    ----------
    name : str
    images : CentralImages or None
        For a method of central images, with the rig calibrated on them (:attr:`stereo`) and
        rectified (:attr:`rectification`).
    depth : DepthMaps or None
        For a method that estimates depth itself.
    stereo : StereoCalibration or None
    rectification : Rectification or None
    boards : int
        Board views found in both cameras' images (0 for a depth method).
    error : str or None
        Why the method failed (its set-up or the rig calibration on its images), else None.
    """

    name: str
    images: CentralImages | None = None
    depth: DepthMaps | None = None
    stereo: StereoCalibration | None = None
    rectification: Rectification | None = None
    boards: int = 0
    error: str | None = None

    @property
    def ok(self) -> bool:
        """Whether the method is ready to measure."""
        return self.error is None


def describe_error(exc: BaseException) -> str:
    """One line for a failed method's ``error`` column: the exception's type and message, and
    where in the method it was raised."""
    frames = traceback.extract_tb(exc.__traceback__)
    where = f" (at {Path(frames[-1].filename).name}:{frames[-1].lineno})" if frames else ""
    message = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {message}{where}"


def method_rig(base: RigConfig, setup: RigSetup, boards: dict[float, list[Capture]], warps) -> MethodRig:
    """What the method factories are given (:class:`~simulator.experiments.methods.MethodRig`)."""
    depths = sorted(boards)

    def calibration(name: str, depth_m: float) -> CalibrationViews:
        if depth_m not in boards:
            raise ParameterError(f"no chessboards were rendered at depth_m={depth_m!r}; there are some at {depths}")
        scenes = {c.name: c.scene for c in base.cameras}
        if name not in scenes:
            raise ParameterError(f"the rig has no camera {name!r}; it has {list(scenes)}")
        scene = scenes[name]
        tables = chessboards(base, setup, depth_m)
        return CalibrationViews(
            raws=[b.raw(name) for b in boards[depth_m]],
            pattern=PATTERN,
            square_size_m=tables[0].square_size_m,
            corners_cam=[scene.pose.to_camera(chessboard_corners_world(board)) for board in tables],
        )

    cameras = tuple(
        MethodCamera(name=c.name, camera=c.scene.camera, port=c.scene.port, pose=c.scene.pose, warp=warps[c.name])
        for c in base.cameras
    )
    return MethodRig(cameras=cameras, calibration_depths_m=(depths[0], depths[-1]), calibration=calibration)


def prepare_methods(
    base: RigConfig,
    setup: RigSetup,
    boards: dict[float, list[Capture]],
    *,
    methods: Sequence[str] | None = None,
    progress: bool,
    warps: dict[str, WarpMap] | None = None,
) -> Iterator[PreparedMethod]:
    """Set up each method (``methods``, default every registered one, in the registry's order).

    A method of central images gets the rig calibrated and rectified on its own images of the
    chessboard captures ``boards`` (depth -> the six captures of :func:`chessboards`), with the
    number of board views found in both images. The approximation's camera model belongs to one
    depth (its calibration boards), the rig's pose to none: the rig is calibrated on every board
    given (boards at one depth left the baseline a few per cent off on the small rig's 188 px
    images). The approximation is fitted with the boards' true corners fixing the model's frame (as
    tests/simulator/test_approx_baseline.py does: a free OpenCV fit of boards at one depth trades
    the focal length against the board distances and the principal point against the port's
    deflection). A factory, a projection or a rig calibration that raises gives a
    :class:`PreparedMethod` with its error. ``warps``: the cameras' warp maps if already built
    (:func:`warp_maps`).
    """
    factories = method_factories()
    names = tuple(factories) if methods is None else tuple(methods)
    warps = warp_maps(base) if warps is None else warps
    rig = method_rig(base, setup, boards, warps)
    depths = sorted(boards)
    squares = {d: square_size_m(base, setup, d) for d in depths}
    first, second = base.cameras[0].name, base.cameras[1].name
    for name in tqdm(names, desc="methods (set-up, rig calibration)", disable=not progress):
        try:
            if name not in factories:
                raise ParameterError(f"method {name!r} is not registered; registered: {list(factories)}")
            result = check_result(name, factories[name](rig))
        except Exception as exc:  # a failing method is a table row, not a failed run
            yield PreparedMethod(name=name, error=describe_error(exc))
            continue
        if isinstance(result, DepthMaps):
            yield PreparedMethod(name=name, depth=result)
            continue
        shots = [(b, squares[depth]) for depth in depths for b in boards[depth]]
        yield calibrate_method_rig(name, result, shots, cameras=(first, second))


def calibrate_method_rig(
    name: str, images: CentralImages, boards: Sequence[tuple[Shot, float]], *, cameras: tuple[str, str]
) -> PreparedMethod:
    """Calibrate and rectify a stereo pair on a method's own images of chessboard captures.

    Parameters
    ----------
    name : str
        The method's name (for its :class:`PreparedMethod` and errors).
    images : CentralImages
        The method's images; their ``K`` stay fixed in the calibration.
    boards : sequence of (Shot, float)
        Captures of a :data:`~simulator.boards.SQUARES` chessboard and the edge of its squares, metres.
    cameras : (str, str)
        The left and right cameras' names.

    Returns
    -------
    PreparedMethod
        With the calibrated rig and its rectification, or the error that stopped it (a projection
        that raises, fewer than 3 captures with the board found in both images, a failed
        calibration): a failing method is a table row, not a failed run.
    """
    first, second = cameras
    try:
        for camera in (first, second):
            if camera not in images.outputs:
                raise ParameterError(f"method {name!r} gave no output geometry for camera {camera!r}")
        found = [
            (
                find_corners(images.project(first, shot), canonical=True),
                find_corners(images.project(second, shot), canonical=True),
                square,
            )
            for shot, square in boards
        ]
        pairs = [(lft, rgt, square) for lft, rgt, square in found if lft is not None and rgt is not None]
        if len(pairs) < 3:
            raise ParameterError(
                f"the chessboard was found in both images of {len(pairs)} of {len(found)} board captures; "
                "the rig calibration needs 3 or more"
            )
        stereo = calibrate_stereo(
            [p[0] for p in pairs],
            [p[1] for p in pairs],
            [board_points_m(p[2]) for p in pairs],
            left=images.outputs[first],
            right=images.outputs[second],
        )
    except Exception as exc:  # a failing method is a table row, not a failed run
        return PreparedMethod(name=name, error=describe_error(exc))
    return PreparedMethod(name=name, images=images, stereo=stereo, rectification=rectify(stereo), boards=len(pairs))
