"""Ground-truth disparity of sub-aperture view stacks, in the HCI 4D light field benchmark's convention.

The views (:func:`lfrefract.synthesis.views.subaperture_stack`): view ``[r, c]`` of a
``grid x grid`` stack with spacing ``s`` (sensor pixels) samples every micro-image at the offset
``((c - h) s, (r - h) s)``, ``h = (grid - 1) / 2``. For the thin main lens all those rays pass the
point ``C_rc = ((c - h) b, (r - h) b, 0)`` of the main-lens plane (camera frame, metres;
``b = s * pixel_pitch * f' / f_mla`` the baseline, :func:`~lfrefract.synthesis.views.subaperture_centre_m`),
and the view places each ray at the pixel ``K (slope, 1)`` of its true slope (with ``f' != f`` the
sub-aperture rays are tilted by ``subaperture_slope_shift``, and the resampling places the lenses shifted by it,
so the tilt is already in the pixel positions). So in the air view ``[r, c]``'s pixel ``p`` is the ray
from ``C_rc`` along ``K^-1 p``: a pinhole with the stack's common ``K`` (the ideal image's
:class:`~lfrefract.optics.pinhole.PinholeCamera` in a dataset) and the camera frame's orientation.
Behind a port that air-side ray is refracted on into the water.

Disparity (the HCI convention)
------------------------------
The benchmark (Honauer et al., ACCV 2016; its toolkit ``lightfield-analysis/evaluation-toolkit``,
``source/toolkit/scenes/base_scene.py``, ``depth2disp``, and the Blender add-on that rendered it,
``lightfield-analysis/blender-addon``, ``lightfield_simulator.py``) lays out its cameras with
``input_Cam000`` at the top left, columns to the right (+x) and rows downwards, all parallel, and
converts depth to disparity by::

    disp = (f * focus_distance_m / depth - f) / focus_distance_m / sensor_size_mm,
    f = baseline_mm / 1000 * focal_length_mm * max(width, height)

that is ``disp = baseline_m * focal_px * (1 / depth - 1 / focus_distance_m)`` with
``focal_px = focal_length_mm * max(width, height) / sensor_size_mm`` and ``depth`` the camera-frame z.
Its cameras are shifted (sensor shift) so that the focus plane has zero disparity; positive
disparity is nearer than it, and such a point moves left (towards -u) in the view one column to
the right and up (-v) in the view one row down. This project's stacks are not shifted:
``parameters.cfg`` (:mod:`lfrefract.formats.viewstack`) says ``focus_distance_m = inf``,
``focal_length_mm = f'`` and ``sensor_size_mm = max(width, height) * f' / focal_px``, so the benchmark's
relation reads ``disp = focal_px * baseline_m / depth`` (its limit as the focus distance grows; the
formula evaluated literally with ``inf`` gives ``inf / inf``).

Here the disparity is defined by the displacement itself, which is what the benchmark's formula
gives for its central pinhole cameras and what stays meaningful behind a port, where the views are
no longer shifted copies of one central camera: for view ``[r, c]``'s pixel ``p = (u, v)`` whose
ray meets its first surface at ``X``,

* ``disparity_x_px[r, c, v, u] = u - u'``, ``(u', v')`` the pixel at which the view one column to
  the right (centre ``C_rc + (b, 0, 0)``) sees ``X``;
* ``disparity_y_px[r, c, v, u] = v - v''``, ``(u'', v'')`` the pixel at which the view one row down
  (centre ``C_rc + (0, b, 0)``) sees ``X``.

``X`` is projected into the neighbouring view through the port by
:func:`lfrefract.optics.forward.project_through_port`. For the last column (row) the neighbour is
the pinhole one step beyond the stack, at the centre the grid continues to (a geometric
neighbour; it need not be a recordable view). Occlusion in the neighbour is not considered (as
in the benchmark: a disparity is a property of the point seen in this view). In the air (no
port) both are exactly ``focal_px * baseline_m / Z``, ``Z`` the camera-frame z of ``X``, the same in
every view: the benchmark's value from ``parameters.cfg``. Behind a tilted port they differ from
each other, vary across a plane and from view to view; behind a port parallel to the main lens
they are the same in every view (the set-up is invariant under a shift of the centre along the
port) but still vary with the field angle (refraction at a flat face is not a central projection).

NaN marks a pixel with no disparity: its ray meets no surface, is not transmitted by the port
(:attr:`~lfrefract.optics.port.PortTrace.valid`), or is not recorded in the view (the pixel lies
outside the hull of the lenses, where the view itself is NaN:
:func:`~lfrefract.synthesis.views.resampling_matrix`), or ``X`` cannot be seen from the neighbour
(:func:`~lfrefract.optics.forward.forward_project`).

Scene rays are traced with Mitsuba's ``scene.ray_intersect`` in the scene built without the port
(as :func:`simulator.groundtruth.depth_map` does); the port is applied in float64 by
:meth:`FlatPort.trace_from_air`, and ``X`` is the float64 point at Mitsuba's (float32) distance along
the float64 ray. Only the thin main lens is modelled: with a real main lens (``config.lens``) the
views' pixels are not one pinhole's rays, and :class:`ParameterError` is raised.

Memory: the result holds ``8 * grid^2 * width * height`` bytes (two float32 maps per view,
:func:`view_disparity_bytes`); the work runs per view, in chunks of at most :data:`CHUNK_PIXELS`
pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from lfrefract import LightFieldCamera, PinholeCamera, virtual_camera_for
from lfrefract._memory import require_memory
from lfrefract.errors import ParameterError
from lfrefract.optics.forward import project_through_port
from lfrefract.synthesis.views import (
    lens_count,
    resampling_bytes,
    resampling_matrix,
    subaperture_centre_m,
    subaperture_limit_px,
    subaperture_slope_shift,
)
from lfrefract.validate import positive_float
from simulator.config import SceneConfig

__all__ = [
    "CHUNK_PIXELS",
    "WORK_BYTES_PER_PIXEL",
    "ViewDisparity",
    "stack_spacing_px",
    "view_disparity",
    "view_disparity_bytes",
    "view_stack_disparity",
]

#: Pixels traced at once: bounds the working memory of one chunk to about
#: ``CHUNK_PIXELS * WORK_BYTES_PER_PIXEL`` (34 MB) whatever the image size.
CHUNK_PIXELS = 1 << 16

#: Working memory per traced pixel, bytes: the float64 rays through the port, Mitsuba's arrays, the
#: points and two forward projections with their solver's state (measured with tracemalloc on the
#: tiny camera behind a tilted port: 340 B per pixel of a 92 x 69 px view, rounded up).
WORK_BYTES_PER_PIXEL = 512


@dataclass(frozen=True, kw_only=True, eq=False)
class ViewDisparity:
    """Ground-truth disparity of every view of a stack (see the module docstring for the definition).

    Attributes
    ----------
    disparity_x_px : ndarray, float32, shape (grid, grid, height, width)
        ``[r, c, v, u]``: how far, in pixels towards -u, the point seen at ``(u, v)`` in view
        ``[r, c]`` lies in the view one column to the right; NaN where there is none.
    disparity_y_px : ndarray, float32, shape (grid, grid, height, width)
        The same towards -v for the view one row down.
    offsets_px : ndarray, shape (grid, grid, 2)
        Sensor offsets ``((c - h) s, (r - h) s)`` of the views, pixels (as
        :class:`~lfrefract.synthesis.views.ViewStack`).
    centres_m : ndarray, shape (grid, grid, 3)
        Centres of projection ``((c - h) b, (r - h) b, 0)``, camera frame, metres.
    output : PinholeCamera
        Intrinsics and size of every view.
    """

    disparity_x_px: np.ndarray
    disparity_y_px: np.ndarray
    offsets_px: np.ndarray
    centres_m: np.ndarray
    output: PinholeCamera

    @property
    def grid(self) -> int:
        """Views per row and per column (odd)."""
        return int(self.disparity_x_px.shape[0])

    @property
    def centre_index(self) -> int:
        """Row and column ``h = (grid - 1) / 2`` of the central view."""
        return (self.grid - 1) // 2

    @property
    def spacing_px(self) -> float:
        """Sensor offset between neighbouring views' samples, pixels."""
        return float(self.offsets_px[0, 1, 0] - self.offsets_px[0, 0, 0])

    @property
    def baseline_m(self) -> float:
        """Distance between the centres of neighbouring views, metres."""
        return float(self.centres_m[0, 1, 0] - self.centres_m[0, 0, 0])


