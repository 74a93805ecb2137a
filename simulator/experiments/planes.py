"""The ``planes`` experiment (paper Figs. 5-6): stereo on a textured plane at three depths, by method.

A stereo rig (two light-field cameras behind one tilted glass wall, :mod:`simulator.rig`) sees a
slanted textured plane at a near, a medium and a far depth. Each method turns both raw images into
central projections (:mod:`lfrefract.methods`):

- ``approx far`` / ``approx near``: the approximation baseline calibrated per camera from
  chessboard captures at the far / near depth (paper conditions (a), (b));
- ``proposed``: the refraction-free synthesis (c);
- ``proposed+distortion``: with a residual distortion fitted on synthesized chessboard images (d);
- ``ideal``: the simulator's ground-truth refraction-free pinhole images, the floor.

For every method the rig is stereo-calibrated from its own images of all the chessboards (OpenCV,
intrinsics fixed to the method's ``K``), rectified, matched by ZNCC (:func:`lfrefract.stereo.zncc_disparity`)
and triangulated into the left camera's frame. Measured per method and depth:

- ``plane_rmse_mm``: the paper's figure, the RMS distance of the points to a plane fitted after
  outlier removal (RANSAC, threshold 1 % of the depth);
- ``truth_error_mm``: the mean absolute distance of those inlier points to the true plane (left
  camera frame; the experiment's ground truth, which the paper did not have), and
  ``outlier_share``, the share of points RANSAC left out;
- ``completeness``: the share of the rectified left image's pixels with a disparity.
"""

from __future__ import annotations

import math
import re
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lfrefract import Pose, virtual_camera_for
from lfrefract.calibration.approx import detect_chessboard
from lfrefract.io import read_exr, read_json, write_json, write_ply
from lfrefract.methods import CalibrationViews, build_projector
from lfrefract.metrics import fit_plane_ransac
from lfrefract.stereo import (
    Rectification,
    StereoCalibration,
    calibrate_stereo,
    disparity_to_depth,
    disparity_to_points,
    rectify,
    zncc_disparity,
)
from lfrefract.synthesis import build_warp_map
from simulator.assets import chessboard_inner_corners
from simulator.config import read_toml
from simulator.experiments import ExperimentResult, check_scale, register
from simulator.rig import RigConfig, embedded_rigs, parse_rig, render_rig

__all__ = ["METHOD_NAMES", "PlanesSetup", "run_planes", "setup_for"]

#: Methods compared, in table order.
METHOD_NAMES = ("approx far", "approx near", "proposed", "proposed+distortion", "ideal")


@dataclass(frozen=True)
class PlanesSetup:
    """What the ``planes`` experiment renders at one scale.

    Attributes
    ----------
    rig : str
        The embedded rig (``scenes/rigs/``) whose wall and cameras are used; its objects, lights and
        render settings are replaced by the experiment's.
    plane_depths_m : (float, float, float)
        Near, medium and far plane (world z of its centre).
    calibration_depths_m : (float, float)
        Near and far chessboard depths (the approximation baseline's two calibrations).
    px_per_square : float
        Chessboard squares in the views at their depth, pixels (about).
    spp : int
        Samples per pixel.
    """

    rig: str
    plane_depths_m: tuple[float, float, float]
    calibration_depths_m: tuple[float, float]
    px_per_square: float
    spp: int


def setup_for(scale: str) -> PlanesSetup:
    """The setup of ``scale``: ``tiny``, the default rig (two tiny-2x cameras); ``illum``, the Illum rig."""
    if check_scale(scale) == "tiny":
        return PlanesSetup(
            rig="default", plane_depths_m=(0.3, 0.45, 0.6), calibration_depths_m=(0.3, 0.6), px_per_square=10.0, spp=16
        )
    return PlanesSetup(
        rig="illum", plane_depths_m=(0.4, 0.7, 1.0), calibration_depths_m=(0.4, 1.0), px_per_square=30.0, spp=8
    )


#: Chessboard squares (columns, rows) and where the calibration boards sit: offsets from the rig's
#: line of sight as fractions of the depth, and their rotations (perspective fixes the focal length).
SQUARES = (7, 5)
_BOARD_OFFSETS = ((-0.07, -0.05), (0.07, -0.05), (-0.07, 0.05), (0.07, 0.05), (0.0, 0.0), (0.0, -0.06))
_BOARD_ROTATIONS_DEG = ((-20, 15, 5), (15, -20, -5), (20, 20, 10), (-15, -15, 0), (0, 0, 20), (25, 0, -10))
_LIGHTS = [
    {"type": "point", "position_m": [-0.2, -0.25, 0.1], "intensity_w_sr": 0.4},
    {"type": "point", "position_m": [0.25, -0.1, 0.08], "intensity_w_sr": 0.35},
]


