"""Scene configuration: TOML files in ``scenes/`` parsed into frozen, validated dataclasses.

A scene file has these tables (every length in metres, angles only in ``*_deg`` fields)::

    name = "..."                      # optional label
    medium = "water"                  # optional: "water" (default) or "air": the camera and the
                                      #   objects stand in air (in-air calibration captures): no
                                      #   [port], no [water]; a real lens needs no port there
    [camera]                          # preset = "tiny" | "f01" | "illum", or every field of
    preset = "tiny"                   #   LightFieldCamera.to_dict() (with [camera.mla], [camera.sensor])
    lens = "thin"                     # optional main lens: "thin" (default), a lens preset
                                      #   ("double-gauss", "wide-angle": lfsim lenses) or the path
                                      #   of a lens file (relative to the scene file; scenes/lenses/)
                                      #   scaled and stopped to the camera, or a [camera.lens] table
                                      #   (a LensPrescription, used as it is); a real lens needs a
                                      #   [port] clear of it
    [camera.pose]                     # optional; camera-to-world, default identity
    rotation_xyz_deg = [0, 0, 0]
    position_m = [0, 0, 0]
    [port]                            # optional; no [port] table means no port (camera in water)
    distance_m = 0.02                 # see lfrefract.FlatPort
    thickness_m = 0.005
    tilt_x_deg = 20.0
    [water]                           # optional; no [water] table: clear water, the port's n_water
    salinity_psu = 35.0               # with temperature_c (both or neither): n_water from Quan and
    temperature_c = 20.0              #   Fry (1995), lfrefract.seawater_index; 0-35 psu, 0-30 C
    wavelength_nm = 589.3             # optional, 400-700 nm (default 589.3)
    absorption_per_m = [0.4, 0.07, 0.02]  # sigma_a, 1/m, one number or RGB (default 0)
    scattering_per_m = 0.1            # sigma_s, 1/m, one number or RGB (default 0)
    phase_g = 0.9                     # Henyey-Greenstein asymmetry in (-1, 1) (default 0)
    [sensor]                          # optional: the sensor model (simulator.detector), which turns
    preset = "illum"                  #   raw.exr into mosaic.npz; a detector preset ("illum", "f01",
    iso = 320.0                       #   "tiny") and/or any DetectorConfig field but pixel_pitch_m and
    frames = 1                        #   microlens_f_number (the camera's); frames: exposures averaged
                                      #   (64 for a white image as Lytro ships it); sensor = "illum"
                                      #   is short for a preset alone
    [render]
    spp = 16                          # samples per pixel of the raw image
    seed = 0
    port_model = "sensor"             # or "geometry" (see PORT_MODELS)
    ideal_spp = 256                   # optional, of the ideal image (default DEFAULT_IDEAL_SPP)
    [[light]]                         # type = "point" | "constant"
    [[object]]                        # type = "textured_plane" | "chessboard" | "disc" | "bowl"
                                      #        | "figurine" | "mesh"

Objects are placed in the world frame by ``position_m`` and ``rotation_xyz_deg``; in their
local frame +x is right, +y down and +z away from a camera with identity pose (OpenCV), so an
unrotated plane faces that camera with its texture upright. Unknown keys are errors.

``[water]`` (:class:`Water`) makes the water physical. Its salinity and temperature set the
port's ``n_water`` (a ``[port]`` table that also states ``n_water`` must agree to within
:data:`N_WATER_TOLERANCE`); its absorption and scattering coefficients fill the water with a
homogeneous participating medium (:func:`simulator.scene.water_medium`). Without a ``[water]``
table, or with both coefficients zero, the scene renders exactly as clear water.

Types and ranges
----------------
A value of the wrong TOML type (a list where a number belongs, a string for a table, a float
for an integer) is an error naming the key, the type it needs and the value. Every number has a
range; Mitsuba computes in float32 (largest 3.4e38, 7 significant digits), so the bounds also
keep every product it forms (position plus size, scale times a mesh's coordinates, intensity
over squared distance, radiance times samples) far inside float32. The bounds and their reasons:

- Positions, ``position_m`` of objects and point lights and ``camera.pose.position_m``: each
  coordinate within +-100 m (:data:`MAX_COORDINATE_M`). Beyond any underwater visibility (tens
  of metres in the clearest ocean); float32 steps are 7.6 um at 100 m, and Mitsuba moves ray
  origins off surfaces by 8.9e-5 of their distance from the origin (9 mm at 100 m), so larger
  scenes lose the millimetre detail of the objects near the camera.
- Rotations, ``rotation_xyz_deg`` of objects: each angle within +-360 deg
  (:data:`MAX_ANGLE_DEG`). A whole turn either way; larger angles repeat the same rotations,
  and one of 1e20 deg has no fraction of a turn left in float64.
- Sizes, ``size_m``, ``square_size_m`` (and the whole board with its margin), ``radius_m``,
  ``depth_m``, a bowl's ``thickness_m``, ``height_m``: 1e-5 m to 100 m (:data:`MIN_SIZE_M`,
  :data:`MAX_SIZE_M`). No preset camera resolves 10 um (a quarter of the Illum's
  refraction-free pixel at 2 cm), and float32 steps at 100 m are 7.6 um; 100 m as for positions.
  A bowl is at most a hemisphere (``depth_m <= radius_m``) with ``thickness_m < depth_m``.
- A mesh's ``scale``: 1e-6 to 1000 (:data:`MIN_MESH_SCALE`, :data:`MAX_MESH_SCALE`), a file in
  micrometres to one in kilometres; once loaded, its vertices in the world must lie within the
  bound of positions. Its ``path`` must be a regular file (not a directory or FIFO) of at most
  512 MiB (:data:`simulator.assets.MAX_MESH_FILE_BYTES`, where the reason is given), whose
  content is checked before Mitsuba reads it (:func:`simulator.assets.check_mesh_content`).
- ``intensity_w_sr`` of a point light: 0 to 1e6 W/sr per channel (:data:`MAX_INTENSITY_W_SR`).
  A 10 kW lamp radiates under 1e3 W/sr; the headroom is for exposure, and 1e6 W/sr at 1 mm,
  summed over every sample of a pixel, is still far inside float32.
- ``radiance`` of a constant light or a luminous disc: 0 to 1e8 W/(m^2 sr) per channel
  (:data:`MAX_RADIANCE`), above the Sun's (about 2e7).
- ``reflectance``: 0 to 1 per channel.
- ``render.spp`` and ``render.ideal_spp`` (the ideal image's, default :data:`DEFAULT_IDEAL_SPP`):
  1 to 65536 (:data:`MAX_SPP`). Mitsuba takes spp as a 32-bit unsigned integer (it fails on
  4294967297); 65536 samples of every pixel take about 13 minutes for the tiny
  camera and 50 hours for the Illum at the 15 Msample/s measured here: more is a typo.
- Seeds, ``render.seed``, ``texture_seed``, a figurine's ``seed``: integers in [0, 2**31)
  (:data:`SEED_LIMIT`), the one rule of every seed of the simulator (:mod:`simulator.seeds`, where
  the reason is given; a dataset's ``sweep.seed`` follows it too).
- ``texture_px``: 64 to 8192 (:data:`MIN_TEXTURE_PX`, :data:`MAX_TEXTURE_PX`). The random
  texture's 6 octaves need 64 texels; 8192 texels a side are 0.8 GB and a minute to make.
- A chessboard's ``squares`` (at least 2 each), ``texels_per_square`` (at least 1) and
  ``margin_squares`` (at least 0, a whole number of texels): its texture at most 8192 texels a
  side, as above.
- ``water.absorption_per_m`` and ``water.scattering_per_m``: 0 to 1000 per metre per channel
  (:data:`MAX_WATER_COEFFICIENT_PER_M`). The murkiest harbour water is some tens per metre; at
  1000 (a mean free path of 1 mm) nothing beyond the port can be seen.
- ``water.phase_g``: -0.99 to 0.99 (:data:`MAX_ABS_PHASE_G`). Sea water's asymmetry is about
  0.92; float32 rounds g within 3e-8 of 1 to 1, where the Henyey-Greenstein function is 0/0.
- ``water.salinity_psu``, ``water.temperature_c``, ``water.wavelength_nm``: 0-35 psu, 0-30 C,
  400-700 nm, the range of the index equation (:func:`lfrefract.seawater_index`).

The camera's and the port's own parameters are checked by :class:`lfrefract.LightFieldCamera`
and :class:`lfrefract.FlatPort`. Scene files are UTF-8 text (as TOML requires) of at most
:data:`MAX_TOML_BYTES`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lfrefract import FlatPort, LightFieldCamera, Pose, camera_preset, seawater_index
from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.paramfile import read_lens_file
from lfrefract.optics.lens import LENS_PRESETS, LensPrescription, lens_preset
from lfrefract.optics.pose import rotation_from_euler_xyz
from lfrefract.optics.real_lens import RealLensCamera
from lfrefract.optics.water import SODIUM_D_NM
from lfrefract.validate import (
    as_table,
    bounded_float,
    bounded_int,
    file_problem,
    finite_float,
    finite_vector,
    one_of,
    path_of,
    regular_file,
    reject_unknown_keys,
    shown,
    text,
)
from simulator import assets, seeds
from simulator.detector import DetectorConfig
from simulator.seeds import SEED_LIMIT

__all__ = [
    "DEFAULT_IDEAL_SPP",
    "MAX_ABS_PHASE_G",
    "MAX_ANGLE_DEG",
    "MAX_COORDINATE_M",
    "MAX_INTENSITY_W_SR",
    "MAX_MESH_SCALE",
    "MAX_RADIANCE",
    "MAX_SENSOR_FRAMES",
    "MAX_SIZE_M",
    "MAX_SPP",
    "MAX_TEXTURE_PX",
    "MAX_TOML_BYTES",
    "MAX_WATER_COEFFICIENT_PER_M",
    "MEDIA",
    "MIN_MESH_SCALE",
    "MIN_SIZE_M",
    "MIN_TEXTURE_PX",
    "N_WATER_TOLERANCE",
    "OBJECT_TYPES",
    "PORT_MODELS",
    "SEED_LIMIT",
    "THIN_LENS",
    "Bowl",
    "Chessboard",
    "ConstantLight",
    "Disc",
    "Figurine",
    "MeshFile",
    "Placement",
    "PointLight",
    "RenderSettings",
    "SceneConfig",
    "SensorSettings",
    "TexturedPlane",
    "Water",
    "apply_water_index",
    "default_scene_path",
    "embedded_scenes",
    "lens_option",
    "lens_record",
    "load_scene",
    "main_lens",
    "parse_scene",
    "read_toml",
    "scene_files",
    "sensor_model",
]


# The ranges of the scene's numbers; the module docstring gives each one's reason.

#: The ``camera.lens`` value of the thin main lens (the default).
THIN_LENS = "thin"
#: What the objects stand in (``medium``): water (behind a port, or with the camera in it) or air.
MEDIA = ("water", "air")

#: Largest absolute coordinate of a position (objects, point lights, the camera), metres.
MAX_COORDINATE_M = 100.0
#: Smallest and largest size of an object (lengths, radii, thicknesses, heights), metres.
MIN_SIZE_M, MAX_SIZE_M = 1e-5, 100.0
#: Largest absolute Euler angle of an object's rotation, degrees.
MAX_ANGLE_DEG = 360.0
#: Range of a user mesh's ``scale`` (file units to metres).
MIN_MESH_SCALE, MAX_MESH_SCALE = 1e-6, 1e3
#: Largest radiant intensity of a point light, W/sr per channel.
MAX_INTENSITY_W_SR = 1e6
#: Largest emitted radiance (constant light, luminous disc), W/(m^2 sr) per channel.
MAX_RADIANCE = 1e8
#: Largest samples per pixel (Mitsuba's limit is 2**32 - 1).
MAX_SPP = 2**16
#: Smallest random-texture side: the texture's octaves need ``2 ** octaves`` texels.
MIN_TEXTURE_PX = 2**assets.TEXTURE_OCTAVES
#: Largest texture side (random texture, chessboard): 8192^2 RGB float32 texels are 0.8 GB, and
#: generating a random one takes about a minute; anything larger is a typo, not a scene.
MAX_TEXTURE_PX = 8192
#: Largest absorption or scattering coefficient of the water, 1/m per channel.
MAX_WATER_COEFFICIENT_PER_M = 1e3
#: Largest magnitude of the water's Henyey-Greenstein asymmetry ``phase_g``.
MAX_ABS_PHASE_G = 0.99
#: Most exposures a ``[sensor]`` averages (``frames``): Lytro's white images average some tens;
#: each frame costs a Poisson draw of the whole sensor (about 2 s for an Illum).
MAX_SENSOR_FRAMES = 4096
#: ``DetectorConfig`` fields that a scene's ``[sensor]`` takes from its camera, never states.
_CAMERA_SENSOR_KEYS = ("pixel_pitch_m", "microlens_f_number")
#: Relative difference allowed between a sensor's pixel pitch or microlens f-number and its camera's
#: (both derive from the same numbers; 1e-9 allows the f-number's division only).
_SENSOR_CAMERA_RTOL = 1e-9
#: Largest scene, rig or sweep TOML file: such files are a few KiB; 16 MiB refuses a wrong file
#: (an image, a mesh, a huge sparse file) from its size before reading it.
MAX_TOML_BYTES = 16 * 2**20


def _rgb(name: str, value: Any, high: float) -> tuple[float, float, float]:
    """A colour given as one number or three; every entry finite and in [0, high]."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = (value, value, value)
    elif isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__"):
        raise ParameterError(f"{name} must be one number or a list of 3 numbers (RGB), got {shown(value)}")
    rgb = finite_vector(name, value, 3)
    return tuple(bounded_float(f"{name}[{i}]", c, 0.0, high) for i, c in enumerate(rgb))


