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
intrinsics fixed to the method's ``K``), rectified, matched by each of
:data:`~simulator.experiments.rigstereo.MATCHERS` (ZNCC, the paper's cost, and OpenCV's SGBM) and
triangulated into the left camera's frame. Measured per matcher, method and depth:

- ``plane_rmse_mm``: the paper's figure, the RMS distance of the points to a plane fitted after
  outlier removal (RANSAC, threshold 1 % of the depth);
- ``truth_error_mm``: the mean absolute distance of those inlier points to the true plane (left
  camera frame; the experiment's ground truth, which the paper did not have), and
  ``outlier_share``, the share of points RANSAC left out;
- ``completeness``: the share of the rectified left image's pixels with a disparity;
- ``exact_share`` and ``exact_plane_rmse_mm``, ``exact_truth_error_mm``, ``exact_outlier_share``:
  the share of the points inside both cameras' exact coverage
  (:func:`~simulator.experiments.rigstereo.exact_coverage`, where the synthesis's every necessary
  ray is recorded) and the same measures on those points alone. Outside it the synthesis
  approximates; on the ``illum`` rig the coverage is a fraction of the image.
"""

from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path

import numpy as np

from lfrefract import Pose
from lfrefract.formats.ply import write_ply
from lfrefract.metrics import fit_plane_ransac
from lfrefract.stereo.geometry import disparity_to_depth, disparity_to_points
from simulator.experiments import ExperimentResult, check_scale, register
from simulator.experiments.rigstereo import (
    BOARD_OFFSETS,
    MATCHERS,
    METHOD_NAMES,
    RigSetup,
    aim,
    calibrated_methods,
    chessboards,
    exact_coverage,
    grey,
    match,
    render_captures,
    rig_data,
    warp_maps,
)
from simulator.rig import RigConfig, parse_rig

__all__ = ["PLANE_DEPTHS_M", "run_planes", "setup_for"]

#: Plane depths (near, medium, far), metres, per scale (world z of the plane's centre).
PLANE_DEPTHS_M = {"tiny": (0.3, 0.45, 0.6), "illum": (0.4, 0.7, 1.0)}


def setup_for(scale: str) -> RigSetup:
    """The rig of ``scale``: ``tiny``, the default rig (two tiny-2x cameras); ``illum``, the Illum rig."""
    if check_scale(scale) == "tiny":
        return RigSetup(rig="default", calibration_depths_m=(0.3, 0.6), px_per_square=10.0, spp=16)
    return RigSetup(rig="illum", calibration_depths_m=(0.4, 1.0), px_per_square=30.0, spp=8)


def _plane(rig: RigConfig, depth_m: float, seed: int) -> dict:
    return {
        "type": "textured_plane",
        "position_m": aim(rig, depth_m).tolist(),
        "rotation_xyz_deg": [10.0, -15.0, 0.0],
        "size_m": [1.4 * depth_m, 1.1 * depth_m],
        "texture_px": 1024,
        "texture_seed": seed,
    }


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
    base = parse_rig(rig_data(setup, []))
    with tempfile.TemporaryDirectory(prefix="lfsim-planes-") as tmp:
        work = Path(tmp) if renders_dir is None else Path(renders_dir)
        return _run(out_dir, setup, scale, base, work, progress=progress, write_clouds=write_clouds)


def _run(
    out_dir: Path, setup: RigSetup, scale: str, base: RigConfig, work: Path, *, progress: bool, write_clouds: bool
) -> ExperimentResult:
    """Render (into ``work``) and measure; see :func:`run_planes`."""
    plane_depths = PLANE_DEPTHS_M[scale]
    near, far = setup.calibration_depths_m
    jobs = [(f"board-{d}-{i}", [b]) for d in (near, far) for i, b in enumerate(chessboards(base, setup, d))]
    jobs += [(f"plane-{d}", [_plane(base, d, 7)]) for d in plane_depths]
    captures = render_captures(setup, jobs, work, progress=progress)
    boards = {d: [captures[f"board-{d}-{i}"] for i in range(len(BOARD_OFFSETS))] for d in (near, far)}
    planes = {d: captures[f"plane-{d}"] for d in plane_depths}
    truth = {depth: _plane_in_left(base, _plane(base, depth, 7)) for depth in plane_depths}

    warps = warp_maps(base)
    rows, disparities = [], {}
    for method, project, rect, stereo, pairs in calibrated_methods(base, setup, boards, progress=progress, warps=warps):
        for depth in plane_depths:
            left, right = rect.apply(project("left", planes[depth]), project("right", planes[depth]))
            expected = rect.focal_px * rect.baseline_m / depth
            for matcher in MATCHERS:
                disparity = match(
                    matcher,
                    left,
                    right,
                    min_disparity_px=max(int(expected * 0.5), 0),
                    num_disparities=int(expected) + 8,
                )
                disparities[(matcher, method, depth)] = disparity
                points = disparity_to_points(disparity, rect)
                if write_clouds and matcher == MATCHERS[0] and depth == plane_depths[1]:
                    finite = np.isfinite(disparity_to_depth(disparity, rect))
                    colours = np.clip(left[finite] / max(float(np.nanpercentile(left, 99)), 1e-12), 0, 1)
                    cloud = Path(out_dir) / f"cloud_{re.sub('[^a-z]+', '_', method)}.ply"
                    write_ply(cloud, points, (colours * 255).astype(np.uint8))
                exact = exact_coverage(points, base, warps)
                everywhere = _plane_measures(points, truth[depth], depth)
                inside = _plane_measures(points[exact], truth[depth], depth)
                rows.append(
                    {
                        "matcher": matcher,
                        "method": method,
                        "depth_m": depth,
                        **everywhere,
                        "completeness": float(np.isfinite(disparity).sum() / max(np.isfinite(grey(left)).sum(), 1)),
                        "exact_share": float(exact.mean()) if len(exact) else math.nan,
                        **{f"exact_{k}": v for k, v in inside.items()},
                        "stereo_rms_px": stereo.rms_px,
                        "boards": pairs,
                    }
                )
    figures = _figures(out_dir, rows, disparities, plane_depths)
    return ExperimentResult(
        name="planes",
        scale=scale,
        rows=tuple(rows),
        figures=figures,
        summary=_summary(rows, plane_depths),
        parameters=dict(setup.__dict__) | {"plane_depths_m": plane_depths},
    )


def _plane_measures(points: np.ndarray, truth: tuple[np.ndarray, float], depth_m: float) -> dict[str, float]:
    """Plane-fit RMSE, mean error against the true plane (mm) and outlier share of ``points`` (N, 3)."""
    normal, offset = truth
    if len(points) < 3:  # no match at all is a result too, not a crash
        return {"plane_rmse_mm": math.nan, "truth_error_mm": math.nan, "outlier_share": math.nan}
    fit = fit_plane_ransac(points, threshold_m=0.01 * depth_m, seed=0)
    return {
        "plane_rmse_mm": fit.rmse_m * 1e3,
        "truth_error_mm": float(np.mean(np.abs(points[fit.inliers] @ normal - offset))) * 1e3,
        "outlier_share": 1.0 - float(np.mean(fit.inliers)),
    }


def _plane_in_left(rig: RigConfig, table: dict) -> tuple[np.ndarray, float]:
    """The plane object's normal and offset (``normal . X = offset``) in the left camera frame."""
    placement = Pose.from_euler_xyz_deg(table["rotation_xyz_deg"], table["position_m"])
    local = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) * 0.1
    points = rig.cameras[0].scene.pose.to_camera(placement.to_world(local))
    normal = np.cross(points[1] - points[0], points[2] - points[0])
    normal /= np.linalg.norm(normal)
    return normal, float(normal @ points[0])


