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
never reach the port are reported in masks, never dropped. A ray that meets a face it must cross
at a cosine below :data:`GRAZING_COS_MIN` counts as never reaching it (see there): no ray whose
mask says valid carries a NaN or infinite point or direction.

Accepted parameter ranges (anything else is a :class:`~lfrefract.validate.ParameterError`):
refractive indices in [:data:`N_MIN`, :data:`N_MAX`], distance in (0, :data:`MAX_DISTANCE_M`],
thickness in [0, :data:`MAX_THICKNESS_M`], each tilt angle in (-pi/2, pi/2) with ``n_z > 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.validate import (
    as_points,
    finite_float,
    finite_vector,
    non_negative_float,
    positive_float,
    reject_unknown_keys,
    require_keys,
    shown,
)

__all__ = [
    "GRAZING_COS_MIN",
    "MAX_DISTANCE_M",
    "MAX_THICKNESS_M",
    "N_MAX",
    "N_MIN",
    "FlatPort",
    "PortTrace",
    "fresnel_transmittance",
    "refract",
]

#: Smallest and largest refractive index accepted (absolute, i.e. relative to vacuum; air is
#: 1.0003, so indices relative to air are the same to 3e-4). Every transparent medium has a phase
#: index of at least 1 at optical wavelengths; the largest of real window and immersion media are
#: diamond 2.42, rutile 2.9 and, in the infrared, silicon 3.4 and germanium 4.0. Five leaves a
#: margin above all of them while keeping every index ratio within [0.2, 5], so the squares and
#: products of the Snell and Fresnel terms stay within a factor 25 of 1 (an index of 1e300
#: overflowed them). Below 1 a medium would be faster than light in vacuum: a typo (0.133 for
#: 1.33) or an index relative to another medium, which this model does not take.
N_MIN = 1.0
N_MAX = 5.0

#: Largest perpendicular distance from the main-lens centre to the air-side face, metres. A
#: camera housing's port is millimetres to centimetres away, a camera behind an aquarium wall a
#: few metres; 100 m is beyond any window one looks through and keeps every hit point of a trace
#: (distance / cos, cos >= GRAZING_COS_MIN) below 1e8 m, far inside float64 and float32 range.
MAX_DISTANCE_M = 100.0

#: Smallest z component of the port's unit normal: a port closer to edge-on than that (tilt within
#: 6e-8 deg of 90) does not face the camera.
_MIN_NORMAL_Z = 1e-9

#: Largest glass thickness, metres. Port glass is millimetres thick; the thickest windows built
#: (acrylic aquarium panels) are under 0.8 m.
MAX_THICKNESS_M = 1.0

#: Smallest cosine between a ray and the normal of a face it must cross for the ray to count as
#: reaching it. The hit distance ``h / cos`` (``h`` the gap to the face) is computed from a cosine
#: that carries an absolute round-off of a few 1e-16 (a dot product of unit vectors), i.e. a
#: relative error of about ``1e-16 / cos`` in the hit distance and in the hit point's position
#: along the face: at 1e-6 that is ~1e-10 of the distance travelled, while closer to grazing it
#: grows without bound (at cos = 1e-10 the old trace gave infinite exit points: the refracted
#: cosine rounded to 0). Physically such rays carry next to nothing (at an interface of different
#: media the Fresnel transmittance vanishes linearly in cos: 6e-6 from air into glass at 1e-6)
#: and would cross a 5 cm gap 50 km from where they started. Rays refracted into the glass within
#: ``GRAZING_COS_MIN**2 / 2`` (5e-13) of the critical sine are caught by it at the second face.
#: (Refraction near the critical angle is ill-conditioned in itself: a refracted cosine ``c_t``
#: inherits a relative error of about ``1e-16 (n1 / n2)^2 / c_t^2`` from the rounding of the
#: incoming direction, whatever the algorithm; such rays are valid and finite, not exact.)
GRAZING_COS_MIN = 1e-6


