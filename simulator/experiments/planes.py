"""The ``planes`` experiment (paper Figs. 5-6): stereo on a textured plane at three depths, by method.

A stereo rig (two light-field cameras behind one tilted glass wall, :mod:`simulator.rig`) sees a
slanted textured plane at a near, a medium and a far depth. Each method of the registry
(:mod:`simulator.experiments.methods`; ``ExperimentOptions.methods`` chooses) turns both raw
images into central projections or estimates depth itself. Built in:

- ``approx far`` / ``approx near``: the approximation baseline calibrated per camera from
  chessboard captures at the far / near depth (paper conditions (a), (b));
- ``proposed``: the refraction-free synthesis (c);
- ``proposed+distortion``: with a residual distortion fitted on synthesized chessboard images (d);
- ``ideal``: the simulator's ground-truth refraction-free pinhole images, the floor.

For every method of central images the rig is stereo-calibrated from its own images of all the
chessboards (OpenCV, intrinsics fixed to the method's ``K``), rectified, matched by each of
:data:`~simulator.experiments.rigstereo.MATCHERS` (ZNCC, the paper's cost, and OpenCV's SGBM) and
triangulated into the left camera's frame; a method's depth maps (left camera frame) are turned
into points directly (one row per depth, ``matcher = "none"``). Measured per matcher, method and
depth:

- ``plane_rmse_mm``: the paper's figure, the RMS distance of the points to a plane fitted after
  outlier removal (RANSAC, threshold 1 % of the depth);
- ``truth_error_mm``: the mean absolute distance of those inlier points to the true plane (left
  camera frame; the experiment's ground truth, which the paper did not have), and
  ``outlier_share``, the share of points RANSAC left out;
- ``completeness``: the share of the rectified left image's pixels with a disparity (of the depth
  map's pixels with a depth);
- ``exact_share`` and ``exact_plane_rmse_mm``, ``exact_truth_error_mm``, ``exact_outlier_share``:
  the share of the points inside both cameras' exact coverage
  (:func:`~simulator.experiments.rigstereo.exact_coverage`, where the synthesis's every necessary
  ray is recorded) and the same measures on those points alone. Outside it the synthesis
  approximates; on the ``illum`` rig the coverage is a fraction of the image;
- ``status`` (``ok`` or ``failed``) and ``error``: a method that raises (in its set-up, the rig
  calibration on its images, or on one capture) gives rows with its error and NaN measures.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lfrefract.figures import NO_VALUE_RGB, new_figure, save_figure
from lfrefract.formats.outputs import scratch_directory
from lfrefract.formats.ply import write_ply
from lfrefract.metrics import fit_plane_ransac
from lfrefract.stereo.geometry import disparity_to_depth, disparity_to_points
from simulator.config import Placement, TexturedPlane
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
    grey,
    match,
    prepare_methods,
    render_captures,
    rig_setup,
    warp_maps,
)
from simulator.rig import RigConfig

__all__ = [
    "DEPTH_MATCHER",
    "PLANE_DEPTHS_M",
    "PLANE_ROTATION_XYZ_DEG",
    "disparity_figure",
    "errors_figure",
    "plane_figures",
    "plane_in_left",
    "plane_measures",
    "plane_rows",
    "run_planes",
    "setup_for",
    "textured_plane",
]

#: Plane depths (near, medium, far), metres, per scale (world z of the plane's centre).
PLANE_DEPTHS_M = {"tiny": (0.3, 0.45, 0.6), "illum": (0.4, 0.7, 1.0)}
#: The plane's rotation (x, y, z Euler angles, degrees): slanted, so that its depth varies across the view.
PLANE_ROTATION_XYZ_DEG = (10.0, -15.0, 0.0)
#: The ``matcher`` of the rows of a method that estimates depth itself (no stereo matching).
DEPTH_MATCHER = "none"
#: Texture seed of the plane.
PLANE_TEXTURE_SEED = 7
#: Resolution of the figures, dots per inch.
FIGURE_DPI = 90


def setup_for(scale: str) -> RigSetup:
    """The rig of ``scale``: ``tiny``, the default rig (two tiny-2x cameras); ``illum``, the Illum rig."""
    if check_scale(scale) == "tiny":
        return RigSetup(rig="default", calibration_depths_m=(0.3, 0.6), px_per_square=10.0, spp=16)
    return RigSetup(rig="illum", calibration_depths_m=(0.4, 1.0), px_per_square=30.0, spp=8)


def textured_plane(rig: RigConfig, depth_m: float, seed: int = PLANE_TEXTURE_SEED) -> TexturedPlane:
    """The slanted textured plane centred on the rig's line of sight at ``depth_m`` (it fills the views)."""
    return TexturedPlane(
        placement=Placement(position_m=tuple(aim(rig, depth_m)), rotation_xyz_deg=PLANE_ROTATION_XYZ_DEG),
        size_m=(1.4 * depth_m, 1.1 * depth_m),
        texture_px=1024,
        texture_seed=seed,
    )


