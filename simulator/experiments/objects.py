"""The ``objects`` experiment (paper Fig. 7): a bowl and a figurine, reconstructed by every method.

A rig (:mod:`simulator.experiments.planes` and :mod:`simulator.experiments.rigstereo` explain the
rig, the methods and how each method's rig is calibrated; the scene is built of typed objects,
:func:`scene_objects`) sees a textured bowl and a textured
figurine in front of a textured backdrop. The chessboards that calibrate the approximation and the
rig are farther than both objects (``approx near`` / ``approx far``), as in the paper. ``tiny``:
the default rig, objects at 0.31 and 0.34 m, backdrop at 0.7 m, boards at 0.45 and 0.6 m.
``illum``: the Illum rig, the same scene 1.5 times larger and farther.

Per matcher (:data:`~simulator.experiments.rigstereo.MATCHERS`) and method, the disparity is
triangulated into the left camera's frame, written as a point cloud (``cloud_<method>.ply`` for
ZNCC, ``cloud_<method>_sgbm.ply`` for SGBM) and splatted into a depth map of the left ideal
image's geometry (nearest pixel, nearest point). Against the ground truth on the objects' pixels:

- ``median_abs_mm``, ``mean_abs_mm``, ``rms_mm``, ``bias_mm``: errors of the estimated depth
  (camera z, :func:`lfrefract.metrics.depth_errors`); the mean and RMS include the mismatches at
  the objects' outlines (backdrop points far behind), the median does not;
- ``bad_0.5px``, ``bad_1px``, ``bad_2px``: Middlebury-style bad-pixel rates
  (:func:`lfrefract.metrics.disparity_errors`) of the disparity ``f B / z`` that each depth
  implies on the method's rectified rig (pixels without an estimate count as bad);
- ``completeness``: the share of the objects' pixels with an estimate;
- ``exact_share``, ``exact_median_abs_mm``, ``exact_mean_abs_mm``: the share of the objects'
  pixels whose true surface point both cameras see through exact pixels
  (:func:`~simulator.experiments.rigstereo.exact_coverage`), and the errors on those pixels alone.

- ``status`` and ``error``: a method that fails gives rows with its error and NaN measures
  (:mod:`simulator.experiments.methods`); a method that returns depth maps gives one row with
  ``matcher = "none"``, its depth splatted and scored as above (its disparity from the cameras'
  true baseline).

The methods come from the registry (``ExperimentOptions.methods`` chooses); ``camera``,
``port_distance_m`` and ``thickness_m`` change the rig as in ``planes``. Figures: the depth error
maps by matcher and method (``objects_depth_error.png``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfrefract.figures import NO_VALUE_RGB, new_figure, save_figure
from lfrefract.formats.outputs import scratch_directory
from lfrefract.formats.ply import write_ply
from lfrefract.metrics import depth_errors, disparity_errors
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.stereo.geometry import disparity_to_points
from simulator.config import Bowl, Figurine, Placement, SceneObject, TexturedPlane
from simulator.experiments import ExperimentOptions, ExperimentResult, check_scale, register
from simulator.experiments.methods import check_file_stems, depth_points, file_stem, method_names
from simulator.experiments.rigstereo import (
    BOARD_OFFSETS,
    MATCHERS,
    PreparedMethod,
    RigSetup,
    aim,
    chessboards,
    describe_error,
    exact_coverage,
    experiment_rig,
    match,
    prepare_methods,
    render_captures,
    rig_setup,
    warp_maps,
)
from simulator.rig import RigConfig

__all__ = [
    "BACKDROP_RGB",
    "BAD_PIXEL_THRESHOLDS_PX",
    "DEPTH_MATCHER",
    "ObjectsSetup",
    "objects_error_figure",
    "run_objects",
    "scene_objects",
    "setup_for",
]

#: Disparity error thresholds of the bad-pixel rates, pixels (Middlebury's usual ones).
BAD_PIXEL_THRESHOLDS_PX = (0.5, 1.0, 2.0)
#: The ``matcher`` of the rows of a method that estimates depth itself (no stereo matching).
DEPTH_MATCHER = "none"
#: Colour of the backdrop's pixels (not scored) in the error figure, RGB in 0..1: a pale blue, outside
#: the error colour map and unlike the grey of pixels with no estimate.
BACKDROP_RGB = (0.78, 0.86, 0.94)
#: Resolution of the figures, dots per inch.
FIGURE_DPI = 90


@dataclass(frozen=True)
class ObjectsSetup:
    """What one scale of the experiment renders.

    Attributes
    ----------
    rig : RigSetup
        The rig, the chessboards' depths (near, far) and the render settings.
    size : float
        Scale of the scene: object sizes, depths and offsets are the tiny scene's times ``size``.
    mask_depth_m : float
        Pixels of the left ideal image nearer than this are the objects' (the backdrop is farther).
    """

    rig: RigSetup
    size: float
    mask_depth_m: float


def setup_for(scale: str) -> ObjectsSetup:
    """The set-up of ``scale``: ``tiny`` (default rig) or ``illum`` (Illum rig, 1.5 x the scene)."""
    if check_scale(scale) == "tiny":
        return ObjectsSetup(
            rig=RigSetup(rig="default", calibration_depths_m=(0.45, 0.6), px_per_square=10.0, spp=16),
            size=1.0,
            mask_depth_m=0.5,
        )
    return ObjectsSetup(
        rig=RigSetup(rig="illum", calibration_depths_m=(0.675, 0.9), px_per_square=30.0, spp=8),
        size=1.5,
        mask_depth_m=0.75,
    )


def scene_objects(base: RigConfig, size: float) -> tuple[SceneObject, ...]:
    """The bowl (0.31 m), the figurine (0.34 m) and the backdrop (0.7 m), times ``size``, on the rig's
    line of sight."""
    bowl_at = aim(base, 0.31 * size) + np.array([-0.05, 0.01, 0.0]) * size
    figurine_at = aim(base, 0.34 * size) + np.array([0.05, 0.0, 0.0]) * size
    return (
        Bowl(
            placement=Placement(position_m=tuple(bowl_at), rotation_xyz_deg=(-30.0, 0.0, 0.0)),
            radius_m=0.045 * size,
            depth_m=0.03 * size,
            texture_seed=11,
        ),
        Figurine(placement=Placement(position_m=tuple(figurine_at)), height_m=0.1 * size, seed=3, texture_seed=12),
        TexturedPlane(
            placement=Placement(position_m=tuple(aim(base, 0.7 * size))),
            size_m=(1.0 * size, 0.8 * size),
            texture_px=1024,
            texture_seed=13,
        ),
    )


def run_objects(
    out_dir: Path, *, scale: str = "tiny", options: ExperimentOptions | None = None, progress: bool = True
) -> ExperimentResult:
    """Run the experiment (see the module docstring); figures and clouds go to ``out_dir``.

    ``options``: the methods, camera and wall of :class:`~simulator.experiments.ExperimentOptions`
    (its scale replaces ``scale``).
    """
    options = options if options is not None else ExperimentOptions(scale=scale)
    scale = options.scale
    objects_setup = setup_for(scale)
    setup = objects_setup.rig
    base = experiment_rig(setup, options)
    depths = setup.calibration_depths_m
    nearest, farthest = 0.25 * objects_setup.size, 0.8 * objects_setup.size  # disparity search range
    check_file_stems(options.methods if options.methods is not None else method_names())
    first = base.cameras[0].name
    with scratch_directory(prefix="lfsim-objects-") as work:
        jobs = [(f"board-{d}-{i}", [b]) for d in depths for i, b in enumerate(chessboards(base, setup, d))]
        jobs.append(("objects", scene_objects(base, objects_setup.size)))
        captures = render_captures(base, jobs, work, progress=progress)
        boards = {d: [captures[f"board-{d}-{i}"] for i in range(len(BOARD_OFFSETS))] for d in depths}
        scene = captures["objects"]
        truth = scene.depth(first)
        mask = np.isfinite(truth) & (truth < objects_setup.mask_depth_m)
        view = virtual_camera_for(base.cameras[0].scene.camera)
        warps = warp_maps(base)
        directions = view.pixel_directions().reshape(view.height_px, view.width_px, 3)
        surface = directions[mask] * (truth[mask] / directions[mask][:, 2])[:, None]  # left frame, m
        exact = np.zeros_like(mask)
        exact[mask] = exact_coverage(surface, base, warps)
        measure = _Measure(out_dir=Path(out_dir), view=view, truth=truth, mask=mask, exact=exact)
        rows, errors, order = [], {}, []
        prepared = prepare_methods(base, setup, boards, methods=options.methods, progress=progress, warps=warps)
        for method in prepared:
            order.append(method.name)
            if not method.ok:
                rows += [_failed(method.name, method.error, m) for m in MATCHERS]
                continue
            clouds: list[tuple[Path, np.ndarray]] = []
            try:
                new = measure.rows(method, scene, base, (nearest, farthest), errors, clouds)
            except Exception as exc:  # a method failing on the capture is a row, not a failed run
                matchers = (DEPTH_MATCHER,) if method.depth is not None else MATCHERS
                rows += [_failed(method.name, describe_error(exc), m) for m in matchers]
            else:  # written outside the try: a full disk fails the run, not the method
                rows += new
                for path, points in clouds:
                    write_ply(path, points)
    figure = Path(out_dir) / "objects_depth_error.png"
    objects_at = f"bowl {0.31 * objects_setup.size:.3g} m, figurine {0.34 * objects_setup.size:.3g} m away"
    save_figure(objects_error_figure(errors, order, mask=mask, setup=f"{rig_setup(base)}; {objects_at}"), figure)
    summary = "\n".join(
        f"- {r['matcher']}, {r['method']}: {r['median_abs_mm']:.2f} mm median, {r['mean_abs_mm']:.2f} mm mean, "
        f"{r['rms_mm']:.2f} mm RMS, bad 1 px {r['bad_1px']:.2f}, completeness {r['completeness']:.2f}; "
        f"exact coverage ({r['exact_share']:.2f} of the pixels): {r['exact_median_abs_mm']:.2f} mm median"
        if r["status"] == "ok"
        else f"- {r['matcher']}, {r['method']}: failed: {r['error']}"
        for r in rows
    )
    return ExperimentResult(
        name="objects",
        scale=scale,
        rows=tuple(rows),
        figures=(figure,),
        summary="depth error on the bowl and the figurine:\n" + summary,
        parameters=dict(setup.__dict__)
        | {"size": objects_setup.size, "object_mask_depth_m": objects_setup.mask_depth_m, "methods": order}
        | {"wall": base.wall.to_dict(), "camera": base.cameras[0].scene.camera.name},
    )


def _failed(method: str, error: str, matcher: str) -> dict:
    return {"matcher": matcher, "method": method, "status": "failed", "error": error}


@dataclass(frozen=True, eq=False)
class _Measure:
    """The ground truth of the objects' capture and how a method's points are scored against it."""

    out_dir: Path
    view: PinholeCamera  # the left ideal image's geometry
    truth: np.ndarray  # (H, W) true depth, metres
    mask: np.ndarray  # (H, W) the objects' pixels
    exact: np.ndarray  # (H, W) those seen through exact pixels of both cameras

    def rows(self, method: PreparedMethod, shot, base: RigConfig, search_m, errors: dict, clouds: list) -> list[dict]:
        """One row per matcher (one for a depth method), the error maps into ``errors`` and the
        point clouds to write, (path, points), into ``clouds``."""
        nearest, farthest = search_m
        if method.depth is not None:
            points = depth_points(np.asarray(method.depth.depth(shot)), method.depth.output)
            # The disparity that each depth implies on a rig of the cameras' true baseline and the view's focal length.
            baseline = float(np.linalg.norm(base.relative_pose(1)[1]))
            return [self._row(method, DEPTH_MATCHER, points, self.view.focal_px * baseline, errors, math.nan, 0)]
        rect = method.rectification
        first, second = base.cameras[0].name, base.cameras[1].name
        left, right = rect.apply(method.images.project(first, shot), method.images.project(second, shot))
        focal_baseline = rect.focal_px * rect.baseline_m  # disparity (px) times depth (m)
        low, high = focal_baseline / farthest, focal_baseline / nearest
        out = []
        for matcher in MATCHERS:
            disparity = match(matcher, left, right, min_disparity_px=int(low), num_disparities=int(high - low) + 3)
            points = disparity_to_points(disparity, rect)
            suffix = "" if matcher == MATCHERS[0] else f"_{matcher}"
            clouds.append((self.out_dir / f"cloud_{file_stem(method.name)}{suffix}.ply", points))
            out.append(self._row(method, matcher, points, focal_baseline, errors, method.stereo.rms_px, method.boards))
        return out

    def _row(self, method, matcher, points, focal_baseline, errors, stereo_rms_px, boards) -> dict:
        mask, truth, exact = self.mask, self.truth, self.exact
        estimate = _splat(points, self.view)
        result = depth_errors(estimate, truth, valid=mask)
        bad = disparity_errors(
            focal_baseline / estimate, focal_baseline / truth, thresholds_px=BAD_PIXEL_THRESHOLDS_PX, valid=mask
        )
        error = np.where(mask, np.abs(estimate - truth), np.nan)
        errors[(matcher, method.name)] = error
        return {
            "matcher": matcher,
            "method": method.name,
            "median_abs_mm": _mm(np.nanmedian, error[mask]),
            "mean_abs_mm": result.mean_abs_m * 1e3,
            "rms_mm": result.rms_m * 1e3,
            "bias_mm": result.bias_m * 1e3,
            **{f"bad_{t:g}px": f for t, f in zip(BAD_PIXEL_THRESHOLDS_PX, bad.bad_fractions, strict=True)},
            "completeness": result.completeness,
            "exact_share": float(exact.sum() / max(mask.sum(), 1)),
            "exact_median_abs_mm": _mm(np.nanmedian, error[exact]),
            "exact_mean_abs_mm": _mm(np.nanmean, error[exact]),
            "stereo_rms_px": stereo_rms_px,
            "boards": boards,
            "status": "ok",
            "error": "",
        }


def _mm(statistic, errors_m: np.ndarray) -> float:
    """``statistic`` (nanmedian, nanmean) of errors in metres, in mm; NaN without a finite error."""
    return float(statistic(errors_m)) * 1e3 if np.isfinite(errors_m).any() else math.nan


def _splat(points_cam: np.ndarray, view) -> np.ndarray:
    """Depth map (H, W) of ``view``: the nearest point's z at each point's nearest pixel; NaN elsewhere."""
    depth = np.full((view.height_px, view.width_px), np.inf)
    if len(points_cam):
        uv = np.rint(view.project(points_cam)).astype(np.int64)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < view.width_px) & (uv[:, 1] >= 0) & (uv[:, 1] < view.height_px)
        np.minimum.at(depth, (uv[inside, 1], uv[inside, 0]), points_cam[inside, 2])
    depth[np.isinf(depth)] = np.nan
    return depth


def objects_error_figure(errors: dict[tuple[str, str], np.ndarray], order: list[str], *, mask: np.ndarray, setup: str):
    """The depth error maps as a Figure: a row per matcher, a column per method (a method that
    estimates depth itself in every row), one colour bar in mm, the objects' pixels with no estimate
    grey and the backdrop (not scored) in :data:`BACKDROP_RGB`, each with a legend entry, and the
    set-up in the title.

    Parameters
    ----------
    errors : dict
        ``(matcher, method) -> |depth error|`` (H, W), metres, NaN where not scored or no estimate.
    order : list of str
        Methods, in order (a method with no map, failed, gets a panel that says so).
    mask : ndarray, shape (H, W)
        The objects' pixels (the others are the backdrop).
    setup : str
        The set-up, for the title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib as mpl
    from matplotlib.patches import Patch

    mask = np.asarray(mask, dtype=bool)
    columns = max(len(order), 1)
    height, width = mask.shape
    fig = new_figure(2.9 * columns + 1.2, (2.9 * height / width + 0.6) * len(MATCHERS) + 1.3, dpi=FIGURE_DPI)
    axes = fig.subplots(len(MATCHERS), columns, squeeze=False)
    top = max((float(np.nanpercentile(e, 95)) for e in errors.values() if np.isfinite(e).any()), default=1e-3)
    colours = mpl.colormaps["magma"].with_extremes(bad=NO_VALUE_RGB)
    backdrop = np.zeros((height, width, 4))
    backdrop[~mask] = (*BACKDROP_RGB, 1.0)
    image = None
    for i, matcher in enumerate(MATCHERS):
        for j in range(columns):
            ax = axes[i, j]
            if j >= len(order):
                ax.set_axis_off()
                continue
            error = errors.get((matcher, order[j]))
            own_depth = error is None and (DEPTH_MATCHER, order[j]) in errors
            error = errors.get((DEPTH_MATCHER, order[j])) if own_depth else error
            title = f"{order[j]}, {'its own depth' if own_depth else matcher.upper()}"
            if error is None:  # said in the middle: an empty axes' title would sit above the row's
                ax.text(0.5, 0.5, f"{title}:\nno depth map (failed)", ha="center", va="center", transform=ax.transAxes)
                ax.set_axis_off()
                continue
            ax.set_title(title, fontsize=8)
            image = ax.imshow(error * 1e3, cmap=colours, vmin=0.0, vmax=top * 1e3, interpolation="nearest")
            ax.imshow(backdrop, interpolation="nearest")
            ax.set_xlabel("u (px)", fontsize=8)
            ax.set_ylabel("v (px)", fontsize=8)
            ax.tick_params(labelsize=7)
    if image is not None:
        fig.colorbar(image, ax=axes, shrink=0.8, extend="max").set_label("|depth error| (mm)")
    handles = [
        Patch(facecolor=NO_VALUE_RGB, edgecolor="0.3", label="no estimate"),
        Patch(facecolor=BACKDROP_RGB, edgecolor="0.3", label="backdrop (not scored)"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncols=2, fontsize=8)
    fig.suptitle(f"depth error on the bowl and the figurine (left ideal view), by method\n{setup}", fontsize=9)
    return fig


@register("objects", options=("methods", "camera", "lens", "port_distance_m", "thickness_m"))
def run(out_dir: Path, options: ExperimentOptions, *, progress: bool) -> ExperimentResult:
    """A textured bowl and figurine reconstructed by every method (paper Fig. 7)."""
    return run_objects(out_dir, options=options, progress=progress)
