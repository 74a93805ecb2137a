"""The ``objects`` experiment (paper Fig. 7): a bowl and a figurine, reconstructed by every method.

The default rig (:mod:`simulator.experiments.planes` and :mod:`simulator.experiments.rigstereo`
explain the rig, the methods and how each method's rig is calibrated) sees a textured bowl and a
textured figurine about 0.3 m away in front of a textured backdrop at 0.7 m. The chessboards that
calibrate the approximation and the rig are farther than both objects, at 0.45 and 0.6 m
(``approx near`` / ``approx far``), as in the paper.

Per method, the ZNCC disparity is triangulated into the left camera's frame, written as a point
cloud (``cloud_<method>.ply``) and splatted into a depth map of the left ideal image's geometry
(nearest pixel, nearest point). Against the ground-truth depth on the objects' pixels
(:func:`lfrefract.metrics.depth_errors`):

- ``median_abs_mm``, ``mean_abs_mm``, ``rms_mm``, ``bias_mm``: errors of the estimated depth
  (camera z); the mean and RMS include the mismatches at the objects' outlines (backdrop points
  0.4 m behind), the median does not;
- ``completeness``: the share of the objects' pixels with an estimate.

Figures: the depth error maps by method (``objects_depth_error.png``).
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np

from lfrefract import ParameterError, virtual_camera_for
from lfrefract.io import read_exr, write_ply
from lfrefract.metrics import depth_errors
from lfrefract.stereo import disparity_to_points, zncc_disparity
from simulator.experiments import ExperimentResult, check_scale, register
from simulator.experiments.rigstereo import (
    BOARD_OFFSETS,
    METHOD_NAMES,
    RigSetup,
    aim,
    calibrated_methods,
    chessboards,
    grey,
    render_captures,
    rig_data,
)
from simulator.rig import parse_rig

__all__ = ["OBJECT_MASK_DEPTH_M", "run_objects"]

#: Pixels of the left ideal image nearer than this are the objects' (the backdrop is at 0.7 m).
OBJECT_MASK_DEPTH_M = 0.5


def _setup(scale: str) -> RigSetup:
    if check_scale(scale) != "tiny":
        raise ParameterError(f"scale={scale!r}: the objects experiment runs at the tiny scale only so far")
    return RigSetup(rig="default", calibration_depths_m=(0.45, 0.6), px_per_square=10.0, spp=16)


def _scene_objects(base) -> list[dict]:
    bowl_at = aim(base, 0.31) + np.array([-0.05, 0.01, 0.0])
    figurine_at = aim(base, 0.34) + np.array([0.05, 0.0, 0.0])
    return [
        {
            "type": "bowl",
            "position_m": bowl_at.tolist(),
            "rotation_xyz_deg": [-30.0, 0.0, 0.0],
            "radius_m": 0.045,
            "depth_m": 0.03,
            "texture_seed": 11,
        },
        {"type": "figurine", "position_m": figurine_at.tolist(), "height_m": 0.1, "seed": 3, "texture_seed": 12},
        {
            "type": "textured_plane",
            "position_m": aim(base, 0.7).tolist(),
            "size_m": [1.0, 0.8],
            "texture_px": 1024,
            "texture_seed": 13,
        },
    ]


def run_objects(out_dir: Path, *, scale: str = "tiny", progress: bool = True) -> ExperimentResult:
    """Run the experiment (see the module docstring); figures and clouds go to ``out_dir``."""
    setup = _setup(scale)
    base = parse_rig(rig_data(setup, []))
    depths = setup.calibration_depths_m
    with tempfile.TemporaryDirectory(prefix="lfsim-objects-") as tmp:
        work = Path(tmp)
        jobs = [(f"board-{d}-{i}", [b]) for d in depths for i, b in enumerate(chessboards(base, setup, d))]
        jobs.append(("objects", _scene_objects(base)))
        captures = render_captures(setup, jobs, work, progress=progress)
        boards = {d: [captures[f"board-{d}-{i}"] for i in range(len(BOARD_OFFSETS))] for d in depths}
        scene = captures["objects"]
        truth = read_exr(scene.folder / "left" / "depth.exr", role="depth")
        mask = np.isfinite(truth) & (truth < OBJECT_MASK_DEPTH_M)
        view = virtual_camera_for(base.cameras[0].scene.camera)
        rows, errors = [], {}
        for method, project, rect, stereo, pairs in calibrated_methods(base, setup, boards, progress=progress):
            left, right = rect.apply(project("left", scene), project("right", scene))
            low, high = rect.focal_px * rect.baseline_m / 0.8, rect.focal_px * rect.baseline_m / 0.25
            disparity = zncc_disparity(
                grey(left), grey(right), min_disparity_px=int(low), num_disparities=int(high - low) + 3
            )
            points = disparity_to_points(disparity, rect)
            write_ply(Path(out_dir) / f"cloud_{re.sub('[^a-z]+', '_', method)}.ply", points)
            estimate = _splat(points, view)
            result = depth_errors(estimate, truth, valid=mask)
            errors[method] = np.where(mask, np.abs(estimate - truth), np.nan)
            rows.append(
                {
                    "method": method,
                    "median_abs_mm": float(np.nanmedian(errors[method][mask])) * 1e3,
                    "mean_abs_mm": result.mean_abs_m * 1e3,
                    "rms_mm": result.rms_m * 1e3,
                    "bias_mm": result.bias_m * 1e3,
                    "completeness": result.completeness,
                    "stereo_rms_px": stereo.rms_px,
                    "boards": pairs,
                }
            )
    figure = _figure(Path(out_dir), errors)
    summary = "\n".join(
        f"- {r['method']}: {r['median_abs_mm']:.2f} mm median, {r['mean_abs_mm']:.2f} mm mean, "
        f"{r['rms_mm']:.2f} mm RMS, completeness {r['completeness']:.2f}"
        for r in rows
    )
    return ExperimentResult(
        name="objects",
        scale=scale,
        rows=tuple(rows),
        figures=(figure,),
        summary="depth error on the bowl and the figurine:\n" + summary,
        parameters=dict(setup.__dict__) | {"object_mask_depth_m": OBJECT_MASK_DEPTH_M},
    )


def _splat(points_cam: np.ndarray, view) -> np.ndarray:
    """Depth map (H, W) of ``view``: the nearest point's z at each point's nearest pixel; NaN elsewhere."""
    depth = np.full((view.height_px, view.width_px), np.inf)
    if len(points_cam):
        uv = np.rint(view.project(points_cam)).astype(np.int64)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < view.width_px) & (uv[:, 1] >= 0) & (uv[:, 1] < view.height_px)
        np.minimum.at(depth, (uv[inside, 1], uv[inside, 0]), points_cam[inside, 2])
    depth[np.isinf(depth)] = np.nan
    return depth


def _figure(out_dir: Path, errors: dict[str, np.ndarray]) -> Path:
    import matplotlib as mpl

    mpl.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(METHOD_NAMES), figsize=(2.8 * len(METHOD_NAMES), 2.6))
    top = max((float(np.nanpercentile(e, 95)) for e in errors.values() if np.isfinite(e).any()), default=1.0)
    for ax, method in zip(axes, METHOD_NAMES, strict=True):
        image = ax.imshow(errors[method] * 1e3, cmap="magma", vmin=0, vmax=top * 1e3)
        ax.set_title(method, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(image, ax=axes, shrink=0.8, label="|depth error| [mm]")
    fig.suptitle("depth error on the objects (left ideal view; no estimate: white)", fontsize=9)
    path = out_dir / "objects_depth_error.png"
    fig.savefig(path, dpi=90, bbox_inches="tight")
    plt.close(fig)
    return path


@register("objects")
def run(out_dir: Path, *, scale: str, progress: bool) -> ExperimentResult:
    """``lfsim experiment objects``: see :func:`run_objects`."""
    return run_objects(out_dir, scale=scale, progress=progress)
