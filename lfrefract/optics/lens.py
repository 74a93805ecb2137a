"""Multi-element main lenses: a lens-design table, its exact real-ray trace and its first-order data.

A lens is a sequence of spherical (or flat) refracting surfaces in order from the object side, as
in a lens-design table: each :class:`Surface` has a radius of curvature, the thickness to the next
surface, the medium after it and a clear semi-aperture, and exactly one surface is the aperture
stop. Object and image space are air (index 1, as in design tables).

Sign conventions (those of lens design): along the design axis ``t``, which runs from the object to
the image, a radius is positive when the surface's centre of curvature lies on the image side of its
vertex. The first surface's vertex is ``t = 0``.

Placement in the camera frame (OpenCV, +z forward into the scene): the optical axis is the z axis
and light from the scene travels towards -z, so ``t`` runs along -z. The lens is placed with its
**rear principal plane at z = 0** (d line), where the thin lens of today's model sits: a vertex at
``t`` lies at ``z = t_H' - t``. With this placement the image side keeps the thin lens's
meaning: the microlens array at ``z = -f'`` with ``f'`` the effective focal length focuses at
infinity, and the Gaussian lens equation holds with the object distance measured from the front
principal plane. Unlike the thin lens, the entrance pupil (the centre of perspective of the chief
rays) and the front principal plane are not at the origin: :meth:`LensPrescription.first_order`
gives their positions.

The tracer (:func:`trace_lens`) intersects rays with every sphere exactly, refracts them with
Snell's law in vector form (:func:`lfrefract.optics.port.refract`), stops them at every clear
aperture (vignetting) and flags total internal reflection; it traces towards the image (rays from
the scene) or towards the object (rays from the sensor, as a renderer's camera does).

Glass data: Sellmeier coefficients of the SCHOTT optical glass catalogue (Zemax catalogue file of
2017-01-20, as published by SCHOTT and tabulated in the public refractiveindex.info database),
``n^2 - 1 = sum_k B_k lambda^2 / (lambda^2 - C_k)`` with ``lambda`` in micrometres.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.port import refract
from lfrefract.validate import (
    as_table,
    bounded_float,
    bounded_int,
    finite_float,
    non_negative_float,
    one_of,
    positive_float,
    reject_unknown_keys,
    shown,
    text,
)

__all__ = [
    "C_LINE_M",
    "D_LINE_M",
    "F_LINE_M",
    "GLASSES",
    "LENS_PRESETS",
    "FirstOrder",
    "LensPrescription",
    "LensPresetInfo",
    "LensTrace",
    "Medium",
    "Surface",
    "exit_pupil_bounds",
    "lens_preset",
    "trace_lens",
]

#: Fraunhofer d line (helium), the reference wavelength of n_d and V_d, metres.
D_LINE_M = 587.5618e-9
#: Fraunhofer F line (hydrogen), metres.
F_LINE_M = 486.1327e-9
#: Fraunhofer C line (hydrogen), metres.
C_LINE_M = 656.2725e-9

#: Sellmeier coefficients ``(B1, B2, B3), (C1, C2, C3)`` (C in um^2) from the SCHOTT optical glass
#: catalogue (Zemax catalogue file 2017-01-20b).
GLASSES: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "N-BK7": ((1.03961212, 0.231792344, 1.01046945), (0.00600069867, 0.0200179144, 103.560653)),
    "N-SK2": ((1.28189012, 0.257738258, 0.96818604), (0.0072719164, 0.0242823527, 110.377773)),
    "N-SK4": ((1.32993741, 0.228542996, 0.988465211), (0.00716874107, 0.0246455892, 100.886364)),
    "N-SK16": ((1.34317774, 0.241144399, 0.994317969), (0.00704687339, 0.0229005, 92.7508526)),
    "N-SSK2": ((1.4306027, 0.153150554, 1.01390904), (0.00823982975, 0.0333736841, 106.870822)),
    "N-SSK5": ((1.59222659, 0.103520774, 1.05174016), (0.00920284626, 0.0423530072, 106.927374)),
    "N-BAF10": ((1.5851495, 0.143559385, 1.08521269), (0.00926681282, 0.0424489805, 105.613573)),
    "N-LAK9": ((1.46231905, 0.344399589, 1.15508372), (0.00724270156, 0.0243353131, 85.4686868)),
    "N-LAK22": ((1.14229781, 0.535138441, 1.04088385), (0.00585778594, 0.0198546147, 100.834017)),
    "N-LAF3": ((1.73155854, 0.150874455, 1.06586596), (0.00953833914, 0.0407887211, 98.0758545)),
    "F2": ((1.34533359, 0.209073176, 0.937357162), (0.00997743871, 0.0470450767, 111.886764)),
    "F5": ((1.3104463, 0.19603426, 0.96612977), (0.00958633048, 0.0457627627, 115.011883)),
    "SF1": ((1.55912923, 0.284246288, 0.968842926), (0.0121481001, 0.0534549042, 112.174809)),
    "SF5": ((1.46141885, 0.247713019, 0.949995832), (0.0111826126, 0.0508594669, 112.041888)),
    "SF15": ((1.53925927, 0.247620926, 1.03816409), (0.0119307961, 0.0556077536, 116.416747)),
    "N-SF5": ((1.52481889, 0.187085527, 1.42729015), (0.011254756, 0.0588995392, 129.141675)),
}

_N_MAX = 5.0  # the densest optical media (germanium) are about 4; lfrefract.optics.port accepts up to 5
_WAVELENGTH_RANGE_M = (300e-9, 2.5e-6)  # where the catalogue's Sellmeier fits hold
_OVERLAP_SAMPLES = 65  # heights at which neighbouring surfaces are checked not to cross


def _wavelength(value: Any) -> float:
    return bounded_float("wavelength_m", value, *_WAVELENGTH_RANGE_M, unit="m")


@dataclass(frozen=True, kw_only=True)
class Medium:
    """The medium after a surface: air, a catalogue glass, a glass given by ``n_d`` and ``V_d``, or Sellmeier terms.

    Make one with :meth:`air`, :meth:`named`, :meth:`abbe` or :meth:`sellmeier` (or
    :meth:`from_dict`); the fields hold the resolved model.

    Attributes
    ----------
    name : str
        ``"air"``, the catalogue name (``"N-BK7"``), or a free label for the other models.
    model : {"air", "sellmeier", "abbe"}
        How the index is computed. ``"abbe"`` is the two-term Cauchy law ``n = A + B / lambda^2``
        through ``n_d`` with ``n_F - n_C = (n_d - 1) / V_d``; ``V_d = inf`` is a medium without
        dispersion.
    sellmeier_b, sellmeier_c_um2 : tuple of float
        Sellmeier terms (``C`` in um^2) for ``model = "sellmeier"``, else empty.
    n_d, v_d : float
        Index and Abbe number at the d line for ``model = "abbe"``, else NaN.
    """

    name: str
    model: Literal["air", "sellmeier", "abbe"]
    sellmeier_b: tuple[float, ...] = ()
    sellmeier_c_um2: tuple[float, ...] = ()
    n_d: float = math.nan
    v_d: float = math.nan

    def __post_init__(self) -> None:
        text("medium name", self.name)
        one_of("medium model", self.model, ("air", "sellmeier", "abbe"))
        if self.model == "sellmeier":
            b = tuple(finite_float("sellmeier_b", x) for x in self.sellmeier_b)
            c = tuple(non_negative_float("sellmeier_c_um2", x) for x in self.sellmeier_c_um2)
            if not 1 <= len(b) <= 6 or len(b) != len(c):
                raise ParameterError(
                    f"medium {self.name!r}: sellmeier_b and sellmeier_c_um2 must hold the same number (1 to 6) "
                    f"of terms, got {shown(self.sellmeier_b)} and {shown(self.sellmeier_c_um2)}"
                )
            object.__setattr__(self, "sellmeier_b", b)
            object.__setattr__(self, "sellmeier_c_um2", c)
        elif self.model == "abbe":
            n_d = bounded_float(f"medium {self.name!r} n_d", self.n_d, 1.0, _N_MAX)
            v_d = self.v_d
            if not (isinstance(v_d, float) and math.isinf(v_d) and v_d > 0.0):
                v_d = positive_float(f"medium {self.name!r} v_d (inf: no dispersion)", v_d)
            object.__setattr__(self, "n_d", n_d)
            object.__setattr__(self, "v_d", v_d)
        if self.model != "sellmeier" and (self.sellmeier_b or self.sellmeier_c_um2):
            raise ParameterError(f"medium {self.name!r}: Sellmeier terms belong to model 'sellmeier' only")
        if self.model != "abbe" and not (math.isnan(self.n_d) and math.isnan(self.v_d)):
            raise ParameterError(f"medium {self.name!r}: n_d and v_d belong to model 'abbe' only")
        if self.model == "air" and self.name != "air":
            raise ParameterError(f"the air medium is named 'air', got {self.name!r}")
        # Every model must give a physical index across the accepted wavelengths.
        probe = np.array([_WAVELENGTH_RANGE_M[0], D_LINE_M, _WAVELENGTH_RANGE_M[1]])
        with np.errstate(all="ignore"):
            n = self._index_array(probe)
        if not np.all(np.isfinite(n)) or np.any(n < 1.0) or np.any(n > _N_MAX):
            raise ParameterError(
                f"medium {self.name!r} gives indices {shown(n.tolist())} at 300 nm, d line, 2.5 um: not a real medium"
            )

    @classmethod
    def air(cls) -> Medium:
        """Air, index 1 at every wavelength (the lens-design convention)."""
        return cls(name="air", model="air")

    @classmethod
    def named(cls, name: str) -> Medium:
        """``"air"`` or a glass of :data:`GLASSES` (SCHOTT catalogue Sellmeier terms)."""
        name = text("medium", name)
        if name.lower() == "air":
            return cls.air()
        key = one_of("medium", name.upper(), tuple(GLASSES))
        b, c = GLASSES[key]
        return cls(name=key, model="sellmeier", sellmeier_b=b, sellmeier_c_um2=c)

    @classmethod
    def abbe(cls, *, n_d: float, v_d: float, name: str = "") -> Medium:
        """A glass given by its d-line index and Abbe number (``v_d = inf``: no dispersion)."""
        label = name or f"n_d={n_d!r} v_d={v_d!r}"
        return cls(name=label, model="abbe", n_d=n_d, v_d=v_d)

    @classmethod
    def sellmeier(cls, *, b: Sequence[float], c_um2: Sequence[float], name: str = "sellmeier") -> Medium:
        """A medium from Sellmeier terms ``n^2 - 1 = sum B lambda^2 / (lambda^2 - C)``, lambda in um."""
        return cls(name=name, model="sellmeier", sellmeier_b=tuple(b), sellmeier_c_um2=tuple(c_um2))

    def _index_array(self, wavelength_m: np.ndarray) -> np.ndarray:
        lam_um = np.asarray(wavelength_m, dtype=np.float64) * 1e6
        if self.model == "air":
            return np.ones_like(lam_um)
        if self.model == "sellmeier":
            l2 = lam_um**2
            n2 = 1.0 + sum(b * l2 / (l2 - c) for b, c in zip(self.sellmeier_b, self.sellmeier_c_um2, strict=True))
            return np.sqrt(n2)
        if math.isinf(self.v_d):
            return np.full_like(lam_um, self.n_d)
        inv2 = 1.0 / np.array([F_LINE_M, C_LINE_M, D_LINE_M]) ** 2 * 1e-12
        slope = (self.n_d - 1.0) / self.v_d / (inv2[0] - inv2[1])
        return self.n_d + slope * (1.0 / lam_um**2 - inv2[2])

    def index(self, wavelength_m: float = D_LINE_M) -> float:
        """Refractive index at ``wavelength_m`` (300 nm to 2.5 um; default the d line)."""
        return float(self._index_array(np.array([_wavelength(wavelength_m)]))[0])

    def to_dict(self) -> str | dict:
        """``"air"`` or the catalogue name, else a table with ``n_d``/``v_d`` or Sellmeier terms."""
        if self.model == "air":
            return "air"
        if self.model == "sellmeier":
            if self.name in GLASSES and GLASSES[self.name] == (self.sellmeier_b, self.sellmeier_c_um2):
                return self.name
            return {
                "name": self.name,
                "sellmeier_b": list(self.sellmeier_b),
                "sellmeier_c_um2": list(self.sellmeier_c_um2),
            }
        return {"name": self.name, "n_d": self.n_d, "v_d": "inf" if math.isinf(self.v_d) else self.v_d}

    @classmethod
    def from_dict(cls, data: Any) -> Medium:
        """Inverse of :meth:`to_dict`: a name, or a table with ``n_d`` (and ``v_d``) or Sellmeier terms."""
        if isinstance(data, str):
            return cls.named(data)
        table = as_table("medium", data)
        reject_unknown_keys("medium", table, {"name", "n_d", "v_d", "sellmeier_b", "sellmeier_c_um2"})
        if "n_d" in table:
            if "sellmeier_b" in table or "sellmeier_c_um2" in table:
                raise ParameterError(f"medium {shown(table)}: give n_d/v_d or Sellmeier terms, not both")
            v_d = table.get("v_d", "inf")
            # No dispersion: the string "inf" (JSON has no infinity) or the number itself (TOML's inf).
            is_inf = v_d == "inf" or (isinstance(v_d, float) and v_d == math.inf)
            v_d = math.inf if is_inf else finite_float("medium v_d", v_d)
            return cls.abbe(n_d=table["n_d"], v_d=v_d, name=str(table.get("name", "")))
        if "sellmeier_b" in table and "sellmeier_c_um2" in table:
            b, c = table["sellmeier_b"], table["sellmeier_c_um2"]
            if not isinstance(b, (list, tuple)) or not isinstance(c, (list, tuple)):
                raise ParameterError(f"medium sellmeier_b and sellmeier_c_um2 must be lists, got {shown(table)}")
            return cls.sellmeier(b=b, c_um2=c, name=str(table.get("name", "sellmeier")))
        raise ParameterError(
            "medium must be a name, or a table with n_d (and v_d) or sellmeier_b and sellmeier_c_um2, "
            f"got {shown(table)}"
        )


@dataclass(frozen=True, kw_only=True)
class Surface:
    """One row of a lens-design table.

    Attributes
    ----------
    radius_m : float
        Radius of curvature, metres; positive when the centre of curvature lies on the image side
        of the vertex. ``0`` or ``inf`` (either sign) is a flat surface, stored as ``inf``.
    thickness_m : float
        Axial distance from this vertex to the next, metres (>= 0). The last surface's is 0: what
        lies behind the lens (the microlens array) is placed by the camera.
    medium : Medium
        The medium after the surface (towards the image).
    semi_aperture_m : float
        Clear semi-aperture (radius of the clear aperture), metres, > 0 and at most ``|radius_m|``.
    stop : bool
        Whether this surface is the aperture stop.
    """

    radius_m: float
    thickness_m: float
    medium: Medium
    semi_aperture_m: float
    stop: bool = False

    def __post_init__(self) -> None:
        number = isinstance(self.radius_m, (int, float, np.number)) and not isinstance(self.radius_m, bool)
        if number and (float(self.radius_m) == 0.0 or math.isinf(float(self.radius_m))):
            object.__setattr__(self, "radius_m", math.inf)
        else:
            object.__setattr__(self, "radius_m", finite_float("radius_m", self.radius_m))
        object.__setattr__(self, "thickness_m", non_negative_float("thickness_m", self.thickness_m))
        object.__setattr__(self, "semi_aperture_m", positive_float("semi_aperture_m", self.semi_aperture_m))
        if not isinstance(self.medium, Medium):
            raise ParameterError(f"medium must be a Medium, got {shown(self.medium)}")
        if not isinstance(self.stop, bool):
            raise ParameterError(f"stop must be true or false, got {shown(self.stop)}")
        if self.semi_aperture_m > abs(self.radius_m):
            raise ParameterError(
                f"semi_aperture_m={self.semi_aperture_m!r} exceeds |radius_m|={abs(self.radius_m)!r}: "
                "a sphere has no points farther from its axis than its radius"
            )

    @property
    def curvature_per_m(self) -> float:
        """``1 / radius_m`` (0 for a flat surface), 1/m."""
        return 0.0 if math.isinf(self.radius_m) else 1.0 / self.radius_m

    def sag_m(self, height_m: np.ndarray) -> np.ndarray:
        """Axial offset of the surface from its vertex at radial ``height_m`` (shape kept), metres."""
        c = self.curvature_per_m
        h2 = np.asarray(height_m, dtype=np.float64) ** 2
        return c * h2 / (1.0 + np.sqrt(np.maximum(1.0 - c * c * h2, 0.0)))

    def to_dict(self) -> dict:
        """The surface as a table (``radius_m = "inf"`` for a flat surface)."""
        out: dict[str, Any] = {
            "radius_m": "inf" if math.isinf(self.radius_m) else self.radius_m,
            "thickness_m": self.thickness_m,
            "medium": self.medium.to_dict(),
            "semi_aperture_m": self.semi_aperture_m,
        }
        if self.stop:
            out["stop"] = True
        return out

    @classmethod
    def from_dict(cls, data: Any) -> Surface:
        """Inverse of :meth:`to_dict`; ``medium`` defaults to air and ``stop`` to false."""
        table = as_table("surface", data)
        reject_unknown_keys("surface", table, {"radius_m", "thickness_m", "medium", "semi_aperture_m", "stop"})
        for key in ("radius_m", "thickness_m", "semi_aperture_m"):
            if key not in table:
                raise ParameterError(f"surface {shown(table)} lacks {key}")
        radius = table["radius_m"]
        if isinstance(radius, str) and radius.lower().lstrip("+-") in ("inf", "infinity"):
            radius = math.inf
        return cls(
            radius_m=radius,
            thickness_m=table["thickness_m"],
            medium=Medium.from_dict(table.get("medium", "air")),
            semi_aperture_m=table["semi_aperture_m"],
            stop=table.get("stop", False),
        )


@dataclass(frozen=True, kw_only=True)
class FirstOrder:
    """First-order (paraxial) data of a lens at one wavelength, object at infinity.

    Positions along the design axis ``t`` (object to image), in metres, relative to the vertex
    named; ``*_z_m`` are the same points in the camera frame (rear principal plane at z = 0, d line).

    Attributes
    ----------
    wavelength_m : float
    efl_m : float
        Effective focal length ``f' = -1 / C`` of the system matrix.
    bfd_m : float
        Back focal distance: last vertex to the rear focal point.
    ffd_m : float
        Front focal distance: the front focal point lies ``ffd_m`` in front of (object side of) the
        first vertex.
    front_principal_m : float
        Front principal plane, from the first vertex (positive: towards the image).
    rear_principal_m : float
        Rear principal plane, from the last vertex (negative: inside or in front of the lens).
    entrance_pupil_m : float
        Entrance pupil, from the first vertex (positive: towards the image).
    entrance_pupil_diameter_m : float
    exit_pupil_m : float
        Exit pupil, from the last vertex (negative: in front of it).
    exit_pupil_diameter_m : float
    f_number : float
        ``efl_m / entrance_pupil_diameter_m``.
    total_track_m : float
        First vertex to last vertex.
    entrance_pupil_z_m, exit_pupil_z_m, front_principal_z_m, front_vertex_z_m, rear_vertex_z_m : float
        Camera-frame z of the entrance pupil, exit pupil, front principal plane and the first and
        last vertices.
    """

    wavelength_m: float
    efl_m: float
    bfd_m: float
    ffd_m: float
    front_principal_m: float
    rear_principal_m: float
    entrance_pupil_m: float
    entrance_pupil_diameter_m: float
    exit_pupil_m: float
    exit_pupil_diameter_m: float
    f_number: float
    total_track_m: float
    entrance_pupil_z_m: float
    exit_pupil_z_m: float
    front_principal_z_m: float
    front_vertex_z_m: float
    rear_vertex_z_m: float


def _refraction(c: float, n_before: float, n_after: float) -> np.ndarray:
    return np.array([[1.0, 0.0], [-(n_after - n_before) * c, 1.0]])


def _transfer(t: float, n: float) -> np.ndarray:
    return np.array([[1.0, t / n], [0.0, 1.0]])


@dataclass(frozen=True, kw_only=True)
class LensPrescription:
    """A main lens as a lens-design table, surfaces in order from the object side.

    Attributes
    ----------
    name : str
        Short name (``"double-gauss"``).
    source : str
        Where the design comes from (book and page, patent number), or ``""`` for one's own.
    surfaces : tuple of Surface
        At least one; exactly one is the stop; the last is followed by air with thickness 0.
        Neighbouring surfaces must not cross within their common clear aperture.
    """

    name: str
    source: str
    surfaces: tuple[Surface, ...]

    def __post_init__(self) -> None:
        if not text("lens name", self.name).strip():
            raise ParameterError("lens name must not be empty")
        if not isinstance(self.source, str):
            raise ParameterError(f"lens source must be a string, got {shown(self.source)}")
        surfaces = tuple(self.surfaces)
        if not surfaces or not all(isinstance(s, Surface) for s in surfaces):
            raise ParameterError(f"lens {self.name!r}: surfaces must be a non-empty sequence of Surface")
        object.__setattr__(self, "surfaces", surfaces)
        stops = [i for i, s in enumerate(surfaces) if s.stop]
        if len(stops) != 1:
            raise ParameterError(
                f"lens {self.name!r}: exactly one surface must be the stop, got {len(stops)} ({stops})"
            )
        last = surfaces[-1]
        if last.medium.model != "air":
            raise ParameterError(
                f"lens {self.name!r}: the medium after the last surface must be air, got {last.medium.name!r}"
            )
        if last.thickness_m != 0.0:
            raise ParameterError(
                f"lens {self.name!r}: the last surface's thickness_m must be 0 (the camera places what follows), "
                f"got {last.thickness_m!r}"
            )
        vertex = self.vertex_t_m
        for i in range(len(surfaces) - 1):
            a, b = surfaces[i], surfaces[i + 1]
            h = np.linspace(0.0, min(a.semi_aperture_m, b.semi_aperture_m), _OVERLAP_SAMPLES)
            gap = (vertex[i + 1] + b.sag_m(h)) - (vertex[i] + a.sag_m(h))
            if np.any(gap < -1e-12 * max(1.0, abs(a.radius_m) if math.isfinite(a.radius_m) else 1.0)):
                k = int(np.argmin(gap))
                raise ParameterError(
                    f"lens {self.name!r}: surfaces {i} and {i + 1} cross at height {float(h[k])!r} m "
                    f"(gap {float(gap[k])!r} m): thickness_m={a.thickness_m!r} is too small for their curvatures"
                )

    @property
    def stop_index(self) -> int:
        """Index of the aperture stop in :attr:`surfaces`."""
        return next(i for i, s in enumerate(self.surfaces) if s.stop)

    @property
    def vertex_t_m(self) -> np.ndarray:
        """Vertex positions along the design axis, first vertex at 0, shape (S,), metres."""
        return np.concatenate([[0.0], np.cumsum([s.thickness_m for s in self.surfaces[:-1]])])

    def indices(self, wavelength_m: float = D_LINE_M) -> np.ndarray:
        """Indices of the media before the first surface (air) and after each surface, shape (S + 1,)."""
        lam = _wavelength(wavelength_m)
        return np.array([1.0] + [s.medium.index(lam) for s in self.surfaces])

    def _matrix(self, start: int, stop: int, wavelength_m: float, *, refract_start: bool = True) -> np.ndarray:
        """(y, n u) matrix from arrival at vertex ``start`` to just after surface ``stop - 1``."""
        n = self.indices(wavelength_m)
        m = np.eye(2)
        for i in range(start, stop):
            if i > start:
                m = _transfer(self.surfaces[i - 1].thickness_m, n[i]) @ m
            if i > start or refract_start:
                m = _refraction(self.surfaces[i].curvature_per_m, n[i], n[i + 1]) @ m
        return m

    def first_order(self, wavelength_m: float = D_LINE_M) -> FirstOrder:
        """Paraxial (y-nu) first-order data at ``wavelength_m`` for an object at infinity.

        Raises
        ------
        ParameterError
            For an afocal system (no focal length) or a stop imaged to infinity.
        """
        lam = _wavelength(wavelength_m)
        count = len(self.surfaces)
        # Camera placement (always at the d line, a mechanical fact): rear principal plane at z = 0.
        (da, _), (dc, _) = self._matrix(0, count, D_LINE_M)
        (a, _b), (c, d) = self._matrix(0, count, lam)
        for wavelength, power in ((D_LINE_M, dc), (lam, c)):
            if abs(power) < 1e-300:
                raise ParameterError(f"lens {self.name!r} is afocal (no focal length) at {wavelength!r} m")
        efl = -1.0 / c
        bfd = -a / c
        ffd = -d / c
        track = float(self.vertex_t_m[-1])
        stop = self.stop_index
        a_stop = self.surfaces[stop].semi_aperture_m
        # Entrance pupil: the stop imaged backwards through the surfaces in front of it; the matrix
        # runs from the first vertex (object space) to arrival at the stop's vertex.
        front = np.eye(2)
        if stop > 0:
            n = self.indices(lam)
            front = _transfer(self.surfaces[stop - 1].thickness_m, n[stop]) @ self._matrix(0, stop, lam)
        fa, fb = front[0]
        if abs(fa) < 1e-300:
            raise ParameterError(f"lens {self.name!r}: its stop is imaged to infinity in object space")
        ep = fb / fa
        epd = 2.0 * a_stop / abs(fa)
        # Exit pupil: the stop imaged forwards through itself and the surfaces behind it.
        (_, rb), (_, rd) = self._matrix(stop, count, lam)
        if abs(rd) < 1e-300:
            raise ParameterError(f"lens {self.name!r}: its stop is imaged to infinity in image space")
        xp = -rb / rd
        xpd = 2.0 * a_stop / abs(rd)
        rear_principal = bfd - efl
        front_principal = -ffd + efl
        t_rear_principal_d = track + (-da / dc) - (-1.0 / dc)

        def z(t: float) -> float:
            return float(t_rear_principal_d - t)

        return FirstOrder(
            wavelength_m=lam,
            efl_m=float(efl),
            bfd_m=float(bfd),
            ffd_m=float(ffd),
            front_principal_m=float(front_principal),
            rear_principal_m=float(rear_principal),
            entrance_pupil_m=float(ep),
            entrance_pupil_diameter_m=float(epd),
            exit_pupil_m=float(xp),
            exit_pupil_diameter_m=float(xpd),
            f_number=float(efl / epd),
            total_track_m=track,
            entrance_pupil_z_m=float(z(ep)),
            exit_pupil_z_m=float(z(track + xp)),
            front_principal_z_m=float(z(front_principal)),
            front_vertex_z_m=float(z(0.0)),
            rear_vertex_z_m=float(z(track)),
        )

    def vertex_z_m(self) -> np.ndarray:
        """Camera-frame z of every vertex (rear principal plane at z = 0, d line), shape (S,), metres."""
        fo = self.first_order()
        return fo.front_vertex_z_m - self.vertex_t_m

    def scaled(self, factor: float) -> LensPrescription:
        """Every length (radii, thicknesses, semi-apertures) times ``factor`` > 0; media and f-number kept."""
        k = positive_float("scale factor", factor)
        return replace(
            self,
            surfaces=tuple(
                replace(
                    s, radius_m=s.radius_m * k, thickness_m=s.thickness_m * k, semi_aperture_m=s.semi_aperture_m * k
                )
                for s in self.surfaces
            ),
        )

    def scaled_to_focal_length(self, focal_length_m: float) -> LensPrescription:
        """The design scaled so that its d-line effective focal length is ``focal_length_m``."""
        target = positive_float("focal_length_m", focal_length_m)
        efl = self.first_order().efl_m
        if efl <= 0.0:
            raise ParameterError(f"lens {self.name!r} has a negative focal length ({efl!r} m): it forms no real image")
        return self.scaled(target / efl)

    def with_f_number(self, f_number: float) -> LensPrescription:
        """The same lens with its stop resized to give ``f_number`` (d line); other clear apertures kept.

        Opening a lens beyond its design makes the other clear apertures vignette the axial beam
        too; the stop may not grow beyond what its own surface allows.
        """
        target = positive_float("f_number", f_number)
        fo = self.first_order()
        i = self.stop_index
        s = self.surfaces[i]
        new = s.semi_aperture_m * fo.f_number / target
        if new > abs(s.radius_m):
            raise ParameterError(f"lens {self.name!r}: f_number={f_number!r} needs a stop larger than its surface")
        return replace(self, surfaces=(*self.surfaces[:i], replace(s, semi_aperture_m=new), *self.surfaces[i + 1 :]))

    def to_dict(self) -> dict:
        """The prescription as a table: ``name``, ``source``, ``surfaces`` (a list of surface tables)."""
        return {"name": self.name, "source": self.source, "surfaces": [s.to_dict() for s in self.surfaces]}

    @classmethod
    def from_dict(cls, data: Any) -> LensPrescription:
        """Inverse of :meth:`to_dict` (``source`` may be left out)."""
        table = as_table("lens", data)
        reject_unknown_keys("lens", table, {"name", "source", "surfaces"})
        rows = table.get("surfaces")
        if not isinstance(rows, (list, tuple)):
            raise ParameterError(f"lens surfaces must be a list of tables, got {shown(rows)}")
        return cls(
            name=table.get("name", ""),
            source=table.get("source", ""),
            surfaces=tuple(Surface.from_dict(r) for r in rows),
        )


@dataclass(frozen=True, kw_only=True)
class LensTrace:
    """Result of :func:`trace_lens` for N rays, in the camera frame.

    Attributes
    ----------
    points_cam : ndarray, shape (N, 3)
        Where each ray leaves the lens: its point on the last surface it crosses (the last
        surface towards the image, the first towards the object), metres; NaN unless ``passed``.
    directions_cam : ndarray, shape (N, 3)
        Unit directions after that surface; NaN unless ``passed``.
    passed : ndarray of bool, shape (N,)
        The ray crossed every surface inside its clear aperture without total internal reflection.
    tir : ndarray of bool, shape (N,)
        The ray was totally internally reflected (at surface ``blocked_at``).
    blocked_at : ndarray of int, shape (N,)
        Index (in the prescription's order) of the surface that stopped the ray: missed sphere,
        outside its clear aperture, or TIR; -1 for rays that passed.
    surface_points_cam : ndarray, shape (S, N, 3) or None
        With ``record=True``, each ray's point on every surface in the prescription's order (NaN
        where it did not get there).
    """

    points_cam: np.ndarray
    directions_cam: np.ndarray
    passed: np.ndarray
    tir: np.ndarray
    blocked_at: np.ndarray
    surface_points_cam: np.ndarray | None = field(default=None, repr=False)

    @property
    def vignetted(self) -> np.ndarray:
        """Rays stopped by a clear aperture (or missing a sphere), not by TIR, shape (N,)."""
        return ~self.passed & ~self.tir


def _trace_design(
    curvature: np.ndarray,
    vertex_t: np.ndarray,
    semi_aperture: np.ndarray,
    n: np.ndarray,
    p: np.ndarray,
    d: np.ndarray,
    record: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Trace rays travelling towards +t through surfaces in the given order (design frame).

    ``n`` has one more entry than the surfaces: the media before the first and after each.
    Returns points, directions, tir, blocked_at (per surface order), surface points.
    """
    count = len(curvature)
    rays = p.shape[0]
    pts = p.copy()
    dirs = d.copy()
    alive = np.ones(rays, dtype=bool)
    tir = np.zeros(rays, dtype=bool)
    blocked = np.full(rays, -1, dtype=np.int64)
    surface_points = np.full((count, rays, 3), np.nan) if record else None
    for i in range(count):
        idx = np.flatnonzero(alive)
        if idx.size == 0:
            break
        c = curvature[i]
        q = pts[idx] - np.array([0.0, 0.0, vertex_t[i]])
        e = dirs[idx]
        # Surface c |X|^2 - 2 z = 0 (vertex at the origin); ray q + s e with |e| = 1:
        # c s^2 - 2 B s + C = 0 with B = e_z - c q.e, C = c |q|^2 - 2 q_z; the root nearer the vertex
        # is s = C / (B + sqrt(B^2 - c C)), stable for any c (c = 0 gives the plane's s = -q_z / e_z).
        # It equals (B - sqrt(B^2 - c C)) / c, the crossing of the vertex-side cap, whatever the sign of
        # its denominator: a ray that meets a strongly curved surface after entering its sphere through
        # the far side (a steep marginal ray of a telephoto's rear group) has B + sqrt(...) < 0. The
        # normal test below refuses a root on the far hemisphere.
        big_b = e[:, 2] - c * np.einsum("ij,ij->i", q, e)
        big_c = c * np.einsum("ij,ij->i", q, q) - 2.0 * q[:, 2]
        disc = big_b * big_b - c * big_c
        denom = big_b + np.sqrt(np.maximum(disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            s = big_c / denom
        hit = q + s[:, None] * e
        ok = (disc >= 0.0) & np.isfinite(s) & (s >= -1e-12 * (1.0 + np.abs(q[:, 2])))
        ok &= hit[:, 0] ** 2 + hit[:, 1] ** 2 <= semi_aperture[i] ** 2
        # Unit normal along the travel: -(c x, c y, c z - 1), of length 1 on the sphere.
        normal = np.stack([-c * hit[:, 0], -c * hit[:, 1], 1.0 - c * hit[:, 2]], axis=1)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        ok &= np.einsum("ij,ij->i", normal, e) > 0.0
        good = idx[ok]
        blocked[idx[~ok]] = i
        alive[idx[~ok]] = False
        if good.size == 0:
            continue
        hit_g = hit[ok] + np.array([0.0, 0.0, vertex_t[i]])
        out, t_ir = refract(e[ok], normal[ok], float(n[i]), float(n[i + 1]))
        out /= np.linalg.norm(out, axis=1, keepdims=True)
        pts[good] = hit_g
        dirs[good] = out
        if record and surface_points is not None:
            surface_points[i, good] = hit_g
        if np.any(t_ir):
            bad = good[t_ir]
            tir[bad] = True
            blocked[bad] = i
            alive[bad] = False
    pts[~alive] = np.nan
    dirs[~alive] = np.nan
    return pts, dirs, tir, blocked, surface_points


def trace_lens(
    lens: LensPrescription,
    origins_cam: np.ndarray,
    directions_cam: np.ndarray,
    *,
    toward: Literal["image", "object"] = "image",
    wavelength_m: float = D_LINE_M,
    record: bool = False,
) -> LensTrace:
    """Trace rays exactly through ``lens`` placed in the camera frame (rear principal plane at z = 0).

    Parameters
    ----------
    lens : LensPrescription
    origins_cam : ndarray, shape (N, 3)
        Ray origins in the camera frame, metres: in object space (in front of the first surface)
        for ``toward="image"``, behind the last surface for ``toward="object"``.
    directions_cam : ndarray, shape (N, 3)
        Directions of travel (normalised here): towards -z for ``"image"``, +z for ``"object"``.
    toward : {"image", "object"}
        Trace from the scene into the camera, or from the sensor side out into the scene.
    wavelength_m : float
        Wavelength for the media's indices, metres (default the d line).
    record : bool
        Keep every ray's point on every surface (:attr:`LensTrace.surface_points_cam`).

    Returns
    -------
    LensTrace
        Exit points and directions in the camera frame, with masks of passed, vignetted and TIR rays.

    Raises
    ------
    ParameterError
        For arrays of the wrong shape, non-finite values, a zero direction, or a direction that
        does not point the way ``toward`` says (it would never reach the lens).
    """
    toward = one_of("toward", toward, ("image", "object"))  # type: ignore[assignment]
    lam = _wavelength(wavelength_m)
    o = np.asarray(origins_cam, dtype=np.float64)
    d = np.asarray(directions_cam, dtype=np.float64)
    if o.ndim != 2 or o.shape[1] != 3 or d.shape != o.shape:
        raise ParameterError(f"origins_cam and directions_cam must both have shape (N, 3), got {o.shape} and {d.shape}")
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))):
        raise ParameterError("origins_cam and directions_cam must be finite")
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    if np.any(norm == 0.0):
        raise ParameterError("directions_cam must not hold zero vectors")
    d = d / norm
    # A ray aimed away from the lens never meets it: that is a caller's mistake, not vignetting.
    away = d[:, 2] >= 0.0 if toward == "image" else d[:, 2] <= 0.0
    if np.any(away):
        k = int(np.flatnonzero(away)[0])
        sense = "-z (towards the image)" if toward == "image" else "+z (towards the object)"
        raise ParameterError(
            f"directions_cam[{k}]={d[k].tolist()} does not point along {sense}, as toward={toward!r} needs: "
            "the ray would never reach the lens"
        )
    z_front = lens.first_order().front_vertex_z_m
    curvature = np.array([s.curvature_per_m for s in lens.surfaces])
    vertex_t = lens.vertex_t_m
    semi = np.array([s.semi_aperture_m for s in lens.surfaces])
    n = lens.indices(lam)
    count = len(lens.surfaces)
    if toward == "image":
        # Design frame: t = z_front - z, x and y kept (a mirror image, harmless for a lens of revolution).
        p = np.column_stack([o[:, 0], o[:, 1], z_front - o[:, 2]])
        e = np.column_stack([d[:, 0], d[:, 1], -d[:, 2]])
        pts, dirs, tir, blocked, sp = _trace_design(curvature, vertex_t, semi, n, p, e, record)
        to_cam_z = lambda t: z_front - t  # noqa: E731
        dirs_cam = np.column_stack([dirs[:, 0], dirs[:, 1], -dirs[:, 2]])
    else:
        # Reversed lens: surfaces last to first, radii negated, media swapped; t' = T - t = z - z_rear.
        track = float(vertex_t[-1])
        z_rear = z_front - track
        p = np.column_stack([o[:, 0], o[:, 1], o[:, 2] - z_rear])
        pts, dirs, tir, blocked_rev, sp_rev = _trace_design(
            -curvature[::-1], track - vertex_t[::-1], semi[::-1], n[::-1], p, d, record
        )
        blocked = np.where(blocked_rev >= 0, count - 1 - blocked_rev, -1)
        sp = sp_rev[::-1] if sp_rev is not None else None
        to_cam_z = lambda t: t + z_rear  # noqa: E731
        dirs_cam = dirs
    pts_cam = np.column_stack([pts[:, 0], pts[:, 1], to_cam_z(pts[:, 2])])
    surface_cam = None
    if sp is not None:
        surface_cam = np.concatenate([sp[..., :2], to_cam_z(sp[..., 2:])], axis=2)
    passed = blocked < 0
    return LensTrace(
        points_cam=pts_cam,
        directions_cam=dirs_cam,
        passed=passed,
        tir=tir,
        blocked_at=blocked,
        surface_points_cam=surface_cam,
    )


