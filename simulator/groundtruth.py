"""Ground truth traced by the project, not read from Mitsuba's AOVs (which stop at the glass).

* The ideal image: the same scene without the port, seen by the virtual pinhole camera
  (centre of projection at the main-lens centre, OpenCV intrinsics K), lit identically, at its
  own samples per pixel (``render.ideal_spp``, default
  :data:`simulator.config.DEFAULT_IDEAL_SPP`), which is independent of the raw image's. In turbid
  water the pinhole stands in the water: its rays are attenuated (and the view veiled) over the
  whole distance from the main-lens centre, where the raw image's rays cross water only beyond
  the port's water face.
* Its depth map: camera-frame z of the first surface along each pixel-centre ray, metres,
  +inf where the ray hits nothing. It is geometric: turbid water does not change it.
* The microlenses: lattice indices, image-plane centres (metres) and micro-image centres
  (raw pixels) of every lens whose micro-image centre lies on the sensor.
* Labels of the ideal image (:func:`surface_labels`), from the same pixel-centre rays and the same
  single intersection as the depth map: the surface normal in the camera frame and the instance id
  of the object seen (:func:`instance_table` lists the ids).
* Raw-pixel truth (:func:`raw_pixel_truth`): for every raw sensor pixel, the depth of the first
  surface along its chief ray traced through the port, and the row of its microlens in the lens
  table.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

import numpy as np

from lfrefract import LightFieldCamera, PinholeCamera, Pose
from lfrefract.errors import ParameterError
from lfrefract.optics.camera import CapturedRays
from lfrefract.optics.lens import LensPrescription
from lfrefract.optics.real_lens import RealLensCamera
from simulator.config import OBJECT_TYPES, SceneConfig
from simulator.render import IDEAL_STREAM, render_bands
from simulator.scene import water_medium
from simulator.sensor import pinhole_sensor_dict

__all__ = [
    "BACKGROUND_ID",
    "DEFAULT_RAW_BLOCK_PIXELS",
    "MAX_INSTANCE_ID",
    "GroundTruth",
    "RawPixelTruth",
    "SurfaceLabels",
    "compute",
    "depth_map",
    "instance_table",
    "lens_table",
    "raw_pixel_truth",
    "surface_labels",
]

#: Instance id of pixels that see no object (no surface along the ray).
BACKGROUND_ID = 0

#: Largest instance id: ids are stored as uint16, object ``i`` of ``config.objects`` is ``i + 1``.
MAX_INSTANCE_ID = int(np.iinfo(np.uint16).max)

#: Raw pixels traced per block by :func:`raw_pixel_truth` (whole sensor rows, at least one row):
#: about 0.3 GB of peak working memory for the thin lens, 0.55 GB with a real lens (see there).
DEFAULT_RAW_BLOCK_PIXELS = 1 << 20


@dataclass(frozen=True)
class GroundTruth:
    """Ideal image (H, W, 3) float32, depth (H, W) float32 metres, lens table of arrays."""

    ideal: np.ndarray
    depth_m: np.ndarray
    lenses: dict[str, np.ndarray]


def lens_table(camera: LightFieldCamera, lens: LensPrescription | None = None) -> dict[str, np.ndarray]:
    """Microlens ground truth for every lens whose micro-image centre is on the sensor (with a real
    ``lens``, its own micro-image centres decide, not the thin lens's).

    Returns
    -------
    dict
        ``lens_index`` (M, 2) int64 lattice indices (i, j); ``lens_centre_m`` (M, 2) image-plane
        centres on the MLA, metres; ``micro_image_centre_px`` (M, 2) raw-pixel (u, v) centres of
        the micro-images (the main lens's exit pupil centre imaged through each lens centre: the
        thin lens's centre, or with a real ``lens`` the paraxial exit pupil,
        :meth:`lfrefract.optics.real_lens.RealLensCamera.micro_image_centres_px`).
    """
    optics = camera if lens is None else RealLensCamera(camera=camera, lens=lens)
    idx = camera.lens_indices_on_sensor(micro_image_scale=optics.micro_image_scale)
    return {
        "lens_index": idx,
        "lens_centre_m": camera.mla.centres_m(idx),
        "micro_image_centre_px": optics.micro_image_centres_px(idx),
    }


def _pinhole_intersection(mi: ModuleType, scene, pinhole: PinholeCamera, pose: Pose):
    """Mitsuba's first intersection of every pixel-centre ray of ``pinhole`` (row-major) and the rays'
    unit directions (N, 3) in the camera frame, float64."""
    d_cam = pinhole.pixel_directions()
    d_world = d_cam @ np.asarray(pose.rotation).T
    origin = np.broadcast_to(np.asarray(pose.position_m), d_world.shape)
    ray = mi.Ray3f(mi.Point3f(origin.T.astype(np.float32)), mi.Vector3f(d_world.T.astype(np.float32)))
    return scene.ray_intersect(ray), d_cam


def _pinhole_depth(si, d_cam: np.ndarray, pinhole: PinholeCamera) -> np.ndarray:
    """Camera-frame z (H, W) float32 of the intersections ``si`` along ``d_cam``; +inf on a miss."""
    t = np.asarray(si.t, dtype=np.float64)
    valid = np.asarray(si.is_valid(), dtype=bool)
    z = np.where(valid, t * d_cam[:, 2], np.inf)
    return z.reshape(pinhole.height_px, pinhole.width_px).astype(np.float32)


def depth_map(mi: ModuleType, scene, pinhole: PinholeCamera, pose: Pose) -> np.ndarray:
    """Camera-frame z (metres) of the first surface along every pixel-centre ray; +inf on a miss.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set.
    scene : mitsuba.Scene
        The scene without the port.
    pinhole : PinholeCamera
    pose : Pose
        Camera-to-world pose.

    Returns
    -------
    ndarray, float32, shape (pinhole.height_px, pinhole.width_px)
    """
    si, d_cam = _pinhole_intersection(mi, scene, pinhole, pose)
    return _pinhole_depth(si, d_cam, pinhole)


# ----------------------------------------------------------------------------- surface labels
@dataclass(frozen=True)
class SurfaceLabels:
    """Per-pixel labels of the ideal image, from one intersection per pixel-centre ray.

    Attributes
    ----------
    depth_m : ndarray, float32, shape (H, W)
        Camera-frame z of the first surface, metres; +inf where the ray hits nothing. Bit-identical
        to :func:`depth_map` of the same scene, pinhole and pose.
    normal_cam : ndarray, float32, shape (H, W, 3)
        Unit surface normal at that point in the camera frame (OpenCV axes: +x right, +y down, +z
        forward), the side facing the camera (``normal . ray direction <= 0``); NaN where no surface.
    instance_id : ndarray, uint16, shape (H, W)
        :data:`BACKGROUND_ID` (0) where no surface, ``i + 1`` where the surface is
        ``config.objects[i]`` (:func:`instance_table`).
    """

    depth_m: np.ndarray
    normal_cam: np.ndarray
    instance_id: np.ndarray


def _object_kind(obj: object) -> str:
    """The config type name (``textured_plane``, ``chessboard``, ...) of a scene object."""
    for name, cls in OBJECT_TYPES.items():
        if type(obj) is cls:
            return name
    raise ParameterError(f"object {obj!r} is of no scene object type ({sorted(OBJECT_TYPES)})")


def _check_object_count(config: SceneConfig) -> None:
    if len(config.objects) > MAX_INSTANCE_ID:
        raise ParameterError(
            f"the scene has {len(config.objects)} objects; instance ids are uint16, so at most {MAX_INSTANCE_ID}"
        )


def instance_table(config: SceneConfig) -> list[dict]:
    """The instance ids of :attr:`SurfaceLabels.instance_id`, for a sidecar (plain JSON data).

    Returns
    -------
    list of dict
        One entry per object of ``config.objects``, in order: ``{"id": i + 1, "type": name,
        "object_index": i}`` with ``name`` the object's config type (``textured_plane``,
        ``chessboard``, ``disc``, ``bowl``, ``figurine``, ``mesh``). Id :data:`BACKGROUND_ID` (0),
        no surface, has no entry.

    Raises
    ------
    ParameterError
        If the scene has more than :data:`MAX_INSTANCE_ID` objects.
    """
    _check_object_count(config)
    return [{"id": i + 1, "type": _object_kind(obj), "object_index": i} for i, obj in enumerate(config.objects)]


def _shape_instance_lookup(mi: ModuleType, scene, config: SceneConfig) -> np.ndarray:
    """uint16 array mapping each Mitsuba shape's registry id to its instance id (0: none).

    :func:`simulator.scene.build_scene` loads object ``i`` under the scene key ``object_{i}``, which
    Mitsuba keeps as the shape's id (one shape per object: a chessboard is one textured rectangle, a
    luminous disc one disk carrying its emitter; lights and the environment are no shapes). The order
    of :meth:`mitsuba.Scene.shapes` is not the config's (it changes from run to run), so shapes are
    matched by id. Per ray, Mitsuba reports the shape hit as a pointer whose registry id is what
    ``drjit.reinterpret_array(UInt32, ...)`` gives (0 for no shape), as it does for
    :meth:`mitsuba.Scene.shapes_dr`, whose order is that of :meth:`mitsuba.Scene.shapes`.
    """
    import drjit as dr

    wanted = {f"object_{i}": i + 1 for i in range(len(config.objects))}
    shapes = scene.shapes()
    registry = np.asarray(dr.reinterpret_array(mi.UInt32, scene.shapes_dr()), dtype=np.int64).reshape(-1)
    names = [shape.id() for shape in shapes]
    strays = [name for name in names if name not in wanted]
    if strays:
        raise ParameterError(
            f"scene: shapes {strays[:5]} are none of config's objects (object_0 .. object_{len(wanted) - 1}); "
            "build it from the same config with build_scene(..., port_geometry=False)"
        )
    missing = sorted(set(wanted) - set(names), key=lambda name: wanted[name])
    if missing or len(names) != len(set(names)):
        raise ParameterError(
            f"scene: its shapes {sorted(names)} do not match config's {len(wanted)} objects one to one "
            f"(missing {missing[:5]}); build it from the same config with build_scene(..., port_geometry=False)"
        )
    lookup = np.zeros(int(registry.max(initial=0)) + 1, dtype=np.uint16)
    lookup[registry] = [wanted[name] for name in names]
    return lookup


def surface_labels(mi: ModuleType, scene, config: SceneConfig, pinhole: PinholeCamera) -> SurfaceLabels:
    """Depth, surface normal and instance id of every pixel of the ideal image.

    One Mitsuba intersection per pixel-centre ray of ``pinhole`` (centre of projection at the
    main-lens centre, moved to the world by ``config.pose``), the rays and intersection of
    :func:`depth_map`.

    The normal is Mitsuba's **shading** normal (``si.sh_frame.n``), rotated into the camera frame
    and turned, where needed, to the side the ray comes from. On the planes and discs (rectangle
    and disk shapes, textured or not: no texture perturbs normals here) it is the geometric normal
    exactly. On the procedural meshes (bowl, figurine), which carry vertex normals, it is the
    interpolated vertex normal: the normal of the smooth surface the triangles approximate, rather
    than one constant normal per facet, and the normal the diffuse BSDF shades with, so it agrees
    with the image's shading. A user mesh file without vertex normals gets its face normals. The
    side is the shading normal's own (as Mitsuba's two-sided material chooses it), so
    ``normal . direction <= 0`` holds at every pixel, silhouettes included.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set.
    scene : mitsuba.Scene
        ``config``'s scene without the port (:func:`simulator.scene.build_scene` with
        ``port_geometry=False``): its shapes are matched to ``config.objects`` by the ids
        ``object_{i}`` that build_scene gives them.
    config : SceneConfig
        The scene's config: its pose (camera to world) and its objects (instance ids).
    pinhole : PinholeCamera
        Geometry of the ideal image.

    Returns
    -------
    SurfaceLabels
        Arrays of shape (pinhole.height_px, pinhole.width_px[, 3]).

    Raises
    ------
    ParameterError
        If the scene's shapes are not ``config.objects`` one to one (another config's scene, or
        one with the port's faces), or there are more than :data:`MAX_INSTANCE_ID` objects.
    """
    import drjit as dr

    _check_object_count(config)
    lookup = _shape_instance_lookup(mi, scene, config)
    si, d_cam = _pinhole_intersection(mi, scene, pinhole, config.pose)
    depth = _pinhole_depth(si, d_cam, pinhole)
    h, w = pinhole.height_px, pinhole.width_px
    valid = np.asarray(si.is_valid(), dtype=bool)
    # World to camera: n_cam = R^T n_world (row vectors: n_world @ R).
    normal = np.asarray(si.sh_frame.n, dtype=np.float64).T @ np.asarray(config.pose.rotation)
    with np.errstate(invalid="ignore", divide="ignore"):
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    normal *= np.where(np.sum(normal * d_cam, axis=1) > 0.0, -1.0, 1.0)[:, None]
    normal[~valid] = np.nan
    shape = np.asarray(dr.reinterpret_array(mi.UInt32, si.shape), dtype=np.int64).reshape(-1)
    ids = np.where(valid, lookup[np.where(valid, shape, 0)], BACKGROUND_ID).astype(np.uint16)
    return SurfaceLabels(
        depth_m=depth,
        normal_cam=normal.reshape(h, w, 3).astype(np.float32),
        instance_id=ids.reshape(h, w),
    )


# ----------------------------------------------------------------------------- raw-pixel truth
@dataclass(frozen=True)
class RawPixelTruth:
    """Ground truth of every raw sensor pixel, along its chief ray.

    Attributes
    ----------
    depth_m : ndarray, float32, shape (H, W)
        Camera-frame z, metres, of the first surface of the port-free scene that the pixel's chief
        ray (pixel centre through its microlens centre, through the main lens, refracted by the
        port into the water) reaches; +inf where it reaches none; NaN where the pixel records no
        ray (the chief ray is stopped by the main lens's aperture, or misses or is totally
        reflected by the port).
    lens_row : ndarray, int32, shape (H, W)
        Row of the pixel's microlens in :func:`lens_table` (``lenses.npz``), -1 where that lens is
        not on the table (its micro-image centre lies off the sensor). Defined for every pixel,
        vignetted ones included.
    """

    depth_m: np.ndarray
    lens_row: np.ndarray


def _lens_rows(table_index: np.ndarray, lens_indices: np.ndarray) -> np.ndarray:
    """Row (N,) int32 of each lattice index (N, 2) in the table's ``lens_index`` (M, 2); -1 if absent."""
    table = np.asarray(table_index, dtype=np.int64).reshape(-1, 2)
    idx = np.asarray(lens_indices, dtype=np.int64).reshape(-1, 2)
    out = np.full(len(idx), -1, dtype=np.int32)
    if len(table) == 0:
        return out
    low = table.min(axis=0)
    span = table.max(axis=0) - low + 1
    grid = np.full((int(span[0]), int(span[1])), -1, dtype=np.int32)
    grid[table[:, 0] - low[0], table[:, 1] - low[1]] = np.arange(len(table), dtype=np.int32)
    rel = idx - low
    inside = np.all((rel >= 0) & (rel < span), axis=1)
    out[inside] = grid[rel[inside, 0], rel[inside, 1]]
    return out


