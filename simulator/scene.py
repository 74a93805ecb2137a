"""Turn a :class:`~simulator.config.SceneConfig` into a Mitsuba scene, and check its geometry.

The world frame is the config's; the camera frame is OpenCV's (``lfrefract``). The port is
attached to the camera: its faces are built in the camera frame and moved by the camera pose.
Each face is a large rectangle carrying the refract-only interface BSDF
(:mod:`simulator.interface`). A rectangle's normal points into the medium its BSDF calls
``ext_ior``: towards the camera for the air-side face, into the water for the water-side face.

Lighting is direct only: next-event estimation at the first diffuse surface (behind the port's
faces when they are geometry). The raw and the ideal image are therefore lit identically, and the
port changes only the geometry of the rays and the radiometric factor of
:class:`lfrefract.PortTrace`.

Turbid water (a :class:`~simulator.config.Water` with a non-zero absorption or scattering
coefficient) is a ``homogeneous`` medium (:func:`water_medium`) that fills the water: it is the
medium of every camera that starts in the water (the plenoptic sensor behind a port it refracts
itself, a camera without a port, the ideal pinhole), of the point lights, of both sides of every
object's surface, and of the water side of the port's water face. Mitsuba's ``volpath``
integrator then attenuates camera rays and shadow rays alike, and scatters single-bounce light
into the view (:func:`integrator`). Clear water builds exactly the scene it always did.
"""

from __future__ import annotations

import functools
from types import ModuleType

import numpy as np

from lfrefract import FlatPort, LightFieldCamera, ParameterError
from lfrefract.errors import FileFormatError
from simulator import assets
from simulator.config import (
    MAX_COORDINATE_M,
    Bowl,
    Chessboard,
    ConstantLight,
    Disc,
    Figurine,
    MeshFile,
    PointLight,
    SceneConfig,
    SceneObject,
    TexturedPlane,
    Water,
)
from simulator.interface import INTERFACE

__all__ = [
    "PORT_FACE_SIZE_M",
    "build_scene",
    "check_geometry",
    "integrator",
    "object_sample_points",
    "port_faces",
    "water_medium",
]

#: Side of the square port faces, metres: far larger than any camera footprint on the port.
PORT_FACE_SIZE_M = 20.0

_TWO_PI = 2.0 * np.pi