def exit_pupil_bounds(
    lens: LensPrescription,
    *,
    plane_z_m: float,
    radii_m: np.ndarray,
    grid: int = 128,
    wavelength_m: float = D_LINE_M,
) -> np.ndarray:
    """Where rays from points of a plane behind the lens can leave through it: bounds on the rear vertex plane.

    For a point ``(r, 0, plane_z_m)`` of a plane behind the lens (the microlens array's), rays aimed
    at a ``grid`` x ``grid`` lattice of points of the rear vertex plane, over a square 1.5 times the
    rear surface's clear semi-aperture, are traced out through the lens (towards the object); the
    result is the axis-aligned box of the points whose rays pass, widened by one lattice spacing on
    every side (the scheme of PBRT-v4's realistic camera). A renderer samples its rays towards this
    box instead of the whole rear element, so vignetted samples are not wasted; for a point at
    polar angle ``phi`` the box is turned by ``phi`` about the axis.

    Parameters
    ----------
    lens : LensPrescription
    plane_z_m : float
        Camera-frame z of the plane (behind the rear vertex: ``plane_z_m < rear_vertex_z_m``), metres.
    radii_m : ndarray, shape (R,)
        Distances from the axis of the plane's points, metres (>= 0).
    grid : int
        Lattice points per side (8 to 2048).
    wavelength_m : float
        Wavelength for the media, metres.

    Returns
    -------
    ndarray, shape (R, 4)
        ``x_min, x_max, y_min, y_max`` on the rear vertex plane (camera-frame x, y), metres; NaN
        rows for points from which no ray passes.
    """
    n_grid = bounded_int("grid", grid, 8, 2048)
    radii = np.asarray(radii_m, dtype=np.float64)
    if radii.ndim != 1 or not np.all(np.isfinite(radii)) or np.any(radii < 0.0):
        raise ParameterError(f"radii_m must be a 1-D array of distances >= 0, got {shown(radii_m)}")
    fo = lens.first_order()
    z_plane = finite_float("plane_z_m", plane_z_m)
    if z_plane >= fo.rear_vertex_z_m:
        raise ParameterError(
            f"plane_z_m={plane_z_m!r} must lie behind the lens's rear vertex (z < {fo.rear_vertex_z_m!r} m)"
        )
    half = 1.5 * lens.surfaces[-1].semi_aperture_m
    step = 2.0 * half / n_grid
    axis = -half + step * (np.arange(n_grid) + 0.5)
    gx, gy = (g.ravel() for g in np.meshgrid(axis, axis, indexing="xy"))
    targets = np.column_stack([gx, gy, np.full(gx.size, fo.rear_vertex_z_m)])
    out = np.full((radii.size, 4), np.nan)
    for k, r in enumerate(radii):
        origin = np.array([r, 0.0, z_plane])
        passed = trace_lens(
            lens, np.broadcast_to(origin, targets.shape), targets - origin, toward="object", wavelength_m=wavelength_m
        ).passed
        if np.any(passed):
            x, y = gx[passed], gy[passed]
            out[k] = (x.min() - step, x.max() + step, y.min() - step, y.max() + step)
    return out


