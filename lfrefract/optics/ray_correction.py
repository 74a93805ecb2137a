"""A correction of the thin-lens ray model: how a real camera's rays depart from it.

The thin-lens model (:meth:`lfrefract.optics.camera.LightFieldCamera.captured_rays`) gives each raw
pixel a ray leaving the main-lens plane z = 0 at the aperture point ``a`` with slopes
``t = (dx / dz, dy / dz)``. :class:`RayCorrection` maps it to the camera's ray:

    origin ``(m a, 0)``,  slopes ``s t (1 + k1 |t|^2 + k2 |t|^4)``,

the pupil scale ``m``, the slope (focal) scale ``s`` and two radial terms (the main lens's
distortion). :func:`lfrefract.calibration.calibrate_camera` estimates it from in-air chessboard
light fields; the synthesis takes it through
:attr:`lfrefract.synthesis.warp_map.SynthesisOptions.ray_correction`.

Frames and units: camera frame (OpenCV axes), metres; slopes are dimensionless.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from lfrefract.optics.camera import CapturedRays
from lfrefract.validate import bounded_float, finite_float, reject_unknown_keys, require_keys

__all__ = ["RayCorrection", "apply_correction"]


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
    """

    pupil_scale: float = 1.0
    slope_scale: float = 1.0
    k1: float = 0.0
    k2: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "pupil_scale", bounded_float("pupil_scale", self.pupil_scale, 0.5, 2.0))
        object.__setattr__(self, "slope_scale", bounded_float("slope_scale", self.slope_scale, 0.5, 2.0))
        object.__setattr__(self, "k1", bounded_float("k1", self.k1, -10.0, 10.0))
        object.__setattr__(self, "k2", bounded_float("k2", self.k2, -10.0, 10.0))

    @classmethod
    def from_vector(cls, values: np.ndarray) -> RayCorrection:
        """From ``(pupil_scale, slope_scale, k1, k2)``."""
        m, s, k1, k2 = (float(v) for v in values)
        return cls(pupil_scale=m, slope_scale=s, k1=k1, k2=k2)

    def vector(self) -> np.ndarray:
        """``(pupil_scale, slope_scale, k1, k2)``."""
        return np.array([self.pupil_scale, self.slope_scale, self.k1, self.k2])

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
        return {"pupil_scale": self.pupil_scale, "slope_scale": self.slope_scale, "k1": self.k1, "k2": self.k2}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "correction") -> RayCorrection:
        keys = {"pupil_scale", "slope_scale", "k1", "k2"}
        reject_unknown_keys(where, dict(data), keys)
        require_keys(where, dict(data), keys)
        return cls(**{k: finite_float(f"{where}.{k}", data[k]) for k in keys})


def apply_correction(p: np.ndarray, a: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`RayCorrection.apply` for the parameter vector ``p = (m, s, k1, k2)`` (the fit's form)."""
    m, s, k1, k2 = p
    r2 = np.sum(t * t, axis=1, keepdims=True)
    slopes = s * t * (1.0 + k1 * r2 + k2 * r2 * r2)
    origins = np.column_stack([m * a, np.zeros(len(a))])
    directions = np.column_stack([slopes, np.ones(len(a))])
    return origins, directions / np.linalg.norm(directions, axis=1, keepdims=True)
