"""The flat refractive port (a glass window into water) and exact vector refraction through it.

Port geometry, in the camera frame (metres):

* The unit normal ``n`` points from the camera into the water. It is chosen by two tilt angles,
  applied as a rotation about the camera x axis and then about the y axis::

      n = R_y(tilt_y) @ R_x(tilt_x) @ (0, 0, 1)
        = (sin(tilt_y) cos(tilt_x), -sin(tilt_x), cos(tilt_y) cos(tilt_x))

  so a positive ``tilt_x`` turns the normal up (towards -y, the top of the image) and a
  positive ``tilt_y`` turns it right (+x). The total tilt is ``arccos(n_z)``.
* The air-side face of the glass is the plane ``{X : n . X = d}``, ``d > 0`` the perpendicular
  distance from the main-lens centre; the water-side face is ``{X : n . X = d + t}``.
  ``t = 0`` is a single air/water interface.

Refraction follows Snell's law in vector form. Total internal reflection (TIR) and rays that
never reach the port are reported in masks, never dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lfrefract._validate import (
    ParameterError,
    as_points,
    finite_float,
    finite_vector,
    non_negative_float,
    positive_float,
    reject_unknown_keys,
    require_keys,
)

__all__ = ["FlatPort", "PortTrace", "fresnel_transmittance", "refract"]


def refract(directions: np.ndarray, normals: np.ndarray, n_from: float, n_to: float) -> tuple[np.ndarray, np.ndarray]:
    """Refract unit directions at an interface (Snell's law, vector form).

    Parameters
    ----------
    directions : ndarray, shape (N, 3)
        Unit directions of travel.
    normals : ndarray, shape (3,) or (N, 3)
        Unit interface normals oriented along the travel, ``normals . directions >= 0``.
    n_from, n_to : float
        Refractive indices before and after the interface.

    Returns
    -------
    refracted : ndarray, shape (N, 3)
        Unit refracted directions; NaN where TIR occurs.
    tir : ndarray of bool, shape (N,)
        True where the ray is totally internally reflected.
    """
    d = np.asarray(directions, dtype=np.float64)
    nrm = np.broadcast_to(np.asarray(normals, dtype=np.float64), d.shape)
    cos_i = np.sum(d * nrm, axis=1)
    if np.any(cos_i < -1e-12):
        raise ParameterError(
            f"normals must be oriented along the travel (normals . directions >= 0), got {float(cos_i.min())!r}"
        )
    return _refract(d, nrm, cos_i, n_from / n_to)


def _refract(d: np.ndarray, nrm: np.ndarray, cos_i: np.ndarray, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """Snell's law for unit ``d`` (N, 3), normals ``nrm`` along the travel, ``eta = n_from / n_to``."""
    sin2_t = eta**2 * np.maximum(0.0, 1.0 - cos_i**2)
    tir = sin2_t > 1.0
    cos_t = np.sqrt(np.where(tir, np.nan, 1.0 - sin2_t))
    out = eta * d + (cos_t - eta * cos_i)[:, None] * nrm
    return out, tir


def fresnel_transmittance(cos_i: np.ndarray, n_from: float, n_to: float) -> np.ndarray:
    """Unpolarised Fresnel power transmittance at a smooth interface, shape (N,); 0 under TIR."""
    cos_i = np.abs(np.asarray(cos_i, dtype=np.float64))
    if n_from == n_to:
        return np.ones_like(cos_i)
    eta = n_from / n_to
    sin2_t = eta**2 * (1.0 - cos_i**2)
    ok = sin2_t <= 1.0
    cos_t = np.sqrt(np.where(ok, 1.0 - sin2_t, 0.0))
    rs = ((n_from * cos_i - n_to * cos_t) / (n_from * cos_i + n_to * cos_t)) ** 2
    rp = ((n_from * cos_t - n_to * cos_i) / (n_from * cos_t + n_to * cos_i)) ** 2
    return np.where(ok, 1.0 - 0.5 * (rs + rp), 0.0)


@dataclass(frozen=True)
class PortTrace:
    """Result of tracing rays through the port, camera frame, metres.

    Attributes
    ----------
    entry_points_cam : ndarray, shape (N, 3)
        Where each ray meets the first face it crosses.
    exit_points_cam : ndarray, shape (N, 3)
        Where it leaves the last face (equal to ``entry_points_cam`` for a single interface).
    directions_cam : ndarray, shape (N, 3)
        Unit directions after the last face.
    transmittance : ndarray, shape (N,)
        Product of the unpolarised Fresnel transmittances of the faces (0 where invalid).
    misses : ndarray of bool, shape (N,)
        The ray travels parallel to or away from the port and never reaches it.
    tir : ndarray of bool, shape (N,)
        The ray is totally internally reflected at some face.

    Invalid rays (``misses | tir``) have NaN points and directions.
    """

    entry_points_cam: np.ndarray
    exit_points_cam: np.ndarray
    directions_cam: np.ndarray
    transmittance: np.ndarray
    misses: np.ndarray
    tir: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """Rays that crossed every face, shape (N,)."""
        return ~(self.misses | self.tir)


@dataclass(frozen=True, kw_only=True)
class FlatPort:
    """A flat port: a glass slab of thickness t between air (camera side) and water.

    Parameters
    ----------
    distance_m : float
        Perpendicular distance d from the main-lens centre to the air-side face, metres (> 0).
    thickness_m : float
        Glass thickness t, metres (>= 0; 0 is a single air/water interface).
    tilt_x_rad, tilt_y_rad : float
        Tilt of the normal about the camera x and y axes, radians (see module docstring).
    n_air, n_glass, n_water : float
        Refractive indices (> 0).

    Raises
    ------
    ParameterError
        For non-finite values, a non-positive distance or index, negative thickness, or a tilt
        that puts the port behind the camera (``n_z <= 0``).
    """

    distance_m: float
    thickness_m: float = 0.0
    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0
    n_air: float = 1.0
    n_glass: float = 1.5
    n_water: float = 1.333

    def __post_init__(self) -> None:
        positive_float("port.distance_m", self.distance_m)
        non_negative_float("port.thickness_m", self.thickness_m)
        finite_float("port.tilt_x_rad", self.tilt_x_rad)
        finite_float("port.tilt_y_rad", self.tilt_y_rad)
        for name in ("n_air", "n_glass", "n_water"):
            positive_float(f"port.{name}", getattr(self, name))
        if self.normal[2] <= 1e-9:
            raise ParameterError(
                f"port tilt (tilt_x_rad={self.tilt_x_rad!r}, tilt_y_rad={self.tilt_y_rad!r}) makes the "
                f"normal {self.normal.round(6).tolist()} point away from the view: the port would be "
                "behind the camera"
            )

    @classmethod
    def from_degrees(
        cls,
        *,
        distance_m: float,
        thickness_m: float = 0.0,
        tilt_x_deg: float = 0.0,
        tilt_y_deg: float = 0.0,
        n_air: float = 1.0,
        n_glass: float = 1.5,
        n_water: float = 1.333,
    ) -> FlatPort:
        """Build a port from tilt angles in degrees (the config-file form)."""
        return cls(
            distance_m=distance_m,
            thickness_m=thickness_m,
            tilt_x_rad=math.radians(finite_float("port.tilt_x_deg", tilt_x_deg)),
            tilt_y_rad=math.radians(finite_float("port.tilt_y_deg", tilt_y_deg)),
            n_air=n_air,
            n_glass=n_glass,
            n_water=n_water,
        )

    @classmethod
    def from_normal(cls, normal: np.ndarray, *, distance_m: float, **kwargs: float) -> FlatPort:
        """Build a port from a (not necessarily unit) normal pointing into the water."""
        n = np.asarray(normal, dtype=np.float64).reshape(-1)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0.0:
            raise ParameterError(f"normal must be a finite non-zero 3-vector, got {normal!r}")
        n = n / np.linalg.norm(n)
        if n[2] <= 0.0:
            raise ParameterError(f"normal={n.round(6).tolist()} points towards the camera (n_z <= 0)")
        return cls(
            distance_m=distance_m,
            tilt_x_rad=-math.asin(float(n[1])),
            tilt_y_rad=math.atan2(float(n[0]), float(n[2])),
            **kwargs,
        )

    @classmethod
    def from_dict(cls, data: dict) -> FlatPort:
        """Build from plain data in either radian or ``_deg`` form; unknown keys are an error.

        Accepts the output of :meth:`to_dict`: its derived ``normal`` and ``total_tilt_deg`` must
        then agree with the tilt angles.
        """
        data = dict(data)
        derived = {k: data.pop(k) for k in ("normal", "total_tilt_deg") if k in data}
        require_keys("port", data, {"distance_m"})
        keys = {"distance_m", "thickness_m", "n_air", "n_glass", "n_water"}
        if any(k.endswith("_deg") for k in data):
            reject_unknown_keys("port", data, keys | {"tilt_x_deg", "tilt_y_deg"})
            port = cls.from_degrees(**data)
        else:
            reject_unknown_keys("port", data, keys | {"tilt_x_rad", "tilt_y_rad"})
            port = cls(**data)
        if "normal" in derived:
            normal = finite_vector("port.normal", derived["normal"], 3)
            if not np.allclose(port.normal, normal, atol=1e-9):
                raise ParameterError(
                    f"port.normal={list(normal)} disagrees with the tilt angles ({port.normal.tolist()})"
                )
        if "total_tilt_deg" in derived:
            tilt = finite_float("port.total_tilt_deg", derived["total_tilt_deg"])
            if not math.isclose(tilt, math.degrees(port.total_tilt_rad), abs_tol=1e-9):
                raise ParameterError(
                    f"port.total_tilt_deg={tilt!r} disagrees with the tilt angles "
                    f"({math.degrees(port.total_tilt_rad)!r})"
                )
        return port

    def to_dict(self) -> dict:
        """Plain-data form for JSON sidecars, with the derived normal and tilt."""
        return {
            "distance_m": self.distance_m,
            "thickness_m": self.thickness_m,
            "tilt_x_rad": self.tilt_x_rad,
            "tilt_y_rad": self.tilt_y_rad,
            "n_air": self.n_air,
            "n_glass": self.n_glass,
            "n_water": self.n_water,
            "normal": self.normal.tolist(),
            "total_tilt_deg": math.degrees(self.total_tilt_rad),
        }

    # ----------------------------------------------------------------- geometry
    @property
    def normal(self) -> np.ndarray:
        """Unit normal (3,), camera frame, pointing into the water."""
        cx, sx = math.cos(self.tilt_x_rad), math.sin(self.tilt_x_rad)
        cy, sy = math.cos(self.tilt_y_rad), math.sin(self.tilt_y_rad)
        return np.array([sy * cx, -sx, cy * cx])

    @property
    def total_tilt_rad(self) -> float:
        """Angle between the normal and the optical axis, radians."""
        return math.acos(min(1.0, float(self.normal[2])))

    @property
    def plane(self) -> tuple[np.ndarray, float]:
        """The air-side face as ``(n, d)`` with ``n . X = d``."""
        return self.normal, self.distance_m

    @property
    def faces(self) -> list[tuple[float, float, float]]:
        """Faces from the camera outwards as ``(offset d_i, n before, n after)``."""
        if self.thickness_m == 0.0:
            return [(self.distance_m, self.n_air, self.n_water)]
        return [
            (self.distance_m, self.n_air, self.n_glass),
            (self.distance_m + self.thickness_m, self.n_glass, self.n_water),
        ]

    @property
    def radiance_scale(self) -> float:
        """Factor ``(n_air / n_water)^2`` by which radiance changes from water to air.

        Together with the Fresnel :attr:`PortTrace.transmittance` it relates the radiance a
        camera in air records to the radiance in the water along the same light path.
        """
        return (self.n_air / self.n_water) ** 2

    def clearance_m(self, aperture_radius_m: float) -> float:
        """Smallest distance along z between the lens aperture disc and the air-side face."""
        n = self.normal
        reach = positive_float("aperture_radius_m", aperture_radius_m) * math.hypot(n[0], n[1])
        return (self.distance_m - reach) / n[2]

    # ----------------------------------------------------------------- tracing
    def trace_from_air(self, origins_cam: np.ndarray, directions_cam: np.ndarray) -> PortTrace:
        """Trace rays that start on the camera side out through the port into the water.

        Parameters
        ----------
        origins_cam : array_like, shape (N, 3)
            Ray origins, camera frame, metres, on the camera side of the port.
        directions_cam : array_like, shape (N, 3)
            Unit directions, camera frame.

        Returns
        -------
        PortTrace
            ``directions_cam`` are the water-side directions; ``exit_points_cam`` lie on the water face.
        """
        return self._trace(origins_cam, directions_cam, into_water=True)

    def trace_from_water(self, points_cam: np.ndarray, directions_cam: np.ndarray) -> PortTrace:
        """Trace light that travels from the water towards the camera back into the air.

        Parameters
        ----------
        points_cam : array_like, shape (N, 3)
            Points in the water (or on the water-side face), camera frame, metres.
        directions_cam : array_like, shape (N, 3)
            Unit directions of travel, camera frame, towards the port (``n . d < 0``).

        Returns
        -------
        PortTrace
            ``directions_cam`` are the air-side directions; ``exit_points_cam`` lie on the air face.
        """
        return self._trace(points_cam, directions_cam, into_water=False)

    def _trace(self, origins_cam: np.ndarray, directions_cam: np.ndarray, *, into_water: bool) -> PortTrace:
        o = as_points("origins_cam", origins_cam, 3)
        d = as_points("directions_cam", directions_cam, 3)
        if o.shape != d.shape:
            raise ParameterError(
                f"origins_cam and directions_cam must have the same shape, got {o.shape} and {d.shape}"
            )
        norms = np.linalg.norm(d, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-6):
            worst = float(norms[np.argmax(np.abs(norms - 1.0))])
            raise ParameterError(f"directions_cam must be unit vectors, got a norm of {worst!r}")
        n = self.normal
        faces = self.faces if into_water else [(off, b, a) for off, a, b in reversed(self.faces)]
        travel_normal = n if into_water else -n
        cos0 = d @ travel_normal
        misses = cos0 <= 0.0
        # A ray that already lies past the first face also misses it.
        start = (o @ n) - faces[0][0]
        misses |= (start > 1e-12) if into_water else (start < -1e-12)
        tir = np.zeros(o.shape[0], dtype=bool)
        transmittance = np.ones(o.shape[0])
        point, direction = o.copy(), d.copy()
        entry = None
        with np.errstate(invalid="ignore", divide="ignore"):
            for offset, n_from, n_to in faces:
                t = (offset - point @ n) / (direction @ n)
                point = point + t[:, None] * direction
                if entry is None:
                    entry = point.copy()
                cos_i = direction @ travel_normal
                transmittance *= fresnel_transmittance(cos_i, n_from, n_to)
                direction, tir_here = _refract(direction, travel_normal, cos_i, n_from / n_to)
                tir |= tir_here
        bad = misses | tir
        for arr in (entry, point, direction):
            arr[bad] = np.nan
        transmittance[bad] = 0.0
        return PortTrace(
            entry_points_cam=entry,
            exit_points_cam=point,
            directions_cam=direction,
            transmittance=transmittance,
            misses=misses,
            tir=tir & ~misses,
        )