# --- presets -------------------------------------------------------------------------------------


def _table(rows: Sequence[tuple[float, float, Medium, float]], *, stop: int, scale_m: float) -> tuple[Surface, ...]:
    """Surfaces from ``(radius, thickness, medium after, semi-aperture)`` rows in the table's unit."""
    return tuple(
        Surface(
            radius_m=r * scale_m if r else math.inf,
            thickness_m=t * scale_m,
            medium=m,
            semi_aperture_m=a * scale_m,
            stop=i == stop,
        )
        for i, (r, t, m, a) in enumerate(rows)
    )


def _aim_meridional(
    lens: LensPrescription, half_field_rad: np.ndarray, pupil: np.ndarray, wavelength_m: float = D_LINE_M
) -> np.ndarray:
    """Heights on every surface of real meridional rays aimed at ``pupil * stop semi-aperture``.

    Rays come from a distant object at each of ``half_field_rad`` (F,), ascending from 0, and are
    aimed, by damped Newton steps on their height, through the stop at fractional heights ``pupil``
    (P,); each field starts from the previous field's solution. Clear apertures are ignored.

    Returns
    -------
    ndarray, shape (S, F, P)
        |height| of each ray on each surface, metres.

    Raises
    ------
    ParameterError
        If some ray misses a surface, is totally reflected, or cannot be aimed.
    """
    fo = lens.first_order(wavelength_m)
    curvature = np.array([s.curvature_per_m for s in lens.surfaces])
    vertex_t = lens.vertex_t_m
    n = lens.indices(wavelength_m)
    stop = lens.stop_index
    a_stop = lens.surfaces[stop].semi_aperture_m
    reach = float(np.max([abs(s.radius_m) if math.isfinite(s.radius_m) else 0.0 for s in lens.surfaces]))
    t0 = -(fo.total_track_m + reach + abs(fo.entrance_pupil_m))
    unlimited = np.full(len(curvature), np.inf)
    target = pupil * a_stop

    def heights(y1: np.ndarray, angle: float) -> np.ndarray:
        # The ray crosses the first vertex plane at height y1 and starts at t0 in front of it.
        origins = np.column_stack([np.zeros_like(y1), y1 + t0 * math.tan(angle), np.full_like(y1, t0)])
        dirs = np.tile([0.0, math.sin(angle), math.cos(angle)], (y1.size, 1))
        *_, sp = _trace_design(curvature, vertex_t, unlimited, n, origins, dirs, True)
        assert sp is not None
        return sp[..., 1]

    step = 1e-7 * fo.entrance_pupil_diameter_m
    y0 = pupil * fo.entrance_pupil_diameter_m / 2.0 - fo.entrance_pupil_m * math.tan(float(half_field_rad[0]))
    out = np.empty((len(curvature), len(half_field_rad), len(pupil)))
    for k, angle in enumerate(half_field_rad):
        angle = float(angle)
        for _ in range(60):
            both = heights(np.concatenate([y0, y0 + step]), angle)[stop]
            f0 = both[: y0.size] - target
            slope = (both[y0.size :] - target - f0) / step
            if not np.all(np.isfinite(f0) & np.isfinite(slope)):
                raise ParameterError(
                    f"lens {lens.name!r}: a ray of the beam at {math.degrees(angle):.1f} deg "
                    "cannot be aimed through the stop"
                )
            if np.max(np.abs(f0)) < 1e-11 * a_stop:
                break
            update = f0 / slope
            # Damped: halve the step of any ray whose update would lose it.
            for _ in range(30):
                trial = heights(y0 - update, angle)[stop]
                lost = ~np.isfinite(trial)
                if not np.any(lost):
                    break
                update = np.where(lost, update / 2.0, update)
            y0 = y0 - update
        final = heights(y0, angle)
        if not np.all(np.isfinite(final)) or np.max(np.abs(final[stop] - target)) > 1e-9 * a_stop:
            raise ParameterError(f"lens {lens.name!r}: the beam at {math.degrees(angle):.1f} deg misses the stop")
        out[:, k] = np.abs(final)
    return out


