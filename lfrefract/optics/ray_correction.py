"""A correction of the thin-lens ray model: how a real camera's rays depart from it.

The thin-lens model (:meth:`lfrefract.optics.camera.LightFieldCamera.captured_rays`) gives each raw
pixel a ray leaving the main-lens plane z = 0 at the aperture point ``a`` with slopes
``t = (dx / dz, dy / dz)``. :class:`RayCorrection` maps it to the camera's ray:

    slopes ``t' = s t (1 + k1 |t|^2 + k2 |t|^4)``, through the point ``(m a, d |t'|^2)``,

the pupil scale ``m``, the slope (focal) scale ``s``, two radial terms (the main lens's distortion)
and the pupil's drift ``d``: a real lens's entrance pupil moves along the axis with the field angle
(pupil aberration), so the rays of slope ``t'`` cross the axis-normal plane ``z = d |t'|^2`` at the
scaled aperture point (the ray is written from where it crosses z = 0: ``(m a - d |t'|^2 t', 0)``).
The pupil's position on the axis itself is not a parameter: in-air views fix the camera only up to a
shift of its frame along z, so the model keeps the thin lens's plane z = 0 for the field's centre.

:meth:`RayCorrection.thin_lens_rays` inverts the map: the thin-lens ray whose corrected ray is a
given one (the slope equation is radial, solved for ``|t|`` by Newton's method). The synthesis
uses it to predict, with the thin-lens search's lattice arithmetic, which pixels record a ray.

:func:`lfrefract.calibration.calibrate_camera` estimates it from in-air chessboard
light fields; the synthesis takes it through
:attr:`lfrefract.synthesis.warp_map.SynthesisOptions.ray_correction`.

Frames and units: camera frame (OpenCV axes), metres; slopes are dimensionless.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import CapturedRays
from lfrefract.optics.real_lens import TRACED_FAMILY, TracedLens
from lfrefract.validate import (
    bounded_float,
    bounded_int,
    finite_float,
    named,
    reject_unknown_keys,
    require_keys,
    shown,
)

__all__ = [
    "HELD_SLOPE_SCALE_STD",
    "PARAMETERS",
    "POLYNOMIAL_CAPACITIES",
    "UNSTRUCTURED",
    "Capacity",
    "Correction",
    "CorrectionEstimate",
    "PolynomialCorrection",
    "RayCorrection",
    "TracedLens",
    "apply_correction",
    "corrected_slopes",
    "correction_from_dict",
    "frame_directions",
    "moved",
    "polynomial_exponents",
    "symmetric_directions",
]

#: Newton steps :meth:`RayCorrection.thin_lens_rays` takes at most (3 on the Illum's calibrated
#: model over slopes up to 0.35: the radial terms are a few per cent of the slope).
_INVERSE_MAX_STEPS = 50

#: Relative residual of the slope equation below which a root counts as found (a few ulps).
_INVERSE_TOLERANCE = 1e-14

#: The relative standard deviation of the slope scale (a focal-length correction) when the captures
#: do not determine it: the focal length a capture's file records taken as the main lens's to 1 %.
#: The radial model's calibration holds the scale at 1 with it
#: (:func:`lfrefract.calibration.calibrate_camera`), a joint refinement with the port may move it by
#: it, and the polynomial model's fit takes it as the slope scale's prior.
HELD_SLOPE_SCALE_STD = 0.01

#: The parameters, in the order of :meth:`RayCorrection.vector`.
PARAMETERS = ("pupil_scale", "slope_scale", "k1", "k2", "pupil_drift_m")

#: Each parameter's range (inclusive) and unit (see :class:`RayCorrection`).
_RANGES = {
    "pupil_scale": (0.5, 2.0, ""),
    "slope_scale": (0.5, 2.0, ""),
    "k1": (-10.0, 10.0, ""),
    "k2": (-10.0, 10.0, ""),
    "pupil_drift_m": (-0.5, 0.5, "m"),
}


def _checked(name: str, value: Any, *, where: str = "") -> float:
    """The parameter ``name``'s ``value`` as a float in its range; a message names it as ``where.name``."""
    low, high, unit = _RANGES[name]
    return bounded_float(f"{where}.{name}" if where else name, value, low, high, unit=unit)


