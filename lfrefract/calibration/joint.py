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

The refined model is kept only if it predicts boards it was not fitted on better than the in-air
model does (:class:`HeldBackCheck`): the boards are split into folds; for each, the port alone on
the in-air model and the port with the model are fitted without the fold's boards, and each held-back
board's pose alone is fitted with them fixed. The joint result is kept if its pooled held-back RMS is
lower by more than one standard error of the difference (paired over boards); otherwise the port on
the in-air model (:attr:`JointCalibration.sequential`) and the in-air model are.

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
from lfrefract.calibration.distinct import view_names
from lfrefract.calibration.port import (
    BoardView,
    PortCalibration,
    board_residuals_px,
    calibrate_port,
    port_from_parameters,
    port_result,
)
from lfrefract.calibration.uncertainty import fit_covariances, larger_covariance
from lfrefract.errors import CalibrationError, ParameterError
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.port import FlatPort
from lfrefract.optics.pose import Pose
from lfrefract.optics.ray_correction import PARAMETERS, CorrectionEstimate, RayCorrection, apply_correction

__all__ = [
    "HELD_BACK_FOLDS",
    "INVALID_PORT_RESIDUAL_PX",
    "MIN_CHECK_BOARDS",
    "TILT_LIMIT_RAD",
    "HeldBackCheck",
    "JointCalibration",
    "calibrate_port_and_camera",
]

#: Most folds the held-back check splits the boards into (each board is held back in one of them).
HELD_BACK_FOLDS = 5
#: Fewest boards the held-back check runs on: with fewer, a fold's fits would rest on two boards.
MIN_CHECK_BOARDS = 4
#: The verdicts of :class:`HeldBackCheck`: the jointly refined model, or the in-air one.
KEPT = ("joint", "in-air")


@dataclass(frozen=True)
class HeldBackCheck:
    """Whether the refined ray model predicts held-back boards better than the in-air model.

    Attributes
    ----------
    kept : {"joint", "in-air"}
        Which result :func:`calibrate_port_and_camera` returns.
    reason : str
        Why, in one sentence (with the figures below).
    in_air_rms_px, joint_rms_px : float or None
        Pooled RMS of the held-back boards' residuals (:func:`~lfrefract.calibration.port.board_residuals_px`,
        pixels) with the port fitted on the in-air model alone, and with the port and model fitted
        together, each without the board; None where the check did not run.
    standard_error_px : float or None
        Standard error of ``in_air_rms_px - joint_rms_px`` (pixels), paired over the held-back boards.
    folds : int
        Folds the boards were split into (0: the check did not run).
    board_in_air_rms_px, board_joint_rms_px : tuple of float
        Each held-back board's RMS (pixels), in the order of the views; empty where the check did not run.
    """

    kept: str
    reason: str
    in_air_rms_px: float | None = None
    joint_rms_px: float | None = None
    standard_error_px: float | None = None
    folds: int = 0
    board_in_air_rms_px: tuple[float, ...] = ()
    board_joint_rms_px: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.kept not in KEPT:
            raise ParameterError(f"kept must be one of {KEPT}, got {self.kept!r}")

    @property
    def accepted(self) -> bool:
        """True if the jointly refined model is kept."""
        return self.kept == "joint"

    def to_dict(self) -> dict:
        """Plain data for a JSON file."""
        return {
            "kept": self.kept,
            "reason": self.reason,
            "in_air_rms_px": self.in_air_rms_px,
            "joint_rms_px": self.joint_rms_px,
            "standard_error_px": self.standard_error_px,
            "folds": self.folds,
            "board_in_air_rms_px": list(self.board_in_air_rms_px),
            "board_joint_rms_px": list(self.board_joint_rms_px),
        }


