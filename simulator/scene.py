"""Turn a :class:`~simulator.config.SceneConfig` into a Mitsuba scene.

Each object type's Mitsuba shape is registered with :func:`functools.singledispatch` (``_shape``),
from the type's geometry in :mod:`simulator.geometry`; the geometry checks
(:func:`~simulator.geometry.check_geometry`, re-exported here) are there too, without Mitsuba.
Mitsuba itself is never imported by this module: :func:`build_scene` takes the module.

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

from lfrefract import FlatPort, ParameterError
from lfrefract.errors import FileFormatError
from simulator import assets, lighting
from simulator.config import (
    MAX_COORDINATE_M,
    Bowl,
    Chessboard,
    ConstantLight,
    Disc,
    Figurine,
    Light,
    MeshFile,
    PointLight,
    SceneConfig,
    SceneObject,
    TexturedPlane,
    Water,
)
from simulator.geometry import (
    check_geometry,
    object_sample_points,
    plane_size_m,
    require_water_side,
    world_mesh,
    wrapped_texcoords,
)
from simulator.interface import INTERFACE
from simulator.lighting import EVERY_EMITTER

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


def _plane_matrix(placement_matrix: np.ndarray, width: float, height: float) -> np.ndarray:
    return placement_matrix @ np.diag([width / 2.0, height / 2.0, 1.0, 1.0])


# The Mitsuba shape of each object type: ``_shape(obj, mi=..., config=..., index=..., media=...)``
# returns a dict for ``mi.load_dict`` or a loaded shape; ``media`` maps ``interior`` and
# ``exterior`` to the water's medium (empty in clear water). The geometry itself is
# :mod:`simulator.geometry`'s.
@functools.singledispatch
def _shape(obj: SceneObject, *, mi: ModuleType, config: SceneConfig, index: int, media: dict):
    raise TypeError(f"object[{index}]: no Mitsuba shape registered for {type(obj).__name__} ({obj!r})")


@_shape.register
def _(obj: TexturedPlane, *, mi: ModuleType, config: SceneConfig, index: int, media: dict) -> dict:
    tex = _random_texture(obj.texture_px, obj.texture_seed)
    return {
        "type": "rectangle",
        "to_world": mi.ScalarTransform4f(_plane_matrix(obj.placement.matrix, *plane_size_m(obj)).tolist()),
        "bsdf": _diffuse(_texture(mi, tex, nearest=False)),
        **media,
    }


@_shape.register
def _(obj: Chessboard, *, mi: ModuleType, config: SceneConfig, index: int, media: dict) -> dict:
    tex = obj.texture()
    return {
        "type": "rectangle",
        "to_world": mi.ScalarTransform4f(_plane_matrix(obj.placement.matrix, *plane_size_m(obj)).tolist()),
        "bsdf": _diffuse(_texture(mi, tex, nearest=True)),
        **media,
    }


@_shape.register
def _(obj: Disc, *, mi: ModuleType, config: SceneConfig, index: int, media: dict) -> dict:
    # Mitsuba's disk faces +z and area lights emit on that side only: turn it (180 deg about
    # local x) to face -z, towards a camera with identity pose.
    m = obj.placement.matrix @ np.diag([obj.radius_m, -obj.radius_m, -1.0, 1.0])
    out = {"type": "disk", "to_world": mi.ScalarTransform4f(m.tolist()), "bsdf": _diffuse(obj.reflectance), **media}
    if max(obj.radiance) > 0:
        out["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": list(obj.radiance)}}
    return out


def _procedural_shape(obj: Bowl | Figurine, *, mi: ModuleType, config: SceneConfig, index: int, media: dict):
    v, f, n = world_mesh(obj)
    if obj.texture_seed is None:
        return _mesh(mi, f"object_{index}", v, f, n, _diffuse(obj.reflectance), media=media)
    bsdf = _diffuse(_texture(mi, _random_texture(obj.texture_px, obj.texture_seed), nearest=False))
    return _mesh(mi, f"object_{index}", v, f, n, bsdf, wrapped_texcoords(obj), media=media)


_shape.register(Bowl, _procedural_shape)
_shape.register(Figurine, _procedural_shape)


@_shape.register
def _load_mesh_file(obj: MeshFile, *, mi: ModuleType, config: SceneConfig, index: int, media: dict):
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
    require_water_side(config, vertices, f"object[{index}] (mesh {obj.path.name})")
    return shape


# The Mitsuba emitter of each light type; ``medium`` is the water's loaded medium or None.
@functools.singledispatch
def _emitter(light: Light, *, medium) -> dict:
    raise TypeError(f"no Mitsuba emitter registered for {type(light).__name__} ({light!r})")


@_emitter.register
def _(light: PointLight, *, medium) -> dict:
    out = {"type": "point", "position": list(light.position_m)}
    out["intensity"] = {"type": "rgb", "value": list(light.intensity_w_sr)}
    return out if medium is None else {**out, "medium": medium}


@_emitter.register
def _(light: ConstantLight, *, medium) -> dict:
    return {"type": "constant", "radiance": {"type": "rgb", "value": list(light.radiance)}}


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

    Clear water (``water`` None or without a medium): the project's every-emitter direct
    lighting (:data:`simulator.lighting.EVERY_EMITTER`): one shadow ray to each light at the
    first diffuse surface, so that two point lights add no noise; with the port as geometry
    (``port`` given), the camera path first crosses its faces (``max_delta_depth``, one per
    face). It replaces Mitsuba's ``direct`` and the ``path`` integrator cut after next-event
    estimation, which pick one light at random per shadow ray (about 20 % per-pixel noise on a
    white plane at 8 spp with the default scene's two lamps, docs/simulator.md).

    Turbid water: ``volpath`` with the depth of the clear scene (two interactions beyond the
    port's faces, no Russian roulette). It attenuates every camera and shadow ray through the
    medium (Beer-Lambert, by free-flight sampling: unbiased, noisier than a closed form) and adds
    single scattering: one scattering event in the water, lit by next-event estimation, like a
    surface. Multiple scattering is cut off, as multiple surface bounces are. It still picks one
    light per shadow ray.
    """
    faces = 0 if port is None else len(port.faces)
    if water is not None and water.has_medium:
        depth = 2 + faces
        return {"type": "volpath", "max_depth": depth, "rr_depth": depth + 1, "hide_emitters": False}
    return {"type": EVERY_EMITTER, "max_delta_depth": faces, "hide_emitters": False}


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
    lighting.register(mi)
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
        scene[f"light_{i}"] = _emitter(light, medium=medium)
    for i, obj in enumerate(config.objects):
        scene[f"object_{i}"] = _shape(obj, mi=mi, config=config, index=i, media=media)
    return mi.load_dict(scene)