@dataclass(frozen=True, kw_only=True)
class RayCorrection:
    """How a camera's rays depart from its thin-lens model (see the module docstring).

    Attributes
    ----------
    pupil_scale : float
        ``m``: aperture points scale by it, in (0.5, 2).
    slope_scale : float
        ``s``: the slopes scale by it (a focal-length correction), in (0.5, 2).
    k1, k2 : float
        Radial terms of the slopes, per squared and fourth power of the slope, each in [-10, 10].
    pupil_drift_m : float
        ``d``: where the entrance pupil of the rays of slope ``t'`` lies on the axis, per ``|t'|^2``,
        metres (positive: forward, into the scene), in [-0.5, 0.5]. Absent from a file written
        before it was part of the model: 0 (the pupil does not move), that model's meaning.
    """

    pupil_scale: float = 1.0
    slope_scale: float = 1.0
    k1: float = 0.0
    k2: float = 0.0
    pupil_drift_m: float = 0.0

    def __post_init__(self) -> None:
        for name in PARAMETERS:
            object.__setattr__(self, name, _checked(name, getattr(self, name)))

    @classmethod
    def from_vector(cls, values: np.ndarray) -> RayCorrection:
        """From ``(pupil_scale, slope_scale, k1, k2, pupil_drift_m)`` (:data:`PARAMETERS`)."""
        m, s, k1, k2, d = (float(v) for v in values)
        return cls(pupil_scale=m, slope_scale=s, k1=k1, k2=k2, pupil_drift_m=d)

    def vector(self) -> np.ndarray:
        """``(pupil_scale, slope_scale, k1, k2, pupil_drift_m)`` (:data:`PARAMETERS`)."""
        return np.array([self.pupil_scale, self.slope_scale, self.k1, self.k2, self.pupil_drift_m])

    def apply(self, aperture_points_m: np.ndarray, slopes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The camera's rays for thin-lens rays (aperture points (N, 2), slopes (N, 2)).

        Returns
        -------
        origins_cam : ndarray, shape (N, 3)
            On the plane z = 0, metres.
        directions_cam : ndarray, shape (N, 3)
            Unit directions.
        """
        return apply_correction(self.vector(), np.asarray(aperture_points_m, float), np.asarray(slopes, float))

    def slopes(self, slopes: np.ndarray) -> np.ndarray:
        """The camera's slopes ``t'`` (N, 2) of thin-lens slopes ``t`` (N, 2): ``s t (1 + k1 |t|^2 + k2 |t|^4)``."""
        return corrected_slopes(self.vector(), np.asarray(slopes, dtype=float))

    def thin_lens_rays(
        self, points_cam: np.ndarray, directions_cam: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The thin-lens rays that :meth:`apply` maps to the given rays (its inverse).

        Parameters
        ----------
        points_cam : ndarray, shape (N, 3)
            A point on each ray, camera frame, metres.
        directions_cam : ndarray, shape (N, 3)
            Their directions (any length, ``z > 0``).

        Returns
        -------
        aperture_points_m : ndarray, shape (N, 2)
            The thin-lens rays' points on the plane z = 0, metres.
        slopes : ndarray, shape (N, 2)
            Their slopes ``t``.
        found : ndarray of bool, shape (N,)
            The ray has a thin-lens ray: the slope equation ``s rho (1 + k1 rho^2 + k2 rho^4) = |t'|``
            has a root on the branch through 0 where the map is increasing (always, unless the radial
            terms fold the field over). Both outputs are NaN where not.
        """
        p = np.asarray(points_cam, dtype=np.float64)
        d = np.asarray(directions_cam, dtype=np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            slopes_out = d[:, :2] / d[:, 2:3]
        rho_out = np.hypot(slopes_out[:, 0], slopes_out[:, 1])
        s, k1, k2 = self.slope_scale, self.k1, self.k2

        def radial(rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """``s rho (1 + k1 rho^2 + k2 rho^4) - |t'|`` and its derivative in ``rho``."""
            r2 = rho * rho
            return s * rho * (1.0 + k1 * r2 + k2 * r2 * r2) - rho_out, s * (1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2)

        tolerance = _INVERSE_TOLERANCE * np.maximum(rho_out, 1e-300)
        rho = rho_out / s
        for step in range(_INVERSE_MAX_STEPS + 1):
            residual, derivative = radial(rho)
            if step == _INVERSE_MAX_STEPS or not np.any(np.abs(residual) > tolerance):  # NaN: done
                break
            with np.errstate(invalid="ignore", divide="ignore"):
                rho = rho - residual / derivative
        # On the branch through 0: rho >= 0 and the map increasing there (k2 >= 0 or below its turn).
        found = (np.abs(residual) <= 1e3 * tolerance) & (rho >= 0.0) & (derivative > 0.0) & np.isfinite(rho_out)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(rho_out > 0.0, rho / np.where(rho_out > 0.0, rho_out, 1.0), 1.0 / s)
        slopes = np.where(found[:, None], slopes_out * ratio[:, None], np.nan)
        # The corrected ray crosses z = 0 at o = m a - d |t'|^2 t'.
        crossing = p[:, :2] - p[:, 2:3] * slopes_out
        drifted = self.pupil_drift_m * (rho_out * rho_out)[:, None] * slopes_out
        aperture = np.where(found[:, None], (crossing + drifted) / self.pupil_scale, np.nan)
        return aperture, slopes, found

    def corrected(self, rays: CapturedRays) -> CapturedRays:
        """``rays`` (thin-lens captured rays) with the correction applied; masks and lenses kept."""
        return _corrected(self.apply, rays)

    def to_dict(self) -> dict:
        """Plain data: :data:`PARAMETERS` and their values."""
        return dict(zip(PARAMETERS, (float(v) for v in self.vector()), strict=True))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "correction") -> RayCorrection:
        """From :meth:`to_dict`'s data (``pupil_drift_m`` optional: 0 in earlier files)."""
        optional = {"pupil_drift_m"}
        table: Any = data  # any value read from a file: reject_unknown_keys says if it is no table
        reject_unknown_keys(where, table, set(PARAMETERS))
        require_keys(where, table, set(PARAMETERS) - optional)
        return cls(**{k: _checked(k, table[k], where=where) for k in PARAMETERS if k in table})


@dataclass(frozen=True, eq=False, kw_only=True)
class CorrectionEstimate:
    """A calibrated :class:`RayCorrection` with its uncertainty: what a later fit may refine.

    Attributes
    ----------
    correction : RayCorrection
    covariance : ndarray, shape (5, 5)
        Covariance of :data:`PARAMETERS` (in that order; the drift's entries in metres), marginal over
        everything else the calibration fitted (the board poses). Symmetric positive definite.
    """

    correction: RayCorrection
    covariance: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.correction, RayCorrection):
            raise ParameterError(f"correction must be a RayCorrection, got {type(self.correction).__name__}")
        cov = _checked_covariance(np.asarray(self.covariance, dtype=np.float64), "covariance").copy()
        cov.setflags(write=False)
        object.__setattr__(self, "covariance", cov)

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of :data:`PARAMETERS`, shape (5,)."""
        return np.sqrt(np.diag(self.covariance))

    def covariance_to_dict(self) -> dict:
        """The covariance as plain data: its parameter order and its rows."""
        return {"parameters": list(PARAMETERS), "matrix": self.covariance.tolist()}

    @staticmethod
    def covariance_from_dict(data: Mapping[str, Any], *, where: str = "correction_covariance") -> np.ndarray:
        """The matrix of :meth:`covariance_to_dict`'s data: its parameter order checked, and the
        matrix finite, symmetric and positive definite (every message names ``where`` and the key)."""
        table: Any = data  # any value read from a file: reject_unknown_keys says if it is no table
        reject_unknown_keys(where, table, {"parameters", "matrix"})
        require_keys(where, table, {"parameters", "matrix"})
        if table["parameters"] != list(PARAMETERS):
            raise ParameterError(f"{where}.parameters must be {list(PARAMETERS)}, got {shown(table['parameters'])}")
        rows = table["matrix"]
        n = len(PARAMETERS)
        if not isinstance(rows, list) or len(rows) != n or not all(isinstance(r, list) and len(r) == n for r in rows):
            raise ParameterError(f"{where}.matrix must be {n} rows of {n} numbers, got {shown(rows)}")
        matrix = np.array(
            [[finite_float(f"{where}.matrix[{i}][{j}]", v) for j, v in enumerate(r)] for i, r in enumerate(rows)]
        )
        return _checked_covariance(matrix, where)


def _checked_covariance(cov: np.ndarray, where: str) -> np.ndarray:
    """``cov`` if it is a finite, symmetric, positive definite matrix over :data:`PARAMETERS`."""
    n = len(PARAMETERS)
    if cov.shape != (n, n) or not np.all(np.isfinite(cov)):
        raise ParameterError(f"{where} must be a finite {n} x {n} matrix, got shape {cov.shape}")
    if not np.allclose(cov, cov.T, rtol=1e-9, atol=0.0):
        raise ParameterError(f"{where} must be symmetric")
    if np.linalg.eigvalsh(cov)[0] <= 0.0:
        raise ParameterError(f"{where} must be positive definite (every parameter determined)")
    return cov


def _corrected(
    apply: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]], rays: CapturedRays
) -> CapturedRays:
    """Thin-lens captured rays mapped by a model's ``apply`` (aperture points, slopes -> origins,
    directions); the aperture mask and the lens indices kept."""
    d = rays.directions_cam
    origins, directions = apply(rays.origins_cam[:, :2], d[:, :2] / d[:, 2:3])
    return CapturedRays(
        origins_cam=origins,
        directions_cam=directions,
        in_aperture=rays.in_aperture,
        lens_indices=rays.lens_indices,
    )


def apply_correction(p: np.ndarray, a: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`RayCorrection.apply` for the parameter vector ``p`` (:data:`PARAMETERS`; the fit's form)."""
    m, drift = p[0], p[4]
    slopes = corrected_slopes(p, t)
    shift = drift * np.sum(slopes * slopes, axis=1, keepdims=True) * slopes  # back from z = d |t'|^2 to z = 0
    origins = np.column_stack([m * a - shift, np.zeros(len(a))])
    directions = np.column_stack([slopes, np.ones(len(a))])
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)