def _frame_matrix(origin: np.ndarray, z_axis: np.ndarray, half_size: float) -> np.ndarray:
    """4x4 matrix mapping Mitsuba's unit rectangle ([-1, 1]^2, normal +z) onto a plane."""
    z = z_axis / np.linalg.norm(z_axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = half_size * x, half_size * y, z, origin
    return m


def port_faces(port: FlatPort) -> list[dict]:
    """Faces of the port in the camera frame, from the camera outwards.

    Returns
    -------
    list of dict
        Each with ``matrix`` (4x4, camera frame, rectangle normal = side of ``ext_ior``),
        ``int_ior``, ``ext_ior``, and ``water_side``: which side of the rectangle is water
        (``"exterior"``, ``"interior"``, or None for the air/glass face of a slab).
    """
    n = port.normal
    faces = []
    for i, (offset, n_before, n_after) in enumerate(port.faces):
        centre = np.array([0.0, 0.0, offset / n[2]])  # where the optical axis meets the face
        last = i == len(port.faces) - 1 and len(port.faces) > 1
        if last:  # water-side face of a slab: normal into the water, glass behind it
            normal, ext, inner, water = n, n_after, n_before, "exterior"
        else:  # camera-side face (or the only one): normal towards the camera
            normal, ext, inner = -n, n_before, n_after
            water = "interior" if len(port.faces) == 1 else None  # a bare air/water interface
        faces.append(
            {
                "matrix": _frame_matrix(centre, normal, PORT_FACE_SIZE_M / 2),
                "int_ior": inner,
                "ext_ior": ext,
                "water_side": water,
            }
        )
    return faces


@functools.lru_cache(maxsize=8)
def _random_texture(size_px: int, seed: int) -> np.ndarray:
    """Seeded texture, cached: the raw and the ideal scene of a job share it (about 1 s per Mpx)."""
    texture = assets.random_texture(size_px=size_px, seed=seed)
    texture.flags.writeable = False
    return texture


def _texture(mi: ModuleType, image: np.ndarray, *, nearest: bool) -> dict:
    return {
        "type": "bitmap",
        "bitmap": mi.Bitmap(np.ascontiguousarray(image, dtype=np.float32)),
        "raw": True,
        "filter_type": "nearest" if nearest else "bilinear",
        "wrap_mode": "clamp",
    }


def _diffuse(reflectance) -> dict:
    value = reflectance if isinstance(reflectance, dict) else {"type": "rgb", "value": list(reflectance)}
    return {"type": "twosided", "material": {"type": "diffuse", "reflectance": value}}


def _mesh(
    mi: ModuleType,
    name: str,
    vertices: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    bsdf: dict,
    texcoords: np.ndarray | None = None,
    media: dict | None = None,
):
    import drjit as dr

    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    for side, medium in (media or {}).items():
        props[side] = medium
    mesh = mi.Mesh(
        name, len(vertices), len(faces), props, has_vertex_normals=True, has_vertex_texcoords=texcoords is not None
    )
    params = mi.traverse(mesh)
    params["vertex_positions"] = dr.ravel(mi.Point3f(np.asarray(vertices, dtype=np.float32).T))
    params["vertex_normals"] = dr.ravel(mi.Normal3f(np.asarray(normals, dtype=np.float32).T))
    params["faces"] = dr.ravel(mi.Vector3u(np.asarray(faces, dtype=np.uint32).T))
    if texcoords is not None:
        params["vertex_texcoords"] = dr.ravel(mi.Point2f(np.asarray(texcoords, dtype=np.float32).T))
    params.update()
    return mesh


def _wrapped_texcoords(local: np.ndarray, axis: int, extent_m: float) -> np.ndarray:
    """Texture coordinates (N, 2) of mesh vertices (N, 3) in the object's local frame: the angle
    about local ``axis`` (u, one turn) and the position along it over ``extent_m`` (v). The
    texture tiles, so u wraps without a seam in the image; the triangles that straddle the
    wrap get a narrow stripe of compressed texture."""
    a, b = [i for i in range(3) if i != axis]
    u = np.arctan2(local[:, a], local[:, b]) / (2.0 * np.pi) + 0.5
    v = (local[:, axis] - local[:, axis].min()) / extent_m
    return np.stack([u, v], axis=1)


def _plane_matrix(placement_matrix: np.ndarray, width: float, height: float) -> np.ndarray:
    return placement_matrix @ np.diag([width / 2.0, height / 2.0, 1.0, 1.0])


def _local_mesh(obj: SceneObject) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if isinstance(obj, Bowl):
        return _procedural_mesh("bowl", radius_m=obj.radius_m, depth_m=obj.depth_m, thickness_m=obj.thickness_m)
    return _procedural_mesh("figurine", height_m=obj.height_m, seed=obj.seed)


@functools.lru_cache(maxsize=64)
def _procedural_mesh(kind: str, **shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The local mesh of a procedural object, read-only and cached: a dataset sweep checks the
    geometry of every sample before rendering any (:func:`check_geometry`), and regenerating the
    meshes was two thirds of that check."""
    mesh = assets.bowl_mesh(**shape) if kind == "bowl" else assets.figurine_mesh(**shape)
    for array in mesh:
        array.setflags(write=False)
    return mesh


def _mesh_in_world(obj: SceneObject) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    v, f, n = _local_mesh(obj)
    rot = obj.placement.matrix[:3, :3]
    return obj.placement.to_world(v), f, n @ rot.T


def _object_dict(mi: ModuleType, config: SceneConfig, index: int, media: dict):
    """The Mitsuba shape (dict or loaded mesh) of object ``index``; ``media`` maps ``interior``
    and ``exterior`` to the water's medium (empty in clear water)."""
    shape = _object_shape(mi, config, index, media)
    if isinstance(shape, dict):
        shape.update(media)
    return shape


def _object_shape(mi: ModuleType, config: SceneConfig, index: int, media: dict):
    obj = config.objects[index]
    if isinstance(obj, TexturedPlane):
        tex = _random_texture(obj.texture_px, obj.texture_seed)
        return {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f(_plane_matrix(obj.placement.matrix, *obj.size_m).tolist()),
            "bsdf": _diffuse(_texture(mi, tex, nearest=False)),
        }
    if isinstance(obj, Chessboard):
        kw = {"squares": obj.squares, "margin_squares": obj.margin_squares}
        tex = assets.chessboard_texture(texels_per_square=obj.texels_per_square, **kw)
        w, h = assets.chessboard_size_m(square_size_m=obj.square_size_m, **kw)
        return {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f(_plane_matrix(obj.placement.matrix, w, h).tolist()),
            "bsdf": _diffuse(_texture(mi, tex, nearest=True)),
        }
    if isinstance(obj, Disc):
        # Mitsuba's disk faces +z and area lights emit on that side only: turn it (180 deg about
        # local x) to face -z, towards a camera with identity pose.
        m = obj.placement.matrix @ np.diag([obj.radius_m, -obj.radius_m, -1.0, 1.0])
        out = {"type": "disk", "to_world": mi.ScalarTransform4f(m.tolist()), "bsdf": _diffuse(obj.reflectance)}
        if max(obj.radiance) > 0:
            out["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": list(obj.radiance)}}
        return out
    if isinstance(obj, (Bowl, Figurine)):
        v, f, n = _mesh_in_world(obj)
        if obj.texture_seed is None:
            return _mesh(mi, f"object_{index}", v, f, n, _diffuse(obj.reflectance), media=media)
        # Bowl: around its axis (z), across its depth; figurine: around its height (y).
        local = _local_mesh(obj)[0]
        axis, extent = (2, 2.0 * obj.radius_m) if isinstance(obj, Bowl) else (1, obj.height_m)
        texcoords = _wrapped_texcoords(local, axis, extent)
        bsdf = _diffuse(_texture(mi, _random_texture(obj.texture_px, obj.texture_seed), nearest=False))
        return _mesh(mi, f"object_{index}", v, f, n, bsdf, texcoords, media=media)
    if isinstance(obj, MeshFile):
        return _load_mesh_file(mi, config, index, media)
    raise TypeError(f"unknown scene object {obj!r}")


def _load_mesh_file(mi: ModuleType, config: SceneConfig, index: int, media: dict):
    """Load a user OBJ/PLY mesh (with ``media`` on its sides) and check every vertex against the
    bound of positions and the port (its extent is only known once loaded).

    The file's kind, size and content are checked first (:func:`simulator.assets.check_mesh_content`),
    so that a wrong file is named with its problem rather than with Mitsuba's internal message.

    Raises
    ------
    ParameterError
        If the path is no longer a regular file of an accepted size, or a vertex lies beyond
        :data:`simulator.config.MAX_COORDINATE_M` or on the camera side of the port.
    FileFormatError
        If the file's content is not a triangle mesh (the message names the file and the
        problem), or Mitsuba cannot load it.
    """
    import drjit as dr

    obj = config.objects[index]
    where = f"object[{index}] (mesh)"
    try:
        assets.check_mesh_content(obj.path)
    except FileFormatError as exc:
        raise FileFormatError(f"{where}: cannot load {exc}") from None
    except ParameterError as exc:
        raise ParameterError(f"{where}: {exc}") from None
    m = obj.placement.matrix @ np.diag([obj.scale, obj.scale, obj.scale, 1.0])
    spec = {
        "type": obj.path.suffix.lower()[1:],
        "filename": str(obj.path),
        "to_world": mi.ScalarTransform4f(m.tolist()),
        "bsdf": _diffuse(obj.reflectance),
        **media,
    }
    try:
        shape = mi.load_dict(spec)
    except RuntimeError as exc:
        raise FileFormatError(f"{where}: cannot load {str(obj.path)!r}: {exc}") from None
    vertices = np.asarray(dr.unravel(mi.Point3f, mi.traverse(shape)["vertex_positions"]), dtype=np.float64).T
    outside = ~np.all(np.isfinite(vertices) & (np.abs(vertices) <= MAX_COORDINATE_M), axis=1)
    if outside.any():
        p = vertices[outside][0]
        raise ParameterError(
            f"object[{index}] (mesh {obj.path.name}): with scale={obj.scale!r} and position_m="
            f"{list(obj.placement.position_m)}, a vertex lies at {p.tolist()} m in the world, beyond the "
            f"scene's bound of +-{MAX_COORDINATE_M:g} m per coordinate (simulator.config.MAX_COORDINATE_M)"
        )
    _require_water_side(config, vertices, f"object[{index}] (mesh {obj.path.name})")
    return shape


def water_medium(water: Water | None) -> dict | None:
    """Mitsuba dict of the ``homogeneous`` medium of turbid water; None for clear water.

    Extinction ``sigma_t = sigma_a + sigma_s`` and albedo ``sigma_s / sigma_t`` per channel, per
    metre (the scene unit), with a Henyey-Greenstein phase function (``isotropic`` for g = 0).
    Mitsuba's RGB values must lie in [0, 1], so an RGB extinction is given divided by its
    largest channel and that channel is the medium's ``scale``.

    Parameters
    ----------
    water : Water or None

    Returns
    -------
    dict or None
        None when there is no water or neither coefficient is positive: no medium at all.
    """
    if water is None or not water.has_medium:
        return None
    sigma_t, albedo = water.extinction_per_m, water.albedo
    scale = max(sigma_t)
    grey_t, grey_albedo = len(set(sigma_t)) == 1, len(set(albedo)) == 1
    phase = {"type": "isotropic"} if water.phase_g == 0.0 else {"type": "hg", "g": water.phase_g}
    return {
        "type": "homogeneous",
        "sigma_t": 1.0 if grey_t else {"type": "rgb", "value": [c / scale for c in sigma_t]},
        "scale": scale,
        "albedo": albedo[0] if grey_albedo else {"type": "rgb", "value": list(albedo)},
        "phase": phase,
    }


def integrator(port: FlatPort | None, *, water: Water | None = None) -> dict:
    """Integrator for direct lighting at the first diffuse surface behind ``port``'s faces.

    Clear water (``water`` None or without a medium): without port geometry, Mitsuba's ``direct``
    with next-event estimation only (one shadow ray per sample; the scenes' lights are points and
    small luminous discs); with the port as geometry, ``path``, cut after next-event estimation at
    the first surface behind its faces.

    Turbid water: ``volpath`` with the same depth as ``path`` (two interactions beyond the port's
    faces, no Russian roulette). It attenuates every camera and shadow ray through the medium
    (Beer-Lambert, by free-flight sampling: unbiased, noisier than a closed form) and adds single
    scattering: one scattering event in the water, lit by next-event estimation, like a surface.
    Multiple scattering is cut off, as multiple surface bounces are.
    """
    if water is not None and water.has_medium:
        depth = 2 + (0 if port is None else len(port.faces))
        return {"type": "volpath", "max_depth": depth, "rr_depth": depth + 1, "hide_emitters": False}
    if port is None:
        return {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0}
    depth = 2 + len(port.faces)
    return {"type": "path", "max_depth": depth, "rr_depth": depth + 1, "hide_emitters": False}


def build_scene(mi: ModuleType, config: SceneConfig, *, port_geometry: bool):
    """Load the Mitsuba scene for ``config``.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set (:func:`simulator.backend.load_mitsuba`).
    config : SceneConfig
    port_geometry : bool
        Build the port's faces as geometry (the ``geometry`` port model). False builds the scene
        without glass: for the ideal image and depth, and for the ``sensor`` port model, where
        the plenoptic sensor refracts its rays through the port itself.

    Returns
    -------
    mitsuba.Scene
        Without a sensor of its own: render it with an explicit ``sensor=``. With turbid water,
        a sensor that starts in the water needs the medium too (``medium=water_medium(...)`` of
        :func:`simulator.sensor.plenoptic_sensor_dict` and :func:`~simulator.sensor.pinhole_sensor_dict`).
    """
    port = config.port if port_geometry else None
    scene: dict = {"type": "scene", "integrator": integrator(port, water=config.water)}
    medium_spec = water_medium(config.water)
    medium = None if medium_spec is None else mi.load_dict(medium_spec)
    media = {} if medium is None else {"interior": medium, "exterior": medium}
    if port is not None:
        pose = config.pose.matrix
        for i, face in enumerate(port_faces(port)):
            scene[f"port_face_{i}"] = {
                "type": "rectangle",
                "to_world": mi.ScalarTransform4f((pose @ face["matrix"]).tolist()),
                "bsdf": {"type": INTERFACE, "int_ior": face["int_ior"], "ext_ior": face["ext_ior"]},
            }
            if medium is not None and face["water_side"] is not None:
                scene[f"port_face_{i}"][face["water_side"]] = medium
    for i, light in enumerate(config.lights):
        if isinstance(light, PointLight):
            scene[f"light_{i}"] = {
                "type": "point",
                "position": list(light.position_m),
                "intensity": {"type": "rgb", "value": list(light.intensity_w_sr)},
            }
            if medium is not None:
                scene[f"light_{i}"]["medium"] = medium
        elif isinstance(light, ConstantLight):
            scene[f"light_{i}"] = {"type": "constant", "radiance": {"type": "rgb", "value": list(light.radiance)}}
    for i in range(len(config.objects)):
        scene[f"object_{i}"] = _object_dict(mi, config, i, media)
    return mi.load_dict(scene)


# --------------------------------------------------------------------------- geometry checks
def object_sample_points(obj: SceneObject) -> np.ndarray:
    """World points (N, 3) on an object's extent, used to check which side of the port it is on.

    Planes and discs give their outline, procedural meshes their vertices, and mesh files their
    placement centre (their vertices are checked when Mitsuba loads them).
    """
    if isinstance(obj, (TexturedPlane, Chessboard)):
        if isinstance(obj, TexturedPlane):
            w, h = obj.size_m
        else:
            w, h = assets.chessboard_size_m(
                squares=obj.squares, square_size_m=obj.square_size_m, margin_squares=obj.margin_squares
            )
        local = np.array([[-w, -h, 0], [w, -h, 0], [w, h, 0], [-w, h, 0]]) / 2.0
        return obj.placement.to_world(local)
    if isinstance(obj, Disc):
        ang = np.linspace(0.0, _TWO_PI, 32, endpoint=False)
        local = obj.radius_m * np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], axis=1)
        return obj.placement.to_world(local)
    if isinstance(obj, (Bowl, Figurine)):
        return _mesh_in_world(obj)[0]
    return obj.placement.to_world(np.zeros((1, 3)))


def _captured_sample(camera: LightFieldCamera, count: int = 64) -> np.ndarray:
    w, h = camera.sensor.width_px, camera.sensor.height_px
    uu, vv = np.meshgrid(np.linspace(0, w - 1, count), np.linspace(0, h - 1, count))
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def _require_water_side(config: SceneConfig, points_world: np.ndarray, what: str) -> None:
    """Raise unless every world point lies beyond the port's water face (no port: no-op)."""
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
    for i, obj in enumerate(config.objects):
        _require_water_side(config, object_sample_points(obj), f"object[{i}] ({type(obj).__name__})")
    for i, light in enumerate(config.lights):
        if isinstance(light, PointLight):
            _require_water_side(config, np.asarray([light.position_m]), f"light[{i}] (point)")
    return {"tir_fraction": float(np.mean(trace.tir)), "port_clearance_m": float(clearance)}