@dataclass(frozen=True, eq=False)
class JointCalibration:
    """Result of :func:`calibrate_port_and_camera`.

    Attributes
    ----------
    port : PortCalibration
        The port kept (:attr:`check`): :attr:`joint_port` if the refinement was accepted, else
        :attr:`sequential`.
    correction : CorrectionEstimate
        The ray model kept: :attr:`joint_correction` if the refinement was accepted, else :attr:`prior`.
    prior : CorrectionEstimate
        The in-air estimate it started from.
    prior_chi2 : float
        ``(p - p0)^T C^-1 (p - p0)``: how far the refined model lies from the in-air one, in units of
        the in-air covariance.
    sequential : PortCalibration
        The port calibrated on the in-air model alone (the start).
    joint_port : PortCalibration
        The port fitted with the refined ray model (its covariance from the joint fit, marginal over
        the ray model and the board poses), kept or not.
    joint_correction : CorrectionEstimate
        The refined ray model with its covariance after the underwater boards, kept or not.
    check : HeldBackCheck
        The held-back check's verdict and figures.
    """

    port: PortCalibration
    correction: CorrectionEstimate
    prior: CorrectionEstimate
    prior_chi2: float
    sequential: PortCalibration
    joint_port: PortCalibration
    joint_correction: CorrectionEstimate
    check: HeldBackCheck

    @property
    def accepted(self) -> bool:
        """True if the refined model (and its port) is kept."""
        return self.check.accepted

    def to_dict(self) -> dict:
        """Plain data for a JSON file: the refinement's record (the kept port's own data is :attr:`port`'s).
        ``correction`` is the refined model whether kept or not; ``held_back`` says which was kept."""
        return {
            "kept": self.check.kept,
            "held_back": self.check.to_dict(),
            "correction": self.joint_correction.correction.to_dict(),
            "correction_covariance": self.joint_correction.covariance_to_dict(),
            "in_air_correction": self.prior.correction.to_dict(),
            "in_air_correction_covariance": self.prior.covariance_to_dict(),
            "prior_chi2": self.prior_chi2,
            "joint_port": self.joint_port.port.to_dict(),
            "joint_rms_px": self.joint_port.rms_px,
            "sequential_port": self.sequential.port.to_dict(),
            "sequential_rms_px": self.sequential.rms_px,
        }


#: Largest tilt the fit may take (radians), as :func:`~lfrefract.calibration.port.calibrate_port`'s.
TILT_LIMIT_RAD = math.radians(80.0)
#: Residual per component (pixels) of a parameter vector with no valid port (distance <= 0, a tilt
#: beyond :data:`TILT_LIMIT_RAD`): what a line of sight that misses its board costs, so that the
#: solver turns back from such a step instead of failing.
INVALID_PORT_RESIDUAL_PX = 1e3
#: Standard deviation limits of a fold's fits in the held-back check (degrees, metres): a fit on
#: fewer boards may be less certain than the command accepts; what it predicts is what is checked.
_FOLD_LIMITS = {"max_normal_std_deg": 180.0, "max_distance_std_m": 1e3}


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

    def view_residuals_px(self, p: np.ndarray, port: FlatPort, view: int, pose6: np.ndarray) -> np.ndarray:
        """One view's residuals (:func:`~lfrefract.calibration.port.board_residuals_px`, pixels, (2 N,))
        with the correction parameters ``p`` (5,), ``port`` and the board pose ``pose6`` (rad, m)."""
        origins, directions = apply_correction(p, *self.observed[view])
        return board_residuals_px(port, origins, directions, self.views[view].board_points_m, pose6, self.focal_px)

    def residuals_px(self, x: np.ndarray) -> np.ndarray:
        """Every view's residuals (:func:`~lfrefract.calibration.port.board_residuals_px`) in turn,
        pixels; :data:`INVALID_PORT_RESIDUAL_PX` everywhere when ``x`` holds no valid port."""
        npar = len(PARAMETERS)
        tilts, distance_m = x[npar : npar + 2], x[npar + 2]
        if not (distance_m > 0.0 and np.all(np.abs(tilts) < TILT_LIMIT_RAD)):
            return np.full(2 * sum(self.sizes), INVALID_PORT_RESIDUAL_PX)
        port = port_from_parameters(x[npar : npar + 3], self.template)
        return np.concatenate(
            [
                self.view_residuals_px(x[:npar], port, i, x[npar + 3 + 6 * i : npar + 9 + 6 * i])
                for i in range(len(self.views))
            ]
        )

    def held_back_sum(self, p: np.ndarray, port: FlatPort, view: int, start: np.ndarray) -> float:
        """Sum of squared residuals (pixels^2) of one view with only its board pose fitted (from
        ``start``, rad and m), the correction ``p`` and the port fixed."""
        fit = least_squares(lambda pose6: self.view_residuals_px(p, port, view, pose6), start, method="lm")
        return float(np.sum(fit.fun**2))