def _first_hit_z(mi: ModuleType, scene, origins_cam: np.ndarray, directions_cam: np.ndarray, pose: Pose) -> np.ndarray:
    """Camera-frame z (N,) float64 of the first surface along camera-frame rays (N, 3); +inf on a miss."""
    if len(origins_cam) == 0:
        return np.empty(0)
    rotation = np.asarray(pose.rotation)
    o_world = origins_cam @ rotation.T + np.asarray(pose.position_m)
    d_world = directions_cam @ rotation.T
    ray = mi.Ray3f(mi.Point3f(o_world.T.astype(np.float32)), mi.Vector3f(d_world.T.astype(np.float32)))
    hit = scene.ray_intersect_preliminary(ray)
    t = np.asarray(hit.t, dtype=np.float64)
    valid = np.asarray(hit.is_valid(), dtype=bool)
    # The rigid pose keeps lengths: t along the world ray is t along the camera-frame one.
    return np.where(valid, origins_cam[:, 2] + t * directions_cam[:, 2], np.inf)


def raw_pixel_truth(
    mi: ModuleType, scene, config: SceneConfig, *, max_block_pixels: int = DEFAULT_RAW_BLOCK_PIXELS
) -> RawPixelTruth:
    """Depth along the true captured ray, and the microlens, of every raw sensor pixel.

    A pixel's ray is the core's captured-ray model of its centre (through its microlens centre
    and the main lens): :meth:`lfrefract.LightFieldCamera.captured_rays` for the thin lens,
    :meth:`lfrefract.optics.real_lens.RealLensCamera.chief_rays` with ``config.lens``. It is traced
    through ``config.port`` (:meth:`lfrefract.FlatPort.trace_from_air`; straight on without a port),
    moved to the world with ``config.pose`` and intersected (once, float32 in Mitsuba) with the
    port-free scene. The pixel's microlens is the one these rays pass through (the core's rule: the
    lens whose micro-image centre is nearest, :meth:`lfrefract.LightFieldCamera.lens_indices_for_pixels`
    or its real-lens twin), given as its row in :func:`lens_table` ``(config.camera, config.lens)``.

    The sensor is processed in blocks of whole rows, at most ``max_block_pixels`` pixels each (one
    row at least); no per-pixel Python loop. Memory: the outputs take 8 B per pixel (0.33 GB for an
    Illum's 41 Mpx), and a block's working set about 300 B per pixel with the thin lens (numpy
    temporaries of the lens assignment, the rays and the port trace, and Mitsuba's float32 rays and
    preliminary intersections) and about 550 B with a real lens (its surface-by-surface trace):
    0.3 GB and 0.55 GB at the default :data:`DEFAULT_RAW_BLOCK_PIXELS` (1 Mpx, 135 Illum rows;
    measured peaks of the resident set above the outputs). Time: about 1 s per Mpx with the thin
    lens, 2 s with a real lens, on 2 CPU cores (an Illum in 36 s).

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set.
    scene : mitsuba.Scene
        ``config``'s scene without the port (:func:`simulator.scene.build_scene` with
        ``port_geometry=False``): the port is traced here, exactly, in float64.
    config : SceneConfig
        Camera, optional real lens, port and pose.
    max_block_pixels : int
        Largest number of pixels traced at once.

    Returns
    -------
    RawPixelTruth
        Arrays of the sensor's shape (height_px, width_px).
    """
    if isinstance(max_block_pixels, bool) or not isinstance(max_block_pixels, (int, np.integer)):
        raise ParameterError(f"max_block_pixels must be a positive integer, got {max_block_pixels!r}")
    if max_block_pixels < 1:
        raise ParameterError(f"max_block_pixels must be a positive integer, got {max_block_pixels!r}")
    camera = config.camera
    real = None if config.lens is None else RealLensCamera(camera=camera, lens=config.lens)
    table_index = lens_table(camera, config.lens)["lens_index"]
    h, w = camera.sensor.height_px, camera.sensor.width_px
    depth = np.empty((h, w), dtype=np.float32)
    lens_row = np.empty((h, w), dtype=np.int32)
    rows = max(1, int(max_block_pixels) // w)
    for v0 in range(0, h, rows):
        v1 = min(h, v0 + rows)
        vv, uu = np.mgrid[v0:v1, 0:w]
        uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
        del vv, uu
        rays: CapturedRays = camera.captured_rays(uv) if real is None else real.chief_rays(uv)
        del uv
        lens_row[v0:v1] = _lens_rows(table_index, rays.lens_indices).reshape(v1 - v0, w)
        recorded = np.asarray(rays.in_aperture, dtype=bool).copy()
        origins, directions = rays.origins_cam[recorded], rays.directions_cam[recorded]
        del rays
        if config.port is not None:
            trace = config.port.trace_from_air(origins, directions)
            passed = trace.valid
            recorded[recorded] = passed
            origins, directions = trace.exit_points_cam[passed], trace.directions_cam[passed]
            del trace
        z = np.full(recorded.shape, np.nan)
        z[recorded] = _first_hit_z(mi, scene, origins, directions, config.pose)
        depth[v0:v1] = z.reshape(v1 - v0, w)
    return RawPixelTruth(depth_m=depth, lens_row=lens_row)


def compute(
    mi: ModuleType,
    scene,
    config: SceneConfig,
    pinhole: PinholeCamera,
    *,
    seed: int,
    spp: int | None = None,
    progress: bool = True,
) -> GroundTruth:
    """Render the ideal image and trace the depth map and lens table for ``config``.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set.
    scene : mitsuba.Scene
        ``config``'s scene built without the port (:func:`simulator.scene.build_scene` with
        ``port_geometry=False``).
    config : SceneConfig
    pinhole : PinholeCamera
        Geometry of the ideal image.
    seed : int
        Job seed of the ideal render (its stream is :data:`simulator.render.IDEAL_STREAM`).
    spp : int, optional
        Samples per pixel of the ideal render; default ``config.render.ideal_spp`` (the raw
        image's ``config.render.spp`` is not used).
    progress : bool
        Show a progress bar.
    """
    if spp is None:
        spp = config.render.ideal_spp
    medium = water_medium(config.water)
    ideal = render_bands(
        mi,
        scene,
        lambda crop: pinhole_sensor_dict(mi, pinhole, config.pose, spp=spp, crop=crop, medium=medium),
        pinhole.width_px,
        pinhole.height_px,
        spp=spp,
        seed=seed,
        progress=progress,
        label="ideal",
        stream=IDEAL_STREAM,
    )
    return GroundTruth(
        ideal=ideal, depth_m=depth_map(mi, scene, pinhole, config.pose), lenses=lens_table(config.camera, config.lens)
    )