def _rig_data(setup: PlanesSetup, objects: list[dict]) -> dict:
    """The rig file's wall and cameras with the experiment's lights, render settings and ``objects``."""
    data = read_toml(embedded_rigs()[setup.rig], "rig")
    data.update(name=f"planes-{setup.rig}", render={"spp": setup.spp, "seed": 0}, light=_LIGHTS, object=objects)
    return data


def _aim(rig: RigConfig, depth_m: float) -> np.ndarray:
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


def _square_size_m(rig: RigConfig, setup: PlanesSetup, depth_m: float) -> float:
    view = virtual_camera_for(rig.cameras[0].scene.camera)
    water = rig.wall.n_water / rig.wall.n_air
    return setup.px_per_square * depth_m / (water * view.focal_px)


def _boards(rig: RigConfig, setup: PlanesSetup, depth_m: float) -> list[dict]:
    centre = _aim(rig, depth_m)
    square = _square_size_m(rig, setup, depth_m)
    return [
        {
            "type": "chessboard",
            "position_m": (centre + depth_m * np.array([dx, dy, 0.0])).tolist(),
            "rotation_xyz_deg": list(rotation),
            "squares": list(SQUARES),
            "square_size_m": square,
        }
        for (dx, dy), rotation in zip(_BOARD_OFFSETS, _BOARD_ROTATIONS_DEG, strict=True)
    ]


def _plane(rig: RigConfig, depth_m: float, seed: int) -> dict:
    return {
        "type": "textured_plane",
        "position_m": _aim(rig, depth_m).tolist(),
        "rotation_xyz_deg": [10.0, -15.0, 0.0],
        "size_m": [1.4 * depth_m, 1.1 * depth_m],
        "texture_px": 1024,
        "texture_seed": seed,
    }


@dataclass(frozen=True)
class _Capture:
    """One rendered rig capture on disk; images are read when asked for (an Illum raw image is
    0.5 GB, and the experiment has thirty)."""

    folder: Path

    def raw(self, camera: str) -> np.ndarray:
        return read_exr(self.folder / camera / "raw.exr", role="raw")

    def ideal(self, camera: str) -> np.ndarray:
        return read_exr(self.folder / camera / "ideal.exr", role="ideal")


def _capture(setup: PlanesSetup, objects: list[dict], folder: Path) -> _Capture:
    """Render the rig with ``objects`` into ``folder`` (kept if it already holds this very rig)."""
    rig = parse_rig(_rig_data(setup, objects))
    meta = folder / "meta.json"
    if not (meta.is_file() and read_json(meta).get("objects") == objects):
        render_rig(rig, folder, progress=False, write_previews=False, overwrite=True)
        kept = {k: v for k, v in read_json(meta).items() if k != "schema_version"}
        write_json(meta, {**kept, "objects": objects})
    return _Capture(folder)


def _inner_corners_world(table: dict) -> np.ndarray:
    """Inner corners (N, 3) of a chessboard table in the world frame, in the board's order."""
    placement = Pose.from_euler_xyz_deg(table["rotation_xyz_deg"], table["position_m"])
    local = chessboard_inner_corners(squares=tuple(table["squares"]), square_size_m=table["square_size_m"])
    return placement.to_world(np.concatenate([local, np.zeros((len(local), 1))], axis=1))


def _board_points_m(square: float) -> np.ndarray:
    cols, rows = SQUARES[0] - 1, SQUARES[1] - 1
    jj, ii = np.mgrid[0:rows, 0:cols]
    return np.stack([ii.ravel(), jj.ravel()], axis=1) * square