def view_disparity_bytes(camera: LightFieldCamera, output: PinholeCamera, grid: int) -> int:
    """Estimated peak memory of :func:`view_stack_disparity`, bytes (see :mod:`lfrefract._memory`).

    The result, ``8 * grid^2`` bytes per output pixel (two float32 maps per view); the pixels'
    unit directions (24 B) and a view's hull mask (9 B); the larger of: the views' resampling that
    decides the hull (:func:`~lfrefract.synthesis.views.resampling_bytes` over ``camera``'s lenses: per
    pixel, per lens and one chunk; freed before the tracing) and one chunk's work
    (:data:`WORK_BYTES_PER_PIXEL` per pixel of at most :data:`CHUNK_PIXELS`). :func:`view_disparity`
    (one view) needs the same with ``grid = 1``. Measured with tracemalloc on the tiny camera behind a
    tilted port (3 x 3 stacks of 6 348 and 25 392 px views): 0.55-0.8 of the estimate, 0.88-0.91 with
    qhull's 950 B per lens, which tracemalloc does not see.
    """
    pixels = output.width_px * output.height_px
    resampling = resampling_bytes(lenses=lens_count(camera), pixels=pixels)
    work = max(resampling, WORK_BYTES_PER_PIXEL * min(pixels, CHUNK_PIXELS))
    return int(8 * grid * grid * pixels + 24 * pixels + 9 * pixels + work)