def run_planes(
    out_dir: Path,
    *,
    scale: str = "tiny",
    options: ExperimentOptions | None = None,
    progress: bool = True,
    renders_dir: Path | None = None,
    write_clouds: bool = False,
) -> ExperimentResult:
    """Run the experiment (see the module docstring); figures go to ``out_dir``.

    ``options``: the methods, camera and wall of :class:`~simulator.experiments.ExperimentOptions`
    (its scale replaces ``scale``). ``renders_dir``: keep the rig renders there and reuse those
    that match on a later run (default: a temporary directory, deleted). ``write_clouds``: also
    write each method's point cloud of the medium plane, ``cloud_<method>.ply`` (left camera frame,
    metres, coloured).
    """
    options = options if options is not None else ExperimentOptions(scale=scale)
    setup = setup_for(options.scale)
    base = experiment_rig(setup, options)
    with scratch_directory(prefix="lfsim-planes-") as tmp:
        work = tmp if renders_dir is None else Path(renders_dir)
        return _run(out_dir, setup, options, base, work, progress=progress, write_clouds=write_clouds)


def _failed(method: str, error: str, depths, matchers) -> list[dict]:
    return [
        {"matcher": m, "method": method, "depth_m": d, "status": "failed", "error": error}
        for m in matchers
        for d in depths
    ]


def _run(
    out_dir: Path,
    setup: RigSetup,
    options: ExperimentOptions,
    base: RigConfig,
    work: Path,
    *,
    progress: bool,
    write_clouds: bool,
) -> ExperimentResult:
    """Render (into ``work``) and measure; see :func:`run_planes`."""
    check_file_stems(options.methods if options.methods is not None else method_names())
    scale = options.scale
    plane_depths = PLANE_DEPTHS_M[scale]
    near, far = setup.calibration_depths_m
    jobs = [(f"board-{d}-{i}", [b]) for d in (near, far) for i, b in enumerate(chessboards(base, setup, d))]
    jobs += [(f"plane-{d}", [textured_plane(base, d)]) for d in plane_depths]
    captures = render_captures(base, jobs, work, progress=progress)
    boards = {d: [captures[f"board-{d}-{i}"] for i in range(len(BOARD_OFFSETS))] for d in (near, far)}
    planes = {d: captures[f"plane-{d}"] for d in plane_depths}
    truth = {depth: plane_in_left(base, textured_plane(base, depth)) for depth in plane_depths}

    warps = warp_maps(base)
    rows, disparities, order = [], {}, []
    prepared = prepare_methods(base, setup, boards, methods=options.methods, progress=progress, warps=warps)
    for method in prepared:
        order.append(method.name)
        if not method.ok:
            rows += _failed(method.name, method.error, plane_depths, MATCHERS)
            continue
        for depth in plane_depths:
            clouds: list[tuple[Path, np.ndarray, np.ndarray]] = []
            try:
                new = plane_rows(
                    method,
                    planes[depth],
                    depth,
                    truth[depth],
                    base,
                    warps,
                    disparities,
                    out_dir,
                    clouds=clouds if write_clouds and depth == plane_depths[1] else None,
                )
            except Exception as exc:  # a method failing on one capture is a row, not a failed run
                matchers = (DEPTH_MATCHER,) if method.depth is not None else MATCHERS
                new = _failed(method.name, describe_error(exc), (depth,), matchers)
            else:  # written outside the try: a full disk fails the run, not the method
                for path, points, colours in clouds:
                    write_ply(path, points, colours)
            rows += new
    figures = plane_figures(out_dir, rows, disparities, plane_depths, order, setup=rig_setup(base))
    return ExperimentResult(
        name="planes",
        scale=scale,
        rows=tuple(rows),
        figures=figures,
        summary=_summary(rows, plane_depths, order),
        parameters=dict(setup.__dict__)
        | {"plane_depths_m": plane_depths, "methods": order, "wall": base.wall.to_dict()}
        | {"camera": base.cameras[0].scene.camera.name},
    )


