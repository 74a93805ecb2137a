"""Stereo rigs: light-field cameras behind one flat tank wall, rendered together with ground truth.

A rig file (TOML, ``scenes/rigs/``) holds a ``[wall]``, two or more ``[[camera]]`` tables and the
usual ``[render]``, ``[[light]]`` and ``[[object]]`` tables of a scene. Everything is in one world
frame (metres, OpenCV axes). The wall is a glass slab: its air-side face is the plane
``normal . X = distance_m`` (``normal`` a unit vector pointing into the water) and its water-side
face lies ``thickness_m`` further along the normal. Each camera has a ``preset`` (or ``optics``, a
camera table as :meth:`lfrefract.LightFieldCamera.from_dict` reads it) and a pose
(``position_m``, ``rotation_xyz_deg``: camera to world); its port is the wall seen from that camera
(:meth:`Wall.port_for`), so the cameras may be slanted against the wall and each sees its own
tilted port, from the one wall.

An optional ``[water]`` table (:class:`simulator.config.Water`) describes the one water behind the
wall for every camera: its salinity and temperature set the wall's ``n_water`` (a ``[wall]`` that
also states ``n_water`` must agree, as a scene's ``[port]`` must), and its turbidity fills the
water of every camera's scene.

This module reads rigs; :mod:`simulator.rig_render` renders them: ``lfsim rig [RIG] --out DIR``
renders every camera into ``DIR/<name>/`` (the capture folders of ``lfsim render``) and writes
``DIR/meta.json`` with the wall, each camera's pose and port, and the stereo ground truth: the
pose of every camera relative to the first (``X_cam = R X_first + t``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfrefract import FlatPort, ParameterError, Pose
from lfrefract.validate import as_table, finite_vector, positive_float, reject_unknown_keys, require_keys, text
from simulator.config import SceneConfig, Water, apply_water_index, parse_scene, read_toml, scenes_dir

__all__ = ["RigCamera", "RigConfig", "Wall", "embedded_rigs", "load_rig", "parse_rig"]

_WALL_KEYS = {"normal", "distance_m", "thickness_m", "n_air", "n_glass", "n_water"}


@dataclass(frozen=True, kw_only=True)
class Wall:
    """A flat glass wall, world frame.

    Attributes
    ----------
    normal : tuple of float
        Unit normal pointing into the water (normalised on construction; must be non-zero).
    distance_m : float
        The air-side face is the plane ``normal . X = distance_m``, metres.
    thickness_m, n_air, n_glass, n_water : float
        Glass thickness (metres) and refractive indices, as :class:`lfrefract.FlatPort`.
    """

    normal: tuple[float, float, float]
    distance_m: float
    thickness_m: float
    n_air: float = 1.0
    n_glass: float = 1.5
    n_water: float = 1.333

    def __post_init__(self) -> None:
        n = np.asarray(finite_vector("wall.normal", self.normal, 3))
        if np.linalg.norm(n) == 0.0:
            raise ParameterError(f"wall.normal must be non-zero, got {self.normal!r}")
        object.__setattr__(self, "normal", tuple(float(v) for v in n / np.linalg.norm(n)))
        positive_float("wall.thickness_m", self.thickness_m)
        finite_vector("wall.distance_m", [self.distance_m], 1)

    def port_for(self, pose: Pose) -> FlatPort:
        """The wall as the port of a camera at ``pose`` (camera to world), in that camera's frame.

        Raises
        ------
        ParameterError
            If the camera is not on the air side of the wall, or looks at it edge-on or away
            from it (the port's normal must have a positive z in the camera frame).
        """
        rotation = np.asarray(pose.rotation)
        normal_cam = rotation.T @ np.asarray(self.normal)
        distance = self.distance_m - float(np.asarray(self.normal) @ np.asarray(pose.position_m))
        if distance <= 0.0:
            raise ParameterError(
                f"camera at position_m={list(pose.position_m)} is {-distance * 1e3:.4g} mm on the water side "
                "of the wall (it must be on the air side)"
            )
        return FlatPort.from_normal(
            normal_cam,
            distance_m=distance,
            thickness_m=self.thickness_m,
            n_air=self.n_air,
            n_glass=self.n_glass,
            n_water=self.n_water,
        )

    def to_dict(self) -> dict:
        """Plain data (the TOML table's keys)."""
        return {
            "normal": list(self.normal),
            "distance_m": self.distance_m,
            "thickness_m": self.thickness_m,
            "n_air": self.n_air,
            "n_glass": self.n_glass,
            "n_water": self.n_water,
        }


@dataclass(frozen=True)
class RigCamera:
    """One camera of a rig: its name (the output folder) and its whole scene (pose, port)."""

    name: str
    scene: SceneConfig


@dataclass(frozen=True, kw_only=True)
class RigConfig:
    """A stereo rig: cameras behind one wall, sharing lights, objects, render settings and water."""

    name: str
    wall: Wall
    cameras: tuple[RigCamera, ...]
    water: Water | None = None
    source: str = "<memory>"

    def relative_pose(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Rotation (3, 3) and translation (3,), metres, of camera ``index`` relative to the first:
        ``X_cam = R @ X_first + t`` (the convention of :class:`lfrefract.stereo.geometry.StereoCalibration`)."""
        first, other = self.cameras[0].scene.pose, self.cameras[index].scene.pose
        r0, r1 = np.asarray(first.rotation), np.asarray(other.rotation)
        rotation = r1.T @ r0
        translation = r1.T @ (np.asarray(first.position_m) - np.asarray(other.position_m))
        return rotation, translation


def parse_rig(data: dict, *, base_dir: Path | str = ".", source: str = "<memory>") -> RigConfig:
    """Build a :class:`RigConfig` from parsed TOML data (see the module docstring).

    Raises
    ------
    ParameterError
        For unknown or missing keys, fewer than two cameras, repeated camera names, a camera on
        the water side of the wall, a ``[wall]`` ``n_water`` that disagrees with ``[water]``, and
        anything :func:`simulator.config.parse_scene` rejects.
    """
    reject_unknown_keys("rig", data, {"name", "wall", "camera", "render", "light", "object", "water"})
    require_keys("rig", data, {"wall", "camera"})
    water = Water.from_dict(data["water"]) if "water" in data else None
    rig_name = text("name", data["name"]) if "name" in data else Path(source).stem
    wall_table = as_table("[wall]", data["wall"])
    reject_unknown_keys("wall", wall_table, _WALL_KEYS)
    require_keys("wall", wall_table, {"normal", "distance_m", "thickness_m"})
    wall = Wall(**apply_water_index(wall_table, water, where="wall"))
    tables = data["camera"]
    if not isinstance(tables, list) or len(tables) < 2:
        raise ParameterError(f"a rig needs at least two [[camera]] tables, got {tables!r}")
    cameras, names = [], set()
    for i, table in enumerate(tables):
        table = as_table(f"camera[{i}]", table)
        reject_unknown_keys(f"camera[{i}]", table, {"name", "preset", "optics", "position_m", "rotation_xyz_deg"})
        require_keys(f"camera[{i}]", table, {"name"})
        if ("preset" in table) == ("optics" in table):
            raise ParameterError(f"camera[{i}] needs either preset or optics (a camera table), not both or neither")
        name = text(f"camera[{i}].name", table["name"])
        if not name or not name.replace("-", "").replace("_", "").isalnum() or name in names:
            raise ParameterError(f"camera[{i}].name must be a unique plain name (letters, digits, - _), got {name!r}")
        names.add(name)
        pose = Pose.from_euler_xyz_deg(
            table.get("rotation_xyz_deg", (0.0, 0.0, 0.0)), table.get("position_m", (0.0, 0.0, 0.0))
        )
        try:
            port = wall.port_for(pose)
        except ParameterError as exc:
            raise ParameterError(f"camera[{i}] ({name!r}): {exc}") from None
        scene_data = {
            "name": f"{rig_name}-{name}",
            "camera": {
                **(
                    {"preset": table["preset"]}
                    if "preset" in table
                    else as_table(f"camera[{i}].optics", table["optics"])
                ),
                "pose": pose.to_dict(),
            },
            "port": port.to_dict(),
            **{key: data[key] for key in ("render", "light", "object", "water") if key in data},
        }
        cameras.append(RigCamera(name=name, scene=parse_scene(scene_data, base_dir=base_dir, source=source)))
    name = rig_name
    return RigConfig(name=name, wall=wall, cameras=tuple(cameras), water=water, source=source)


def rigs_dir() -> Path:
    """The directory of embedded rigs (``scenes/rigs/``)."""
    return scenes_dir() / "rigs"


def embedded_rigs() -> dict[str, Path]:
    """Embedded rig names (file stems) and their files."""
    return {p.stem: p for p in sorted(rigs_dir().glob("*.toml"))}


def load_rig(path: str | Path | None = None) -> RigConfig:
    """Load a rig TOML file, or an embedded rig by name; ``None`` loads the embedded ``default``.

    Raises
    ------
    FileNotFoundError
        If there is no such file or embedded rig.
    ParameterError
        If the file is not valid TOML or describes an invalid rig; every message starts with
        ``rig file '<path>'``, then names the key as the file spells it.
    """
    if path is None or (not Path(path).exists() and str(path) in embedded_rigs()):
        path = embedded_rigs()["default" if path is None else str(path)]
    p = Path(path)
    if not p.exists():  # a directory or FIFO is refused by read_toml, by its kind
        raise FileNotFoundError(f"rig file {str(p)!r} does not exist (embedded rigs: {sorted(embedded_rigs())})")
    data = read_toml(p, "rig")  # its errors name the file already
    try:
        return parse_rig(data, base_dir=p.parent, source=str(p))
    except ParameterError as exc:
        raise ParameterError(f"rig file {str(p)!r}: {exc}") from None