def _albedo(name: str, value: Any) -> tuple[float, float, float]:
    """A reflectance: one number or three, each in [0, 1]."""
    return _rgb(name, value, 1.0)


def _size(name: str, value: Any) -> float:
    """A size of an object, metres: in [MIN_SIZE_M, MAX_SIZE_M] (below 0 "must be positive")."""
    out = finite_float(name, value)
    if out <= 0.0:
        raise ParameterError(f"{name} must be positive, got {shown(value)}")
    return bounded_float(name, out, MIN_SIZE_M, MAX_SIZE_M, unit="m")


def _position(name: str, value: Any) -> tuple[float, float, float]:
    """A position in the world, metres: 3 coordinates within +-MAX_COORDINATE_M."""
    xyz = finite_vector(name, value, 3)
    return tuple(
        bounded_float(f"{name}[{i}]", c, -MAX_COORDINATE_M, MAX_COORDINATE_M, unit="m") for i, c in enumerate(xyz)
    )


def _texture_px(name: str, value: Any) -> int:
    return bounded_int(name, value, MIN_TEXTURE_PX, MAX_TEXTURE_PX)


@dataclass(frozen=True, kw_only=True)
class Placement:
    """Where an object sits: local-to-world rotation (extrinsic x-y-z Euler, degrees) and centre."""

    position_m: tuple[float, float, float]
    rotation_xyz_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_m", _position("position_m", self.position_m))
        angles = finite_vector("rotation_xyz_deg", self.rotation_xyz_deg, 3)
        for i, angle in enumerate(angles):
            bounded_float(f"rotation_xyz_deg[{i}]", angle, -MAX_ANGLE_DEG, MAX_ANGLE_DEG, unit="deg")
        object.__setattr__(self, "rotation_xyz_deg", angles)

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous 4x4 local-to-world matrix."""
        m = np.eye(4)
        m[:3, :3] = rotation_from_euler_xyz(tuple(math.radians(a) for a in self.rotation_xyz_deg))
        m[:3, 3] = self.position_m
        return m

    def to_world(self, points_local: np.ndarray) -> np.ndarray:
        """Local points (N, 3) to world points (N, 3)."""
        m = self.matrix
        return np.asarray(points_local, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]


@dataclass(frozen=True, kw_only=True)
class TexturedPlane:
    """A rectangle with a seeded multi-scale random texture (for stereo), in local z = 0."""

    placement: Placement
    size_m: tuple[float, float]
    texture_px: int = 512
    texture_seed: int = 0

    def __post_init__(self) -> None:
        size = finite_vector("size_m", self.size_m, 2)
        object.__setattr__(self, "size_m", tuple(_size(f"size_m[{i}]", s) for i, s in enumerate(size)))
        _texture_px("texture_px", self.texture_px)
        object.__setattr__(self, "texture_seed", seeds.seed("texture_seed", self.texture_seed))


@dataclass(frozen=True, kw_only=True)
class Chessboard:
    """A chessboard target with a white margin, in local z = 0; ``squares`` = (columns, rows)."""

    placement: Placement
    squares: tuple[int, int]
    square_size_m: float
    margin_squares: float = 1.0
    texels_per_square: int = 16

    def __post_init__(self) -> None:
        # A margin wider than the largest texture cannot fit (each margin square is a texel or more).
        bounded_float("margin_squares", self.margin_squares, 0.0, MAX_TEXTURE_PX)
        # The counts and the margin, checked once (simulator.assets.ChessboardLayout); then the
        # texels (a whole number of them in the margin) as the texture needs them, and the
        # texture and the board within their bounds.
        layout = assets.ChessboardLayout(squares=self.squares, margin_squares=self.margin_squares)
        height, width = layout.texture_shape(self.texels_per_square)
        if max(height, width) > MAX_TEXTURE_PX:
            raise ParameterError(
                f"the chessboard's texture (squares={list(self.squares)} with margin_squares={self.margin_squares!r}, "
                f"texels_per_square={self.texels_per_square!r}) would be {width} x {height} texels; at most "
                f"{MAX_TEXTURE_PX} a side"
            )
        object.__setattr__(self, "squares", layout.squares)
        _size("square_size_m", self.square_size_m)
        board = layout.size_m(self.square_size_m)
        if max(board) > MAX_SIZE_M:
            raise ParameterError(
                f"the chessboard (squares={list(self.squares)}, margin_squares={self.margin_squares!r}, "
                f"square_size_m={self.square_size_m!r}) would be {board[0]:g} x {board[1]:g} m; at most "
                f"{MAX_SIZE_M:g} m a side"
            )
        # Derived values, not fields (not in the sidecar, not compared): later code trusts them.
        object.__setattr__(self, "_layout", layout)
        object.__setattr__(self, "_board_size_m", board)

    @property
    def layout(self) -> assets.ChessboardLayout:
        """The board's squares and margin as checked (:class:`simulator.assets.ChessboardLayout`)."""
        return self._layout

    @property
    def board_size_m(self) -> tuple[float, float]:
        """``(width_m, height_m)`` of the whole board, margin included, computed once when the
        board is checked."""
        return self._board_size_m

    def texture(self) -> np.ndarray:
        """The board's texture, float32 (H, W, 3) (:func:`simulator.assets.chessboard_texture`)."""
        return self._layout.texture(self.texels_per_square)

    def inner_corners_local_m(self) -> np.ndarray:
        """Inner corners (N, 2), metres, in the board's plane (local z = 0), in the order of
        :func:`simulator.assets.chessboard_inner_corners`."""
        return self._layout.inner_corners_m(self.square_size_m)


