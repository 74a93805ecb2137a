"""The ``pipeline`` experiment: a tank experiment from Lytro files alone, against today's oracle.

The simulator stands in for two Lytros and a tank. Through a real main lens (default the double
Gauss, ``ExperimentOptions.lens``) and the sensor model (Bayer mosaic, noise, 10-bit Lytro files) it
renders what a real rig gives and nothing else:

- each camera's white image (:func:`simulator.whites.render_whites`);
- each camera's twenty in-air chessboard captures (:func:`simulator.boards.in_air_boards`, both
  rings), for the camera's ray model;
- each camera's twenty port boards, 0.15-0.35 m behind the wall (:func:`simulator.boards.port_boards`,
  both rings), for its port; the calibration boards average :attr:`PipelineSetup.board_frames`
  exposures, as one does with a board that stands still;
- the stereo rig (:func:`simulator.experiments.planes.setup_for`: the default rig at ``tiny``, the
  Illum rig at ``illum``) behind its tilted glass wall: the six chessboards at a near and a far
  depth (:func:`~simulator.experiments.rigstereo.chessboards`; the rig's calibration),
  two slanted test boards between them (held out: the corner error is measured on them) and the
  ``planes`` experiment's slanted textured plane at its three depths.

Only the Lytro files (``capture.lfr``, the whites' ``.raw`` + ``.txt``) are copied into the core's
input folder, ``delivered/``; it holds no ``meta.json``, no ``lenses.npz``, no truth (checked before
the core runs). The core then runs the documented commands on them, in process
(:func:`lfrefract.cli.main`), per camera: ``calibrate mla`` on the white (the camera's nominal
preset, as a user knows their camera's model), ``calibrate camera`` on the in-air boards,
``calibrate port`` on the wall's boards (the data-only chain with ``--refine-camera``: the ray model
refined together with the port) and ``synth`` of every capture. The rows of ``table.csv``,
one per ``method``:

- ``oracle``: today's pipeline. The same scenes rendered through the thin lens the core models,
  noiseless RGB raw images (``raw.exr``) with their ``meta.json``: the true camera and port;
- ``true-rays``: the real captures' Lytro files (what ``data-only`` reads) with the truth: each
  camera's render ``meta.json`` as ``--camera`` and ``--port``, so the core traces the main lens's
  recorded prescription (:class:`~lfrefract.optics.real_lens.TracedLens`) behind the true port. What
  a perfect calibration would give on these images: the oracle of a real-lens capture, beside which
  ``data-only``'s figures measure its calibration alone (the thin-lens ``oracle`` differs from it also
  by the real lens's blur, the sensor's noise and the mosaic);
- ``data-only``: everything calibrated from the delivered files (MLA, camera ray model, port; the
  ray model and the port refined together on the underwater boards);
- ``thin-lens-assumed``: the old core on the real-lens files: the MLA from the white, the port
  calibrated on the thin-lens model (no camera calibration).

Each chain's captures are synthesized by each of ``ExperimentOptions.methods`` (``--methods``), the
methods of ``lfrefract synth --method``: ``proposed`` (the warp map; the default) and
``depth-aware`` (outside the exact coverage, each pixel rendered at the depth its light field
shows, tracing the chain's own ray model). A method other than ``proposed`` labels its rows
``<chain> <method>`` (e.g. ``data-only depth-aware``); the ``synthesis`` column names it.

For each, the rig is stereo-calibrated on its synthesized images of the twelve boards (OpenCV,
intrinsics fixed to its ``K``), rectified, matched (ZNCC, the paper's cost, and SGBM) and
triangulated, as in ``planes``. Columns (units in the names):

- ``corner_rms_px``: the test boards' corners found in the refraction-free images against the
  projection, by the method's own ``K``, of their true positions in each camera's frame (RMS over
  both test boards and both cameras);
- ``plane_rmse_mm``, ``truth_error_mm``: ``planes``'s measures (ZNCC), averaged over the three
  plane depths; ``planes.csv`` has them per depth and matcher, with completeness and the exact
  coverage's share;
- ``port_normal_err_deg``, ``port_distance_err_mm``: the calibrated port against the camera's true
  one (the wall in its frame), the larger of the two cameras' (``oracle``: given, so 0);
- ``ray_rms_mm``, ``ray_angle_mrad``: the method's ray model of the camera against the simulator's
  true rays (every :data:`RAY_PIXEL_STEP` th raw pixel, chief rays through the microlens centres):
  where they cross the true port's air-side face (RMS over both cameras, in the camera frame, no
  alignment) and the angle between them; ``ray_rms_aligned_mm``: the same up to the one thing in-air
  boards leave free, a shift of the model's frame along its axis (:func:`lfrefract.metrics.ray_errors`
  with ``along_axis``), and ``frame_shift_mm`` that shift (the larger of the cameras');
- ``stereo_rms_px``: the rig calibration's reprojection RMS; ``status`` and ``error``;
- ``test_boards_found``: of the test boards' views, how many the method's images show the board in;
  ``corners_exact_share``: of their corners found, the share on output pixels the method renders
  exactly (its synthesis's classes: exact, or exact given the pixel's depth), the rest from nearby
  rays (a real lens's vignetted pupil narrows its exact cone);
  ``boards_left_out``: the board captures (relative to ``delivered/``) that the method's camera and
  port calibrations left out, their board not located (``lfrefract calibrate``'s ``left_out``).
- ``ray_model``: each camera's ray model as its port and synthesis used it (:func:`ray_model_name`).

The ``data-only`` chain is measured in the frame its calibration can know: boards in air fix a
camera's frame but for its position along the axis, which both ray models put at the main lens's
paraxial entrance pupil (:attr:`~lfrefract.optics.real_lens.RealLensCamera.calibration_origin_cam`:
0.5 mm behind the simulator's camera origin for the double Gauss at ``tiny-2x``, 11 mm in front of
it for the retrofocus design), so its ports, rays, corners and planes are compared with the truth
moved there. The ``oracle`` (a thin lens at the
origin) and ``thin-lens-assumed`` (the nominal thin lens, at the origin) keep the simulator's frame.

``ports.csv`` has a row per calibrated port (method and camera): its normal's and distance's errors
against the true port beside the standard deviations its port file states, and the error's length in
that file's covariance (``port_error_sigmas``).

The output directory keeps what the core wrote that a user would keep (``calibration/<camera>/``:
``mla.json``, ``camera.json``, ``camera-refined.json``, ``port.json``, ``port-thin-lens.json``) and
``commands.txt``, every
core command in order (paths relative to the run's work folder).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import shlex
import shutil
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lfrefract import cli as core_cli
from lfrefract.errors import ParameterError
from lfrefract.figures import new_figure, save_figure
from lfrefract.formats.capture import RAW_NAME, camera_model_from_option, port_from_file
from lfrefract.formats.exr import read_exr
from lfrefract.formats.jsonio import read_json, write_text_atomically
from lfrefract.formats.outputs import scratch_directory
from lfrefract.metrics import ray_errors
from lfrefract.optics.camera import CapturedRays, LightFieldCamera
from lfrefract.optics.camera_model import CameraModel
from lfrefract.optics.lens import LensPrescription
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort
from lfrefract.optics.pose import Pose
from lfrefract.optics.ray_correction import PolynomialCorrection
from lfrefract.optics.real_lens import RealLensCamera
from lfrefract.synthesis.depth_aware import FILLED_EXACT_GIVEN_DEPTH
from lfrefract.synthesis.warp_map import FILLED_EXACT, PAPER_K
from simulator import boards as board_scenes
from simulator.config import (
    THIN_LENS,
    Chessboard,
    Placement,
    PointLight,
    RenderSettings,
    SceneConfig,
    SensorSettings,
    lens_record,
    sensor_model,
)
from simulator.experiments import ExperimentOptions, ExperimentResult, complete_rows, register, write_table
from simulator.experiments.kept import kept_render
from simulator.experiments.methods import CentralImages
from simulator.experiments.planes import (
    PLANE_DEPTHS_M,
    plane_figures,
    plane_in_left,
    plane_rows,
    setup_for,
    textured_plane,
)
from simulator.experiments.rigstereo import (
    MATCHERS,
    WALL_OPTIONS,
    Capture,
    PreparedMethod,
    RigSetup,
    aim,
    calibrate_method_rig,
    chessboards,
    describe_error,
    experiment_rig,
    render_capture,
    rig_setup,
    square_size_m,
    warp_maps,
    with_objects,
)
from simulator.job import LFR_NAME, render_job
from simulator.rig import RigCamera, RigConfig
from simulator.whites import render_whites, white_settings

__all__ = [
    "DEFAULT_LENS",
    "DEFAULT_RAY_MODEL",
    "MEASURES",
    "METHODS",
    "RAY_PIXEL_STEP",
    "SENSORS",
    "TEST_BOARD_DEPTHS_M",
    "PipelineSetup",
    "port_board_scene",
    "ray_model_name",
    "real_rig",
    "row_label",
    "run_pipeline",
    "scene_signature",
    "setup_for_pipeline",
    "summary_figure",
    "synthesis_methods",
]

#: The rows of the table, in order.
METHODS = ("oracle", "true-rays", "data-only", "thin-lens-assumed")
#: The table's measures (NaN in a failed method's row).
MEASURES = (
    "corner_rms_px",
    "plane_rmse_mm",
    "truth_error_mm",
    "port_normal_err_deg",
    "port_distance_err_mm",
    "ray_rms_mm",
    "ray_rms_aligned_mm",
    "frame_shift_mm",
    "ray_angle_mrad",
    "stereo_rms_px",
)
#: The main lens of the real-lens captures unless ``ExperimentOptions.lens`` says otherwise.
DEFAULT_LENS = "double-gauss"
#: The sensor model (a detector preset) of each scale's camera.
SENSORS = {"tiny": "tiny", "illum": "illum"}
#: Depths of the two held-out slanted test boards (world z of their centres), metres, per scale:
#: between the near and far calibration boards.
TEST_BOARD_DEPTHS_M = {"tiny": (0.38, 0.5), "illum": (0.55, 0.8)}
#: The test boards' centres off the rig's line of sight, as fractions of their depth.
TEST_BOARD_OFFSETS = ((0.03, -0.02), (-0.03, 0.02))
#: The test boards' slant (x, y, z Euler angles, degrees): :data:`simulator.boards.SLANT_XYZ_DEG`.
TEST_BOARD_ROTATION_XYZ_DEG = board_scenes.SLANT_XYZ_DEG
#: Every how many raw pixels (along each axis) the ray models are compared with the true rays.
RAY_PIXEL_STEP = {"tiny": 2, "illum": 8}
#: The data-only chain's camera calibration refined with its port (``calibrate port --refine-camera``).
REFINED_CAMERA_NAME = "camera-refined.json"
#: The ray models ``calibrate port --refine-camera`` refines (it refuses a polynomial camera file: the
#: core uses that model as calibrated, docs/calibration.md).
REFINED_RAY_MODELS = ("radial",)
#: The data-only chain's ray model unless ``ExperimentOptions.ray_model`` says otherwise.
DEFAULT_RAY_MODEL = "radial"
#: How the core's command line starts its error message on standard error.
ERROR_PREFIX = "lfrefract: error:"
#: File suffixes a Lytro camera gives (captures and its white images); nothing else is delivered.
LYTRO_SUFFIXES = (".lfr", ".raw", ".txt")


@dataclass(frozen=True)
class PipelineSetup:
    """What the pipeline renders at one scale (beside the rig's :class:`RigSetup`).

    Attributes
    ----------
    rig : RigSetup
        The stereo rig, its boards' depths and size, its spp (``planes``'s).
    sensor : str
        The detector preset of the sensor model.
    white_frames : int
        Exposures averaged into each white image (Lytro's factory whites average many).
    white_spp : int
        Samples per pixel of a white render.
    board_spp : int
        Samples per pixel of a calibration board capture (in air and behind the port). A real capture
        has no Monte Carlo noise: enough samples leave the sensor's noise the one that counts.
    board_frames : int
        Exposures averaged into each calibration board capture, as one averages frames of a board
        that stands still (the sensor's noise falls as the square root).
    """

    rig: RigSetup
    sensor: str
    white_frames: int
    white_spp: int
    board_spp: int
    board_frames: int


def setup_for_pipeline(scale: str) -> PipelineSetup:
    """The pipeline's set-up at ``scale`` (``tiny`` runs in CI; ``illum`` is the paper's camera)."""
    rig = setup_for(scale)
    if scale == "tiny":
        return PipelineSetup(
            rig=rig, sensor=SENSORS[scale], white_frames=16, white_spp=32, board_spp=64, board_frames=8
        )
    return PipelineSetup(rig=rig, sensor=SENSORS[scale], white_frames=8, white_spp=16, board_spp=32, board_frames=8)


# ----------------------------------------------------------------------------------- the scenes
def _with_sensor(rig: RigConfig, sensor: str) -> RigConfig:
    """``rig`` with every camera's sensor model (preset ``sensor``)."""
    cameras = tuple(
        RigCamera(c.name, c.scene.with_overrides(sensor=sensor_model(sensor, c.scene.camera))) for c in rig.cameras
    )
    return dataclasses.replace(rig, cameras=cameras)


def _with_seeds(rig: RigConfig, first_seed: int) -> RigConfig:
    """``rig`` with camera ``i`` rendering (and drawing its noise) with seed ``first_seed + i``."""
    cameras = tuple(
        RigCamera(c.name, c.scene.with_overrides(render=dataclasses.replace(c.scene.render, seed=first_seed + i)))
        for i, c in enumerate(rig.cameras)
    )
    return dataclasses.replace(rig, cameras=cameras)


def _test_boards(rig: RigConfig, setup: RigSetup, scale: str) -> dict[str, Chessboard]:
    """The held-out slanted test boards by capture name."""
    out = {}
    for depth, (dx, dy) in zip(TEST_BOARD_DEPTHS_M[scale], TEST_BOARD_OFFSETS, strict=True):
        centre = aim(rig, depth) + depth * np.array([dx, dy, 0.0])
        out[f"test-{depth:g}"] = Chessboard(
            placement=Placement(position_m=tuple(centre), rotation_xyz_deg=TEST_BOARD_ROTATION_XYZ_DEG),
            squares=board_scenes.SQUARES,
            square_size_m=square_size_m(rig, setup, depth),
        )
    return out


def _rig_jobs(rig: RigConfig, setup: RigSetup, scale: str) -> tuple[list[tuple[str, list]], dict[str, float]]:
    """The rig's captures ``(name, objects)`` and the square size of each board capture, metres."""
    near, far = setup.calibration_depths_m
    jobs: list[tuple[str, list]] = []
    squares = {}
    for depth in (near, far):
        for i, board in enumerate(chessboards(rig, setup, depth)):
            jobs.append((f"board-{depth:g}-{i}", [board]))
            squares[jobs[-1][0]] = board.square_size_m
    for name, board in _test_boards(rig, setup, scale).items():
        jobs.append((name, [board]))
    jobs += [(f"plane-{depth:g}", [textured_plane(rig, depth)]) for depth in PLANE_DEPTHS_M[scale]]
    return jobs, squares


def _board_sensor(camera_scene: SceneConfig, frames: int) -> SensorSettings:
    """``camera_scene``'s sensor model with ``frames`` exposures averaged (a calibration board's)."""
    return SensorSettings(detector=camera_scene.sensor.detector, frames=frames)


def _port_board_scene(camera_scene: SceneConfig, table: dict, spp: int, seed: int, frames: int) -> SceneConfig:
    """A port calibration board (a :func:`simulator.boards.port_boards` table, camera frame) before
    one rig camera alone: its scene in its own frame (identity pose, the wall as its port, the
    lights moved with it), its sensor averaging ``frames`` exposures."""
    pose = camera_scene.pose
    lights = tuple(
        dataclasses.replace(light, position_m=tuple(pose.to_camera(np.array([light.position_m]))[0]))
        if isinstance(light, PointLight)
        else light
        for light in camera_scene.lights
    )
    board = Chessboard(
        placement=Placement(position_m=tuple(table["position_m"]), rotation_xyz_deg=tuple(table["rotation_xyz_deg"])),
        squares=tuple(table["squares"]),
        square_size_m=table["square_size_m"],
    )
    return camera_scene.with_overrides(
        name=f"{camera_scene.name}-port-board",
        pose=Pose(),
        lights=lights,
        objects=(board,),
        render=RenderSettings(spp=spp, ideal_spp=1, seed=seed),
        sensor=_board_sensor(camera_scene, frames),
    )


def port_board_scene(
    options: ExperimentOptions,
    camera_name: str,
    table: dict,
    *,
    seed: int,
    spp: int | None = None,
    frames: int | None = None,
) -> SceneConfig:
    """A port calibration board before one rig camera, as the pipeline renders its port boards for
    ``options`` (the real main lens, the sensor model, the wall as the camera's port): e.g. more boards
    like those of a kept run.

    Parameters
    ----------
    options : ExperimentOptions
        The run's options (scale, ``lens``, the wall's options), as its ``meta.json`` records them.
    camera_name : str
        The rig camera (``"left"``, ``"right"``).
    table : dict
        The board, a :func:`simulator.boards.board_table` (``position_m``, ``rotation_xyz_deg``,
        ``squares``, ``square_size_m``) in that camera's frame: OpenCV axes, metres. The scene is in
        the camera's own frame (identity pose; the rig's lights moved into it), so a pose in the camera
        frame (a calibration's, :func:`lfrefract.calibration.advice.advise_port_views`'s) is its placement.
    seed : int
        The render's seed (its sensor noise's too).
    spp, frames : int, optional
        Samples per pixel and exposures averaged; default the scale's ``board_spp`` and ``board_frames``
        (:func:`setup_for_pipeline`). A run made with others records them (``parameters`` of its meta.json).

    Returns
    -------
    SceneConfig
    """
    setup = setup_for_pipeline(options.scale)
    cameras = {c.name: c for c in real_rig(setup, options).cameras}
    if camera_name not in cameras:
        raise ParameterError(f"camera_name must be one of the rig's cameras {sorted(cameras)}, got {camera_name!r}")
    spp = setup.board_spp if spp is None else spp
    frames = setup.board_frames if frames is None else frames
    return _port_board_scene(cameras[camera_name].scene, table, spp, seed, frames)


def real_rig(setup: PipelineSetup, options: ExperimentOptions) -> RigConfig:
    """The rig of the real captures: ``options``'s main lens (default :data:`DEFAULT_LENS`) and wall,
    each camera with the scale's sensor model (``setup``: :func:`setup_for_pipeline`)."""
    lens = options.lens if options.lens is not None else DEFAULT_LENS
    return _with_sensor(experiment_rig(setup.rig, dataclasses.replace(options, lens=lens)), setup.sensor)


def _focus_distance_m(camera: LightFieldCamera) -> float:
    """The distance the camera focuses on (thin-lens model, from the main lens), metres; inf at infinity."""
    excess = 1.0 / camera.focal_length_m - 1.0 / camera.lens_to_mla_m
    return math.inf if excess <= 0.0 else 1.0 / excess


def _air_board_scene(
    table: dict, camera_scene: SceneConfig, lens: str | LensPrescription, spp: int, seed: int, frames: int
) -> SceneConfig:
    """An in-air board before ``camera_scene``'s camera, through ``lens``, with its sensor model
    averaging ``frames`` exposures."""
    config = board_scenes.in_air_board_scene(table, lens=lens, spp=spp, seed=seed, camera=camera_scene.camera.name)
    return config.with_overrides(camera=camera_scene.camera, sensor=_board_sensor(camera_scene, frames))


# ------------------------------------------------------------------------------------- the core
class _Core:
    """Runs the core's command line in process, records each command, fails with its message.

    ``roots``: folders and the names they are shown by in the record (paths inside one are
    written relative to it, after its name)."""

    def __init__(self, roots: dict[Path, str], log: list[str]):
        self.roots = roots
        self.log = log

    def _shown(self, arg: str) -> str:
        path = Path(arg)
        for root, name in self.roots.items():
            if path.is_absolute() and path.is_relative_to(root):
                return str(Path(name) / path.relative_to(root))
        return arg

    def __call__(self, *argv: str) -> str:
        argv_list = [str(a) for a in argv]
        self.log.append("lfrefract " + " ".join(shlex.quote(self._shown(a)) for a in argv_list))
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = core_cli.main(argv_list)
        if status != 0:
            message = " ".join(err.getvalue().split()) or f"exit status {status}"
            # the refusal itself, not the notes on every capture before it (the calibration files keep those)
            message = message[message.rfind(ERROR_PREFIX) :] if ERROR_PREFIX in message else message
            raise RuntimeError(f"lfrefract {argv_list[0]} {argv_list[1] if len(argv_list) > 1 else ''}: {message}")
        return out.getvalue()


def _check_delivered(folder: Path) -> list[str]:
    """The files of ``folder`` (relative, sorted); :class:`ParameterError` for anything a Lytro
    camera does not give (truth must not cross over to the core)."""
    files = sorted(p for p in folder.rglob("*") if p.is_file())
    foreign = [p for p in files if p.suffix.lower() not in LYTRO_SUFFIXES]
    if foreign:
        raise ParameterError(f"the core's input folder holds files a camera does not give: {foreign[:5]}")
    return [str(p.relative_to(folder)) for p in files]


# --------------------------------------------------------------------------------------- the run
def run_pipeline(
    out_dir: Path,
    *,
    options: ExperimentOptions | None = None,
    progress: bool = True,
    renders_dir: Path | None = None,
) -> ExperimentResult:
    """Run the experiment (see the module docstring); figures and the core's outputs go to ``out_dir``.

    ``options``: the scale, ``lens`` (the real captures' main lens, default :data:`DEFAULT_LENS`;
    ``"thin"`` makes the data-only chain calibrate a camera that is what the core models),
    ``port_distance_m``, ``thickness_m``, ``port_tilt_x_deg``, ``port_tilt_y_deg``, ``n_glass`` and
    ``n_water`` (the rig's wall: :func:`~simulator.experiments.rigstereo.wall_with_options`) and
    ``ray_model`` (the data-only chain's, default :data:`DEFAULT_RAY_MODEL`; the ``ray_model``
    column and ``ports.csv``, each calibrated port against the truth with its stated standard
    deviations, say what was used and found) and ``methods`` (:func:`synthesis_methods`).
    ``renders_dir``: keep the renders there and reuse those that match on a later run (default: a
    temporary directory, deleted).
    """
    options = options if options is not None else ExperimentOptions()
    # The core's input folder and its products live in a fresh temporary folder of every run: nothing
    # in renders_dir (the caller's) is ever deleted, and no earlier run's copy can reach the core.
    with (
        scratch_directory(prefix="lfsim-pipeline-") as tmp,
        scratch_directory(prefix="lfsim-pipeline-core-") as scratch,
    ):
        work = Path(tmp) if renders_dir is None else Path(renders_dir)
        return _run(Path(out_dir), options, work, Path(scratch), progress=progress)


@dataclass(frozen=True)
class _Rendered:
    """What :func:`_render` made.

    Attributes
    ----------
    setup : PipelineSetup
        The scale's set-up.
    lens : str or LensPrescription
        The real captures' main lens: a preset's name or a design (``ExperimentOptions.lens``).
    thin, real : RigConfig
        The oracle's rig (thin lens, no sensor model) and the real one (``lens``, the sensor model).
    jobs : list of (str, list)
        The rig's captures, ``(name, objects)``.
    squares : dict of str to float
        The square size of each rig board capture, metres.
    air_squares : list of float
        The square size of each in-air board (the same boards before every camera), metres.
    port_squares : dict of str to list of float
        The square size of each port board by camera, metres.
    oracle, captures : dict of str to Capture
        The rig's captures by name: the thin-lens renders (raw.exr, meta.json) and the real ones.
    """

    setup: PipelineSetup
    lens: str | LensPrescription
    thin: RigConfig
    real: RigConfig
    jobs: list[tuple[str, list]]
    squares: dict[str, float]
    air_squares: list[float]
    port_squares: dict[str, list[float]]
    oracle: dict[str, Capture]
    captures: dict[str, Capture]


#: Seeds set aside for each camera's white images (one per zoom / focus setting; the pipeline renders
#: one setting, the block leaves room for more without moving every later seed).
WHITE_SEEDS_PER_CAMERA = 16


class _Seeds:
    """Hands out consecutive blocks of render seeds, so no two renders share one."""

    def __init__(self, first: int):
        self._next = first

    def block(self, size: int) -> int:
        """The first seed of a fresh block of ``size``."""
        first, self._next = self._next, self._next + size
        return first


def _render(options: ExperimentOptions, work: Path, delivered: Path, *, progress: bool) -> _Rendered:
    """Render the oracle's and the real captures into ``work / "renders"``; copy the Lytro files into
    ``delivered`` (a new folder)."""
    scale = options.scale
    setup = setup_for_pipeline(scale)
    lens = options.lens if options.lens is not None else DEFAULT_LENS
    experiment_rig(setup.rig, options)  # the user's options alone first: an impossible rig names only their flags
    thin = experiment_rig(setup.rig, dataclasses.replace(options, lens=THIN_LENS))
    real = real_rig(setup, options)
    jobs, squares = _rig_jobs(thin, setup.rig, scale)
    renders = work / "renders"
    oracle, captures = {}, {}
    seeds = _Seeds(1)
    cameras = len(real.cameras)
    bar = tqdm(total=2 * len(jobs), desc="rendering the rig", unit="capture", disable=not progress)
    for name, objects in jobs:
        oracle[name] = render_capture(with_objects(thin, objects), renders / "oracle" / name)
        bar.update()
        seeded = _with_seeds(with_objects(real, objects), seeds.block(cameras))
        captures[name] = render_capture(seeded, renders / "real" / name, write_lfr=True)
        bar.update()
    bar.close()
    for camera in real.cameras:
        for name, capture in captures.items():
            target = delivered / "rig" / camera.name / f"{name}.lfr"
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(capture.folder / camera.name / LFR_NAME, target)
    whites_first = seeds.block(cameras * WHITE_SEEDS_PER_CAMERA)
    for i, camera in enumerate(real.cameras):
        scene = camera.scene
        sensor = SensorSettings(detector=scene.sensor.detector, frames=setup.white_frames)
        whites = renders / "whites" / camera.name
        settings = white_settings(scene.camera, focus_distances_m=(_focus_distance_m(scene.camera),))
        if len(settings) > WHITE_SEEDS_PER_CAMERA:
            raise ParameterError(f"at most {WHITE_SEEDS_PER_CAMERA} white settings per camera, got {len(settings)}")
        white_seed = whites_first + i * len(settings)  # setting k renders with white_seed + k
        _once(
            whites,
            {
                "camera": scene.camera.to_dict(),
                "settings": [dataclasses.asdict(x) for x in settings],
                "sensor": sensor.to_dict(),
                "lens": lens_record(lens),
                "spp": setup.white_spp,
                "seed": white_seed,
            },
            lambda scene=scene, whites=whites, sensor=sensor, settings=settings, white_seed=white_seed: render_whites(
                whites,
                camera=scene.camera,
                settings=settings,
                sensor=sensor,
                lens=None if lens == THIN_LENS else lens,
                spp=setup.white_spp,
                seed=white_seed,
                overwrite=True,
                progress=False,
            ),
        )
        for white in whites.iterdir():
            if white.suffix in (".raw", ".txt"):
                (delivered / "whites" / camera.name).mkdir(parents=True, exist_ok=True)
                shutil.copyfile(white, delivered / "whites" / camera.name / white.name)
    view = virtual_camera_for(real.cameras[0].scene.camera)
    air_boards = board_scenes.in_air_boards(view, outer_ring=True)
    air_squares = [table["square_size_m"] for table in air_boards]
    for camera in real.cameras:
        first = seeds.block(len(air_boards))
        for k, table in enumerate(tqdm(air_boards, desc=f"in-air boards ({camera.name})", disable=not progress)):
            config = _air_board_scene(table, camera.scene, lens, setup.board_spp, first + k, setup.board_frames)
            _render_and_deliver(config, renders / "air" / camera.name / f"board-{k}", delivered / "air" / camera.name)
    port_squares = {}
    for camera in real.cameras:
        tables = board_scenes.port_boards(camera.scene.port, virtual_camera_for(camera.scene.camera), outer_ring=True)
        port_squares[camera.name] = [table["square_size_m"] for table in tables]
        first = seeds.block(len(tables))
        for k, table in enumerate(tqdm(tables, desc=f"port boards ({camera.name})", disable=not progress)):
            config = _port_board_scene(camera.scene, table, setup.board_spp, first + k, setup.board_frames)
            _render_and_deliver(config, renders / "port" / camera.name / f"board-{k}", delivered / "port" / camera.name)
    return _Rendered(setup, lens, thin, real, jobs, squares, air_squares, port_squares, oracle, captures)


def scene_signature(config: SceneConfig) -> dict:
    """What a kept render of one scene (a calibration board's) is recorded and reused by: the whole
    scene as plain data (camera, main lens, port, objects, lights, render and sensor settings), its
    source file left out."""
    return {k: v for k, v in config.to_dict().items() if k != "source"}


def _render_and_deliver(config: SceneConfig, folder: Path, delivered: Path) -> None:
    """Render ``config`` into ``folder`` (kept if it holds this scene's render) and copy its Lytro file
    into ``delivered`` as ``<folder name>.lfr``."""
    _once(
        folder,
        scene_signature(config),
        lambda: render_job(config, folder, progress=False, write_previews=False, write_lfr=True, overwrite=True),
    )
    delivered.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(folder / LFR_NAME, delivered / f"{folder.name}.lfr")


def _once(folder: Path, signature, render) -> None:
    """Call ``render()`` to (re)make ``folder`` unless it was made for the same ``signature`` and its
    files are as they were rendered (:func:`simulator.experiments.kept.kept_render`)."""
    kept_render(folder, signature, render)


def _synth_all(
    core: _Core,
    captures: dict[str, Path],
    model_args: Sequence[str],
    products: Path,
    chain: str,
    camera: str,
    syntheses: Sequence[str],
    models: _Models,
) -> None:
    """``lfrefract synth --method M`` of each capture (name -> raw file) for each of ``syntheses``
    into ``products/synth/<M>/<chain>/<camera>/<name>.exr``, k = the paper's 32 (the warp maps
    cached in ``products/maps``). A synthesis method that fails is noted in ``models`` for that method
    (:meth:`_Models.fail_synthesis`); the other methods still run."""
    for synthesis in syntheses:
        out = products / "synth" / synthesis / chain / camera
        out.mkdir(parents=True, exist_ok=True)
        try:
            for name, raw in captures.items():
                target = out / f"{name}.exr"
                method = ["--method", synthesis, "--quiet", "--map-cache", products / "maps"]
                core("synth", raw, *model_args, "--k", PAPER_K, *method, "--out", target)
        except Exception as exc:  # this method's rows fail; the chain's others stand
            models.fail_synthesis(synthesis, camera, exc)


def _images(synth_dir: Path, cameras: Sequence[str], reference: str) -> CentralImages:
    """A method's synthesized images (``synth_dir/<camera>/<capture>.exr``) as central images; their
    ``K`` from the synth sidecar of capture ``reference``. A shot's folder name names its capture."""
    outputs = {}
    for camera in cameras:
        meta = read_json(synth_dir / camera / f"{reference}.json")
        k = np.asarray(meta["K"], dtype=np.float64)
        outputs[camera] = PinholeCamera(
            focal_px=float(k[0, 0]),
            cx_px=float(k[0, 2]),
            cy_px=float(k[1, 2]),
            width_px=int(meta["width_px"]),
            height_px=int(meta["height_px"]),
        )

    def project(camera: str, shot) -> np.ndarray:
        # synth writes NaN where a pixel has no value; OpenCV's corner finders and matchers take 0,
        # what the in-memory synthesis gives there (WarpMap.apply).
        image = read_exr(synth_dir / camera / f"{shot.folder.name}.exr", role="refraction_free")
        return np.nan_to_num(image, nan=0.0)

    return CentralImages(outputs=outputs, project=project)


@dataclass
class _Models:
    """One method's models of each camera, filled as its chain runs."""

    ports: dict[str, FlatPort] = dataclasses.field(default_factory=dict)
    rays: dict[str, CapturedRays] = dataclasses.field(default_factory=dict)
    error: str | None = None
    #: Board captures its calibrations left out (board not located), relative to ``delivered/``.
    left_out: list[str] = dataclasses.field(default_factory=list)
    #: Each camera's port calibration file (``lfrefract calibrate port --out``).
    port_files: dict[str, Path] = dataclasses.field(default_factory=dict)
    #: Each camera's ray model as the chain's port and synthesis used it (:func:`ray_model_name`).
    ray_models: dict[str, str] = dataclasses.field(default_factory=dict)

    #: Synthesis methods that failed (method -> what failed, per camera): only their rows fail.
    synthesis_errors: dict[str, str] = dataclasses.field(default_factory=dict)

    def fail(self, camera: str, exc: BaseException) -> None:
        """Note that the chain failed for ``camera`` (the other cameras' chains still run, so that each
        camera's calibrations are reported)."""
        failure = f"{camera}: {describe_error(exc)}"
        self.error = failure if self.error is None else f"{self.error}; {failure}"

    def fail_synthesis(self, synthesis: str, camera: str, exc: BaseException) -> None:
        """Note that synthesis method ``synthesis`` failed for ``camera`` (the chain's calibrations and
        its other methods stand)."""
        failure = f"{camera}: {describe_error(exc)}"
        earlier = self.synthesis_errors.get(synthesis)
        self.synthesis_errors[synthesis] = failure if earlier is None else f"{earlier}; {failure}"

    def error_of(self, synthesis: str) -> str | None:
        """Why the rows of synthesis method ``synthesis`` failed (the chain's error first); None if not."""
        return self.error if self.error is not None else self.synthesis_errors.get(synthesis)

    def note_left_out(self, calibration: Path, delivered: Path) -> None:
        """Add the captures that the calibration file ``calibration`` lists as left out."""
        for item in read_json(calibration)["left_out"]:
            self.left_out.append(Path(item["source"]).relative_to(delivered).as_posix())


def _numbered(folder: Path) -> list[Path]:
    """The ``board-<k>.lfr`` files of ``folder`` in the order of ``k``."""
    return sorted(folder.glob("board-*.lfr"), key=lambda p: int(p.stem.split("-")[-1]))


def ray_model_name(model: CameraModel) -> str:
    """The ray model of a camera calibration's model as reports name it: ``"radial"``, or the generic
    model's member its calibration chose (:attr:`PolynomialCorrection.name`: ``"symmetric-D"`` or
    ``"polynomial-D-Da"``, total degree ``D`` and degree ``Da`` in the aperture point, the file's
    ``correction.degree`` and ``correction.aperture_degree``)."""
    correction = model.correction
    return correction.name if isinstance(correction, PolynomialCorrection) else "radial"


def synthesis_methods(options: ExperimentOptions) -> tuple[str, ...]:
    """The synthesis methods every chain's captures go through (``lfrefract synth --method``):
    ``options.methods``, each one of :data:`lfrefract.cli.SYNTH_METHODS`, default the first
    (``proposed``); :class:`ParameterError` naming ``--methods`` for another name."""
    if options.methods is None:
        return core_cli.SYNTH_METHODS[:1]
    for name in options.methods:
        if name not in core_cli.SYNTH_METHODS:
            raise ParameterError(
                f"--methods: the pipeline synthesizes with lfrefract synth's methods {list(core_cli.SYNTH_METHODS)}, "
                f"got {name!r}"
            )
    return tuple(options.methods)


def row_label(chain: str, synthesis: str) -> str:
    """A table row's ``method``: the chain (:data:`METHODS`), followed by the synthesis method
    where that is not the default ``proposed`` (e.g. ``"data-only depth-aware"``)."""
    return chain if synthesis == core_cli.SYNTH_METHODS[0] else f"{chain} {synthesis}"


def _refinement_note(refined: Path | None) -> str:
    """How a ray model relates to its port, for the ``ray_model`` column: ``""`` (no refinement asked),
    ``" refined with the port"``, or ``" in-air (its refinement rejected)"`` where ``calibrate port
    --refine-camera`` kept the in-air model (the refined one did no better on held-back boards; the
    file's ``refinement.accepted``)."""
    if refined is None:
        return ""
    accepted = read_json(refined).get("refinement", {}).get("accepted", True)
    return " refined with the port" if accepted else " in-air (its refinement rejected)"


def _core_stage(
    core: _Core,
    delivered: Path,
    products: Path,
    cal_out: Path,
    runs: dict,
    *,
    ray_model: str,
    syntheses: Sequence[str],
) -> dict[str, _Models]:
    """The data-only and thin-lens-assumed chains, per camera, on the delivered files only; the
    data-only chain's camera with ``ray_model`` (``calibrate camera --ray-model``), refined with its
    port where the core takes it (the radial model: ``calibrate port --refine-camera``; the core
    uses the polynomial model as calibrated)."""
    models = {"data-only": _Models(), "thin-lens-assumed": _Models()}
    board_args = ["--squares", *map(str, board_scenes.SQUARES)]
    for camera, run in runs.items():
        whites = delivered / "whites" / camera
        rig = delivered / "rig" / camera
        out = cal_out / camera
        out.mkdir(parents=True, exist_ok=True)
        mla, camera_json = out / "mla.json", out / "camera.json"
        try:
            white = sorted(whites.glob("*.raw"))[0]
            core("calibrate", "mla", white, "--camera", run["preset"], "--out", mla)
        except Exception as exc:  # both chains need the MLA
            for chain in models.values():
                chain.fail(camera, exc)
            continue
        air = _numbered(delivered / "air" / camera)
        chains = {"data-only": camera_json, "thin-lens-assumed": mla}
        for method, model in chains.items():
            chain = models[method]
            try:
                if method == "data-only":
                    sizes = [str(s) for s in run["air_squares"]]
                    core(
                        "calibrate",
                        "camera",
                        *air,
                        "--camera",
                        mla,
                        "--white",
                        whites,
                        *board_args,
                        "--square-size-m",
                        *sizes,
                        "--ray-model",
                        ray_model,
                        "--out",
                        camera_json,
                    )
                    chain.note_left_out(camera_json, delivered)
                port = out / ("port.json" if method == "data-only" else "port-thin-lens.json")
                boards = _numbered(delivered / "port" / camera)
                sizes = [str(s) for s in run["port_squares"]]
                # data-only: the ray model refined with the port (what the underwater boards say of it),
                # where the core refines it (the radial model)
                refined = method == "data-only" and ray_model in REFINED_RAY_MODELS
                refine = ["--refine-camera", out / REFINED_CAMERA_NAME] if refined else []
                # The thin-lens baseline is the old core on a real lens: its boards disagree with each other and
                # the port's honest uncertainty is beyond calibrate port's default limits; as the old core
                # did, it is accepted whatever its spread, and its errors are what the table shows.
                limits = (
                    ["--max-normal-std-deg", "90", "--max-distance-std-m", "1"] if method == "thin-lens-assumed" else []
                )
                core(
                    "calibrate",
                    "port",
                    *boards,
                    "--camera",
                    model,
                    "--white",
                    whites,
                    *board_args,
                    "--square-size-m",
                    *sizes,
                    *run["glass"],
                    *refine,
                    *limits,
                    "--out",
                    port,
                )
                chain.note_left_out(port, delivered)
                model = out / REFINED_CAMERA_NAME if refine else model
                captures = {p.stem: p for p in sorted(rig.glob("*.lfr"))}
                args = ["--white", whites, "--camera", model, "--port", port]
                _synth_all(core, captures, args, products, method, camera, syntheses, chain)
                chain.ports[camera] = port_from_file(port)
                chain.port_files[camera] = port
                given = camera_model_from_option(model)
                if method == "data-only":
                    chain.ray_models[camera] = ray_model_name(given) + _refinement_note(model if refine else None)
                    chain.rays[camera] = given.captured_rays(run["uv"])
                else:
                    chain.ray_models[camera] = "thin lens"
                    chain.rays[camera] = given.camera.captured_rays(run["uv"])
            except Exception as exc:  # a failing chain is a table row, not a failed run
                chain.fail(camera, exc)
    return models


def _oracle_stage(
    core: _Core,
    oracle: dict[str, Capture],
    thin: RigConfig,
    products: Path,
    uv: np.ndarray,
    syntheses: Sequence[str],
) -> _Models:
    """Today's pipeline: ``synth`` of the thin-lens renders' noiseless raw images with their meta.json."""
    models = _Models()
    try:
        for camera in thin.cameras:
            captures = {name: capture.folder / camera.name / RAW_NAME for name, capture in oracle.items()}
            _synth_all(core, captures, [], products, "oracle", camera.name, syntheses, models)
            models.ports[camera.name] = camera.scene.port
            models.rays[camera.name] = camera.scene.camera.captured_rays(uv)
            models.ray_models[camera.name] = "true thin lens"
    except Exception as exc:  # a failing chain is a table row, not a failed run
        models.error = describe_error(exc)
    return models


def _true_rays_stage(
    core: _Core,
    delivered: Path,
    captures: dict[str, Capture],
    real: RigConfig,
    products: Path,
    uv: np.ndarray,
    syntheses: Sequence[str],
) -> _Models:
    """``synth`` of the real captures' Lytro files (``delivered``) with the truth: each camera's render
    ``meta.json`` as its camera (the recorded main lens traced) and port."""
    models = _Models()
    first = next(iter(captures.values()))
    for camera in real.cameras:
        try:
            meta = first.folder / camera.name / "meta.json"
            files = {name: delivered / "rig" / camera.name / f"{name}.lfr" for name in captures}
            args = ["--white", delivered / "whites" / camera.name, "--camera", meta, "--port", meta]
            _synth_all(core, files, args, products, "true-rays", camera.name, syntheses, models)
            model = camera_model_from_option(meta)
            models.ports[camera.name] = camera.scene.port
            models.rays[camera.name] = model.captured_rays(uv)
            models.ray_models[camera.name] = "true thin lens" if model.correction is None else model.correction.name
        except Exception as exc:  # a failing chain is a table row, not a failed run
            models.fail(camera.name, exc)
    return models


def _true_rays(rig: RigConfig, uv: np.ndarray) -> dict[str, CapturedRays]:
    """Each camera's true rays through its main lens (thin or real) at raw pixels ``uv`` (N, 2)."""
    out = {}
    for camera in rig.cameras:
        scene = camera.scene
        if scene.lens is None:
            out[camera.name] = scene.camera.captured_rays(uv)
        else:
            out[camera.name] = RealLensCamera(camera=scene.camera, lens=scene.lens).chief_rays(uv)
    return out


def _origins(rig: RigConfig, *, moved: bool) -> dict[str, np.ndarray]:
    """Each camera's frame origin for the measures: where a calibration puts it
    (:attr:`~simulator.config.SceneConfig.calibration_origin_cam`) where ``moved``, else the
    simulator's origin."""
    return {c.name: c.scene.calibration_origin_cam if moved else np.zeros(3) for c in rig.cameras}


def _port_errors(ports: dict[str, FlatPort], truth: RigConfig, origins: dict[str, np.ndarray]) -> tuple[float, float]:
    """(normal angle, deg; distance, mm) of the calibrated ports against the true ones (each camera's
    moved to ``origins``), the larger of the cameras'."""
    angles, distances = [], []
    for camera in truth.cameras:
        true, port = camera.scene.port.seen_from(origins[camera.name]), ports[camera.name]
        angles.append(math.degrees(math.acos(float(np.clip(np.dot(true.normal, port.normal), -1.0, 1.0)))))
        distances.append(abs(port.distance_m - true.distance_m) * 1e3)
    return max(angles), max(distances)


def _port_rows(models: dict[str, _Models], truth: RigConfig, origins: dict[str, dict[str, np.ndarray]]) -> list[dict]:
    """Each calibrated port (the methods that calibrate one) against its camera's true one (moved to
    the method's ``origins``), with the uncertainty its calibration states: one row per method and
    camera (the columns of ``ports.csv``)."""
    rows = []
    for method in METHODS:
        chain = models[method]
        for camera in truth.cameras:
            if camera.name not in chain.port_files:
                continue
            if camera.scene.port is None:  # a rig camera's scene has the wall as its port
                raise ParameterError(f"rig camera {camera.name!r} has no port to measure its calibration against")
            true, port = camera.scene.port.seen_from(origins[method][camera.name]), chain.ports[camera.name]
            data = read_json(chain.port_files[camera.name])
            # (tilt_x_rad, tilt_y_rad, distance_m): the order of the port file's covariance
            delta = np.array([port.tilt_x_rad, port.tilt_y_rad, port.distance_m])
            delta -= np.array([true.tilt_x_rad, true.tilt_y_rad, true.distance_m])
            covariance = np.asarray(data["covariance"], dtype=np.float64)
            parts = data.get("covariance_parts", {})
            model_part = np.asarray(parts.get("camera_model", np.zeros((3, 3))), dtype=np.float64)
            rows.append(
                {
                    "method": method,
                    "camera": camera.name,
                    "ray_model": chain.ray_models[camera.name],
                    "port_normal_err_deg": math.degrees(
                        math.acos(float(np.clip(np.dot(true.normal, port.normal), -1.0, 1.0)))
                    ),
                    "port_normal_std_deg": float(data["normal_std_deg"]),
                    "port_distance_err_mm": delta[2] * 1e3,
                    "port_distance_std_mm": float(data["distance_std_m"]) * 1e3,
                    "port_error_sigmas": float(np.sqrt(delta @ np.linalg.lstsq(covariance, delta, rcond=None)[0])),
                    "camera_model_distance_share": float(model_part[2, 2] / covariance[2, 2]),
                    "port_rms_px": float(data["rms_px"]),
                }
            )
    return rows


def _ray_measures(
    rays: dict[str, CapturedRays], true: dict[str, CapturedRays], truth: RigConfig, origins: dict[str, np.ndarray]
) -> dict:
    """The ray models against the true rays (each camera's moved to ``origins``) at each true port's
    air-side face, RMS over the cameras."""
    positions, aligned, shifts, angles = [], [], [], []
    for camera in truth.cameras:
        origin = origins[camera.name]
        model, ref, port = rays[camera.name], true[camera.name], camera.scene.port.seen_from(origin)
        pair = (model.origins_cam, model.directions_cam, ref.origins_cam - origin, ref.directions_cam)
        where = {
            "plane_normal": port.normal,
            "plane_distance_m": port.distance_m,
            "valid": model.in_aperture & ref.in_aperture,
        }
        errors, moved = ray_errors(*pair, **where), ray_errors(*pair, **where, along_axis=True)
        positions.append(errors.position_rms_m)
        aligned.append(moved.position_rms_m)
        shifts.append(moved.axis_shift_m)
        angles.append(errors.angle_rms_rad)
    rms = lambda values: float(np.sqrt(np.mean(np.square(values))))  # noqa: E731
    return {
        "ray_rms_mm": rms(positions) * 1e3,
        "ray_rms_aligned_mm": rms(aligned) * 1e3,
        "frame_shift_mm": max(shifts, key=abs) * 1e3,
        "ray_angle_mrad": rms(angles) * 1e3,
    }


def _corner_measures(
    images: CentralImages,
    shots: dict[str, Capture],
    tests: dict[str, Chessboard],
    rig: RigConfig,
    origins: dict[str, np.ndarray],
    synth_dir: Path,
) -> dict:
    """The test boards' corners in the method's images (``synth_dir/<camera>/<capture>.exr``) against
    their true projections by its ``K`` from each camera's ``origins``, and the share of the corners
    found whose output pixel the method renders exactly (its ``.filled.exr`` class: exact, or exact
    given its depth)."""
    squared, found, total, exact = [], 0, 0, []
    for name, board in tests.items():
        world = board_scenes.chessboard_corners_world(board)
        for camera in rig.cameras:
            total += 1
            corners = board_scenes.find_corners(images.project(camera.name, shots[name]))
            if corners is None:
                continue
            found += 1
            expected = images.outputs[camera.name].project(camera.scene.pose.to_camera(world) - origins[camera.name])
            squared.append(np.sum(board_scenes.aligned_errors_px(corners, expected) ** 2, axis=1))
            classes = np.asarray(read_exr(synth_dir / camera.name / f"{shots[name].folder.name}.filled.exr"))
            classes = classes[..., 0] if classes.ndim == 3 else classes
            col, row = np.clip(np.rint(corners).astype(int), 0, [classes.shape[1] - 1, classes.shape[0] - 1]).T
            exact.append(np.isin(classes[row, col], (FILLED_EXACT, FILLED_EXACT_GIVEN_DEPTH)))
    rms = float(np.sqrt(np.mean(np.concatenate(squared)))) if squared else math.nan
    share = float(np.mean(np.concatenate(exact))) if exact else math.nan
    return {"corner_rms_px": rms, "test_boards_found": f"{found}/{total}", "corners_exact_share": share}


def _run(out_dir: Path, options: ExperimentOptions, work: Path, scratch: Path, *, progress: bool) -> ExperimentResult:
    """Render (into ``work``), run the core on the delivered files, measure; see :func:`run_pipeline`."""
    scale = options.scale
    syntheses = synthesis_methods(options)
    seconds = {}
    start = time.perf_counter()
    delivered, products = scratch / "delivered", scratch / "core"
    rendered = _render(options, work, delivered, progress=progress)
    setup, lens, thin, real = rendered.setup, rendered.lens, rendered.thin, rendered.real
    jobs, squares, oracle, captures = rendered.jobs, rendered.squares, rendered.oracle, rendered.captures
    seconds["render_s"] = time.perf_counter() - start
    files = _check_delivered(delivered)
    step = RAY_PIXEL_STEP[scale]
    sensor = real.cameras[0].scene.camera.sensor
    vv, uu = np.mgrid[0 : sensor.height_px : step, 0 : sensor.width_px : step]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
    wall = real.wall
    glass = ["--thickness-m", str(wall.thickness_m), "--n-glass", str(wall.n_glass), "--n-water", str(wall.n_water)]
    runs = {
        c.name: {
            "preset": c.scene.camera.name,
            "air_squares": rendered.air_squares,
            "port_squares": rendered.port_squares[c.name],
            "glass": glass,
            "uv": uv,
        }
        for c in real.cameras
    }
    log: list[str] = []
    core = _Core({delivered: "delivered", products: "core", work: "", out_dir: "out"}, log)
    start = time.perf_counter()
    models = {"oracle": _oracle_stage(core, oracle, thin, products, uv, syntheses)}
    seconds["oracle_core_s"] = time.perf_counter() - start
    start = time.perf_counter()
    models["true-rays"] = _true_rays_stage(core, delivered, captures, real, products, uv, syntheses)
    seconds["true_rays_core_s"] = time.perf_counter() - start
    start = time.perf_counter()
    ray_model = options.ray_model if options.ray_model is not None else DEFAULT_RAY_MODEL
    cal_out = out_dir / "calibration"
    models |= _core_stage(core, delivered, products, cal_out, runs, ray_model=ray_model, syntheses=syntheses)
    seconds["data_core_s"] = time.perf_counter() - start

    start = time.perf_counter()
    true_rays = {"oracle": _true_rays(thin, uv)}
    true_rays["true-rays"] = true_rays["data-only"] = true_rays["thin-lens-assumed"] = _true_rays(real, uv)
    warps = warp_maps(thin)
    tests = _test_boards(thin, setup.rig, scale)
    plane_depths = PLANE_DEPTHS_M[scale]
    truth = {depth: plane_in_left(thin, textured_plane(thin, depth)) for depth in plane_depths}
    origins = {method: _origins(real, moved=method == "data-only") for method in METHODS}
    names = [c.name for c in thin.cameras]
    rows, by_depth, disparities = [], [], {}
    labels = []
    for synthesis, method in ((synthesis, method) for synthesis in syntheses for method in METHODS):
        label = row_label(method, synthesis)
        labels.append(label)
        chain, shots = models[method], oracle if method == "oracle" else captures
        row: dict = {"method": label, "synthesis": synthesis} | dict.fromkeys(MEASURES, math.nan)
        row |= {"test_boards_found": "", "corners_exact_share": math.nan, "boards_left_out": " ".join(chain.left_out)}
        row["ray_model"] = ", ".join(f"{camera} {name}" for camera, name in chain.ray_models.items())
        error = chain.error_of(synthesis)
        prepared = PreparedMethod(name=label, error=error)
        if error is None:
            synth_dir = products / "synth" / synthesis / method
            images = _images(synth_dir, names, jobs[0][0])
            boards = [(shots[name], size) for name, size in squares.items()]
            prepared = calibrate_method_rig(label, images, boards, cameras=(names[0], names[1]))
            row |= _corner_measures(images, shots, tests, thin, origins[method], synth_dir)
            row["port_normal_err_deg"], row["port_distance_err_mm"] = _port_errors(chain.ports, thin, origins[method])
            row |= _ray_measures(chain.rays, true_rays[method], thin, origins[method])
        if prepared.ok:
            left = origins[method][names[0]]
            for depth in plane_depths:
                shot = shots[f"plane-{depth:g}"]
                normal, offset = truth[depth]
                moved = (normal, offset - float(normal @ left))
                by_depth += plane_rows(prepared, shot, depth, moved, thin, warps, disparities, out_dir, clouds=None)
            zncc = [r for r in by_depth if r["method"] == label and r["matcher"] == MATCHERS[0]]
            row["plane_rmse_mm"] = float(np.mean([r["plane_rmse_mm"] for r in zncc]))
            row["truth_error_mm"] = float(np.mean([r["truth_error_mm"] for r in zncc]))
            row["stereo_rms_px"] = prepared.stereo.rms_px
            row |= {"status": "ok", "error": ""}
        else:
            row |= {"status": "failed", "error": prepared.error}
            by_depth += [
                {"matcher": m, "method": label, "depth_m": d, "status": "failed", "error": prepared.error}
                for m in MATCHERS
                for d in plane_depths
            ]
        rows.append(row)
    seconds["measure_s"] = time.perf_counter() - start
    rows = list(complete_rows(rows))
    ports = _port_rows(models, thin, origins)
    write_table(complete_rows(by_depth), out_dir, stem="planes")
    if ports:
        write_table(complete_rows(ports), out_dir, stem="ports")
    write_text_atomically(out_dir / "commands.txt", "\n".join(log) + "\n")
    title = f"pipeline ({scale}), {lens if isinstance(lens, str) else lens.name} lens, {setup.sensor} sensor: "
    title += rig_setup(real)
    figures = (
        out_dir / "pipeline_summary.png",
        *plane_figures(out_dir, list(by_depth), disparities, plane_depths, labels, setup=title, prefix="pipeline"),
    )
    save_figure(summary_figure(rows, setup=title), figures[0])
    return ExperimentResult(
        name="pipeline",
        scale=scale,
        rows=tuple(rows),
        figures=figures,
        summary=_summary(rows, ports),
        parameters={
            "rig": dataclasses.asdict(setup.rig),
            "lens": lens_record(lens),
            "sensor": setup.sensor,
            "white_frames": setup.white_frames,
            "white_spp": setup.white_spp,
            "board_spp": setup.board_spp,
            "board_frames": setup.board_frames,
            "wall": real.wall.to_dict(),
            "ports": {c.name: None if c.scene.port is None else c.scene.port.to_dict() for c in real.cameras},
            "ray_model": ray_model,
            "syntheses": list(syntheses),
            "ray_models": {method: dict(models[method].ray_models) for method in METHODS},
            "plane_depths_m": list(plane_depths),
            "test_board_depths_m": list(TEST_BOARD_DEPTHS_M[scale]),
            "ray_pixel_step": step,
            "delivered": files,
            "commands": len(log),
            **seconds,
        },
    )


def _summary(rows: Sequence[dict], ports: Sequence[dict] = ()) -> str:
    """The table as markdown, for the terminal and meta.json; then each calibrated port's errors
    against its stated standard deviations."""
    keys = ("corner_rms_px", "plane_rmse_mm", "truth_error_mm", "port_normal_err_deg", "port_distance_err_mm")
    keys += ("ray_rms_mm",)
    lines = ["| method | " + " | ".join(keys) + " | status |", "|---|" + "---:|" * len(keys) + "---|"]
    for row in rows:
        cells = [f"{row[k]:.3f}" if isinstance(row[k], float) and math.isfinite(row[k]) else "-" for k in keys]
        lines.append(f"| {row['method']} | " + " | ".join(cells) + f" | {row['status']} |")
    if ports:
        lines += ["", "| port | ray model | " + " | ".join(PORT_KEYS) + " |", "|---|---|" + "---:|" * len(PORT_KEYS)]
    for port in ports:
        cells = [f"{port[k]:.3f}" for k in PORT_KEYS]
        lines.append(f"| {port['method']} {port['camera']} | {port['ray_model']} | " + " | ".join(cells) + " |")
    failed = [f"- {r['method']}: {r['error']}" for r in rows if r["status"] != "ok"]
    return "\n".join(lines + (["", "failed:", *failed] if failed else []))


#: The port columns :func:`_summary` shows.
PORT_KEYS = (
    "port_normal_err_deg",
    "port_normal_std_deg",
    "port_distance_err_mm",
    "port_distance_std_mm",
    "port_error_sigmas",
)


def summary_figure(rows: Sequence[dict], *, setup: str):
    """Bars of the table's measures by method, as a Figure: a panel per measure with its unit on the
    y axis, a method with no value there marked "no value" at its place, the set-up in the title.

    Parameters
    ----------
    rows : sequence of dict
        The experiment's rows, one per method.
    setup : str
        The set-up, for the title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    panels = (
        ("corner_rms_px", "test-board corners", "RMS error (px)"),
        ("plane_rmse_mm", "plane fit RMSE (ZNCC)", "RMSE (mm)"),
        ("truth_error_mm", "error against the true plane", "mean error (mm)"),
        ("port_normal_err_deg", "port normal error", "angle (deg)"),
        ("port_distance_err_mm", "port distance error", "error (mm)"),
        ("ray_rms_mm", "ray error at the port", "RMS error (mm)"),
    )
    fig = new_figure(3.0 * len(panels), 4.2, dpi=90)
    axes = fig.subplots(1, len(panels))
    x = np.arange(len(rows))
    for ax, (key, title, unit) in zip(axes, panels, strict=True):
        values = np.array([float(r[key]) if isinstance(r[key], (int, float)) else math.nan for r in rows])
        ax.bar(x, values, color=[f"C{i % 10}" for i in range(len(rows))])
        for i in np.flatnonzero(~np.isfinite(values)):
            ax.text(i, 0.0, "no value", rotation=90, ha="center", va="bottom", fontsize=7, color="0.3")
        ax.set_xticks(x, [r["method"] for r in rows], rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(unit, fontsize=8)
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3, axis="y")
        if not np.isfinite(values).any():
            ax.set_ylim(0.0, 1.0)
    fig.suptitle(
        f"{setup}\noracle = thin lens, true camera and port; true-rays = the real captures, their lens traced",
        fontsize=9,
    )
    return fig


@register(
    "pipeline",
    options=("lens", "port_distance_m", "thickness_m", *WALL_OPTIONS, "ray_model", "methods"),
    keeps_renders=True,
)
def run(
    out_dir: Path, options: ExperimentOptions, *, progress: bool, renders_dir: Path | None = None
) -> ExperimentResult:
    """From Lytro files alone (real lens, sensor model): MLA, camera, port calibrated, stereo; against the oracle."""
    return run_pipeline(out_dir, options=options, progress=progress, renders_dir=renders_dir)