def _port_fit(
    problem: _JointProblem, p: np.ndarray, start_port: FlatPort, start_poses: np.ndarray
) -> tuple[FlatPort, np.ndarray, float] | None:
    """The port alone on the ray model of correction parameters ``p`` (5,), from a port and board
    poses near the answer: what :func:`~lfrefract.calibration.port.calibrate_port` fits on the views
    corrected by ``p`` (the same residuals), without its search for a start.

    Parameters
    ----------
    problem : _JointProblem
        The views.
    p : ndarray, shape (5,)
        The correction's parameters (:data:`PARAMETERS`), held fixed.
    start_port : FlatPort
    start_poses : ndarray, shape (V, 6)
        One board pose per view: rotation vector (rad), translation (m).

    Returns
    -------
    tuple of (FlatPort, ndarray (V, 6), float) or None
        The port, the poses and the residuals' RMS (pixels); None where the fit leaves every valid port.
    """
    # Levenberg-Marquardt, as the joint fit (a bounded trust region crawls along the distance's valley).
    fit = least_squares(
        lambda x: problem.residuals_px(np.concatenate([p, x])),
        np.concatenate([[start_port.tilt_x_rad, start_port.tilt_y_rad, start_port.distance_m], start_poses.ravel()]),
        x_scale="jac",
        method="lm",
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
        max_nfev=2000,
    )
    if np.all(fit.fun == INVALID_PORT_RESIDUAL_PX):
        return None
    port = port_from_parameters(fit.x[:3], problem.template)
    return port, fit.x[3:].reshape(-1, 6), float(math.sqrt(np.mean(fit.fun**2)))


def _joint_fit(
    camera: PinholeCamera,
    views: list[BoardView],
    prior: CorrectionEstimate,
    start: tuple[FlatPort, np.ndarray, float],
    *,
    distance_range_m: tuple[float, float],
    max_normal_std_deg: float,
    max_distance_std_m: float,
) -> tuple[PortCalibration, CorrectionEstimate, float]:
    """The port and the ray model fitted together (the module docstring's cost), from the port on
    the in-air model fitted on the same ``views``: ``start`` holds that port, its board poses (V, 6)
    (rotation vector (rad), translation (m)) and its residuals' RMS (pixels, the corners' noise).

    Returns
    -------
    tuple of (PortCalibration, CorrectionEstimate, float)
        The port, the refined model with its covariance, and ``prior_chi2``.

    Raises
    ------
    CalibrationError
        As :func:`calibrate_port_and_camera`.
    """
    template, poses, rms_px = start
    npar = len(PARAMETERS)
    sigma_px = max(rms_px, 1e-6)  # the corners' noise, as the in-air model leaves it
    p0 = prior.correction.vector()
    # |W (p - p0)|^2 = (p - p0)^T C^-1 (p - p0) for W = L^-1, C = L L^T.
    whiten = scipy.linalg.solve_triangular(np.linalg.cholesky(prior.covariance), np.eye(npar), lower=True)
    problem = _JointProblem(camera, views, template)

    def residuals(x: np.ndarray) -> np.ndarray:
        return np.concatenate([whiten @ (x[:npar] - p0), problem.residuals_px(x) / sigma_px])

    x0 = np.concatenate([p0, [template.tilt_x_rad, template.tilt_y_rad, template.distance_m], poses.ravel()])
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
        bread = np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        raise CalibrationError("the joint fit is not determined: its normal equations are singular") from None
    # As the port on a fixed model (calibrate_port): the larger of the Jacobian's covariance and the one
    # clustered by capture (a capture's corners share errors the model cannot follow), the in-air prior
    # one more cluster. With the Jacobian's alone 2 of 25 synthetic joint ports (five lenses, five seeds)
    # lay beyond three stated sigma (benchmarks/measure_port_uncertainty.py --ray-model radial --refine).
    bounds = np.cumsum([0, npar, *(2 * size for size in problem.sizes)])
    pixel, by_capture = fit_covariances(jac, fit.fun, bread, float(np.sum(fit.fun**2)) / dof, bounds)
    covariance = larger_covariance(pixel, by_capture)
    block = slice(npar, npar + 3)
    port = port_result(
        port_from_parameters(fit.x[npar : npar + 3], template),
        fit.x[npar + 3 :].reshape(-1, 6),
        problem.residuals_px(fit.x),
        problem.sizes,
        covariance[block, block],
        max_normal_std_deg=max_normal_std_deg,
        max_distance_std_m=max_distance_std_m,
        parts={
            "pixel_noise": pixel[block, block],
            "by_capture": by_capture[block, block],
            "noise": covariance[block, block],  # the camera model's share within: it is a parameter here
        },
    )
    refined_covariance = covariance[:npar, :npar]
    try:
        refined = CorrectionEstimate(correction=correction, covariance=(refined_covariance + refined_covariance.T) / 2)
    except ParameterError as exc:
        raise CalibrationError(f"the joint fit does not determine the ray model: {exc}") from None
    return port, refined, float(np.sum((whiten @ (fit.x[:npar] - p0)) ** 2))