def _corners(image: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """The detector's corners in a canonical order: the first one the top-left one (the board is
    turned by less than 90 deg in every view), so that both cameras list them alike."""
    found = detect_chessboard(image, pattern)
    if found is not None and found[0].sum() > found[-1].sum():
        found = found[::-1].copy()
    return found


def _grey(image: np.ndarray) -> np.ndarray:
    return image.mean(axis=2) if image.ndim == 3 else image


def run_planes(
    out_dir: Path,
    *,
    scale: str = "tiny",
    progress: bool = True,
    renders_dir: Path | None = None,
    write_clouds: bool = False,
) -> ExperimentResult:
    """Run the experiment (see the module docstring); figures go to ``out_dir``.

    ``renders_dir``: keep the rig renders there and reuse those that match on a later run
    (default: a temporary directory, deleted). ``write_clouds``: also write each method's point
    cloud of the medium plane, ``cloud_<method>.ply`` (left camera frame, metres, coloured).
    """
    setup = setup_for(scale)
    base = parse_rig(_rig_data(setup, []))
    with tempfile.TemporaryDirectory(prefix="lfsim-planes-") as tmp:
        work = Path(tmp) if renders_dir is None else Path(renders_dir)
        return _run(out_dir, setup, scale, base, work, progress=progress, write_clouds=write_clouds)


def calibrated_methods(
    base: RigConfig, setup: PlanesSetup, boards: dict[float, list[_Capture]], *, progress: bool
) -> Iterator[tuple[str, Callable, Rectification, StereoCalibration, int]]:
    """For each method of :data:`METHOD_NAMES`: its projection ``project(camera, capture)`` of a
    capture into a central image, and the rig calibrated and rectified on its own images of the
    chessboard captures ``boards`` (depth -> six captures of :func:`_boards`), with the number of
    board views found in both images.

    The approximation's camera model is calibrated per camera on the boards at one depth
    (``approx far`` / ``approx near``), with the boards' true corners fixing the model's frame (as
    tests/simulator/test_approx_baseline.py does: a free OpenCV fit of boards at one depth trades
    the focal length against the board distances and the principal point against the port's
    deflection, and its undistorted images leave the frame); ``proposed+distortion`` fits its
    residual distortion on the farthest boards. The rig is calibrated on every board given: the
    approximation's camera model belongs to one depth, the rig's pose to none (boards at one depth
    left the baseline a few per cent off on the small rig's 188 px images).
    """
    names = [c.name for c in base.cameras]
    pattern = (SQUARES[0] - 1, SQUARES[1] - 1)
    depths = sorted(boards)
    near, far = depths[0], depths[-1]
    squares = {d: _square_size_m(base, setup, d) for d in depths}
    cameras = {c.name: c.scene for c in base.cameras}
    warps = {n: build_warp_map(cameras[n].camera, cameras[n].port) for n in names}

    def calibration(name: str, depth: float) -> CalibrationViews:
        pose = cameras[name].pose
        corners = [pose.to_camera(_inner_corners_world(table)) for table in _boards(base, setup, depth)]
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
            (_corners(project("left", b), pattern), _corners(project("right", b), pattern), squares[depth])
            for depth in depths
            for b in boards[depth]
        ]
        pairs = [(lft, rgt, square) for lft, rgt, square in found if lft is not None and rgt is not None]
        stereo = calibrate_stereo(
            [p[0] for p in pairs],
            [p[1] for p in pairs],
            [_board_points_m(p[2]) for p in pairs],
            left=outputs["left"],
            right=outputs["right"],
        )
        yield method, project, rectify(stereo), stereo, len(pairs)


def _run(
    out_dir: Path, setup: PlanesSetup, scale: str, base: RigConfig, work: Path, *, progress: bool, write_clouds: bool
) -> ExperimentResult:
    """Render (into ``work``) and measure; see :func:`run_planes`."""
    near, far = setup.calibration_depths_m
    jobs = [(f"board-{d}-{i}", [b]) for d in (near, far) for i, b in enumerate(_boards(base, setup, d))]
    jobs += [(f"plane-{d}", [_plane(base, d, 7)]) for d in setup.plane_depths_m]
    captures = {
        name: _capture(setup, objects, work / name)
        for name, objects in tqdm(jobs, desc="rendering the rig", unit="capture", disable=not progress)
    }
    boards = {d: [captures[f"board-{d}-{i}"] for i in range(len(_BOARD_OFFSETS))] for d in (near, far)}
    planes = {d: captures[f"plane-{d}"] for d in setup.plane_depths_m}
    truth = {depth: _plane_in_left(base, _plane(base, depth, 7)) for depth in setup.plane_depths_m}

    rows, disparities = [], {}
    for method, project, rect, stereo, pairs in calibrated_methods(base, setup, boards, progress=progress):
        for depth in setup.plane_depths_m:
            left, right = rect.apply(project("left", planes[depth]), project("right", planes[depth]))
            expected = rect.focal_px * rect.baseline_m / depth
            disparity = zncc_disparity(
                _grey(left),
                _grey(right),
                min_disparity_px=max(int(expected * 0.5), 0),
                num_disparities=int(expected) + 8,
            )
            disparities[(method, depth)] = disparity
            points = disparity_to_points(disparity, rect)
            if write_clouds and depth == setup.plane_depths_m[1]:
                finite = np.isfinite(disparity_to_depth(disparity, rect))
                colours = np.clip(left[finite] / max(float(np.nanpercentile(left, 99)), 1e-12), 0, 1)
                cloud = Path(out_dir) / f"cloud_{re.sub('[^a-z]+', '_', method)}.ply"
                write_ply(cloud, points, (colours * 255).astype(np.uint8))
            normal, offset = truth[depth]
            rmse = truth_error = outliers = math.nan  # no match at all is a result too, not a crash
            if len(points) >= 3:
                fit = fit_plane_ransac(points, threshold_m=0.01 * depth, seed=0)
                rmse = fit.rmse_m
                truth_error = float(np.mean(np.abs(points[fit.inliers] @ normal - offset)))
                outliers = 1.0 - float(np.mean(fit.inliers))
            rows.append(
                {
                    "method": method,
                    "depth_m": depth,
                    "plane_rmse_mm": rmse * 1e3,
                    "truth_error_mm": truth_error * 1e3,
                    "outlier_share": outliers,
                    "completeness": float(np.isfinite(disparity).sum() / max(np.isfinite(_grey(left)).sum(), 1)),
                    "stereo_rms_px": stereo.rms_px,
                    "boards": pairs,
                }
            )
    figures = _figures(out_dir, rows, disparities, setup)
    return ExperimentResult(
        name="planes",
        scale=scale,
        rows=tuple(rows),
        figures=figures,
        summary=_summary(rows, setup),
        parameters=dict(setup.__dict__),
    )