@dataclass(frozen=True, kw_only=True)
class Disc:
    """A flat disc in local z = 0: a diffuse target, or a light if ``radiance`` is non-zero.

    A luminous disc emits from its -z face (towards a camera with identity pose) only.
    """

    placement: Placement
    radius_m: float
    reflectance: tuple[float, float, float] = (0.8, 0.8, 0.8)
    radiance: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        _size("radius_m", self.radius_m)
        object.__setattr__(self, "reflectance", _albedo("reflectance", self.reflectance))
        object.__setattr__(self, "radiance", _rgb("radiance", self.radiance, MAX_RADIANCE))


def _mesh_texture(obj) -> None:
    """Check a procedural mesh's optional texture: ``texture_seed`` (None: plain ``reflectance``)
    and ``texture_px``. With a seed the surface carries the seeded multi-scale colour texture of
    ``textured_plane`` (for stereo), wrapped around the mesh's axis."""
    if obj.texture_seed is not None:
        object.__setattr__(obj, "texture_seed", seeds.seed("texture_seed", obj.texture_seed))
    _texture_px("texture_px", obj.texture_px)


@dataclass(frozen=True, kw_only=True)
class Bowl:
    """A thin-walled bowl opening towards -z (towards a camera with identity pose); plain
    ``reflectance``, or with ``texture_seed`` a random colour texture."""

    placement: Placement
    radius_m: float
    depth_m: float
    thickness_m: float = 0.004
    reflectance: tuple[float, float, float] = (0.7, 0.45, 0.3)
    texture_seed: int | None = None
    texture_px: int = 512

    def __post_init__(self) -> None:
        for name in ("radius_m", "depth_m", "thickness_m"):
            _size(name, getattr(self, name))
        # At most a hemisphere, a wall thinner than the depth: as the mesh needs them.
        assets.bowl_cap_geometry(radius_m=self.radius_m, depth_m=self.depth_m, thickness_m=self.thickness_m)
        object.__setattr__(self, "reflectance", _albedo("reflectance", self.reflectance))
        _mesh_texture(self)


@dataclass(frozen=True, kw_only=True)
class Figurine:
    """An organic, figurine-like closed shape standing along -y (up), ``height_m`` tall; plain
    ``reflectance``, or with ``texture_seed`` a random colour texture."""

    placement: Placement
    height_m: float
    seed: int = 0
    reflectance: tuple[float, float, float] = (0.35, 0.6, 0.4)
    texture_seed: int | None = None
    texture_px: int = 512

    def __post_init__(self) -> None:
        _size("height_m", self.height_m)
        object.__setattr__(self, "seed", seeds.seed("seed", self.seed))
        object.__setattr__(self, "reflectance", _albedo("reflectance", self.reflectance))
        _mesh_texture(self)


