"""The geometry of a scene, in numpy: each object type's shape, and the checks that the scene is
physically possible. Nothing here imports Mitsuba (:mod:`simulator.scene` builds the Mitsuba
scene from these shapes).

Every object type of :mod:`simulator.config` registers its own geometry with the generic
functions below (:func:`functools.singledispatch`), so that a new type is one registration per
function, beside the others, instead of a branch in each function that uses it:

- :func:`plane_size_m`: the ``(width, height)`` of a rectangle in its local z = 0 plane
  (textured plane, chessboard with its margin);
- :func:`local_mesh`: the triangle mesh of a procedural object in its local frame (bowl,
  figurine), cached and read-only;
- :func:`texture_wrap`: the local axis a procedural mesh's texture wraps around, and its extent;
- :func:`local_sample_points`: points on an object's extent in its local frame (outline of a
  plane or a disc, vertices of a procedural mesh, the centre of a mesh file, whose vertices are
  only known once Mitsuba loads it).

Local frames are the config's (+x right, +y down, +z away from a camera with identity pose);
:meth:`simulator.config.Placement.to_world` moves them into the world frame. All lengths are
metres.
"""

from __future__ import annotations

import functools

import numpy as np

from lfrefract import LightFieldCamera, ParameterError
from simulator import assets
from simulator.config import (
    OBJECT_TYPES,
    Bowl,
    Chessboard,
    Disc,
    Figurine,
    MeshFile,
    PointLight,
    SceneConfig,
    SceneObject,
    TexturedPlane,
)

__all__ = [
    "DISC_OUTLINE_POINTS",
    "check_geometry",
    "local_mesh",
    "local_sample_points",
    "object_sample_points",
    "plane_size_m",
    "require_water_side",
    "texture_wrap",
    "world_mesh",
    "wrapped_texcoords",
]

#: Points on a disc's rim that :func:`local_sample_points` checks against the port.
DISC_OUTLINE_POINTS = 32
#: Captured pixels per side of the grid that :func:`check_geometry` traces through the port.
CAPTURED_SAMPLE_SIDE = 64


def _unknown(what: str, obj: object):
    raise TypeError(f"{what}: no geometry registered for scene object type {type(obj).__name__} ({obj!r})")


# --------------------------------------------------------------------------- planes
@functools.singledispatch
def plane_size_m(obj: SceneObject) -> tuple[float, float]:
    """``(width_m, height_m)`` of a rectangular object in its local z = 0 plane, centred on its
    placement.

    Raises
    ------
    TypeError
        For an object that is not a rectangle.
    """
    _unknown("plane_size_m", obj)


@plane_size_m.register
def _(obj: TexturedPlane) -> tuple[float, float]:
    return obj.size_m


@plane_size_m.register
def _(obj: Chessboard) -> tuple[float, float]:
    return obj.board_size_m