def plane_rows(
    method: PreparedMethod,
    shot,
    depth: float,
    truth: tuple[np.ndarray, float],
    base: RigConfig,
    warps,
    disparities: dict,
    out_dir: Path,
    *,
    clouds: list | None,
) -> list[dict]:
    """The rows of one method on the plane at ``depth``: one per matcher, or one for a depth method.

    Parameters
    ----------
    method : PreparedMethod
        A method ready to measure (its rig calibrated on its images, or its depth maps).
    shot : Shot
        The capture of the plane.
    depth : float
        The plane's depth, metres (its ``depth_m`` column; the matchers' disparity range and the
        outlier threshold follow from it).
    truth : (ndarray, float)
        The true plane in the left camera frame (:func:`plane_in_left`).
    base : RigConfig
        The rig (its true poses give the exact coverage).
    warps : dict of str to WarpMap
        The cameras' true warp maps (:func:`~simulator.experiments.rigstereo.warp_maps`), whose
        exact pixels give ``exact_share``.
    disparities : dict
        Filled with each matcher's disparity map, keyed ``(matcher, method name, depth)``.
    out_dir : Path
        Where the point clouds go.
    clouds : list, optional
        Where to put the point cloud to write (path, points, colours), or None for none.
    """
    if method.depth is not None:
        estimate = np.asarray(method.depth.depth(shot), dtype=np.float64)
        points = depth_points(estimate, method.depth.output)
        exact = exact_coverage(points, base, warps)
        return [
            {
                "matcher": DEPTH_MATCHER,
                "method": method.name,
                "depth_m": depth,
                **plane_measures(points, truth, depth),
                "completeness": float(np.isfinite(estimate).mean()),
                "exact_share": float(exact.mean()) if len(exact) else math.nan,
                **{f"exact_{k}": v for k, v in plane_measures(points[exact], truth, depth).items()},
                "stereo_rms_px": math.nan,
                "boards": 0,
                "status": "ok",
                "error": "",
            }
        ]
    rect = method.rectification
    first, second = base.cameras[0].name, base.cameras[1].name
    left, right = rect.apply(method.images.project(first, shot), method.images.project(second, shot))
    expected = rect.focal_px * rect.baseline_m / depth
    rows = []
    for matcher in MATCHERS:
        disparity = match(
            matcher,
            left,
            right,
            min_disparity_px=max(int(expected * 0.5), 0),
            num_disparities=int(expected) + 8,
        )
        disparities[(matcher, method.name, depth)] = disparity
        points = disparity_to_points(disparity, rect)
        if clouds is not None and matcher == MATCHERS[0]:
            finite = np.isfinite(disparity_to_depth(disparity, rect))
            colours = np.clip(left[finite] / max(float(np.nanpercentile(left, 99)), 1e-12), 0, 1)
            cloud = Path(out_dir) / f"cloud_{file_stem(method.name)}.ply"
            clouds.append((cloud, points, (colours * 255).astype(np.uint8)))
        exact = exact_coverage(points, base, warps)
        inside = plane_measures(points[exact], truth, depth)
        rows.append(
            {
                "matcher": matcher,
                "method": method.name,
                "depth_m": depth,
                **plane_measures(points, truth, depth),
                "completeness": float(np.isfinite(disparity).sum() / max(np.isfinite(grey(left)).sum(), 1)),
                "exact_share": float(exact.mean()) if len(exact) else math.nan,
                **{f"exact_{k}": v for k, v in inside.items()},
                "stereo_rms_px": method.stereo.rms_px,
                "boards": method.boards,
                "status": "ok",
                "error": "",
            }
        )
    return rows


def plane_measures(points: np.ndarray, truth: tuple[np.ndarray, float], depth_m: float) -> dict[str, float]:
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


def plane_in_left(rig: RigConfig, plane: TexturedPlane) -> tuple[np.ndarray, float]:
    """The plane's normal and offset (``normal . X = offset``) in the left camera frame."""
    local = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) * 0.1
    points = rig.cameras[0].scene.pose.to_camera(plane.placement.to_world(local))
    normal = np.cross(points[1] - points[0], points[2] - points[0])
    normal /= np.linalg.norm(normal)
    return normal, float(normal @ points[0])


def _cell(rows: list[dict], method: str, matcher: str, depth: float, prefix: str) -> str:
    row = next(
        (
            r
            for r in rows
            if r["method"] == method and r["depth_m"] == depth and r["matcher"] in (matcher, DEPTH_MATCHER)
        ),
        None,
    )
    if row is None or row["status"] != "ok":
        return "failed"
    return f"{row[prefix + 'plane_rmse_mm']:.2f} / {row[prefix + 'truth_error_mm']:.2f}"