@dataclass(frozen=True, kw_only=True)
class MeshFile:
    """A user mesh from an OBJ or PLY file, scaled uniformly then placed.

    The file's kind and size are checked here, from its metadata
    (:func:`simulator.assets.check_mesh_file`: a regular file of at most
    :data:`simulator.assets.MAX_MESH_FILE_BYTES`); its content when the scene is built
    (:func:`simulator.assets.check_mesh_content`), before Mitsuba reads it.
    """

    placement: Placement
    path: Path
    scale: float = 1.0
    reflectance: tuple[float, float, float] = (0.7, 0.7, 0.7)

    def __post_init__(self) -> None:
        path = path_of("path", self.path)
        if path.suffix.lower() not in (".obj", ".ply"):
            raise ParameterError(f"mesh path must end in .obj or .ply, got {str(path)!r}")
        assets.check_mesh_file(path)
        object.__setattr__(self, "path", path)
        bounded_float("scale", self.scale, MIN_MESH_SCALE, MAX_MESH_SCALE)
        object.__setattr__(self, "reflectance", _albedo("reflectance", self.reflectance))


@dataclass(frozen=True, kw_only=True)
class PointLight:
    """An isotropic point light in the water; ``intensity_w_sr`` is radiant intensity (RGB)."""

    position_m: tuple[float, float, float]
    intensity_w_sr: tuple[float, float, float]

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_m", _position("position_m", self.position_m))
        object.__setattr__(self, "intensity_w_sr", _rgb("intensity_w_sr", self.intensity_w_sr, MAX_INTENSITY_W_SR))


@dataclass(frozen=True, kw_only=True)
class ConstantLight:
    """Uniform radiance from every direction (an environment; used for white images).

    Behind a port its light reaches objects only through the glass, so it is meant for scenes
    without a port; :func:`parse_scene` rejects it together with a port.
    """

    radiance: tuple[float, float, float]

    def __post_init__(self) -> None:
        object.__setattr__(self, "radiance", _rgb("radiance", self.radiance, MAX_RADIANCE))


#: How the port is rendered. ``sensor``: the plenoptic sensor refracts its rays through the port's
#: planes in closed form (the housing is part of the camera), so camera paths start in the water;
#: ``geometry``: the glass is scene geometry with a refracting BSDF and Mitsuba's path tracer
#: crosses it. Both are exact; ``geometry`` is the slower reference the tests compare against.
PORT_MODELS = ("sensor", "geometry")


#: Samples per pixel of the ideal (refraction-free ground-truth) image unless ``render.ideal_spp``
#: says otherwise. From the curve of docs/simulator.md ("The ideal image's samples"): the RMS
#: error of the chessboard corners that the core's detector finds in the ideal image, against the
#: pinhole projection of the board's corners, falls with spp to the detector's own floor on a
#: noise-free image (0.073 px); at 256 spp it is within 8 % of that floor (the sampling noise adds
#: about 0.03 px in quadrature), at 64 spp still 34 % above it. The ideal image has two pixels per
#: microlens pitch, 2-4 % of the raw image's pixels, so 256 spp of it cost as many samples as
#: 5-10 spp of the raw image (0.3 s for the tiny-2x camera's 188 x 141 px).
DEFAULT_IDEAL_SPP = 256


@dataclass(frozen=True, kw_only=True)
class RenderSettings:
    """Samples per pixel, the seed of the sampler, and the port model (see :data:`PORT_MODELS`).

    Parameters
    ----------
    spp : int
        Samples per pixel of the raw image, 1 to :data:`MAX_SPP`.
    seed : int
        Job seed, in [0, 2**31).
    port_model : str
        One of :data:`PORT_MODELS`.
    ideal_spp : int
        Samples per pixel of the ideal (refraction-free) ground-truth image, 1 to :data:`MAX_SPP`;
        default :data:`DEFAULT_IDEAL_SPP`, whatever ``spp`` is: clean ground truth does not need
        a raw image at high spp.
    """

    spp: int = 16
    seed: int = 0
    port_model: str = "sensor"
    ideal_spp: int = DEFAULT_IDEAL_SPP

    def __post_init__(self) -> None:
        bounded_int("render.spp", self.spp, 1, MAX_SPP)
        bounded_int("render.ideal_spp", self.ideal_spp, 1, MAX_SPP)
        one_of("render.port_model", self.port_model, PORT_MODELS)
        object.__setattr__(self, "seed", seeds.seed("render.seed", self.seed))


#: Largest difference between an ``n_water`` stated in ``[port]`` (or a rig's ``[wall]``) and the
#: index that ``[water]`` computes before the two count as a conflict. About the equation's own
#: error against the data it fits (up to 6e-5 against the tabulated values of Austin and Halikas),
#: so an index that agrees to the fourth decimal passes, while one psu of salinity (1.8e-4) or two
#: degrees of temperature (1.8e-4 at 20 C) is refused.
N_WATER_TOLERANCE = 1e-4


