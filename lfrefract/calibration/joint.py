"""The camera's ray model and the port, refined together on the underwater boards.

The in-air calibration (:func:`lfrefract.calibration.camera.calibrate_camera`) fixes the ray model
from boards 0.2-0.6 m away; the port, centimetres in front of the lens, is then found on that model
(:func:`lfrefract.calibration.port.calibrate_port`). What the far boards barely constrain (the
entrance pupil's scale and its drift with the field) the port's distance depends on most: errors of
the model well inside its in-air uncertainty move the distance by millimetres, always the same way
for every board. The underwater boards see the model too, so here the model and the port are fitted
together. The cost is

    sum over the underwater corners of |r / sigma|^2  +  (p - p0)^T C^-1 (p - p0)

with ``r`` the port calibration's geometric residuals (pixels, :func:`~lfrefract.calibration.port.board_residuals_px`),
``sigma`` their noise (the RMS of the port fitted on the in-air model), ``p`` the correction's
parameters (:data:`~lfrefract.optics.ray_correction.PARAMETERS`), and ``p0``, ``C`` the in-air
calibration's estimate and covariance (marginal over its board poses). To second order this is the
fit of the in-air and the underwater captures together, without the in-air captures at hand: the
camera file carries what they said.

The second term at the solution, ``prior_chi2``, says how far the underwater boards moved the model
in units of its in-air uncertainty (a chi-square with five degrees of freedom if the model were
exact; it is usually far larger, since a five-parameter model does not fit a real lens exactly and
its in-air covariance is too small: the move is still what makes the port right, measured in
docs/calibration.md).

Frames and units: camera frame (OpenCV axes), metres, radians; residuals in pixels of the views' ``K``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from lfrefract.calibration.camera import corrected_view, observed_rays
from lfrefract.calibration.port import (
    BoardView,
    PortCalibration,
    board_residuals_px,
    calibrate_port,
    port_from_parameters,
    port_result,
)
from lfrefract.errors import CalibrationError, ParameterError
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.port import FlatPort
from lfrefract.optics.ray_correction import PARAMETERS, CorrectionEstimate, RayCorrection, apply_correction

__all__ = ["INVALID_PORT_RESIDUAL_PX", "TILT_LIMIT_RAD", "JointCalibration", "calibrate_port_and_camera"]


@dataclass(frozen=True, eq=False)
class JointCalibration:
    """Result of :func:`calibrate_port_and_camera`.

    Attributes
    ----------
    port : PortCalibration
        The port fitted with the refined ray model (its covariance from the joint fit, marginal
        over the ray model and the board poses).
    correction : CorrectionEstimate
        The refined ray model with its covariance after the underwater boards.
    prior : CorrectionEstimate
        The in-air estimate it started from.
    prior_chi2 : float
        ``(p - p0)^T C^-1 (p - p0)``: how far the refined model lies from the in-air one, in units of
        the in-air covariance.
    sequential : PortCalibration
        The port calibrated on the in-air model alone (the start).
    """

    port: PortCalibration
    correction: CorrectionEstimate
    prior: CorrectionEstimate
    prior_chi2: float
    sequential: PortCalibration

    def to_dict(self) -> dict:
        """Plain data for a JSON file: the refinement's record (the port's own data is :attr:`port`'s)."""
        return {
            "correction": self.correction.correction.to_dict(),
            "correction_covariance": self.correction.covariance_to_dict(),
            "in_air_correction": self.prior.correction.to_dict(),
            "in_air_correction_covariance": self.prior.covariance_to_dict(),
            "prior_chi2": self.prior_chi2,
            "sequential_port": self.sequential.port.to_dict(),
            "sequential_rms_px": self.sequential.rms_px,
        }


#: Largest tilt the fit may take (radians), as :func:`~lfrefract.calibration.port.calibrate_port`'s.
TILT_LIMIT_RAD = math.radians(80.0)
#: Residual per component (pixels) of a parameter vector with no valid port (distance <= 0, a tilt
#: beyond :data:`TILT_LIMIT_RAD`): what a line of sight that misses its board costs, so that the
#: solver turns back from such a step instead of failing.
INVALID_PORT_RESIDUAL_PX = 1e3


class _JointProblem:
    """The underwater views' residuals for a parameter vector ``(correction (5), tilt_x_rad,
    tilt_y_rad, distance_m, one pose (6) per view)``."""

    def __init__(self, camera: PinholeCamera, views: list[BoardView], template: FlatPort):
        self.focal_px = camera.focal_px
        self.views = views
        self.template = template
        k_inverse = np.linalg.inv(camera.K)
        self.observed = [observed_rays(v, k_inverse) for v in views]
        self.sizes = [len(v.corners_px) for v in views]

    def residuals_px(self, x: np.ndarray) -> np.ndarray:
        """Every view's residuals (:func:`~lfrefract.calibration.port.board_residuals_px`) in turn,
        pixels; :data:`INVALID_PORT_RESIDUAL_PX` everywhere when ``x`` holds no valid port."""
        npar = len(PARAMETERS)
        tilts, distance_m = x[npar : npar + 2], x[npar + 2]
        if not (distance_m > 0.0 and np.all(np.abs(tilts) < TILT_LIMIT_RAD)):
            return np.full(2 * sum(self.sizes), INVALID_PORT_RESIDUAL_PX)
        port = port_from_parameters(x[npar : npar + 3], self.template)
        parts = []
        for i, ((a, t), view) in enumerate(zip(self.observed, self.views, strict=True)):
            origins, directions = apply_correction(x[:npar], a, t)
            pose6 = x[npar + 3 + 6 * i : npar + 9 + 6 * i]
            parts.append(board_residuals_px(port, origins, directions, view.board_points_m, pose6, self.focal_px))
        return np.concatenate(parts)


