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

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import CapturedRays
from lfrefract.validate import bounded_float, finite_float, reject_unknown_keys, require_keys, shown

__all__ = ["PARAMETERS", "CorrectionEstimate", "RayCorrection", "apply_correction", "corrected_slopes"]

#: Newton steps :meth:`RayCorrection.thin_lens_rays` takes at most (3 on the Illum's calibrated
#: model over slopes up to 0.35: the radial terms are a few per cent of the slope).
_INVERSE_MAX_STEPS = 50

#: Relative residual of the slope equation below which a root counts as found (a few ulps).
_INVERSE_TOLERANCE = 1e-14

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
        d = rays.directions_cam
        origins, directions = self.apply(rays.origins_cam[:, :2], d[:, :2] / d[:, 2:3])
        return CapturedRays(
            origins_cam=origins,
            directions_cam=directions,
            in_aperture=rays.in_aperture,
            lens_indices=rays.lens_indices,
        )

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