@dataclass(frozen=True, kw_only=True)
class Water:
    """The water the objects stand in: its refractive index and its turbidity (``[water]``).

    Parameters
    ----------
    salinity_psu, temperature_c : float, optional
        Practical salinity (0 to 35 psu) and temperature (0 to 30 degrees Celsius), both or
        neither. Given, the refractive index of the water follows from them
        (:func:`lfrefract.seawater_index`, Quan and Fry 1995; relative to air) and, times the
        port's ``n_air`` (1 unless stated), is the port's ``n_water``.
    wavelength_nm : float, optional
        Wavelength in vacuum of that index, nanometres, 400 to 700; only with salinity and
        temperature (default then 589.3, the sodium D line).
    absorption_per_m, scattering_per_m : float or sequence of 3 floats
        Absorption and scattering coefficients sigma_a and sigma_s of the water, per metre
        (0 to :data:`MAX_WATER_COEFFICIENT_PER_M`; one number for all three colour channels, or
        RGB; their sum, the extinction, is either 0 in every channel or positive in every
        channel). Default 0: clear water.
    phase_g : float
        Asymmetry g of the Henyey-Greenstein phase function of the scattering, within
        +-:data:`MAX_ABS_PHASE_G` (0.99): 0 isotropic, towards 1 forward (typical of sea water:
        about 0.9). Default 0.

    Attributes
    ----------
    n_water : float or None
        The computed refractive index (relative to air), None without salinity and temperature.

    Raises
    ------
    ParameterError
        For one of salinity and temperature without the other, a wavelength without them, a value
        outside the index equation's ranges, a negative or non-finite coefficient, an extinction
        ``absorption_per_m + scattering_per_m`` that is 0 in some channel but positive in another
        (Mitsuba's ``volpath`` renders such a medium as NaN), or a value out of its range; the
        message names the key (``water.<key>``) and the value.
    """

    salinity_psu: float | None = None
    temperature_c: float | None = None
    wavelength_nm: float | None = None
    absorption_per_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scattering_per_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    phase_g: float = 0.0
    n_water: float | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        if (self.salinity_psu is None) != (self.temperature_c is None):
            raise ParameterError(
                "water.salinity_psu and water.temperature_c go together (both or neither), got "
                f"salinity_psu={self.salinity_psu!r}, temperature_c={self.temperature_c!r}"
            )
        if self.salinity_psu is None:
            if self.wavelength_nm is not None:
                raise ParameterError(
                    f"water.wavelength_nm={self.wavelength_nm!r} is the wavelength of the index that "
                    "salinity_psu and temperature_c give; it needs them"
                )
        else:
            wavelength = SODIUM_D_NM if self.wavelength_nm is None else self.wavelength_nm
            try:
                n = seawater_index(
                    salinity_psu=self.salinity_psu, temperature_c=self.temperature_c, wavelength_nm=wavelength
                )
            except ParameterError as exc:
                raise ParameterError(f"water.{exc}") from None
            for name, value in (("salinity_psu", self.salinity_psu), ("temperature_c", self.temperature_c)):
                object.__setattr__(self, name, float(value))
            object.__setattr__(self, "wavelength_nm", float(wavelength))
            object.__setattr__(self, "n_water", n)
        for name in ("absorption_per_m", "scattering_per_m"):
            value = _rgb(f"water.{name}", getattr(self, name), MAX_WATER_COEFFICIENT_PER_M)
            object.__setattr__(self, name, value)
        empty = [i for i, t in enumerate(self.extinction_per_m) if t == 0.0]
        if self.has_medium and empty:
            # Mitsuba's volpath divides by every channel's extinction at each medium interaction:
            # a channel at 0 beside a positive one turns the whole image into NaN.
            raise ParameterError(
                f"water.absorption_per_m={list(self.absorption_per_m)} plus water.scattering_per_m="
                f"{list(self.scattering_per_m)} is 0 in channel(s) {empty} but positive in another: "
                "Mitsuba's volpath cannot render a medium that is empty in some colour channels (the "
                "image would be NaN); give every channel a positive absorption (water absorbs at every "
                "visible wavelength) or make both coefficients 0 in all channels"
            )
        g = finite_float("water.phase_g", self.phase_g)
        if not -1.0 < g < 1.0:
            raise ParameterError(f"water.phase_g must lie in (-1, 1), got {shown(self.phase_g)}")
        bounded_float("water.phase_g", g, -MAX_ABS_PHASE_G, MAX_ABS_PHASE_G)
        object.__setattr__(self, "phase_g", g)

    @classmethod
    def from_dict(cls, table: Any) -> Water:
        """Build from a ``[water]`` table; unknown keys are an error, lists become tuples."""
        table = as_table("[water]", table)
        keys = {f.name for f in dataclasses.fields(cls) if f.init}
        reject_unknown_keys("water", table, keys)
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in table.items()})

    @property
    def has_medium(self) -> bool:
        """Whether the water absorbs or scatters (then it is rendered as a participating medium)."""
        return max(self.absorption_per_m) > 0.0 or max(self.scattering_per_m) > 0.0

    @property
    def extinction_per_m(self) -> tuple[float, float, float]:
        """Extinction coefficient sigma_t = sigma_a + sigma_s per channel, per metre."""
        return tuple(a + s for a, s in zip(self.absorption_per_m, self.scattering_per_m, strict=True))

    @property
    def albedo(self) -> tuple[float, float, float]:
        """Single-scattering albedo sigma_s / sigma_t per channel (0 where sigma_t is 0)."""
        pairs = zip(self.scattering_per_m, self.extinction_per_m, strict=True)
        return tuple(s / t if t > 0.0 else 0.0 for s, t in pairs)

    def to_dict(self) -> dict:
        """Plain data: the table's keys with the effective wavelength, and the derived ``n_water``."""
        return {
            "salinity_psu": self.salinity_psu,
            "temperature_c": self.temperature_c,
            "wavelength_nm": self.wavelength_nm,
            "n_water": self.n_water,
            "n_water_source": None if self.n_water is None else "Quan and Fry (1995), Appl. Opt. 34(18), 3477",
            "absorption_per_m": list(self.absorption_per_m),
            "scattering_per_m": list(self.scattering_per_m),
            "phase_g": self.phase_g,
        }


def apply_water_index(table: dict, water: Water | None, *, where: str) -> dict:
    """A copy of a port-like table (a rig's ``[wall]``, a ``[port]`` without an ``n_water``) with
    the water's ``n_water``.

    The water's index is relative to air; the table's ``n_water`` becomes it times the table's
    ``n_air`` (1 unless stated), so that ``n_water / n_air``, the ratio refraction depends on, is
    the water's index whichever reference the table's indices use.

    Parameters
    ----------
    table : dict
        The table; its ``n_water`` key, if any, is the index the user stated.
    water : Water or None
        The scene's water; without a computed index the table is returned unchanged (copied).
    where : str
        The table's name in errors (``"port"``, ``"wall"``).

    Raises
    ------
    ParameterError
        If the table states an ``n_water`` that differs from the water's computed index (times
        ``n_air``) by more than :data:`N_WATER_TOLERANCE`: neither is picked silently.
    """
    out = as_table(f"[{where}]", table)
    if water is None or water.n_water is None:
        return out
    n_air = finite_float(f"{where}.n_air", out.get("n_air", 1.0))
    expected = water.n_water * n_air
    if "n_water" in out:
        stated = finite_float(f"{where}.n_water", out["n_water"])
        if abs(stated - expected) > N_WATER_TOLERANCE:
            scaled = "" if n_air == 1.0 else f" relative to air, {expected:.6f} with {where}.n_air={n_air!r}"
            raise ParameterError(
                f"{where}.n_water={stated!r} conflicts with the index of [water] (salinity_psu="
                f"{water.salinity_psu!r}, temperature_c={water.temperature_c!r}, wavelength_nm="
                f"{water.wavelength_nm!r}: n_water={water.n_water:.6f}{scaled}, Quan and Fry 1995); they differ by "
                f"{abs(stated - expected):.2g} > {N_WATER_TOLERANCE:g}. Remove one of them or make them agree"
            )
    out["n_water"] = expected
    return out


SceneObject = TexturedPlane | Chessboard | Disc | Bowl | Figurine | MeshFile
Light = PointLight | ConstantLight

OBJECT_TYPES: dict[str, type] = {
    "textured_plane": TexturedPlane,
    "chessboard": Chessboard,
    "disc": Disc,
    "bowl": Bowl,
    "figurine": Figurine,
    "mesh": MeshFile,
}
LIGHT_TYPES: dict[str, type] = {"point": PointLight, "constant": ConstantLight}


def _check_real_lens(
    camera: LightFieldCamera, lens: LensPrescription, port: FlatPort | None, *, sees_water: bool
) -> None:
    """A real main lens must fit the camera (:class:`RealLensCamera`) and sit in air: behind a port
    that clears its front when it looks into water (``sees_water``), since a lens prescription is
    designed for air in front of it. An in-air scene, or one without objects (a white image:
    uniform radiance from every direction, which no ray's direction changes), needs no port."""
    real = RealLensCamera(camera=camera, lens=lens)
    if port is None and not sees_water:
        return
    if port is None:
        raise ParameterError(
            f"camera.lens={lens.name!r} needs a [port]: a real lens is designed for air in front of it, "
            'and without a port the camera stands in the water (use lens = "thin" there)'
        )
    # The port's inner face n.x = distance_m must clear every point of the lens: the frontmost
    # surface point lies at most max semi-aperture off the axis.
    normal = np.asarray(port.normal, dtype=np.float64)
    reach_m = max(s.semi_aperture_m for s in lens.surfaces)
    nearest_m = normal[2] * real.extent_z_m[1] + math.hypot(normal[0], normal[1]) * reach_m
    if nearest_m >= port.distance_m:
        raise ParameterError(
            f"port.distance_m={port.distance_m!r} does not clear the main lens {lens.name!r}: its front reaches "
            f"z = {real.extent_z_m[1]:.6g} m with a clear semi-aperture up to {reach_m:.6g} m, which touches the "
            f"port's face (needs distance_m > {nearest_m:.6g} m at this tilt)"
        )