def _summary(rows: list[dict], plane_depths: tuple[float, ...], order: list[str]) -> str:
    parts = []
    for matcher in MATCHERS:
        for prefix, what in (("", "all points"), ("exact_", "points in the exact coverage")):
            lines = ["| method | " + " | ".join(f"{d:g} m" for d in plane_depths) + " |"]
            lines.append("|---|" + "---|" * len(plane_depths))
            for method in order:
                cells = [_cell(rows, method, matcher, d, prefix) for d in plane_depths]
                lines.append(f"| {method} | " + " | ".join(cells) + " |")
            title = f"{matcher}, {what}: plane RMSE / error against the true plane, mm"
            if prefix:
                shares = [
                    r["exact_share"]
                    for r in rows
                    if r["matcher"] == matcher and r["method"] == "ideal" and r["status"] == "ok"
                ]
                if shares:
                    title += " (share of the ideal images' points: " + ", ".join(f"{x:.2f}" for x in shares) + ")"
            parts.append(title + ":\n" + "\n".join(lines))
    failed = sorted({(r["method"], r["error"]) for r in rows if r["status"] != "ok"})
    if failed:
        parts.append("failed methods:\n" + "\n".join(f"- {m}: {e}" for m, e in failed))
    if any(r["matcher"] == DEPTH_MATCHER for r in rows):
        parts.append("methods that estimate depth themselves (no stereo matching) appear under every matcher")
    return "\n\n".join(parts)


def plane_figures(
    out_dir: Path,
    rows,
    disparities,
    plane_depths: Sequence[float],
    order: list[str],
    *,
    setup: str,
    prefix: str = "planes",
) -> tuple[Path, ...]:
    """Write the disparity maps per matcher (``<prefix>_disparity_<matcher>.png``,
    :func:`disparity_figure`) and the errors by depth and method (``<prefix>_errors.png``,
    :func:`errors_figure`); the paths.

    Parameters
    ----------
    out_dir : Path
    rows : list of dict
        :func:`plane_rows`'s rows.
    disparities : dict
        ``(matcher, method, depth) -> disparity map`` as :func:`plane_rows` fills it.
    plane_depths : sequence of float
        Depths, metres, in order.
    order : list of str
        Methods, in order.
    setup : str
        The set-up, for the titles (:func:`~simulator.experiments.rigstereo.rig_setup`).
    prefix : str
        The files' prefix.
    """
    paths = []
    for matcher in MATCHERS:
        paths.append(Path(out_dir) / f"{prefix}_disparity_{matcher}.png")
        save_figure(disparity_figure(disparities, matcher, plane_depths, order, rows=rows, setup=setup), paths[-1])
    paths.append(Path(out_dir) / f"{prefix}_errors.png")
    save_figure(errors_figure(rows, plane_depths, order, setup=setup), paths[-1])
    return tuple(paths)