def _plane_in_left(rig: RigConfig, table: dict) -> tuple[np.ndarray, float]:
    """The plane object's normal and offset (``normal . X = offset``) in the left camera frame."""
    placement = Pose.from_euler_xyz_deg(table["rotation_xyz_deg"], table["position_m"])
    local = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) * 0.1
    points = rig.cameras[0].scene.pose.to_camera(placement.to_world(local))
    normal = np.cross(points[1] - points[0], points[2] - points[0])
    normal /= np.linalg.norm(normal)
    return normal, float(normal @ points[0])


def _summary(rows: list[dict], setup: PlanesSetup) -> str:
    lines = ["| method | " + " | ".join(f"{d:g} m" for d in setup.plane_depths_m) + " |"]
    lines.append("|---|" + "---|" * len(setup.plane_depths_m))
    for method in METHOD_NAMES:
        cells = [f"{r['plane_rmse_mm']:.2f} / {r['truth_error_mm']:.2f}" for r in rows if r["method"] == method]
        lines.append(f"| {method} | " + " | ".join(cells) + " |")
    return "plane RMSE / error against the true plane, mm:\n" + "\n".join(lines)


def _figures(out_dir: Path, rows, disparities, setup: PlanesSetup) -> tuple[Path, ...]:
    import matplotlib as mpl

    mpl.use("Agg")
    import matplotlib.pyplot as plt

    depths = setup.plane_depths_m
    fig, axes = plt.subplots(len(depths), len(METHOD_NAMES), figsize=(2.6 * len(METHOD_NAMES), 2.2 * len(depths)))
    for i, depth in enumerate(depths):
        values = [disparities[(m, depth)] for m in METHOD_NAMES]
        finite = np.concatenate([v[np.isfinite(v)] for v in values])
        lo, hi = np.percentile(finite, [2, 98]) if len(finite) else (0.0, 1.0)
        for j, method in enumerate(METHOD_NAMES):
            ax = axes[i, j]
            ax.imshow(values[j], cmap="viridis", vmin=lo, vmax=hi)
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(method, fontsize=9)
            if j == 0:
                ax.set_ylabel(f"{depth:g} m", fontsize=9)
    fig.suptitle("disparity maps (rectified left view; NaN white)", fontsize=9)
    montage = Path(out_dir) / "planes_disparity.png"
    fig.savefig(montage, dpi=90, bbox_inches="tight")
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    width = 0.8 / len(METHOD_NAMES)
    x = np.arange(len(depths))
    for j, method in enumerate(METHOD_NAMES):
        ours = [r for r in rows if r["method"] == method]
        for ax, key in zip(axes, ("plane_rmse_mm", "truth_error_mm"), strict=True):
            ax.bar(x + (j - len(METHOD_NAMES) / 2 + 0.5) * width, [r[key] for r in ours], width, label=method)
    for ax, title in zip(axes, ("plane fit RMSE (paper's metric)", "mean error against the true plane"), strict=True):
        ax.set(xticks=x, xticklabels=[f"{d:g} m" for d in depths], ylabel="mm", title=title)
        ax.grid(alpha=0.3, axis="y")
    axes[0].legend(fontsize=8)
    bars = Path(out_dir) / "planes_errors.png"
    fig.savefig(bars, dpi=90, bbox_inches="tight")
    plt.close(fig)
    return montage, bars


@register("planes")
def run(out_dir: Path, *, scale: str, progress: bool) -> ExperimentResult:
    """``lfsim experiment planes``: see :func:`run_planes`."""
    return run_planes(out_dir, scale=scale, progress=progress)