def stack_spacing_px(camera: LightFieldCamera, grid: int, spacing_px: float | None = None) -> float:
    """The spacing of a ``grid x grid`` stack, pixels, checked as
    :func:`~lfrefract.synthesis.views.subaperture_stack` does.

    Parameters
    ----------
    camera : LightFieldCamera
    grid : int
        Odd, >= 3.
    spacing_px : float, optional
        Given spacing, > 0, whose corner views must stay within
        :func:`~lfrefract.synthesis.views.subaperture_limit_px`. Default: the largest such spacing,
        the stack's own default.

    Returns
    -------
    float

    Raises
    ------
    ParameterError
        For a grid that is not an odd integer >= 3, a camera with no room for views, or a spacing
        that is not positive or reaches beyond the limit.
    """
    grid = _grid_size(grid)
    half = (grid - 1) // 2
    limit = subaperture_limit_px(camera)
    if limit <= 0.0:
        raise ParameterError(
            f"camera {camera.name!r} has micro-images of radius {camera.micro_image_radius_px:.3g} px: "
            "no sub-aperture view but the central one stays a pixel inside the rim"
        )
    largest = limit / (math.sqrt(2.0) * half)
    while math.hypot(half * largest, half * largest) > limit:  # as subaperture_stack: the corner must pass
        largest = math.nextafter(largest, 0.0)
    if spacing_px is None:
        return largest
    spacing = positive_float("spacing_px", spacing_px)
    reach = math.hypot(half * spacing, half * spacing)
    if reach > limit:
        raise ParameterError(
            f"spacing_px={spacing_px!r} puts the corner views of the {grid} x {grid} grid {reach:.4g} px from the "
            f"micro-image centres, beyond the limit of {limit:.4g} px; at most {largest:.4g} px for grid={grid}"
        )
    return spacing