# --------------------------------------------------------------------------- procedural meshes
@functools.lru_cache(maxsize=64)
def _procedural_mesh(kind: str, **shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The local mesh of a procedural object, read-only and cached: a dataset sweep checks the
    geometry of every sample before rendering any (:func:`check_geometry`), and regenerating the
    meshes was two thirds of that check."""
    mesh = assets.bowl_mesh(**shape) if kind == "bowl" else assets.figurine_mesh(**shape)
    for array in mesh:
        array.setflags(write=False)
    return mesh


@functools.singledispatch
def local_mesh(obj: SceneObject) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triangle mesh of a procedural object in its local frame, cached and read-only.

    Returns
    -------
    vertices : ndarray, float64, shape (V, 3)
        Local frame, metres.
    faces : ndarray, int, shape (F, 3)
        Vertex indices, counter-clockwise seen from outside.
    normals : ndarray, float64, shape (V, 3)
        Unit vertex normals, local frame.

    Raises
    ------
    TypeError
        For an object without a procedural mesh.
    """
    _unknown("local_mesh", obj)


@local_mesh.register
def _(obj: Bowl) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return _procedural_mesh("bowl", radius_m=obj.radius_m, depth_m=obj.depth_m, thickness_m=obj.thickness_m)


@local_mesh.register
def _(obj: Figurine) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return _procedural_mesh("figurine", height_m=obj.height_m, seed=obj.seed)


def world_mesh(obj: Bowl | Figurine) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`local_mesh` moved into the world frame: vertices (V, 3) m, faces (F, 3), unit
    normals (V, 3), all in the world frame."""
    v, f, n = local_mesh(obj)
    rot = obj.placement.matrix[:3, :3]
    return obj.placement.to_world(v), f, n @ rot.T


@functools.singledispatch
def texture_wrap(obj: SceneObject) -> tuple[int, float]:
    """``(axis, extent_m)``: the local axis (0, 1, 2 for x, y, z) that a procedural mesh's texture
    wraps around, and the length along it that the texture's height covers.

    Raises
    ------
    TypeError
        For an object without a procedural mesh.
    """
    _unknown("texture_wrap", obj)


@texture_wrap.register
def _(obj: Bowl) -> tuple[int, float]:
    return 2, 2.0 * obj.radius_m  # around its axis (z), across its depth


@texture_wrap.register
def _(obj: Figurine) -> tuple[int, float]:
    return 1, obj.height_m  # around its height (y)


def wrapped_texcoords(obj: Bowl | Figurine) -> np.ndarray:
    """Texture coordinates (V, 2) of the vertices of :func:`local_mesh`: the angle about the
    :func:`texture_wrap` axis (u, one turn) and the position along it over its extent (v). The
    texture tiles, so u wraps without a seam in the image; the triangles that straddle the wrap
    get a narrow stripe of compressed texture."""
    local = local_mesh(obj)[0]
    axis, extent_m = texture_wrap(obj)
    a, b = [i for i in range(3) if i != axis]
    u = np.arctan2(local[:, a], local[:, b]) / (2.0 * np.pi) + 0.5
    v = (local[:, axis] - local[:, axis].min()) / extent_m
    return np.stack([u, v], axis=1)


# --------------------------------------------------------------------------- sample points
@functools.singledispatch
def local_sample_points(obj: SceneObject) -> np.ndarray:
    """Points (N, 3) on an object's extent in its local frame, metres: what
    :func:`check_geometry` holds to the water side of the port.

    Raises
    ------
    TypeError
        For a type that registered no sample points.
    """
    _unknown("local_sample_points", obj)


def _rectangle_corners(obj: TexturedPlane | Chessboard) -> np.ndarray:
    w, h = plane_size_m(obj)
    return np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]]) / 2.0


local_sample_points.register(TexturedPlane, _rectangle_corners)
local_sample_points.register(Chessboard, _rectangle_corners)


@local_sample_points.register
def _(obj: Disc) -> np.ndarray:
    ang = np.linspace(0.0, 2.0 * np.pi, DISC_OUTLINE_POINTS, endpoint=False)
    return obj.radius_m * np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], axis=1)


def _mesh_vertices(obj: Bowl | Figurine) -> np.ndarray:
    return local_mesh(obj)[0]


local_sample_points.register(Bowl, _mesh_vertices)
local_sample_points.register(Figurine, _mesh_vertices)


@local_sample_points.register
def _(obj: MeshFile) -> np.ndarray:
    # Its vertices are checked when Mitsuba loads the file (simulator.scene).
    return np.zeros((1, 3))


def object_sample_points(obj: SceneObject) -> np.ndarray:
    """World points (N, 3), metres, on an object's extent: :func:`local_sample_points` placed.

    Planes and discs give their outline, procedural meshes their vertices, and mesh files their
    placement centre (their vertices are checked when Mitsuba loads them).
    """
    return obj.placement.to_world(local_sample_points(obj))


# --------------------------------------------------------------------------- checks
def _captured_sample(camera: LightFieldCamera, count: int = CAPTURED_SAMPLE_SIDE) -> np.ndarray:
    """A ``count`` x ``count`` grid of pixel positions (count^2, 2) over the whole sensor."""
    w, h = camera.sensor.width_px, camera.sensor.height_px
    uu, vv = np.meshgrid(np.linspace(0, w - 1, count), np.linspace(0, h - 1, count))
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def require_water_side(config: SceneConfig, points_world: np.ndarray, what: str) -> None:
    """Raise unless every world point lies beyond the port's water face (no port: no-op).

    Parameters
    ----------
    config : SceneConfig
        Its port and camera pose.
    points_world : ndarray, shape (N, 3)
        World points, metres.
    what : str
        The points' owner in the message (``"object[2] (disc)"``).

    Raises
    ------
    ParameterError
        Naming ``what`` and the first point on the camera side, in the camera frame.
    """
    port = config.port
    if port is None:
        return
    water_face = port.distance_m + port.thickness_m
    points_cam = config.pose.to_camera(points_world)
    bad = points_cam @ port.normal <= water_face
    if np.any(bad):
        p = points_cam[bad][0]
        raise ParameterError(
            f"{what} reaches the camera side of the port: camera-frame point {np.round(p, 4).tolist()} m has "
            f"n.X = {p @ port.normal:.4f} m <= {water_face:.4f} m (water face); objects and lights must be in the water"
        )


def check_geometry(config: SceneConfig) -> dict:
    """Check that the scene is physically possible; return figures for the sidecar.

    Raises
    ------
    ParameterError
        If the port cuts the main-lens aperture, an object or light reaches the camera side of
        the port's water face, or every captured ray is totally internally reflected.

    Returns
    -------
    dict
        ``tir_fraction`` and ``port_clearance_m`` (None without a port).
    """
    port, camera = config.port, config.camera
    if port is None:
        return {"tir_fraction": None, "port_clearance_m": None}
    clearance = port.clearance_m(camera.aperture_radius_m)
    if clearance <= 0.0:
        raise ParameterError(
            f"port.distance_m={port.distance_m!r} with tilt {np.degrees(port.total_tilt_rad):.2f} deg cuts the "
            f"main-lens aperture (radius {camera.aperture_radius_m:.4g} m)"
        )
    rays = camera.captured_rays(_captured_sample(camera))
    trace = port.trace_from_air(rays.origins_cam[rays.in_aperture], rays.directions_cam[rays.in_aperture])
    if not np.any(trace.valid):
        why = "totally internally reflected" if np.any(trace.tir) else "turned away from"
        raise ParameterError(
            f"every captured ray is {why} by the port (n_air={port.n_air}, n_glass={port.n_glass}, "
            f"n_water={port.n_water}, tilt {np.degrees(port.total_tilt_rad):.2f} deg): "
            f"{int(trace.tir.sum())} TIR, {int(trace.misses.sum())} never reach it"
        )
    kinds = {cls: kind for kind, cls in OBJECT_TYPES.items()}  # the type as a scene file names it
    for i, obj in enumerate(config.objects):
        require_water_side(config, object_sample_points(obj), f"object[{i}] ({kinds[type(obj)]})")
    for i, light in enumerate(config.lights):
        if isinstance(light, PointLight):
            require_water_side(config, np.asarray([light.position_m]), f"light[{i}] (point)")
    return {"tir_fraction": float(np.mean(trace.tir)), "port_clearance_m": float(clearance)}