def disparity_figure(
    disparities, matcher: str, plane_depths: Sequence[float], order: Sequence[str], *, rows=(), setup: str
):
    """The disparity maps of ``matcher`` as a Figure: a row per plane depth with its colour bar in
    pixels, a column per method that has a map, pixels with no disparity grey (with a legend entry),
    and the set-up in the title.

    Parameters
    ----------
    disparities : dict
        ``(matcher, method, depth) -> disparity map`` (rectified left view, px; NaN: no match).
    matcher : str
        The matcher shown.
    plane_depths : sequence of float
        Depths, metres, in order (the rows).
    order : sequence of str
        Methods, in order; those without a map of any matcher are left out.
    rows : sequence of dict
        :func:`plane_rows`'s rows: a panel with no map says whether its method failed there.
    setup : str
        The set-up, for the title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib as mpl
    from matplotlib.patches import Patch

    depths = tuple(plane_depths)
    shown = [m for m in order if any((k, m, d) in disparities for k in MATCHERS for d in depths)]
    columns = max(len(shown), 1)
    fig = new_figure(2.7 * columns + 1.0, 2.3 * len(depths) + 1.3, dpi=FIGURE_DPI)
    axes = fig.subplots(len(depths), columns, squeeze=False)
    colours = mpl.colormaps["viridis"].with_extremes(bad=NO_VALUE_RGB)
    failed = {(r["method"], r["depth_m"]) for r in rows if r.get("status") != "ok"}
    for i, depth in enumerate(depths):
        values = [disparities.get((matcher, m, depth)) for m in shown]
        finite = [v[np.isfinite(v)] for v in values if v is not None]
        finite = np.concatenate(finite) if finite else np.zeros(0)
        lo, hi = np.percentile(finite, [2, 98]) if len(finite) else (0.0, 1.0)
        image = None
        for j in range(columns):
            ax = axes[i, j]
            title = f"{shown[j]}, {depth:g} m" if j < len(shown) else ""
            if j < len(shown) and values[j] is not None:
                image = ax.imshow(values[j], cmap=colours, vmin=lo, vmax=hi, interpolation="nearest")
                ax.set_title(title, fontsize=8)
                ax.set_xlabel("u (px)", fontsize=8)
                ax.set_ylabel("v (px)", fontsize=8)
                ax.tick_params(labelsize=7)
            else:  # said in the middle: an empty axes' title would sit above the row's
                why = "failed" if j < len(shown) and (shown[j], depth) in failed else "no disparity map"
                ax.text(
                    0.5, 0.5, f"{title}:\n{why}" if title else why, ha="center", va="center", transform=ax.transAxes
                )
                ax.set_axis_off()
        if image is not None:
            bar = fig.colorbar(image, ax=axes[i, :], shrink=0.9, extend="both")
            bar.set_label(f"disparity at {depth:g} m (px)", fontsize=8)
            bar.ax.tick_params(labelsize=7)
    no_match = Patch(facecolor=NO_VALUE_RGB, edgecolor="0.3", label="no disparity (no match)")
    fig.legend(handles=[no_match], loc="outside lower center", fontsize=8)
    fig.suptitle(
        f"{matcher.upper()} disparity maps of the rectified left view, by method and plane depth\n{setup}", fontsize=9
    )
    return fig


def errors_figure(rows, plane_depths: Sequence[float], order: Sequence[str], *, setup: str):
    """The errors by plane depth and method as a Figure: bars of the plane-fit RMSE, the error against
    the true plane and that error in the exact coverage, a row per matcher; a method with no value is
    named in the legend; the set-up in the title.

    Parameters
    ----------
    rows : sequence of dict
        :func:`plane_rows`'s rows.
    plane_depths : sequence of float
        Depths, metres, in order.
    order : sequence of str
        Methods, in order.
    setup : str
        The set-up, for the title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.patches import Patch

    depths = tuple(plane_depths)
    keys = (
        ("plane_rmse_mm", "plane fit RMSE (paper's metric)"),
        ("truth_error_mm", "error against the true plane"),
        ("exact_truth_error_mm", "same, exact coverage only"),
    )
    fig = new_figure(15.0, 3.2 * len(MATCHERS) + 1.3, dpi=FIGURE_DPI)
    axes = fig.subplots(len(MATCHERS), len(keys), squeeze=False)
    width = 0.8 / max(len(order), 1)
    x = np.arange(len(depths))
    colours = [f"C{j % 10}" for j in range(len(order))]
    missing: dict[str, set] = {m: set() for m in order}
    for i, matcher in enumerate(MATCHERS):
        for j, method in enumerate(order):
            ours = {
                r["depth_m"]: r
                for r in rows
                if r["method"] == method and r["matcher"] in (matcher, DEPTH_MATCHER) and r["status"] == "ok"
            }
            for ax, (key, _) in zip(axes[i], keys, strict=True):
                heights = [float(ours[d].get(key, math.nan)) if d in ours else math.nan for d in depths]
                missing[method] |= {d for d, h in zip(depths, heights, strict=True) if not math.isfinite(h)}
                ax.bar(x + (j - len(order) / 2 + 0.5) * width, heights, width, color=colours[j])
        for ax, (_, title) in zip(axes[i], keys, strict=True):
            ax.set(xticks=x, xticklabels=[f"{d:g}" for d in depths], title=f"{matcher.upper()}: {title}")
            ax.set_xlabel("plane depth (m)")
            ax.set_ylabel("error (mm)")
            ax.grid(alpha=0.3, axis="y")
    handles = []
    for method, colour in zip(order, colours, strict=True):
        gaps = sorted(missing[method])
        label = method if not gaps else f"{method} (no value at {', '.join(f'{d:g}' for d in gaps)} m)"
        handles.append(Patch(facecolor=colour, label=label))
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4) or 1, fontsize=8)
    fig.suptitle(f"plane reconstruction errors by method and plane depth\n{setup}", fontsize=10)
    return fig


@register("planes", options=("methods", "camera", "lens", "port_distance_m", "thickness_m"), keeps_renders=True)
def run(
    out_dir: Path, options: ExperimentOptions, *, progress: bool, renders_dir: Path | None = None
) -> ExperimentResult:
    """Stereo on a slanted textured plane at three depths, by method (paper Figs. 5-6)."""
    return run_planes(out_dir, options=options, progress=progress, renders_dir=renders_dir)