@dataclass(frozen=True, kw_only=True)
class SceneConfig:
    """A whole scene: camera, pose, optional port, lights, objects and render settings.

    With a ``water`` whose salinity and temperature give an index, the port's ``n_water`` must be
    that index times the port's ``n_air`` to within :data:`N_WATER_TOLERANCE` (the one check of a
    scene's water index, however the config is built); one within the tolerance is replaced by
    the computed index.
    """

    camera: LightFieldCamera
    pose: Pose = field(default_factory=Pose)
    port: FlatPort | None = None
    lens: LensPrescription | None = None
    lights: tuple[Light, ...] = ()
    objects: tuple[SceneObject, ...] = ()
    render: RenderSettings = field(default_factory=RenderSettings)
    water: Water | None = None
    sensor: SensorSettings | None = None
    medium: str = "water"
    name: str = "scene"
    source: str = "<memory>"

    def __post_init__(self) -> None:
        one_of("medium", self.medium, MEDIA)
        if self.medium == "air" and self.port is not None:
            raise ParameterError('medium = "air" takes no [port]: the camera looks straight into the air')
        if self.medium == "air" and self.water is not None:
            raise ParameterError('medium = "air" takes no [water]')
        constant = any(isinstance(light, ConstantLight) for light in self.lights)
        if self.port is not None and constant:
            raise ParameterError(
                "a constant (environment) light cannot light a scene behind a port: the glass would "
                "shadow it; use point lights in the water, or remove [port]"
            )
        if not self.lights:
            raise ParameterError("the scene has no [[light]]: it would render black")
        if self.lens is not None:
            # In air a real lens needs no port; in water it does (unless nothing is in front of it).
            sees_water = self.medium == "water" and bool(self.objects)
            _check_real_lens(self.camera, self.lens, self.port, sees_water=sees_water)
        if self.sensor is not None:
            _check_sensor(self.sensor, self.camera)
        _position("camera.pose.position_m", self.pose.position_m)
        water = self.water
        if water is not None and not isinstance(water, Water):
            raise ParameterError(f"water must be a Water or None, got {water!r}")
        if water is not None and water.has_medium and constant:
            raise ParameterError(
                "a constant (environment) light lies at infinity, beyond an infinite expanse of turbid water "
                f"(water.absorption_per_m={list(water.absorption_per_m)}, water.scattering_per_m="
                f"{list(water.scattering_per_m)}): none of its light would arrive; use point lights or luminous discs"
            )
        n_water = None if water is None else water.n_water
        # The water's index is relative to air: the port's n_water / n_air must match it.
        if n_water is not None and self.port is not None:
            expected = n_water * self.port.n_air
            if abs(self.port.n_water - expected) > N_WATER_TOLERANCE:
                raise ParameterError(
                    f"port.n_water={self.port.n_water!r} conflicts with the index of the water "
                    f"(n_water={n_water:.6f} relative to air from water.salinity_psu={water.salinity_psu!r}, "
                    f"water.temperature_c={water.temperature_c!r}, times port.n_air={self.port.n_air!r}); build "
                    "the port with n_water=water.n_water * n_air"
                )
            if self.port.n_water != expected:  # within the tolerance: the computed index, exactly
                object.__setattr__(self, "port", dataclasses.replace(self.port, n_water=expected))

    @property
    def calibration_origin_cam(self) -> np.ndarray:
        """Where a calibration from boards in air puts this scene's camera (3,), camera frame, metres:
        a real main lens's paraxial entrance pupil
        (:attr:`lfrefract.optics.real_lens.RealLensCamera.calibration_origin_cam`), the origin for the
        thin lens. A calibrated port, ray model or board pose is compared with this scene's truth
        moved there (e.g. ``scene.port.seen_from(scene.calibration_origin_cam)``)."""
        if self.lens is None:
            return np.zeros(3)
        return RealLensCamera(camera=self.camera, lens=self.lens).calibration_origin_cam

    def with_overrides(self, **changes: Any) -> SceneConfig:
        """A copy with some fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        """Plain data for the sidecar (tuples as lists, paths as strings)."""

        def plain(value: Any) -> Any:
            if dataclasses.is_dataclass(value) and not isinstance(value, type):
                if hasattr(value, "to_dict"):
                    return value.to_dict()
                out = {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
                kind = {v: k for k, v in {**OBJECT_TYPES, **LIGHT_TYPES}.items()}.get(type(value))
                return {"type": kind, **out} if kind else out
            if isinstance(value, (tuple, list)):
                return [plain(v) for v in value]
            if isinstance(value, Path):
                return str(value)
            return value

        return {
            "name": self.name,
            "source": self.source,
            "camera": self.camera.to_dict(),
            "lens": THIN_LENS if self.lens is None else self.lens.to_dict(),
            "pose": self.pose.to_dict(),
            "port": None if self.port is None else self.port.to_dict(),
            "lights": plain(self.lights),
            "objects": plain(self.objects),
            "render": plain(self.render),
            "water": None if self.water is None else self.water.to_dict(),
            "sensor": None if self.sensor is None else self.sensor.to_dict(),
            "medium": self.medium,
        }


def _build(cls: type, table: Any, where: str, base_dir: Path) -> Any:
    """Instantiate a config dataclass from a TOML table, with placement and path handling."""
    table = as_table(where, table)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    names = set(fields)
    kwargs: dict[str, Any] = {}
    if "placement" in names:
        place = {k: table.pop(k) for k in ("position_m", "rotation_xyz_deg") if k in table}
        if "position_m" not in place:
            raise ParameterError(f"{where}: missing key 'position_m'")
        try:
            kwargs["placement"] = Placement(**place)
        except ParameterError as exc:
            raise ParameterError(f"{where}: {exc}") from None
        names.discard("placement")
    reject_unknown_keys(where, table, names)
    missing = sorted(
        name
        for name in names
        if name not in table
        and fields[name].default is dataclasses.MISSING
        and fields[name].default_factory is dataclasses.MISSING
    )
    if missing:
        raise ParameterError(f"{where}: missing key(s) {missing}")
    try:
        for key, value in table.items():
            if key == "path":
                path = path_of("path", value)
                if "\0" in str(path):
                    raise ParameterError(f"path {shown(str(path))} contains a NUL character")
                try:
                    value = (base_dir / path).resolve()
                except (OSError, RuntimeError) as exc:  # RuntimeError: a symbolic link loop
                    raise ParameterError(f"path {str(path)!r} cannot be resolved: {exc}") from None
            elif isinstance(value, list):
                value = tuple(value)
            kwargs[key] = value
        return cls(**kwargs)
    except ParameterError as exc:
        # A message that already names the key under its table (render.spp) needs no prefix.
        raise ParameterError(str(exc) if str(exc).startswith(f"{where}.") else f"{where}: {exc}") from None


def _typed_entries(data: Any, kinds: dict[str, type], where: str, base_dir: Path) -> tuple:
    if not isinstance(data, list):
        raise ParameterError(f"[[{where}]] must be an array of tables, got {shown(data)}")
    out = []
    for i, table in enumerate(data):
        label = f"{where}[{i}]"
        table = as_table(label, table)
        if "type" not in table:
            raise ParameterError(f"{label} needs a 'type', one of {sorted(kinds)}")
        kind = one_of(f"{label}.type", table.pop("type"), sorted(kinds))
        out.append(_build(kinds[kind], table, f"{label} ({kind})", base_dir))
    return tuple(out)


@dataclass(frozen=True, kw_only=True)
class SensorSettings:
    """The sensor behind the microlenses (a scene's ``[sensor]``): what turns ``raw.exr`` into counts.

    Parameters
    ----------
    detector : simulator.detector.DetectorConfig
        The detector model; its ``pixel_pitch_m`` and ``microlens_f_number`` are the camera's
        (:func:`sensor_model` sets them).
    frames : int
        Exposures averaged into the mosaic, 1 to :data:`MAX_SENSOR_FRAMES`: 1 for a capture, some
        tens for a white image as Lytro's factory calibration holds them
        (:func:`simulator.detector.white_frames`).
    """

    detector: DetectorConfig
    frames: int = 1

    def __post_init__(self) -> None:
        if not isinstance(self.detector, DetectorConfig):
            raise ParameterError(f"sensor.detector must be a DetectorConfig, got {shown(self.detector)}")
        object.__setattr__(self, "frames", bounded_int("sensor.frames", self.frames, 1, MAX_SENSOR_FRAMES))

    def to_dict(self) -> dict:
        """Plain data: ``frames`` and every detector field."""
        return {"frames": self.frames, **self.detector.to_dict()}


def _camera_sensor_fields(camera: LightFieldCamera) -> dict[str, float]:
    return {
        "pixel_pitch_m": camera.sensor.pixel_pitch_m,
        "microlens_f_number": camera.mla.focal_length_m / camera.mla.pitch_m,
    }


def sensor_model(value: Any, camera: LightFieldCamera) -> SensorSettings:
    """The sensor a scene's ``sensor`` value names, for ``camera``.

    Parameters
    ----------
    value : str, mapping or SensorSettings
        A detector preset's name (``"illum"``, ``"f01"``, ``"tiny"``); a ``[sensor]`` table:
        ``frames`` (default 1), optionally ``preset``, and any field of
        :class:`simulator.detector.DetectorConfig` but ``pixel_pitch_m`` and ``microlens_f_number``
        (without a preset, every other field without a default); or an existing sensor, moved to
        ``camera`` (as ``lfsim render --camera`` does).
    camera : LightFieldCamera
        Gives the pixel pitch and the microlens f-number (MLA focal length over pitch).

    Raises
    ------
    ParameterError
        For an unknown preset or key, a camera-given key, or an invalid value (named).
    """
    if isinstance(value, SensorSettings):
        detector = dataclasses.replace(value.detector, **_camera_sensor_fields(camera))
        return SensorSettings(detector=detector, frames=value.frames)
    table = {"preset": value} if isinstance(value, str) else dict(as_table("[sensor]", value))
    stated = [key for key in _CAMERA_SENSOR_KEYS if key in table]
    if stated:
        raise ParameterError(
            f"sensor.{stated[0]} is the camera's (its pixel pitch, or MLA focal length over lens pitch): "
            "leave it out of [sensor]"
        )
    frames = table.pop("frames", 1)
    detector = DetectorConfig.from_dict(table | _camera_sensor_fields(camera), where="sensor")
    return SensorSettings(detector=detector, frames=frames)


def _check_sensor(sensor: SensorSettings, camera: LightFieldCamera) -> None:
    if not isinstance(sensor, SensorSettings):
        raise ParameterError(f"sensor must be a SensorSettings or None, got {shown(sensor)}")
    for key, expected in _camera_sensor_fields(camera).items():
        value = getattr(sensor.detector, key)
        if not math.isclose(value, expected, rel_tol=_SENSOR_CAMERA_RTOL):
            raise ParameterError(
                f"sensor.{key}={value!r} is not the camera's ({expected!r}): build the sensor for this camera "
                "(simulator.config.sensor_model)"
            )


def main_lens(value: Any, camera: LightFieldCamera, *, base_dir: Path | str = ".") -> LensPrescription | None:
    """The main lens a ``camera.lens`` value names.

    Parameters
    ----------
    value : str, LensPrescription or table
        ``"thin"`` (None: the thin lens); a preset name of :data:`lfrefract.optics.lens.LENS_PRESETS`;
        the path of a lens file (:func:`lfrefract.formats.paramfile.read_lens_file`; ``scenes/lenses/`` holds a
        family of them); a :class:`LensPrescription` (a design, such as a lens file's,
        :func:`lens_option`) -- these three scaled to ``camera``'s focal length and stopped to its
        f-number -- or a lens table (:meth:`LensPrescription.from_dict`), used as it is: it must
        already have the camera's focal length and f-number.
    camera : LightFieldCamera
    base_dir : path-like
        What a relative lens-file path is relative to (a scene file's folder).

    Raises
    ------
    ParameterError
        For a string that is none of these (naming ``camera.lens``, the value and why the path is no
        file), for a lens file that is invalid (naming it and its key) or cannot be stopped to the
        camera's f-number, or for an invalid table.
    """
    if isinstance(value, LensPrescription):
        return value.scaled_to_focal_length(camera.focal_length_m).with_f_number(camera.f_number)
    if isinstance(value, str):
        if value == THIN_LENS:
            return None
        if value in LENS_PRESETS:
            return lens_preset(value, focal_length_m=camera.focal_length_m, f_number=camera.f_number)
        path = Path(value) if Path(value).is_absolute() else Path(base_dir) / value
        _require_lens_file(f"camera.lens={value!r}", value, path)
        try:
            return read_lens_file(path, focal_length_m=camera.focal_length_m, f_number=camera.f_number)
        except (FileFormatError, ParameterError) as exc:
            raise ParameterError(f"camera.lens={value!r}: {exc}") from None
    return LensPrescription.from_dict(as_table("[camera.lens]", value))


def _require_lens_file(what: str, value: str, path: Path) -> None:
    """Refuse a lens value that names no lens file at ``path``, naming ``what`` and why."""
    problem = "an empty path" if not value else file_problem(path)
    if problem is not None:
        raise ParameterError(
            f"{what} is neither {THIN_LENS!r}, a lens preset ({', '.join(sorted(LENS_PRESETS))}) "
            f"nor a lens file, TOML or JSON ({problem})"
        )


def lens_record(value: str | LensPrescription) -> str | dict:
    """How a run records a main lens it was given (:func:`lens_option`): ``"thin"`` or the preset's
    name, or a design by its table (:meth:`LensPrescription.to_dict`), never by the path it came from."""
    return value if isinstance(value, str) else value.to_dict()


def lens_option(value: str, *, flag: str = "--lens") -> str | LensPrescription:
    """What a command line's ``--lens`` names: ``"thin"`` or a preset name (returned as it is), else the
    design of an existing lens file (:func:`lfrefract.formats.paramfile.read_lens_file`, unscaled: :func:`main_lens`
    scales and stops it to each camera, so a run records the lens by its table, not its path).

    Raises
    ------
    ParameterError
        If ``value`` is neither, naming ``flag`` and the value.
    FileFormatError
        If the lens file is invalid (naming ``flag``, the file and the key).
    """
    if value == THIN_LENS or value in LENS_PRESETS:
        return value
    _require_lens_file(f"{flag} {value!r}", value, Path(value))
    try:
        return read_lens_file(value)
    except FileFormatError as exc:
        raise FileFormatError(f"{flag}: {exc}") from None


def _camera(table: Any, base_dir: Path) -> tuple[LightFieldCamera, Pose, LensPrescription | None]:
    table = as_table("[camera]", table)
    pose_table = as_table("[camera.pose]", table.pop("pose")) if "pose" in table else {}
    if "position_m" in pose_table:  # the scene's bound first (lfrefract's Pose allows a wider one)
        _position("camera.pose.position_m", pose_table["position_m"])
    pose = Pose.from_dict(pose_table) if pose_table else Pose()
    lens_value = table.pop("lens", THIN_LENS)
    if "preset" in table:
        reject_unknown_keys("camera", table, {"preset"})
        camera = camera_preset(table["preset"])
    else:
        camera = LightFieldCamera.from_dict(table)
    return camera, pose, main_lens(lens_value, camera, base_dir=base_dir)


def _port(table: Any, water: Water | None) -> FlatPort:
    """The ``[port]``; without an ``n_water`` of its own it takes the water's index
    (:func:`apply_water_index`). A stated one is checked against the water once, by
    :class:`SceneConfig`, which also replaces one within :data:`N_WATER_TOLERANCE` by the computed
    index."""
    table = as_table("[port]", table)
    if "n_water" not in table:
        table = apply_water_index(table, water, where="port")
    return FlatPort.from_dict(table)


def parse_scene(data: dict, *, base_dir: Path | str = ".", source: str = "<memory>") -> SceneConfig:
    """Build a :class:`SceneConfig` from parsed TOML data.

    Parameters
    ----------
    data : dict
        The TOML document as a dict.
    base_dir : path-like
        Directory that relative mesh paths are resolved against.
    source : str
        Where the data came from, recorded in the config.

    Raises
    ------
    ParameterError
        For unknown keys, values of the wrong type, missing keys, and values out of their range
        (see the module docstring); the message names the key, and for a type the type it
        needs and the value. With a ``[water]`` index, also for a ``[port]`` ``n_water`` that
        disagrees with it.
    """
    base = Path(base_dir)
    data = as_table("scene", data)
    keys = {"name", "camera", "port", "render", "light", "object", "water", "sensor", "medium"}
    reject_unknown_keys("scene", data, keys)
    if "camera" not in data:
        raise ParameterError("scene: missing [camera] table")
    camera, pose, lens = _camera(data["camera"], base)
    water = Water.from_dict(data["water"]) if "water" in data else None
    port = _port(data["port"], water) if "port" in data else None
    render = _build(RenderSettings, data.get("render", {}), "render", base)
    return SceneConfig(
        water=water,
        name=text("name", data["name"]) if "name" in data else Path(source).stem,
        source=source,
        camera=camera,
        lens=lens,
        pose=pose,
        port=port,
        lights=_typed_entries(data.get("light", []), LIGHT_TYPES, "light", base),
        objects=_typed_entries(data.get("object", []), OBJECT_TYPES, "object", base),
        render=render,
        sensor=sensor_model(data["sensor"], camera) if "sensor" in data else None,
        medium=text("medium", data["medium"]) if "medium" in data else "water",
    )


#: Values that hold no file path (skipped while looking for one).
_NO_PATHS = (bool, int, float, complex, str, bytes, type(None), np.ndarray, np.generic)


def scene_files(config: SceneConfig) -> list[tuple[str, Path]]:
    """Every file path held in ``config`` (where in the config, path), sorted: the files its render
    reads besides the scene file itself (meshes today; any ``Path`` field of a scene type counts)."""
    found: list[tuple[str, Path]] = []
    stack: list[tuple[str, Any]] = [("", config)]  # (a recursive closure would be a reference cycle)
    while stack:
        where, value = stack.pop()
        if isinstance(value, Path):
            found.append((where, value))
        elif dataclasses.is_dataclass(value) and not isinstance(value, type):
            for f in dataclasses.fields(value):
                v = getattr(value, f.name)
                if not isinstance(v, _NO_PATHS):
                    stack.append((f"{where}.{f.name}" if where else f.name, v))
        elif isinstance(value, (list, tuple)):
            stack.extend((f"{where}[{i}]", v) for i, v in enumerate(value) if not isinstance(v, _NO_PATHS))
        elif isinstance(value, Mapping):
            stack.extend((f"{where}.{k}", v) for k, v in value.items() if not isinstance(v, _NO_PATHS))
    return sorted(found)


def load_scene(path: str | Path | None = None) -> SceneConfig:
    """Load a scene TOML file; ``None`` loads the embedded default scene.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ParameterError
        If the file is not valid TOML or describes an invalid scene; every message starts with
        ``scene file '<path>'``, then names the key as the file spells it.
    """
    p = default_scene_path() if path is None else Path(path)
    data = read_toml(p, "scene")  # its errors name the file already
    try:
        return parse_scene(data, base_dir=p.parent, source=str(p))
    except ParameterError as exc:
        raise ParameterError(f"scene file {str(p)!r}: {exc}") from None


def read_toml(path: str | Path, what: str) -> dict:
    """The TOML document at ``path`` as a dict; ``what`` names it in errors ("scene", "rig").

    The file must be a regular file of at most :data:`MAX_TOML_BYTES`, checked before it is
    read (a FIFO would block, a huge file take minutes), and UTF-8 text, as TOML requires.

    Raises
    ------
    FileNotFoundError
        If nothing exists at ``path``.
    ParameterError
        If ``path`` is not a regular file (a directory, a FIFO), is larger than
        :data:`MAX_TOML_BYTES`, cannot be read, is not UTF-8 text (a UTF-16 file, one with a
        byte-order mark, or any other encoding: the message says which byte on which line), or
        is not valid TOML; the message names the file.
    """
    path = Path(path)
    label = f"{what} file"
    if not os.path.lexists(path):
        raise FileNotFoundError(f"{label} {str(path)!r} does not exist")
    regular_file(label, path, max_bytes=MAX_TOML_BYTES)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ParameterError(f"{label} {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    return _parse_toml(data, f"{label} {str(path)!r}")


def _parse_toml(data: bytes, where: str) -> dict:
    """Decode ``data`` as UTF-8 and parse it as TOML; ``where`` names it in errors.

    Raises
    ------
    ParameterError
        If ``data`` is not UTF-8 text (a byte-order mark, NUL bytes, bytes that do not decode)
        or not valid TOML (including integers too long to convert and nesting too deep to parse).
    """
    boms = {
        b"\xef\xbb\xbf": "a UTF-8 byte-order mark",
        b"\xff\xfe": "a UTF-16 byte-order mark",
        b"\xfe\xff": "a UTF-16 byte-order mark",
    }
    for bom, name in boms.items():
        if data.startswith(bom):
            raise ParameterError(
                f"{where} starts with {name}: TOML must be UTF-8 text without one; save it as UTF-8 (no BOM)"
            )
    nul = data.find(b"\0")
    if nul >= 0:  # valid UTF-8, but never in TOML: UTF-16 text (of ASCII characters) or a binary file
        line = data.count(b"\n", 0, nul) + 1
        raise ParameterError(
            f"{where} is not UTF-8 text: it holds NUL bytes (from line {line}), as UTF-16 text or a binary "
            "file does; TOML must be UTF-8, save it as UTF-8"
        )
    try:
        document = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ParameterError(
            f"{where} is not UTF-8 text: byte 0x{data[exc.start]:02x} on line {line} cannot be decoded (another "
            "encoding, such as Latin-1 or UTF-16?); TOML must be UTF-8, save it as UTF-8"
        ) from None
    try:
        return tomllib.loads(document)
    except ValueError as exc:  # TOMLDecodeError, or an integer of more than 4300 digits
        raise ParameterError(f"{where} is not valid TOML: {exc}") from None
    except RecursionError:
        raise ParameterError(f"{where} nests arrays or tables too deeply to be read") from None


def scenes_dir() -> Path:
    """The directory of embedded scenes: ``scenes/`` of a source tree, or its copy in a wheel."""
    here = Path(__file__).resolve().parent
    for candidate in (here.parent / "scenes", here / "scenes"):
        if (candidate / "default.toml").is_file():
            return candidate
    raise FileNotFoundError(f"no embedded scenes found beside {str(here)!r}")


def embedded_scenes() -> dict[str, Path]:
    """Embedded scene names (file stems) and their files."""
    return {p.stem: p for p in sorted(scenes_dir().glob("*.toml"))}


def default_scene_path() -> Path:
    """Path of the embedded default scene (``scenes/default.toml``)."""
    return scenes_dir() / "default.toml"