def _poses6(poses: Sequence[Pose]) -> np.ndarray:
    """Board poses as rows (V, 6) of rotation vector (rad) and translation (m)."""
    return np.array([np.concatenate([Rotation.from_matrix(p.rotation).as_rotvec(), p.position_m]) for p in poses])


def _fold_of(count: int) -> np.ndarray:
    """The fold (0 .. k - 1) each of ``count`` boards is held back in: ``k = min(HELD_BACK_FOLDS,
    count)`` folds, boards dealt in turn (neighbouring captures fall in different folds)."""
    return np.arange(count) % min(HELD_BACK_FOLDS, count)


def _verdict(in_air: np.ndarray, joint: np.ndarray, sizes: np.ndarray, folds: int) -> HeldBackCheck:
    """The check's verdict from each held-back board's sums of squared residuals (pixels^2) with the
    in-air and the joint fits, and its residual count ``sizes``.

    The pooled mean squares differ by ``D = sum_i (a_i - b_i) / N``; paired over the ``n`` boards,
    ``D`` is the weighted mean of ``d_i = (a_i - b_i) / N_i`` with weights ``w_i = N_i / N``, of
    standard error ``sqrt(n / (n - 1) sum_i w_i^2 (d_i - D)^2)``. The RMS values differ by
    ``D / (rms_a + rms_b)``, and their standard error is scaled alike.
    """
    total = float(np.sum(sizes))
    rms_a, rms_b = math.sqrt(float(np.sum(in_air)) / total), math.sqrt(float(np.sum(joint)) / total)
    d, w = (in_air - joint) / sizes, sizes / total
    mean = float(np.sum(w * d))
    n = len(sizes)
    se = math.sqrt(n / (n - 1) * float(np.sum((w * (d - mean)) ** 2))) / max(rms_a + rms_b, 1e-300)
    gain = rms_a - rms_b
    figures = (
        f"on held-back boards ({n}, {folds} folds) the corners miss by {rms_b:.4g} px RMS with the refined model "
        f"and {rms_a:.4g} px with the in-air model: "
    )
    if gain > se:
        kept, why = "joint", f"lower by {gain:.3g} px, more than its standard error {se:.3g} px"
    else:
        side = "lower" if gain >= 0 else "higher"
        kept, why = "in-air", f"{side} by {abs(gain):.3g} px, against a standard error of {se:.3g} px"
    return HeldBackCheck(
        kept=kept,
        reason=figures + why,
        in_air_rms_px=rms_a,
        joint_rms_px=rms_b,
        standard_error_px=se,
        folds=folds,
        board_in_air_rms_px=tuple(np.sqrt(in_air / sizes).tolist()),
        board_joint_rms_px=tuple(np.sqrt(joint / sizes).tolist()),
    )