def _grid_size(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 3 or value % 2 != 1:
        raise ParameterError(f"grid must be an odd integer >= 3 (a central view with neighbours), got {value!r}")
    return int(value)


def _checked(config: Any, output: Any) -> PinholeCamera:
    if not isinstance(config, SceneConfig):
        raise ParameterError(f"config must be a SceneConfig, got {type(config).__name__}")
    if config.lens is not None:
        raise ParameterError(
            f"camera.lens={config.lens.name!r}: with a real main lens the sub-aperture views' pixels are not a "
            "pinhole's rays (their centres move with the field), so their disparity is not traced; only the thin "
            'main lens (camera.lens = "thin") is supported for now'
        )
    if output is None:
        return virtual_camera_for(config.camera)
    if not isinstance(output, PinholeCamera):
        raise ParameterError(f"output must be a PinholeCamera, got {output!r}")
    return output


def _geometry(camera: LightFieldCamera, grid: int, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Offsets (grid, grid, 2) pixels and centres (grid, grid, 3) metres of the stack's views."""
    steps = (np.arange(grid, dtype=np.float64) - (grid - 1) // 2) * spacing
    offsets = np.stack(np.broadcast_arrays(steps[None, :], steps[:, None]), axis=-1)
    scale = subaperture_centre_m(camera, (1.0, 0.0))[0]
    centres = np.concatenate([offsets * scale, np.zeros((grid, grid, 1))], axis=2)
    return offsets, centres


def _recorded(camera: LightFieldCamera, output: PinholeCamera, offset: np.ndarray) -> np.ndarray:
    """Pixels (H * W,) bool of the view at sensor ``offset`` that the view has a value for (inside the
    lenses' hull, exactly as its resampling decides)."""
    shift = subaperture_slope_shift(camera, float(offset[0]), float(offset[1]))
    return resampling_matrix(camera, output, slope_shift=shift, lenses=camera.lens_indices_on_sensor())[2]


def _first_surface(
    mi: ModuleType, scene: Any, config: SceneConfig, centre: np.ndarray, directions: np.ndarray
) -> np.ndarray:
    """Camera-frame points (N, 3), metres, where the rays from ``centre`` along ``directions`` (N, 3,
    air side) first meet a surface beyond the port; NaN rows where none or not transmitted."""
    origins = np.broadcast_to(centre, directions.shape)
    out = np.full(directions.shape, np.nan)
    if config.port is not None:
        trace = config.port.trace_from_air(origins, directions)
        keep = trace.valid
        origins, directions = trace.exit_points_cam[keep], trace.directions_cam[keep]
    else:
        keep = np.ones(directions.shape[0], dtype=bool)
    if not keep.any():
        return out
    rotation = np.asarray(config.pose.rotation, dtype=np.float64)
    o_world = origins @ rotation.T + np.asarray(config.pose.position_m, dtype=np.float64)
    d_world = directions @ rotation.T
    ray = mi.Ray3f(mi.Point3f(o_world.T.astype(np.float32)), mi.Vector3f(d_world.T.astype(np.float32)))
    si = scene.ray_intersect(ray)
    distance = np.asarray(si.t, dtype=np.float64)
    hit = np.asarray(si.is_valid(), dtype=bool) & np.isfinite(distance)
    points = np.where(hit[:, None], origins + distance[:, None] * directions, np.nan)
    out[keep] = points
    return out


def _one_view(
    mi: ModuleType,
    scene: Any,
    config: SceneConfig,
    output: PinholeCamera,
    directions: np.ndarray,
    recorded: np.ndarray,
    centre: np.ndarray,
    baseline_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Both disparity maps (H, W) float32 of the view at ``centre``."""
    shape = (output.height_px, output.width_px)
    dx = np.full(shape[0] * shape[1], np.nan, dtype=np.float32)
    dy = np.full(shape[0] * shape[1], np.nan, dtype=np.float32)
    pixels = np.flatnonzero(recorded)
    right = centre + np.array([baseline_m, 0.0, 0.0])
    below = centre + np.array([0.0, baseline_m, 0.0])
    for start in range(0, pixels.size, CHUNK_PIXELS):
        rows = pixels[start : start + CHUNK_PIXELS]
        points = _first_surface(mi, scene, config, centre, directions[rows])
        seen = np.all(np.isfinite(points), axis=1)
        rows, points = rows[seen], points[seen]
        if rows.size == 0:
            continue
        u = (rows % shape[1]).astype(np.float64)
        v = (rows // shape[1]).astype(np.float64)
        dx[rows] = u - project_through_port(config.port, output, right, points)[:, 0]
        dy[rows] = v - project_through_port(config.port, output, below, points)[:, 1]
    return dx.reshape(shape), dy.reshape(shape)


def view_disparity(
    mi: ModuleType,
    scene: Any,
    config: SceneConfig,
    output: PinholeCamera | None = None,
    *,
    row: int,
    column: int,
    grid: int = 9,
    spacing_px: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth disparity of one view ``[row, column]`` of a stack (one entry of :func:`view_stack_disparity`).

    For stacks too large to hold at once: peak memory is :func:`view_disparity_bytes` with ``grid = 1``.

    Parameters
    ----------
    mi, scene, config, output, grid, spacing_px
        As :func:`view_stack_disparity`.
    row, column : int
        The view, each in ``[0, grid)``.

    Returns
    -------
    disparity_x_px, disparity_y_px : ndarray, float32, shape (height, width)
        As :attr:`ViewDisparity.disparity_x_px` ``[row, column]`` and ``disparity_y_px[row, column]``.

    Raises
    ------
    ParameterError
        As :func:`view_stack_disparity`, and for a row or column outside the grid.
    """
    output = _checked(config, output)
    spacing = stack_spacing_px(config.camera, grid, spacing_px)
    for name, value in (("row", row), ("column", column)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value < grid:
            raise ParameterError(f"{name} must be an integer in [0, {grid}), got {value!r}")
    require_memory(
        f"the disparity of a {output.width_px} x {output.height_px} px view",
        view_disparity_bytes(config.camera, output, 1),
    )
    offsets, centres = _geometry(config.camera, grid, spacing)
    recorded = _recorded(config.camera, output, offsets[row, column])
    baseline = float(centres[0, 1, 0] - centres[0, 0, 0])
    return _one_view(mi, scene, config, output, output.pixel_directions(), recorded, centres[row, column], baseline)


def view_stack_disparity(
    mi: ModuleType,
    scene: Any,
    config: SceneConfig,
    output: PinholeCamera | None = None,
    *,
    grid: int = 9,
    spacing_px: float | None = None,
) -> ViewDisparity:
    """Ground-truth disparity of every view of a ``grid x grid`` sub-aperture stack (module docstring).

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set (:func:`simulator.backend.load_mitsuba`).
    scene : mitsuba.Scene
        ``config``'s scene built without the port (:func:`simulator.scene.build_scene` with
        ``port_geometry=False``).
    config : SceneConfig
        Camera (thin main lens), pose and port (or none) of the scene.
    output : PinholeCamera, optional
        Geometry of every view: the ideal image's in a dataset (``PinholeCamera.from_dict(meta["ideal"])``);
        default :func:`lfrefract.virtual_camera_for` the camera, as
        :func:`~lfrefract.synthesis.views.subaperture_stack`.
    grid : int
        Views per row and column; odd, >= 3.
    spacing_px : float, optional
        Sensor offset between neighbouring views, pixels; default the stack's own default
        (:func:`stack_spacing_px`).

    Returns
    -------
    ViewDisparity
        Two float32 maps of shape (grid, grid, height, width), ``8 * grid^2 * width * height`` bytes.

    Raises
    ------
    ParameterError
        For a real main lens (``config.lens``; see the module docstring), a grid or spacing the stack
        would refuse, an output that is not a PinholeCamera, or an estimated memory
        (:func:`view_disparity_bytes`) beyond what is available (checked before allocating).
    """
    output = _checked(config, output)
    spacing = stack_spacing_px(config.camera, grid, spacing_px)
    require_memory(
        f"the disparity of a {grid} x {grid} stack of {output.width_px} x {output.height_px} px views",
        view_disparity_bytes(config.camera, output, grid),
    )
    offsets, centres = _geometry(config.camera, grid, spacing)
    baseline = float(centres[0, 1, 0] - centres[0, 0, 0])
    shape = (grid, grid, output.height_px, output.width_px)
    disparity_x = np.empty(shape, dtype=np.float32)
    disparity_y = np.empty(shape, dtype=np.float32)
    directions = output.pixel_directions()
    camera = config.camera
    cached: tuple[tuple[float, float], np.ndarray] | None = None
    for r in range(grid):
        for c in range(grid):
            shift = subaperture_slope_shift(camera, float(offsets[r, c, 0]), float(offsets[r, c, 1]))
            if cached is None or cached[0] != shift:  # once in all when f' = f
                cached = None
                cached = (shift, _recorded(camera, output, offsets[r, c]))
            disparity_x[r, c], disparity_y[r, c] = _one_view(
                mi, scene, config, output, directions, cached[1], centres[r, c], baseline
            )
    return ViewDisparity(
        disparity_x_px=disparity_x, disparity_y_px=disparity_y, offsets_px=offsets, centres_m=centres, output=output
    )