def _summary(rows: list[dict], plane_depths: tuple[float, ...]) -> str:
    parts = []
    for matcher in MATCHERS:
        for prefix, what in (("", "all points"), ("exact_", "points in the exact coverage")):
            lines = ["| method | " + " | ".join(f"{d:g} m" for d in plane_depths) + " |"]
            lines.append("|---|" + "---|" * len(plane_depths))
            for method in METHOD_NAMES:
                ours = [r for r in rows if r["method"] == method and r["matcher"] == matcher]
                cells = [f"{r[prefix + 'plane_rmse_mm']:.2f} / {r[prefix + 'truth_error_mm']:.2f}" for r in ours]
                lines.append(f"| {method} | " + " | ".join(cells) + " |")
            title = f"{matcher}, {what}: plane RMSE / error against the true plane, mm"
            if prefix:
                shares = [r["exact_share"] for r in rows if r["matcher"] == matcher and r["method"] == "ideal"]
                title += " (share of the ideal images' points: " + ", ".join(f"{x:.2f}" for x in shares) + ")"
            parts.append(title + ":\n" + "\n".join(lines))
    return "\n\n".join(parts)


def _figures(out_dir: Path, rows, disparities, plane_depths: tuple[float, ...]) -> tuple[Path, ...]:
    import matplotlib as mpl

    mpl.use("Agg")
    import matplotlib.pyplot as plt

    depths, paths = plane_depths, []
    for matcher in MATCHERS:
        fig, axes = plt.subplots(len(depths), len(METHOD_NAMES), figsize=(2.6 * len(METHOD_NAMES), 2.2 * len(depths)))
        for i, depth in enumerate(depths):
            values = [disparities[(matcher, m, depth)] for m in METHOD_NAMES]
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
        fig.suptitle(f"{matcher} disparity maps (rectified left view; NaN white)", fontsize=9)
        paths.append(Path(out_dir) / f"planes_disparity_{matcher}.png")
        fig.savefig(paths[-1], dpi=90, bbox_inches="tight")
        plt.close(fig)

    keys = (
        ("plane_rmse_mm", "plane fit RMSE (paper's metric)"),
        ("truth_error_mm", "error against the true plane"),
        ("exact_truth_error_mm", "same, exact coverage only"),
    )
    fig, axes = plt.subplots(len(MATCHERS), len(keys), figsize=(15, 3.4 * len(MATCHERS)), squeeze=False)
    width = 0.8 / len(METHOD_NAMES)
    x = np.arange(len(depths))
    for i, matcher in enumerate(MATCHERS):
        for j, method in enumerate(METHOD_NAMES):
            ours = [r for r in rows if r["method"] == method and r["matcher"] == matcher]
            for ax, (key, _) in zip(axes[i], keys, strict=True):
                ax.bar(x + (j - len(METHOD_NAMES) / 2 + 0.5) * width, [r[key] for r in ours], width, label=method)
        for ax, (_, title) in zip(axes[i], keys, strict=True):
            ax.set(xticks=x, xticklabels=[f"{d:g} m" for d in depths], ylabel="mm", title=f"{matcher}: {title}")
            ax.grid(alpha=0.3, axis="y")
    axes[0, 0].legend(fontsize=8)
    paths.append(Path(out_dir) / "planes_errors.png")
    fig.savefig(paths[-1], dpi=90, bbox_inches="tight")
    plt.close(fig)
    return tuple(paths)


@register("planes")
def run(out_dir: Path, *, scale: str, progress: bool) -> ExperimentResult:
    """``lfsim experiment planes``: see :func:`run_planes`."""
    return run_planes(out_dir, scale=scale, progress=progress)