def _index(name: str, value: float) -> float:
    """Return ``value`` as a float, or raise unless it is a refractive index in [N_MIN, N_MAX]."""
    out = finite_float(name, value)
    if not N_MIN <= out <= N_MAX:
        raise ParameterError(
            f"{name}={value!r} is not the refractive index of a real medium (accepted: {N_MIN} to {N_MAX})"
        )
    return out


def refract(directions: np.ndarray, normals: np.ndarray, n_from: float, n_to: float) -> tuple[np.ndarray, np.ndarray]:
    """Refract unit directions at an interface (Snell's law, vector form).

    Parameters
    ----------
    directions : ndarray, shape (N, 3)
        Unit directions of travel.
    normals : ndarray, shape (3,) or (N, 3)
        Unit interface normals oriented along the travel, ``normals . directions >= 0``.
    n_from, n_to : float
        Refractive indices before and after the interface, in [:data:`N_MIN`, :data:`N_MAX`].

    Returns
    -------
    refracted : ndarray, shape (N, 3)
        Unit refracted directions; NaN where TIR occurs.
    tir : ndarray of bool, shape (N,)
        True where the ray is totally internally reflected.

    Raises
    ------
    ParameterError
        For an index outside the accepted range or a direction against the normal.
    """
    n_from = _index("n_from", n_from)
    n_to = _index("n_to", n_to)
    d = np.asarray(directions, dtype=np.float64)
    nrm = np.broadcast_to(np.asarray(normals, dtype=np.float64), d.shape)
    cos_i = np.sum(d * nrm, axis=1)
    if np.any(cos_i < -1e-12):
        raise ParameterError(
            f"normals must be oriented along the travel (normals . directions >= 0), got {float(cos_i.min())!r}"
        )
    return _refract(d, nrm, cos_i, n_from / n_to)


def _cos2_transmitted(cos_i: np.ndarray, eta: float) -> np.ndarray:
    """``cos^2`` of the refraction angle, ``1 - eta^2 (1 - cos_i^2)``, negative under TIR.

    Written as ``(1 - eta)(1 + eta) + (eta cos_i)^2`` so that it keeps its relative precision
    near grazing incidence: the textbook form loses ``cos_i^2`` against 1 (at ``eta = 1`` and
    ``cos_i = 1e-10`` it gave exactly 0, a refracted ray along the face).
    """
    return (1.0 - eta) * (1.0 + eta) + (eta * cos_i) ** 2