def _held_back_check(
    camera: PinholeCamera,
    views: list[BoardView],
    prior: CorrectionEstimate,
    sequential: PortCalibration,
    *,
    distance_range_m: tuple[float, float],
    names: Sequence[str] | None,
) -> HeldBackCheck:
    """Cross-validate the joint fit against the port on the in-air model (the module docstring).

    Each fold's port on the in-air model is fitted by :func:`_port_fit` from ``sequential`` (the
    same cost as :func:`~lfrefract.calibration.port.calibrate_port`'s, without its search for a
    start), its joint fit by :func:`_joint_fit` from that; each held-back board's pose starts from
    ``sequential``'s.

    Parameters
    ----------
    camera, views, prior, distance_range_m
        As :func:`calibrate_port_and_camera`.
    sequential : PortCalibration
        The port on the in-air model fitted on every view.
    names : sequence of str or None
        How the reason names the views (default ``views[i]``).

    Returns
    -------
    HeldBackCheck
        ``kept="in-air"`` with the reason where the check cannot run (fewer than
        :data:`MIN_CHECK_BOARDS` boards, or the port on the in-air model fails on a fold) or where the
        joint fit fails on a fold.
    """
    if len(views) < MIN_CHECK_BOARDS:
        return HeldBackCheck(
            kept="in-air",
            reason=f"the held-back check needs at least {MIN_CHECK_BOARDS} boards, got {len(views)}: "
            "the refinement cannot be checked",
        )
    fold = _fold_of(len(views))
    folds = int(fold.max()) + 1
    shown = view_names(names, len(views), "views")
    problem = _JointProblem(camera, views, sequential.port)
    starts = _poses6(sequential.board_poses)
    sums = np.zeros((2, len(views)))
    p0 = prior.correction.vector()
    for k in range(folds):
        train, held = np.flatnonzero(fold != k), np.flatnonzero(fold == k)
        without = ", ".join(shown[i] for i in held)
        train_views = [views[i] for i in train]
        in_air = _port_fit(_JointProblem(camera, train_views, sequential.port), p0, sequential.port, starts[train])
        if in_air is None or not distance_range_m[0] < in_air[0].distance_m < distance_range_m[1]:
            return HeldBackCheck(
                kept="in-air",
                reason=f"the held-back check cannot run: without {without} the port on the in-air model leaves "
                f"its range (distance_range_m={distance_range_m!r})",
            )
        try:
            joint_port, joint_model, _ = _joint_fit(
                camera, train_views, prior, in_air, distance_range_m=distance_range_m, **_FOLD_LIMITS
            )
        except CalibrationError as exc:
            return HeldBackCheck(kept="in-air", reason=f"without {without} the joint fit fails ({exc})")
        p = joint_model.correction.vector()
        for i in held.tolist():
            sums[0, i] = problem.held_back_sum(p0, in_air[0], i, starts[i])
            sums[1, i] = problem.held_back_sum(p, joint_port.port, i, starts[i])
    return _verdict(sums[0], sums[1], 2.0 * np.array(problem.sizes, dtype=float), folds)


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
    """Calibrate the port and refine the camera's ray model with it, kept only if it predicts
    held-back boards better (see the module docstring).

    Parameters
    ----------
    camera : PinholeCamera
        The views' geometry ``K`` (the light-field camera's refraction-free view).
    views : sequence of BoardView
        The underwater board views as located with the thin-lens model (not corrected: the
        correction is what is refined), at least two; the held-back check needs
        :data:`MIN_CHECK_BOARDS`.
    prior : CorrectionEstimate
        The in-air calibration's ray model and covariance
        (:attr:`lfrefract.calibration.camera.CameraCalibration.estimate`).
    thickness_m, n_air, n_glass, n_water, distance_range_m, max_normal_std_deg, max_distance_std_m, names
        As :func:`lfrefract.calibration.port.calibrate_port`, which starts the fit on the in-air model.

    Returns
    -------
    JointCalibration
        Its ``port`` and ``correction`` the joint fit's if the held-back check accepted it
        (:attr:`JointCalibration.check`), else the port on the in-air model and the in-air model.

    Raises
    ------
    CalibrationError
        As :func:`~lfrefract.calibration.port.calibrate_port`, for the start or for the joint fit on
        every view; also when the joint fit leaves the ray model's valid range. (A joint fit that
        fails on a fold of the held-back check rejects the refinement instead.)
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
    start = (sequential.port, _poses6(sequential.board_poses), sequential.rms_px)
    joint_port, refined, prior_chi2 = _joint_fit(
        camera,
        views,
        prior,
        start,
        distance_range_m=distance_range_m,
        max_normal_std_deg=max_normal_std_deg,
        max_distance_std_m=max_distance_std_m,
    )
    check = _held_back_check(camera, views, prior, sequential, distance_range_m=distance_range_m, names=names)
    return JointCalibration(
        port=joint_port if check.accepted else sequential,
        correction=refined if check.accepted else prior,
        prior=prior,
        prior_chi2=prior_chi2,
        sequential=sequential,
        joint_port=joint_port,
        joint_correction=refined,
        check=check,
    )
