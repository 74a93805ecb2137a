"""Rigid camera poses.

A :class:`Pose` maps camera-frame points (OpenCV frame, metres) to world-frame points:
``X_world = R @ X_cam + t``, where ``t`` is the camera centre (main-lens centre) in the world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.validate import as_points, finite_vector, reject_unknown_keys

__all__ = ["Pose", "rotation_from_euler_xyz"]


def rotation_from_euler_xyz(angles_rad: tuple[float, float, float]) -> np.ndarray:
    """Rotation matrix (3, 3) for extrinsic rotations about x, then y, then z (radians).

    ``R = R_z(c) @ R_y(b) @ R_x(a)`` for ``angles_rad = (a, b, c)``.
    """
    a, b, c = angles_rad
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return rz @ ry @ rx


#: Largest camera or board coordinate, metres: far beyond any tank or underwater visibility.
MAX_POSITION_M = 1e4


@dataclass(frozen=True, kw_only=True)
class Pose:
    """Camera-to-world rigid transform.

    Parameters
    ----------
    rotation : tuple of tuple of float
        Row-major 3x3 rotation matrix ``R`` (world from camera), orthonormal with det +1.
    position_m : tuple of float
        Camera centre in the world frame, metres.
    """

    rotation: tuple[tuple[float, float, float], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        try:
            rows = np.asarray(self.rotation, dtype=np.float64)
        except (TypeError, ValueError):  # strings or ragged rows: not a matrix of numbers
            raise ParameterError(f"pose.rotation must be a finite 3x3 matrix, got {self.rotation!r}") from None
        if rows.shape != (3, 3) or not np.all(np.isfinite(rows)):
            raise ParameterError(f"pose.rotation must be a finite 3x3 matrix, got {self.rotation!r}")
        if not np.allclose(rows @ rows.T, np.eye(3), atol=1e-9) or np.linalg.det(rows) < 0:
            raise ParameterError(f"pose.rotation must be a proper rotation, got {rows.round(6).tolist()}")
        object.__setattr__(self, "rotation", tuple(tuple(float(v) for v in r) for r in rows))
        position = finite_vector("pose.position_m", self.position_m, 3)
        if max(abs(v) for v in position) > MAX_POSITION_M:
            raise ParameterError(f"pose.position_m must lie within +-{MAX_POSITION_M:g} m, got {self.position_m!r}")
        object.__setattr__(self, "position_m", position)

    @classmethod
    def from_euler_xyz_deg(cls, rotation_xyz_deg=(0.0, 0.0, 0.0), position_m=(0.0, 0.0, 0.0)) -> Pose:
        """Pose from extrinsic x-y-z Euler angles in degrees (the config-file form)."""
        angles = finite_vector("pose.rotation_xyz_deg", rotation_xyz_deg, 3)
        rx, ry, rz = (math.radians(a) for a in angles)
        rows = rotation_from_euler_xyz((rx, ry, rz))
        rotation = tuple((float(r[0]), float(r[1]), float(r[2])) for r in rows)
        return cls(rotation=rotation, position_m=position_m)

    @classmethod
    def from_dict(cls, data: dict) -> Pose:
        """Build from ``{"rotation_xyz_deg": [...], "position_m": [...]}`` or ``{"rotation": ...}``."""
        if not isinstance(data, dict):
            raise ParameterError(f"pose must be a table (a JSON object), got {data!r}")
        if "rotation" in data:
            reject_unknown_keys("pose", data, {"rotation", "position_m"})
            return cls(**data)  # __post_init__ checks and converts both
        reject_unknown_keys("pose", data, {"rotation_xyz_deg", "position_m"})
        return cls.from_euler_xyz_deg(**data)

    def to_dict(self) -> dict:
        """Plain-data form for JSON sidecars."""
        return {"rotation": [list(r) for r in self.rotation], "position_m": list(self.position_m)}

    @property
    def matrix(self) -> np.ndarray:
        """Homogeneous 4x4 camera-to-world matrix."""
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.position_m
        return m

    def to_world(self, points_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) to world-frame points (N, 3)."""
        return as_points("points_cam", points_cam, 3) @ np.asarray(self.rotation).T + np.asarray(self.position_m)

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """World-frame points (N, 3) to camera-frame points (N, 3)."""
        return (as_points("points_world", points_world, 3) - np.asarray(self.position_m)) @ np.asarray(self.rotation)