def calibrate_port_and_camera(
    camera: PinholeCamera,
    views: Sequence[BoardView],
    *,
    prior: CorrectionEstimate,
    thickness_m: float,
    n_air: float = 1.0,
    n_glass: float = 1.5,
    n_water: float = 1.333,
    distance_range_m: tuple[float, float] = (0.002, 0.3),
    max_normal_std_deg: float = 0.5,
    max_distance_std_m: float = 0.002,
    names: Sequence[str] | None = None,
) -> JointCalibration:
    """Calibrate the port and refine the camera's ray model with it (see the module docstring).

    Parameters
    ----------
    camera : PinholeCamera
        The views' geometry ``K`` (the light-field camera's refraction-free view).
    views : sequence of BoardView
        The underwater board views as located with the thin-lens model (not corrected: the
        correction is what is refined), at least two.
    prior : CorrectionEstimate
        The in-air calibration's ray model and covariance
        (:attr:`lfrefract.calibration.camera.CameraCalibration.estimate`).
    thickness_m, n_air, n_glass, n_water, distance_range_m, max_normal_std_deg, max_distance_std_m, names
        As :func:`lfrefract.calibration.port.calibrate_port`, which starts the fit on the in-air model.

    Returns
    -------
    JointCalibration

    Raises
    ------
    CalibrationError
        As :func:`~lfrefract.calibration.port.calibrate_port`, for the start or for the joint fit;
        also when the joint fit leaves the ray model's valid range.
    """
    if not isinstance(camera, PinholeCamera):
        raise ParameterError(f"camera must be a PinholeCamera, got {type(camera).__name__}")
    if not isinstance(prior, CorrectionEstimate):
        raise ParameterError(f"prior must be a CorrectionEstimate, got {type(prior).__name__}")
    views = list(views)
    if not all(isinstance(v, BoardView) for v in views):
        raise ParameterError("views must be BoardView objects")
    sequential = calibrate_port(
        camera,
        [corrected_view(v, prior.correction, camera) for v in views],
        thickness_m=thickness_m,
        n_air=n_air,
        n_glass=n_glass,
        n_water=n_water,
        distance_range_m=distance_range_m,
        names=names,
        max_normal_std_deg=max_normal_std_deg,
        max_distance_std_m=max_distance_std_m,
    )
    template = sequential.port
    npar = len(PARAMETERS)
    sigma_px = max(sequential.rms_px, 1e-6)  # the corners' noise, as the in-air model leaves it
    p0 = prior.correction.vector()
    # |W (p - p0)|^2 = (p - p0)^T C^-1 (p - p0) for W = L^-1, C = L L^T.
    whiten = scipy.linalg.solve_triangular(np.linalg.cholesky(prior.covariance), np.eye(npar), lower=True)
    problem = _JointProblem(camera, views, template)

    def residuals(x: np.ndarray) -> np.ndarray:
        return np.concatenate([whiten @ (x[:npar] - p0), problem.residuals_px(x) / sigma_px])

    poses = [
        np.concatenate([Rotation.from_matrix(p.rotation).as_rotvec(), p.position_m]) for p in sequential.board_poses
    ]
    x0 = np.concatenate([p0, [template.tilt_x_rad, template.tilt_y_rad, template.distance_m], *poses])
    # Levenberg-Marquardt, unbounded: the valley along the pupil and slope scales is long and flat,
    # and a bounded trust region crawls along it (200 steps 4 units of cost short of the minimum
    # that this reaches in five). The port's range is checked after.
    fit = least_squares(residuals, x0, x_scale="jac", method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=2000)
    distance_m = float(fit.x[npar + 2])
    if not (
        distance_range_m[0] < distance_m < distance_range_m[1]
        and np.all(np.abs(fit.x[npar : npar + 2]) < TILT_LIMIT_RAD)
    ):
        raise CalibrationError(
            f"the joint fit left the port's range: distance {distance_m * 1e3:.4g} mm (range "
            f"{distance_range_m!r} m), tilts {np.degrees(fit.x[npar : npar + 2]).round(2).tolist()} deg (limit 80): "
            "these views do not determine the port's distance together with the ray model (as behind a port "
            "square to the optical axis); calibrate the port on the in-air model alone"
        )
    try:
        correction = RayCorrection.from_vector(fit.x[:npar])
    except ParameterError as exc:
        raise CalibrationError(f"the joint fit left the ray model's valid range: {exc}") from None
    jac = fit.jac
    dof = max(len(fit.fun) - len(fit.x), 1)
    try:
        covariance = np.linalg.inv(jac.T @ jac) * (float(np.sum(fit.fun**2)) / dof)
    except np.linalg.LinAlgError:
        raise CalibrationError("the joint fit is not determined: its normal equations are singular") from None
    port = port_result(
        port_from_parameters(fit.x[npar : npar + 3], template),
        fit.x[npar + 3 :].reshape(-1, 6),
        problem.residuals_px(fit.x),
        problem.sizes,
        covariance[npar : npar + 3, npar : npar + 3],
        max_normal_std_deg=max_normal_std_deg,
        max_distance_std_m=max_distance_std_m,
    )
    refined_covariance = covariance[:npar, :npar]
    try:
        refined = CorrectionEstimate(correction=correction, covariance=(refined_covariance + refined_covariance.T) / 2)
    except ParameterError as exc:
        raise CalibrationError(f"the joint fit does not determine the ray model: {exc}") from None
    return JointCalibration(
        port=port,
        correction=refined,
        prior=prior,
        prior_chi2=float(np.sum((whiten @ (fit.x[:npar] - p0)) ** 2)),
        sequential=sequential,
    )