def _refract(d: np.ndarray, nrm: np.ndarray, cos_i: np.ndarray, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """Snell's law for unit ``d`` (N, 3), normals ``nrm`` along the travel, ``eta = n_from / n_to``."""
    cos2_t = _cos2_transmitted(cos_i, eta)
    tir = cos2_t < 0.0
    cos_t = np.sqrt(np.where(tir, np.nan, cos2_t))
    out = eta * d + (cos_t - eta * cos_i)[:, None] * nrm
    return out, tir


def fresnel_transmittance(cos_i: np.ndarray, n_from: float, n_to: float) -> np.ndarray:
    """Unpolarised Fresnel power transmittance at a smooth interface; 0 under TIR.

    Parameters
    ----------
    cos_i : array_like, shape (N,)
        Cosines of the angle of incidence (the sign is ignored), in [-1, 1].
    n_from, n_to : float
        Refractive indices before and after the interface, in [:data:`N_MIN`, :data:`N_MAX`].

    Returns
    -------
    ndarray, shape (N,)
        Transmitted fraction of the power, in [0, 1].

    Raises
    ------
    ParameterError
        For an index outside the accepted range or a cosine that is not finite or beyond 1.
    """
    n_from = _index("n_from", n_from)
    n_to = _index("n_to", n_to)
    cos_i = np.asarray(cos_i, dtype=np.float64)
    bad = ~(np.abs(cos_i) <= 1.0 + 1e-12)  # round-off of a dot product of unit vectors; catches NaN
    if np.any(bad):
        raise ParameterError(f"cos_i must be finite cosines in [-1, 1], got {float(cos_i[bad].ravel()[0])!r}")
    return _fresnel(cos_i, n_from, n_to)


def _fresnel(cos_i: np.ndarray, n_from: float, n_to: float) -> np.ndarray:
    """:func:`fresnel_transmittance` without the checks (NaN in, NaN out)."""
    cos_i = np.minimum(np.abs(cos_i), 1.0)
    if n_from == n_to:
        return np.ones_like(cos_i)
    cos2_t = _cos2_transmitted(cos_i, n_from / n_to)
    ok = cos2_t >= 0.0
    cos_t = np.sqrt(np.where(ok, cos2_t, 0.0))
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
        The ray never reaches a face it must cross: it starts past the first face, travels
        parallel to or away from a face, or meets it at a cosine below :data:`GRAZING_COS_MIN`
        (including a ray refracted into the glass so close to the critical angle that it runs
        along the face), or its points overflow float64 (origins of ~1e300 m).
    tir : ndarray of bool, shape (N,)
        The ray is totally internally reflected at some face (and reached it: ``misses`` and
        ``tir`` are disjoint).

    Invalid rays (``misses | tir``) have NaN points and directions and zero transmittance;
    valid rays have finite ones.
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
        Perpendicular distance d from the main-lens centre to the air-side face, metres,
        in (0, :data:`MAX_DISTANCE_M`].
    thickness_m : float
        Glass thickness t, metres, in [0, :data:`MAX_THICKNESS_M`] (0 is a single air/water
        interface).
    tilt_x_rad, tilt_y_rad : float
        Tilt of the normal about the camera x and y axes, radians, each in (-pi/2, pi/2) (see
        module docstring): every normal with ``n_z > 0`` has exactly one such pair, the one
        :meth:`from_normal` gives.
    n_air, n_glass, n_water : float
        Refractive indices, in [:data:`N_MIN`, :data:`N_MAX`].

    Raises
    ------
    ParameterError
        For non-finite or non-numeric values, values outside the ranges above, or a tilt that
        puts the port behind the camera (``n_z <= 1e-9``).
    """

    distance_m: float
    thickness_m: float = 0.0
    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0
    n_air: float = 1.0
    n_glass: float = 1.5
    n_water: float = 1.333

    def __post_init__(self) -> None:
        # The one place every constructor (from_degrees, from_normal, from_dict) passes through.
        distance = positive_float("port.distance_m", self.distance_m)
        if distance > MAX_DISTANCE_M:
            raise ParameterError(f"port.distance_m={self.distance_m!r} exceeds {MAX_DISTANCE_M} m")
        thickness = non_negative_float("port.thickness_m", self.thickness_m)
        if thickness > MAX_THICKNESS_M:
            raise ParameterError(f"port.thickness_m={self.thickness_m!r} exceeds {MAX_THICKNESS_M} m")
        finite_float("port.tilt_x_rad", self.tilt_x_rad)
        finite_float("port.tilt_y_rad", self.tilt_y_rad)
        for name in ("n_air", "n_glass", "n_water"):
            _index(f"port.{name}", getattr(self, name))
        if self.normal[2] <= _MIN_NORMAL_Z:
            raise ParameterError(
                f"port tilt (tilt_x_rad={self.tilt_x_rad!r}, tilt_y_rad={self.tilt_y_rad!r}) makes the "
                f"normal {self.normal.round(6).tolist()} point away from the view: the port would be "
                "behind the camera"
            )
        for name in ("tilt_x_rad", "tilt_y_rad"):
            # Past +-pi/2 the pair is a second name for a normal that has one inside (e.g. (pi, pi)
            # for the optical axis): refused rather than reduced, so that a sidecar's angles are
            # the ones from_normal would give.
            if not abs(getattr(self, name)) < math.pi / 2:
                raise ParameterError(
                    f"port.{name}={getattr(self, name)!r} is outside (-pi/2, pi/2); the normal "
                    f"{self.normal.round(6).tolist()} has tilt angles inside that range"
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
        """Build a port from tilt angles in degrees (the config-file form); a tilt that turns the
        port away from the view is named in degrees, as the file gives it."""
        tilt_x = finite_float("port.tilt_x_deg", tilt_x_deg)
        tilt_y = finite_float("port.tilt_y_deg", tilt_y_deg)
        for name, tilt in (("tilt_x_deg", tilt_x), ("tilt_y_deg", tilt_y)):
            if not abs(tilt) < 90.0:
                raise ParameterError(
                    f"port.{name} must lie in (-90, 90) deg, got {shown(tilt)}: the port would be behind the camera"
                )
        if math.cos(math.radians(tilt_x)) * math.cos(math.radians(tilt_y)) <= _MIN_NORMAL_Z:
            raise ParameterError(
                f"port tilt (tilt_x_deg={tilt_x!r}, tilt_y_deg={tilt_y!r}) turns the normal within 1e-9 of "
                "perpendicular to the view: the port would be behind the camera"
            )
        return cls(
            distance_m=distance_m,
            thickness_m=thickness_m,
            tilt_x_rad=math.radians(tilt_x),
            tilt_y_rad=math.radians(tilt_y),
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
        if not isinstance(data, dict):
            raise ParameterError(f"port must be a table (a JSON object) of port parameters, got {data!r}")
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

    def seen_from(self, origin_cam: np.ndarray) -> FlatPort:
        """This port in the frame with the same axes and its origin at ``origin_cam``.

        Parameters
        ----------
        origin_cam : array_like, shape (3,)
            The new frame's origin in this port's camera frame, metres (e.g. where a calibration puts
            a real lens's camera, :attr:`lfrefract.optics.real_lens.RealLensCamera.calibration_origin_cam`).

        Returns
        -------
        FlatPort
            The same tilts and glass, ``distance_m`` less ``normal . origin_cam``.

        Raises
        ------
        ParameterError
            If ``origin_cam`` is not 3 finite numbers, or lies at or beyond the port's face (naming
            the distance it would have).

        Examples
        --------
        >>> port = FlatPort.from_degrees(distance_m=0.02, tilt_x_deg=0.0)
        >>> round(port.seen_from([0.0, 0.0, -0.0005]).distance_m, 6)  # from 0.5 mm further back
        0.0205
        """
        origin = np.array(finite_vector("origin_cam", origin_cam, 3))
        return replace(self, distance_m=self.distance_m - float(self.normal @ origin))

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
            Rays that do not reach a face (see :attr:`PortTrace.misses`) or are totally internally
            reflected are flagged and NaN, never dropped; every valid ray's values are finite.

        Raises
        ------
        ParameterError
            For arrays of the wrong shape, non-finite values or directions that are not unit
            vectors (to 1e-6).
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
            Invalid rays are flagged as for :meth:`trace_from_air`.

        Raises
        ------
        ParameterError
            As :meth:`trace_from_air`.
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
        # A ray that already lies past the first face misses it.
        start = (o @ n) - faces[0][0]
        misses = ~(start <= 1e-12) if into_water else ~(start >= -1e-12)
        tir = np.zeros(o.shape[0], dtype=bool)
        alive = ~misses  # rays still travelling; misses and tir stay disjoint
        transmittance = np.ones(o.shape[0])
        point, direction = o.copy(), d.copy()
        entry: np.ndarray | None = None  # where the ray meets the first face
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            for offset, n_from, n_to in faces:
                cos_i = direction @ travel_normal
                # Parallel to the face, away from it, or too close to grazing for the hit to be
                # determined (GRAZING_COS_MIN): the ray does not reach this face.
                grazing = alive & ~(cos_i >= GRAZING_COS_MIN)
                misses |= grazing
                alive &= ~grazing
                t = (offset - point @ n) / (direction @ n)
                point = point + t[:, None] * direction
                if entry is None:
                    entry = point.copy()
                transmittance *= _fresnel(cos_i, n_from, n_to)
                direction, tir_here = _refract(direction, travel_normal, cos_i, n_from / n_to)
                tir |= alive & tir_here
                alive &= ~tir_here
            assert entry is not None  # every port has its air-side face
            # Backstop: origins far beyond any port (finite, but ~1e300 m) can still overflow.
            finite = np.isfinite(np.concatenate([entry, point, direction], axis=1)).all(axis=1)
            misses |= alive & ~finite
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
            tir=tir,
        )