def _fit_clear_apertures(lens: LensPrescription, *, half_field_deg: float, margin: float) -> LensPrescription:
    """Set every surface's clear semi-aperture to the height of the full-field beam that fills the stop.

    Fields 0 to ``half_field_deg`` (21 steps, each aimed from the last) and pupil heights -1 to 1
    (21 steps), real rays at the d line, times ``1 + margin``; the stop keeps its size.
    """
    fields = np.deg2rad(np.linspace(0.0, half_field_deg, 21))
    need = _aim_meridional(lens, fields, np.linspace(-1.0, 1.0, 21)).max(axis=(1, 2)) * (1.0 + margin)
    surfaces = tuple(
        s if s.stop else replace(s, semi_aperture_m=float(h)) for s, h in zip(lens.surfaces, need, strict=True)
    )
    return replace(lens, surfaces=surfaces)


@dataclass(frozen=True, kw_only=True)
class LensPresetInfo:
    """A preset: the half field of view it was designed for and the function that builds it.

    ``build()`` returns the design at its tabulated scale and f-number (cached: prescriptions are
    immutable).
    """

    half_field_deg: float
    build: Callable[[], LensPrescription]


def _double_gauss() -> LensPrescription:
    # Radius, thickness, medium after, clear semi-aperture (mm at f = 50 mm). The table gives n_d only;
    # the V_d are those of catalogue glasses of the same n_d (an assumption: it matters only away from
    # the d line).
    g1 = Medium.abbe(n_d=1.670, v_d=47.1, name="n1.670/47.1")
    g2 = Medium.abbe(n_d=1.699, v_d=30.1, name="n1.699/30.1")
    g3 = Medium.abbe(n_d=1.603, v_d=38.0, name="n1.603/38.0")
    g4 = Medium.abbe(n_d=1.658, v_d=57.3, name="n1.658/57.3")
    g5 = Medium.abbe(n_d=1.717, v_d=48.0, name="n1.717/48.0")
    air = Medium.air()
    rows = [
        (29.475, 3.76, g1, 12.6),
        (84.83, 0.12, air, 12.6),
        (19.275, 4.025, g1, 11.5),
        (40.77, 3.275, g2, 11.5),
        (12.75, 5.705, air, 9.0),
        (0.0, 4.5, air, 8.55),
        (-14.495, 1.18, g3, 8.5),
        (40.77, 6.065, g4, 10.0),
        (-20.385, 0.19, air, 10.0),
        (437.065, 3.22, g5, 10.0),
        (-39.73, 0.0, air, 10.0),
    ]
    return LensPrescription(
        name="double-gauss",
        source=(
            "Double Gauss f/2, 22 deg half field: H. Tronnier, US patent 2,673,491; as tabulated in "
            "W. J. Smith, Modern Lens Design (1992), p. 312, scaled from f = 100 mm to 50 mm"
        ),
        surfaces=_table(rows, stop=5, scale_m=1e-3),
    )