def corrected_slopes(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """:meth:`RayCorrection.slopes` for the parameter vector ``p`` (:data:`PARAMETERS`)."""
    s, k1, k2 = p[1], p[2], p[3]
    r2 = np.sum(t * t, axis=1, keepdims=True)
    return s * t * (1.0 + k1 * r2 + k2 * r2 * r2)


# --------------------------------------------------------------------------- the generic member


class Capacity(NamedTuple):
    """A :class:`PolynomialCorrection`'s capacity: its total degree, its largest degree in the aperture
    point, and whether it is rotationally symmetric (:func:`symmetric_directions`)."""

    degree: int
    aperture_degree: int
    symmetric: bool = False


#: The capacities :func:`lfrefract.calibration.calibrate_camera` tries, by their number of free
#: coefficients: the rotationally symmetric members (any centred lens: 15, 39 and 79 free coefficients
#: at degrees 3, 5 and 7), then the generic ones (a decentred lens: from 118 at (3, 1) to 822 at
#: (7, 3)). Measured on true rays (tiny-2x, every 2nd pixel, fitted directly): (3, 1) leaves the
#: double Gauss 0.03 mm / 0.46 mrad from the true rays 25 mm out, (5, 3) 0.002 mm / 0.09 mrad, the
#: retrofocus wide angle 0.002 mm / 0.02 mrad; which one a camera gets is decided by the error on
#: held-back board captures, never by its lens.
POLYNOMIAL_CAPACITIES: tuple[Capacity, ...] = (
    Capacity(3, 3, symmetric=True),
    Capacity(5, 5, symmetric=True),
    Capacity(7, 7, symmetric=True),
    Capacity(3, 1),
    Capacity(4, 1),
    Capacity(5, 1),
    Capacity(5, 2),
    Capacity(6, 2),
    Capacity(7, 2),
    Capacity(7, 3),
)

#: The columns of :attr:`PolynomialCorrection.coefficients`: what each term adds to.
POLYNOMIAL_COLUMNS = ("origin_x_m", "origin_y_m", "slope_x", "slope_y")

#: Residual (normalised coordinates, about 1e-12 of the aperture radius and the field) at which
#: :meth:`PolynomialCorrection.thin_lens_rays` stops.
_POLY_INVERSE_TOLERANCE = 1e-12

#: Largest degree of :class:`PolynomialCorrection` (a sanity bound for files; 84 terms at 8).
_MAX_DEGREE = 8


@functools.cache
def _exponent_table(degree: int, aperture_degree: int) -> np.ndarray:
    rows = [
        (i, j, k, l)
        for total in range(degree + 1)
        for i in range(total, -1, -1)
        for j in range(total - i, -1, -1)
        for k in range(total - i - j, -1, -1)
        for l in (total - i - j - k,)  # noqa: E741 (the fourth exponent)
        if i + j <= aperture_degree
    ]
    table = np.array(rows, dtype=np.int64).reshape(-1, 4)
    table.setflags(write=False)
    return table


def polynomial_exponents(degree: int, aperture_degree: int) -> np.ndarray:
    """The monomials of a :class:`PolynomialCorrection`, shape (M, 4) int: exponents of
    ``(a_x / R, a_y / R, t_x / T, t_y / T)``, total degree at most ``degree`` and at most
    ``aperture_degree`` in ``a``, in a fixed order (by total degree, then lexicographically)."""
    return _exponent_table(int(degree), int(aperture_degree))


def _monomials(x: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """Each monomial of ``exponents`` (M, 4) at the normalised coordinates ``x`` (N, 4): (N, M)."""
    powers = _powers(x, int(exponents.max(initial=0)))
    out = np.ones((x.shape[0], len(exponents)))
    for c in range(4):
        out *= powers[exponents[:, c], :, c].T
    return out


def _powers(x: np.ndarray, top: int) -> np.ndarray:
    """``x ** p`` for p = 0 .. ``top``: (top + 1, *x.shape)."""
    powers = np.ones((top + 1, *x.shape))
    for p in range(1, top + 1):
        powers[p] = powers[p - 1] * x
    return powers


def _jacobian(x: np.ndarray, exponents: np.ndarray, coefficients: np.ndarray) -> np.ndarray:
    """d(monomials @ coefficients)/dx at ``x`` (N, 4): (N, 4 outputs, 4 coordinates); memory (N, M)."""
    powers = _powers(x, int(exponents.max(initial=0)))
    out = np.empty((x.shape[0], coefficients.shape[1], 4))
    for c in range(4):
        e = exponents[:, c]
        grad = powers[np.maximum(e - 1, 0), :, c].T * e  # d/dx x^e = e x^(e-1)
        for other in range(4):
            if other != c:
                grad *= powers[exponents[:, other], :, other].T
        out[:, :, c] = grad @ coefficients
    return out


@dataclass(frozen=True, eq=False, kw_only=True)
class PolynomialCorrection:
    """A generic non-central ray model: polynomial fields over the thin-lens ray's coordinates.

    A thin-lens ray through the aperture point ``a`` (metres, on z = 0) with slopes ``t`` is the
    camera's ray through ``a + dO(a, t)`` on z = 0 with slopes ``t + dT(a, t)``; ``dO`` and ``dT``
    are polynomials in ``(a / R, t / T)`` of total degree at most ``degree`` and at most
    ``aperture_degree`` in ``a`` (:func:`polynomial_exponents`). A plenoptic pixel's thin-lens ray
    is fixed by its microlens (``t``) and its place in the micro-image (``a``), so this is a smooth
    field over both, with no assumption about the lens's symmetry or design: its capacity is chosen
    by :func:`lfrefract.calibration.calibrate_camera` by the error on held-back board captures.
    The zero polynomial is the thin lens.

    The coefficients carry no rigid motion of the camera frame (in-air views cannot see one: the
    board poses absorb it): they have no component along :func:`frame_directions`, so the frame is
    the thin-lens camera's, its origin at the paraxial entrance pupil, the centre of projection.

    Attributes
    ----------
    degree, aperture_degree : int
        Total degree (1 to 8) and degree in ``a`` (0 to ``degree``).
    symmetric : bool
        The coefficients are a rotationally symmetric member's (:func:`symmetric_directions`): what
        the fit was restricted to; a file that says so is checked. Default False.
    aperture_norm_m : float
        ``R``: the aperture coordinates' scale, metres (the aperture radius).
    slope_norm : float
        ``T``: the slopes' scale (the largest slope of the field).
    coefficients : ndarray, shape (M, 4)
        Per monomial, what it adds to ``(dO_x, dO_y, dT_x, dT_y)`` (:data:`POLYNOMIAL_COLUMNS`;
        metres for the origins).
    """

    degree: int
    aperture_degree: int
    aperture_norm_m: float
    slope_norm: float
    coefficients: np.ndarray
    symmetric: bool = False

    def __post_init__(self) -> None:
        degree = bounded_int("degree", self.degree, 1, _MAX_DEGREE)
        object.__setattr__(self, "degree", degree)
        object.__setattr__(self, "aperture_degree", bounded_int("aperture_degree", self.aperture_degree, 0, degree))
        object.__setattr__(
            self, "aperture_norm_m", bounded_float("aperture_norm_m", self.aperture_norm_m, 1e-6, 1.0, unit="m")
        )
        object.__setattr__(self, "slope_norm", bounded_float("slope_norm", self.slope_norm, 1e-3, 10.0))
        n_terms = len(self.exponents)
        try:
            coef = np.array(self.coefficients, dtype=np.float64)
        except (TypeError, ValueError):
            raise ParameterError(f"coefficients must be {n_terms} rows of 4 numbers") from None
        if coef.shape != (n_terms, 4) or not np.all(np.isfinite(coef)):
            raise ParameterError(
                f"coefficients must be {n_terms} rows of 4 finite numbers for degree {degree} / aperture degree "
                f"{self.aperture_degree}, got shape {coef.shape}"
            )
        coef.setflags(write=False)
        object.__setattr__(self, "coefficients", coef)
        if not isinstance(self.symmetric, bool):
            raise ParameterError(f"symmetric must be true or false, got {shown(self.symmetric)}")
        if self.symmetric:
            normalised = (coef / np.array([self.aperture_norm_m] * 2 + [self.slope_norm] * 2)).ravel()
            orthonormal = _symmetric_orthonormal(degree, self.aperture_degree)
            left = normalised - orthonormal @ (orthonormal.T @ normalised)
            if np.max(np.abs(left), initial=0.0) > 1e-9 * max(1.0, float(np.max(np.abs(normalised), initial=0.0))):
                raise ParameterError(
                    "symmetric is true but the coefficients are not a rotationally symmetric model's "
                    f"(largest departure {np.max(np.abs(left)):.3g} in normalised units)"
                )

    @property
    def exponents(self) -> np.ndarray:
        """The monomials, (M, 4) (:func:`polynomial_exponents`)."""
        return polynomial_exponents(self.degree, self.aperture_degree)

    @property
    def name(self) -> str:
        """``"polynomial-D-Da"`` (``"symmetric-D"`` for a symmetric member): how reports name the model."""
        if self.symmetric:
            return f"symmetric-{self.degree}"
        return f"polynomial-{self.degree}-{self.aperture_degree}"

    @property
    def capacity(self) -> Capacity:
        """Its :class:`Capacity`."""
        return Capacity(self.degree, self.aperture_degree, self.symmetric)

    def _normalised(self, a: np.ndarray, t: np.ndarray) -> np.ndarray:
        return np.column_stack([a / self.aperture_norm_m, t / self.slope_norm])

    def monomials(self, aperture_points_m: np.ndarray, slopes: np.ndarray) -> np.ndarray:
        """The monomials at thin-lens rays (aperture points (N, 2), slopes (N, 2)): (N, M)."""
        a, t = np.asarray(aperture_points_m, float), np.asarray(slopes, float)
        return _monomials(self._normalised(a, t), self.exponents)

    def offsets(self, aperture_points_m: np.ndarray, slopes: np.ndarray) -> np.ndarray:
        """``(dO_x, dO_y, dT_x, dT_y)`` of thin-lens rays (aperture points (N, 2), slopes (N, 2)): (N, 4)."""
        return self.monomials(aperture_points_m, slopes) @ self.coefficients

    def origins_and_slopes(self, aperture_points_m: np.ndarray, slopes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The camera's rays as crossings of z = 0 (N, 2, metres) and slopes (N, 2)."""
        a, t = np.asarray(aperture_points_m, float), np.asarray(slopes, float)
        delta = self.offsets(a, t)
        return a + delta[:, :2], t + delta[:, 2:]

    def apply(self, aperture_points_m: np.ndarray, slopes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The camera's rays for thin-lens rays, as :meth:`RayCorrection.apply`: origins (N, 3) on
        z = 0 and unit directions (N, 3)."""
        origins, out = self.origins_and_slopes(aperture_points_m, slopes)
        directions = np.column_stack([out, np.ones(len(out))])
        return np.column_stack([origins, np.zeros(len(out))]), directions / np.linalg.norm(
            directions, axis=1, keepdims=True
        )

    def thin_lens_rays(
        self, points_cam: np.ndarray, directions_cam: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The thin-lens rays that :meth:`apply` maps to the given rays, as
        :meth:`RayCorrection.thin_lens_rays`: Newton's method on the four coordinates, from the
        ray itself; ``found`` where it converged to a root at which the map keeps its orientation
        (positive Jacobian determinant). Outputs are NaN where not found."""
        p = np.asarray(points_cam, dtype=np.float64)
        d = np.asarray(directions_cam, dtype=np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            target_t = d[:, :2] / d[:, 2:3]
        target_o = p[:, :2] - p[:, 2:3] * target_t
        target = np.column_stack([target_o / self.aperture_norm_m, target_t / self.slope_norm])
        scale = np.array([self.aperture_norm_m] * 2 + [self.slope_norm] * 2)
        coef = self.coefficients / scale  # in normalised output units
        exps = self.exponents
        live = np.all(np.isfinite(target), axis=1)
        goal = np.where(live[:, None], target, 0.0)

        def residual_of(xs: np.ndarray, rows: np.ndarray) -> np.ndarray:
            return xs + _monomials(xs, exps) @ coef - goal[rows]

        x = goal - _monomials(goal, exps) @ coef  # one fixed-point step: the map is near the identity
        res = residual_of(x, np.arange(len(x)))
        norm = np.max(np.abs(res), axis=1)
        todo = np.flatnonzero(live & (norm > _POLY_INVERSE_TOLERANCE))
        for _ in range(_INVERSE_MAX_STEPS):
            if len(todo) == 0:
                break
            xs = x[todo]
            jac = np.eye(4) + _jacobian(xs, exps, coef)
            ok = np.abs(np.linalg.det(jac)) > 1e-12
            step = np.zeros_like(xs)
            step[ok] = np.linalg.solve(jac[ok], res[todo][ok][:, :, None])[:, :, 0]
            # Damped: halve the step until the residual shrinks (at most 20 times).
            fraction = np.ones(len(todo))
            trial = xs - step
            trial_res = residual_of(trial, todo)
            trial_norm = np.max(np.abs(trial_res), axis=1)
            for _ in range(20):
                worse = ~(trial_norm < norm[todo]) & ok
                if not np.any(worse):
                    break
                fraction[worse] *= 0.5
                trial[worse] = xs[worse] - fraction[worse, None] * step[worse]
                trial_res[worse] = residual_of(trial[worse], todo[worse])
                trial_norm[worse] = np.max(np.abs(trial_res[worse]), axis=1)
            better = (trial_norm < norm[todo]) & ok
            x[todo[better]] = trial[better]
            res[todo[better]] = trial_res[better]
            norm[todo[better]] = trial_norm[better]
            todo = todo[better & (trial_norm > _POLY_INVERSE_TOLERANCE)]
        det = np.linalg.det(np.eye(4) + _jacobian(x, exps, coef))
        found = live & (norm <= 1e3 * _POLY_INVERSE_TOLERANCE) & (det > 0.0)
        a = np.where(found[:, None], x[:, :2] * self.aperture_norm_m, np.nan)
        t = np.where(found[:, None], x[:, 2:] * self.slope_norm, np.nan)
        return a, t, found

    def corrected(self, rays: CapturedRays) -> CapturedRays:
        """``rays`` (thin-lens captured rays) with the model applied; masks and lenses kept."""
        return _corrected(self.apply, rays)

    def vector(self) -> np.ndarray:
        """The coefficients, flattened row by row (M * 4,)."""
        return self.coefficients.ravel().copy()

    def to_dict(self) -> dict:
        """Plain data: ``family`` ``"polynomial"``, the capacity, the scales and the coefficients."""
        return {
            "family": "polynomial",
            "degree": self.degree,
            "aperture_degree": self.aperture_degree,
            "symmetric": self.symmetric,
            "aperture_norm_m": self.aperture_norm_m,
            "slope_norm": self.slope_norm,
            "columns": list(POLYNOMIAL_COLUMNS),
            "exponents": self.exponents.tolist(),
            "coefficients": self.coefficients.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "correction") -> PolynomialCorrection:
        """From :meth:`to_dict`'s data; its ``columns`` and ``exponents`` are checked against the capacity."""
        table: Any = data
        keys = {"family", "degree", "aperture_degree", "aperture_norm_m", "slope_norm", "columns", "exponents"}
        reject_unknown_keys(where, table, keys | {"coefficients", "symmetric"})
        require_keys(where, table, keys | {"coefficients"})
        if table["family"] != "polynomial":
            raise ParameterError(f"{where}.family must be 'polynomial', got {shown(table['family'])}")
        if table["columns"] != list(POLYNOMIAL_COLUMNS):
            raise ParameterError(f"{where}.columns must be {list(POLYNOMIAL_COLUMNS)}, got {shown(table['columns'])}")
        degree = bounded_int(f"{where}.degree", table["degree"], 1, _MAX_DEGREE)
        aperture = bounded_int(f"{where}.aperture_degree", table["aperture_degree"], 0, degree)
        if table["exponents"] != polynomial_exponents(degree, aperture).tolist():
            raise ParameterError(
                f"{where}.exponents must be the monomials of degree {degree} and aperture degree {aperture} in "
                f"their order (lfrefract.optics.ray_correction.polynomial_exponents), got {shown(table['exponents'])}"
            )
        rows = table["coefficients"]
        if not isinstance(rows, list) or not all(isinstance(r, list) and len(r) == 4 for r in rows):
            raise ParameterError(f"{where}.coefficients must be rows of 4 numbers, got {shown(rows)}")
        values = [
            [finite_float(f"{where}.coefficients[{i}][{j}]", v) for j, v in enumerate(r)] for i, r in enumerate(rows)
        ]
        with named(where):
            return cls(
                degree=degree,
                aperture_degree=aperture,
                symmetric=table.get("symmetric", False),
                aperture_norm_m=table["aperture_norm_m"],
                slope_norm=table["slope_norm"],
                coefficients=np.array(values).reshape(-1, 4),
            )


def frame_directions(exponents: np.ndarray) -> np.ndarray:
    """The six coefficient directions (6, M * 4) that fix the camera frame of a
    :class:`PolynomialCorrection` with the monomials ``exponents`` (M, 4), unit length (normalised
    coefficients, row-major (M, 4)).

    In-air board views see a ray model only up to a rigid motion of the camera frame (every board
    pose moves with it). Of the model's coefficients, six carry such a motion to first order: the
    constant ``dO`` (a shift across the axis), the constant ``dT`` (a turn about x or y), ``dO``
    along ``t`` equally in x and y (a shift along the axis: where the rays cross z = 0) and ``dT``
    turning ``t`` (``dT_x`` along ``t_y`` minus ``dT_y`` along ``t_x``: a turn about the axis). A
    model without them keeps the thin-lens camera's frame: its axial ray is the thin lens's axis, and
    its paraxial chief rays cross z = 0 at the origin (the entrance pupil, the centre of projection).
    A centred lens, whatever its design, has none of them.
    """
    index = {tuple(int(v) for v in e): m for m, e in enumerate(exponents)}
    one, tx, ty = (0, 0, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1)
    directions: list[dict[tuple[int, tuple[int, ...]], float]] = [
        {(0, one): 1.0},
        {(1, one): 1.0},
        {(2, one): 1.0},
        {(3, one): 1.0},
        {(0, tx): 1.0, (1, ty): 1.0},
        {(2, ty): 1.0, (3, tx): -1.0},
    ]
    table = np.zeros((len(directions), len(exponents), 4))
    for g, direction in enumerate(directions):
        for (column, exponent), value in direction.items():
            if exponent in index:
                table[g, index[exponent], column] = value
    out = table.reshape(len(directions), -1)
    norms = np.linalg.norm(out, axis=1, keepdims=True)
    return out[norms[:, 0] > 0] / norms[norms[:, 0] > 0]


def _poly_product(p: dict, q: dict) -> dict:
    """The product of two polynomials given as ``{exponents (4-tuple): coefficient}``."""
    out: dict = {}
    for ep, cp in p.items():
        for eq, cq in q.items():
            key = tuple(i + j for i, j in zip(ep, eq, strict=True))
            out[key] = out.get(key, 0.0) + cp * cq
    return out


@functools.cache
def _symmetric_table(degree: int, aperture_degree: int) -> np.ndarray:
    exponents = polynomial_exponents(degree, aperture_degree)
    index = {tuple(int(v) for v in e): m for m, e in enumerate(exponents)}
    ax, ay, tx, ty = (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1)
    invariants = (
        {(2, 0, 0, 0): 1.0, (0, 2, 0, 0): 1.0},  # |a|^2
        {(0, 0, 2, 0): 1.0, (0, 0, 0, 2): 1.0},  # |t|^2
        {(1, 0, 1, 0): 1.0, (0, 1, 0, 1): 1.0},  # a.t
    )
    rows = []
    top = (degree - 1) // 2
    for i in range(top + 1):
        for j in range(top + 1 - i):
            for k in range(top + 1 - i - j):
                scalar: dict = {(0, 0, 0, 0): 1.0}
                for power, invariant in zip((i, j, k), invariants, strict=True):
                    for _ in range(power):
                        scalar = _poly_product(scalar, invariant)
                # dO and dT, each along a and along t: (column of x, column of y, the vector's x and y).
                for o_col, vector in ((0, (ax, ay)), (0, (tx, ty)), (2, (ax, ay)), (2, (tx, ty))):
                    row = np.zeros((len(exponents), 4))
                    fits = True
                    for axis in range(2):
                        for key, value in _poly_product(scalar, {vector[axis]: 1.0}).items():
                            if key not in index:
                                fits = False
                                break
                            row[index[key], o_col + axis] += value
                    if fits:
                        rows.append(row.ravel())
    table = np.array(rows).reshape(-1, 4 * len(exponents))
    table.setflags(write=False)
    return table


@functools.cache
def _symmetric_orthonormal(degree: int, aperture_degree: int) -> np.ndarray:
    """An orthonormal basis (M * 4, S') of the span of :func:`symmetric_directions`."""
    _, singular, vt = np.linalg.svd(symmetric_directions(degree, aperture_degree), full_matrices=False)
    basis = vt[singular > 1e-9 * singular.max()].T
    basis.setflags(write=False)
    return basis


def symmetric_directions(degree: int, aperture_degree: int) -> np.ndarray:
    """The coefficient directions (S, M * 4) of the rotationally symmetric members of
    :class:`PolynomialCorrection` (normalised coefficients, row-major (M, 4)).

    A centred lens (every surface on one axis, any design) maps a ray turned about the axis to the
    turned ray, and a mirrored ray to the mirrored one. Its ``dO`` and ``dT`` are then sums of
    ``a s(a, t)`` and ``t s(a, t)``, with ``s`` a polynomial in the invariants ``|a|^2``, ``|t|^2`` and
    ``a . t`` (the ray-aberration expansion of a centred system: distortion, pupil aberration,
    field curvature, coma, spherical aberration and their higher orders). Each row is one such term
    whose monomials lie within the capacity (degree, aperture degree).
    """
    return _symmetric_table(int(degree), int(aperture_degree))


#: Every member of the ray-model family: the thin lens is ``None`` (no correction); the calibrated
#: :class:`RayCorrection` and :class:`PolynomialCorrection`; a known prescription traced,
#: :class:`~lfrefract.optics.real_lens.TracedLens` (a render's truth).
Correction = RayCorrection | PolynomialCorrection | TracedLens

#: The members whose rays of one microlens are not parallel and share no centre per view: the
#: synthesis searches their rays with the k-d tree, sub-aperture views refuse them.
UNSTRUCTURED = (PolynomialCorrection, TracedLens)


def moved(correction: Correction, delta: np.ndarray) -> Correction:
    """``correction`` with ``delta`` added to its :meth:`vector` (same family and capacity): how a
    direction of its spread (:func:`lfrefract.calibration.uncertainty.spread_factors`) moves it."""
    step = np.asarray(delta, dtype=np.float64)
    if step.shape != correction.vector().shape or not np.all(np.isfinite(step)):
        raise ParameterError(f"delta must be {correction.vector().size} finite numbers, got shape {step.shape}")
    if isinstance(correction, RayCorrection):
        return RayCorrection.from_vector(correction.vector() + step)
    if isinstance(correction, TracedLens):  # no parameters: delta is empty
        return correction
    return dataclasses.replace(correction, coefficients=correction.coefficients + step.reshape(-1, 4))


def correction_from_dict(data: Any, *, where: str = "correction") -> Correction:
    """A ray correction from its plain data: :class:`PolynomialCorrection` when ``family`` is
    ``"polynomial"``, :class:`~lfrefract.optics.real_lens.TracedLens` when it is ``"traced"``, else
    :class:`RayCorrection` (its files carry no ``family``; ``"radial"`` is accepted for it)."""
    table: Any = data
    if not isinstance(table, Mapping):
        raise ParameterError(f"{where} must be a table, got {shown(table)}")
    family = table.get("family", "radial")
    if family == "polynomial":
        return PolynomialCorrection.from_dict(table, where=where)
    if family == TRACED_FAMILY:
        return TracedLens.from_dict(table, where=where)
    if family != "radial":
        raise ParameterError(f"{where}.family must be 'radial', 'polynomial' or {TRACED_FAMILY!r}, got {shown(family)}")
    return RayCorrection.from_dict({k: v for k, v in table.items() if k != "family"}, where=where)