def _wide_angle() -> LensPrescription:
    # Radius, thickness, medium after (SCHOTT N-SK4 and SF1), in the book's units, scaled to f = 20 mm. The book
    # tabulates no clear apertures: each is set to the height of the 50 deg beam that fills the stop
    # (real rays, d line) plus 2 %, and the stop is sized for the book's f/4.
    sk4, sf1, air = Medium.named("N-SK4"), Medium.named("SF1"), Medium.air()
    rows = [
        (8.0107, 0.2500, sk4),
        (1.1856, 0.9613, air),
        (1.6747, 0.3578, sf1),
        (-7.5157, 0.2136, sk4),
        (0.9411, 0.4146, air),
        (-1.7688, 0.3333, sf1),
        (-1.5531, 0.3863, sk4),
        (-2.2281, 0.9842, air),
        (0.0, 0.1000, air),
        (13.6803, 0.1400, sk4),
        (-3.4279, 0.0605, air),
        (20.0257, 0.3332, sk4),
        (-0.9258, 0.4374, sf1),
        (-3.2233, 0.2679, air),
        (10.3847, 0.1400, sf1),
        (2.4272, 0.2609, sk4),
        (-3.8828, 0.0150, air),
        (3.3650, 0.3167, sk4),
        (-14.7547, 0.0, air),
    ]
    # Provisional apertures (0.2 mm, the stop 0.1 mm) only to compute the first-order data.
    draft = LensPrescription(
        name="wide-angle",
        source=(
            "Wide angle, 100 deg field, f/4: M. Laikin, Lens Design, 4th ed. (CRC Press, 2007), p. 108; "
            "scaled to f = 20 mm, clear apertures fitted to the 50 deg beam"
        ),
        surfaces=_table([(r, t, m, 0.1 if i == 8 else 0.2) for i, (r, t, m) in enumerate(rows)], stop=8, scale_m=1e-3),
    )
    draft = draft.with_f_number(4.0)
    return _fit_clear_apertures(draft, half_field_deg=50.0, margin=0.02).scaled_to_focal_length(20e-3)


LENS_PRESETS: dict[str, LensPresetInfo] = {
    "double-gauss": LensPresetInfo(half_field_deg=22.0, build=functools.cache(_double_gauss)),
    "wide-angle": LensPresetInfo(half_field_deg=50.0, build=functools.cache(_wide_angle)),
}


def lens_preset(name: str, *, focal_length_m: float | None = None, f_number: float | None = None) -> LensPrescription:
    """The named published design (:data:`LENS_PRESETS`), optionally scaled and stopped to a camera.

    Parameters
    ----------
    name : str
        ``"double-gauss"`` or ``"wide-angle"``.
    focal_length_m : float, optional
        Scale the design to this d-line effective focal length (a camera's ``focal_length_m``).
    f_number : float, optional
        Resize the stop to this f-number (other clear apertures kept, so opening it vignettes).
    """
    lens = LENS_PRESETS[one_of("lens preset", name, tuple(LENS_PRESETS))].build()
    if focal_length_m is not None:
        lens = lens.scaled_to_focal_length(focal_length_m)
    if f_number is not None:
        lens = lens.with_f_number(f_number)
    return lens
