"""The light-field camera's own ray model, calibrated from in-air chessboard light fields.

The thin-lens model (:meth:`LightFieldCamera.captured_rays`) gives each raw pixel a ray that leaves
the main-lens plane z = 0 at the aperture point ``a`` with slopes ``t = (dx / dz, dy / dz)``. A real
main lens is not thin: its entrance pupil is magnified, and its rays bend more or less towards the
field's edge (distortion). :class:`~lfrefract.optics.ray_correction.RayCorrection` maps the
thin-lens ray to the camera's:

    slopes ``t' = s t (1 + k1 |t|^2 + k2 |t|^4)`` through ``(m a, d |t'|^2)``,

five parameters: the pupil scale ``m``, the slope (focal) scale ``s``, two radial terms and the
pupil's drift with the field ``d``. The pupil's position along the axis is not among them: in-air
views fix the camera only up to a shift of its frame along z (every board pose shifts with it), so
the model keeps the thin lens's plane z = 0, and a port calibrated on this model measures its
distance in the same frame.

:func:`calibrate_camera` fits the model to chessboard corners located in the light field of in-air
captures (:func:`lfrefract.calibration.port.board_view_from_light_field`: each corner seen from
several aperture points, i.e. several thin-lens rays through it): nonlinear least squares (scipy)
of the five parameters and one board pose per capture, minimising the distance from each corner to
each of its rays (the ray reprojection error of Dansereau et al., CVPR 2013), in metres. Board poses
start from OpenCV's ``solvePnP`` on the central view's corners.

What the boards determine. The slope scale ``s`` (a focal-length correction) is told apart from the
boards' distances only by each board's perspective: a board that spans a few degrees of the field
(small boards, or boards far away) looks nearly the same at distance ``Z`` through slopes ``s t`` as
at ``Z s' / s`` through ``s' t``, and the light field's parallax cannot tell them apart either, since
the pupil scale ``m`` rescales it. The corners of one capture share their errors (the lens's departure
from the five-parameter model, the board's pose), so the fit's Jacobian, which counts every corner
observation as independent, overstates what such captures say. The calibration therefore also
estimates the parameters' spread with each capture as one sample (a covariance clustered by capture,
the "sandwich" estimate); where the slope scale's spread exceeds :data:`MAX_SCALE_STD`, the slope
scale is held at 1, the focal length the capture's file records (the nominal camera's), and the other
four are fitted: :attr:`CameraCalibration.held` says so. Measured on Illum in-air boards of 14 px
squares (2.1-4.9 mm at 0.15-0.35 m, each board 3-5 degrees across): slope scale 0.960 with a
clustered spread of 0.051 when fitted (every board then 4 % too far), the true rays' 1.001; held at
1, the boards come out at their true distances (0.2 %) and the rays 0.11 mm from the true ones 25 mm
out (fitted: 0.52 mm).

Frames and units: camera frame (OpenCV axes: x right, y down, z forward), metres; slopes are
dimensionless; the board's own frame has its corners on z = 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from lfrefract.calibration.distinct import require_distinct_corners, view_names
from lfrefract.calibration.port import MIN_BOARD_CORNERS, BoardView, board_corners
from lfrefract.calibration.ray_fit import CapacityScore, PolynomialFit, choose_capacity, fit_polynomial
from lfrefract.calibration.uncertainty import larger_covariance, spread_factors
from lfrefract.errors import CalibrationError, ParameterError
from lfrefract.formats.jsonio import CAMERA_CALIBRATION_KIND
from lfrefract.optics.camera import CapturedRays, LightFieldCamera
from lfrefract.optics.camera_model import CameraModel
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.ray_correction import (
    HELD_SLOPE_SCALE_STD,
    PARAMETERS,
    POLYNOMIAL_CAPACITIES,
    Capacity,
    Correction,
    CorrectionEstimate,
    PolynomialCorrection,
    RayCorrection,
    apply_correction,
)
from lfrefract.validate import one_of

__all__ = [
    "CAMERA_CALIBRATION_KIND",
    "HELD_SLOPE_SCALE_STD",
    "RAY_MODELS",
    "CameraCalibration",
    "RayCorrection",
    "calibrate_camera",
    "corrected_view",
    "observed_rays",
]

#: The ray models :func:`calibrate_camera` fits: ``"radial"``, the five-parameter
#: :class:`RayCorrection`; ``"polynomial"``, the generic :class:`PolynomialCorrection` whose capacity
#: is chosen by the error on held-back captures (:mod:`lfrefract.calibration.ray_fit`).
RAY_MODELS = ("radial", "polynomial")

#: Fewest board captures a calibration takes: one pose per capture and five shared parameters need
#: views at several distances and angles.
MIN_VIEWS = 3
#: The largest standard deviation of the pupil and slope scales accepted (relative; the larger of the
#: fit's and the capture-clustered one): beyond, the views do not determine the scale. The slope scale
#: is then held at its nominal value; an undetermined pupil scale is an error.
MAX_SCALE_STD = 0.01


@dataclass(frozen=True, eq=False, kw_only=True)
class CameraCalibration:
    """A camera's calibrated ray model (:func:`calibrate_camera`).

    Attributes
    ----------
    camera : LightFieldCamera
        The thin-lens camera the correction applies to (the nominal one the views were located with).
    correction : RayCorrection or PolynomialCorrection
        The fitted model (``ray_model`` of :func:`calibrate_camera`).
    ray_rms_m : float
        RMS distance from each corner to each of its rays at the solution, metres.
    initial_ray_rms_m : float
        The same for the thin-lens model (correction identity) with the poses fitted to it.
    per_view_rms_m : tuple of float
        The RMS per capture, metres.
    correction_std : tuple of float
        Standard deviations of the correction's :data:`~lfrefract.optics.ray_correction.PARAMETERS`
        from the fit's Jacobian (a held parameter: :data:`HELD_SLOPE_SCALE_STD`).
    correction_covariance : ndarray, shape (5, 5)
        Their covariance (marginal over the board poses), scaled by the residual variance: what a
        joint refinement with the port (:func:`lfrefract.calibration.joint.calibrate_port_and_camera`)
        takes as the in-air captures' say. A held parameter has no covariance with the others.
    clustered_std : tuple of float
        The same standard deviations with each capture's corners as one sample (a covariance
        clustered by capture; 0 for a held parameter): what decides whether the slope scale is held.
    held : tuple of str
        The parameters not fitted, held at the nominal camera's value: ``("slope_scale",)`` when the
        captures do not determine it (see the module docstring), else empty.
    poses : tuple of tuple of float
        Each capture's board pose: rotation vector (rad) and translation (m), board to camera frame.
    spread : ndarray, shape (k, n)
        The model's uncertainty as directions of its :meth:`~RayCorrection.vector` (``n`` numbers):
        its covariance is about ``spread.T @ spread``, the larger in every direction of the
        Jacobian's and the capture-clustered one
        (:func:`lfrefract.calibration.uncertainty.spread_factors`). A port calibrated on this model
        propagates it (``model_views`` of :func:`lfrefract.calibration.calibrate_port`).
    capacity_scores : tuple of CapacityScore
        For the polynomial model: each capacity tried with its error on held-back captures
        (:func:`lfrefract.calibration.ray_fit.choose_capacity`); empty for the radial model. The
        polynomial model's ``correction_std``, ``correction_covariance`` and ``clustered_std`` are over
        its free coefficients (normalised, in the basis without rigid motions).
    """

    camera: LightFieldCamera
    correction: RayCorrection | PolynomialCorrection
    ray_rms_m: float
    initial_ray_rms_m: float
    per_view_rms_m: tuple[float, ...]
    correction_std: tuple[float, ...]
    correction_covariance: np.ndarray
    clustered_std: tuple[float, ...]
    held: tuple[str, ...]
    poses: tuple[tuple[float, ...], ...]
    spread: np.ndarray
    capacity_scores: tuple[CapacityScore, ...] = ()

    @property
    def estimate(self) -> CorrectionEstimate:
        """The correction with its covariance (the radial model only).

        Raises
        ------
        CalibrationError
            For the polynomial model, which a joint refinement with the port does not take.
        """
        if not isinstance(self.correction, RayCorrection):
            raise CalibrationError(
                f"the {self.correction.name} ray model has no radial estimate to refine (a joint refinement "
                "with the port takes the radial model only)"
            )
        return CorrectionEstimate(correction=self.correction, covariance=self.correction_covariance)

    @property
    def model(self) -> CameraModel:
        """The calibrated camera model: :attr:`camera`, :attr:`correction`, the radial model's
        :attr:`correction_covariance` (None for the polynomial model, whose covariance is over its
        free coefficients) and :attr:`spread`; what ``camera_model_from_option`` reads back from the
        file :meth:`to_dict` writes."""
        covariance = self.correction_covariance if isinstance(self.correction, RayCorrection) else None
        return CameraModel(camera=self.camera, correction=self.correction, covariance=covariance, spread=self.spread)

    def spread_to_dict(self) -> dict:
        """:attr:`spread` as plain data: its rows and what they mean."""
        return {
            "rows": self.spread.tolist(),
            "meaning": "directions of the correction's parameter vector (the radial model's five parameters, or "
            "the polynomial model's coefficients row by row) whose outer products sum to its covariance",
        }

    def captured_rays(self, uv: np.ndarray | None = None) -> CapturedRays:
        """The calibrated ray of each raw pixel (``uv`` (N, 2) or every pixel, as
        :meth:`LightFieldCamera.captured_rays`)."""
        return self.correction.corrected(self.camera.captured_rays(uv))

    def to_dict(self) -> dict:
        """Plain data for the JSON file (``kind`` :data:`CAMERA_CALIBRATION_KIND`)."""
        common = {
            "kind": CAMERA_CALIBRATION_KIND,
            "camera": self.camera.to_dict(),
            "correction": self.correction.to_dict(),
            "ray_rms_m": self.ray_rms_m,
            "initial_ray_rms_m": self.initial_ray_rms_m,
            "per_view_rms_m": list(self.per_view_rms_m),
            "poses": [list(p) for p in self.poses],
            "correction_spread": self.spread_to_dict(),
        }
        if isinstance(self.correction, PolynomialCorrection):
            return {
                **common,
                "capacity_scores": [s.to_dict() for s in self.capacity_scores],
                "model": "the thin-lens ray (a, t) becomes the ray through a + dO(a, t) on z = 0 with slopes "
                "t + dT(a, t), dO and dT polynomials in (a / aperture_norm_m, t / slope_norm) with the "
                "exponents and coefficients given; lfrefract.optics.ray_correction.PolynomialCorrection",
            }
        return {
            **common,
            "correction_std": dict(zip(PARAMETERS, self.correction_std, strict=True)),
            "correction_covariance": self.estimate.covariance_to_dict(),
            "correction_std_clustered": dict(zip(PARAMETERS, self.clustered_std, strict=True)),
            "held": list(self.held),
            "model": "slopes t' = slope_scale * t * (1 + k1 |t|^2 + k2 |t|^4) through (pupil_scale * a, "
            "pupil_drift_m * |t'|^2) for the thin-lens ray (a, t); lfrefract.optics.ray_correction",
        }


def _board_points(view: BoardView) -> np.ndarray:
    return np.column_stack([view.board_points_m, np.zeros(len(view.board_points_m))])


def observed_rays(view: BoardView, k_inverse: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Aperture points (N, 2, metres on z = 0) and thin-lens slopes (N, 2) of a view's corner
    observations, for the inverse ``k_inverse`` (3, 3) of the views' ``K``."""
    x = np.column_stack([view.corners_px, np.ones(len(view.corners_px))]) @ k_inverse.T
    return view.centres[:, :2], x[:, :2] / x[:, 2:3]


def _distances(p: np.ndarray, pose: np.ndarray, points: np.ndarray, a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Components of each corner's offset from its ray, perpendicular to it, metres (N, 3)."""
    rotation = Rotation.from_rotvec(pose[:3]).as_matrix()
    corners = points @ rotation.T + pose[3:]
    origins, directions = apply_correction(p, a, t)
    return np.cross(corners - origins, directions)


def calibrate_camera(
    camera: LightFieldCamera,
    views: Sequence[BoardView],
    *,
    view: PinholeCamera,
    names: Sequence[str] | None = None,
    ray_model: str = "radial",
    capacities: Sequence[Capacity | tuple[int, int]] = POLYNOMIAL_CAPACITIES,
    progress: Callable[[str], None] | None = None,
) -> CameraCalibration:
    """Fit the ray model of ``camera`` to chessboard light fields taken in air.

    Parameters
    ----------
    camera : LightFieldCamera
        The nominal thin-lens camera (e.g. a Lytro file's metadata); the views were located with it.
    views : sequence of BoardView
        One per in-air capture (:func:`lfrefract.calibration.port.board_view_from_light_field`):
        corners in the pinhole views of ``view`` seen from points of the main-lens plane.
    view : PinholeCamera
        The views' geometry ``K``.
    names : sequence of str, optional
        How errors name the views (their files); default ``views[i]``.
    ray_model : {"radial", "polynomial"}
        Which member of the family to fit (:data:`RAY_MODELS`): the five-parameter radial model, or
        the generic polynomial model, its capacity chosen by the error on held-back captures.
    capacities : sequence of Capacity or (int, int)
        The polynomial model's capacities to choose among, smallest first (default
        :data:`~lfrefract.optics.ray_correction.POLYNOMIAL_CAPACITIES`).
    progress : callable, optional
        Called with a line per capacity tried (the polynomial model).

    Raises
    ------
    CalibrationError
        With fewer than :data:`MIN_VIEWS` views, two views of one board pose
        (:func:`lfrefract.calibration.distinct.require_distinct_corners`: the same capture twice is one
        view), when a pose cannot be started (``solvePnP`` fails),
        or when the pupil scale is not determined (its standard deviation above :data:`MAX_SCALE_STD`;
        an undetermined slope scale is held at 1 instead, see the module docstring).
    """
    if not isinstance(camera, LightFieldCamera):
        raise ParameterError(f"camera must be a LightFieldCamera, got {type(camera).__name__}")
    if not isinstance(view, PinholeCamera):
        raise ParameterError(f"view must be a PinholeCamera, got {type(view).__name__}")
    one_of("ray_model", ray_model, RAY_MODELS)
    views = list(views)
    if not all(isinstance(v, BoardView) for v in views):
        raise ParameterError("views must be BoardView objects")
    labels = view_names(names, len(views), "views")
    if len(views) < MIN_VIEWS:
        raise CalibrationError(f"a camera calibration needs at least {MIN_VIEWS} board captures, got {len(views)}")
    require_distinct_corners([board_corners(v) for v in views], labels, what="a camera calibration")
    k_matrix = view.K
    observed = [(_board_points(v), *observed_rays(v, np.linalg.inv(k_matrix))) for v in views]
    poses = []
    for k, v in enumerate(views):
        central = v.central if v.central.sum() >= 4 else np.ones(len(v.corners_px), dtype=bool)
        ok, rvec, tvec = cv2.solvePnP(_board_points(v)[central], v.corners_px[central], k_matrix, None)
        if not ok:  # OpenCV reports failure by its return value
            raise CalibrationError(f"{labels[k]}: no pose from its central view's corners (cv2.solvePnP)")
        poses.append(np.concatenate([rvec.ravel(), tvec.ravel()]))
    identity = RayCorrection().vector()
    everything = np.ones(len(PARAMETERS), dtype=bool)
    # The thin-lens model's own best poses, for the starting figure and a good start.
    start = _fit(observed, identity, ~everything, np.concatenate(poses))
    if ray_model == "polynomial":
        return _calibrate_polynomial(camera, observed, start, capacities, progress)
    fit = _fit(observed, identity, everything, start.x)
    held: tuple[str, ...] = ()
    if _spread(fit)[_SLOPE] > MAX_SCALE_STD:
        free = everything.copy()
        free[_SLOPE] = False
        held = (PARAMETERS[_SLOPE],)
        fit = _fit(observed, identity, free, start.x)
    spread = _spread(fit)
    if spread[_PUPIL] > MAX_SCALE_STD:
        raise CalibrationError(
            f"the board captures do not determine the camera's ray model: pupil scale {fit.correction[_PUPIL]:.4f} "
            f"+- {spread[_PUPIL]:.2g} (add captures at other distances and angles)"
        )
    return CameraCalibration(
        camera=camera,
        correction=RayCorrection.from_vector(fit.correction),
        ray_rms_m=fit.rms_m,
        initial_ray_rms_m=start.rms_m,
        per_view_rms_m=fit.per_capture_rms_m,
        correction_std=tuple(float(x) for x in np.sqrt(np.diag(fit.covariance))),
        correction_covariance=fit.covariance,
        clustered_std=tuple(float(x) for x in np.sqrt(np.diag(fit.clustered))),
        held=held,
        poses=tuple(tuple(float(x) for x in pose) for pose in fit.poses),
        spread=spread_factors(larger_covariance(fit.covariance, fit.clustered)),
    )


def _calibrate_polynomial(
    camera: LightFieldCamera,
    observed: list,
    start: _Fit,
    capacities: Sequence[Capacity | tuple[int, int]],
    progress: Callable[[str], None] | None,
) -> CameraCalibration:
    """:func:`calibrate_camera` for the polynomial model: its capacity by held-back captures."""
    sensor = camera.sensor
    half_diagonal_m = 0.5 * math.hypot(sensor.width_px, sensor.height_px) * sensor.pixel_pitch_m
    r_norm, t_norm = camera.aperture_radius_m, half_diagonal_m / camera.lens_to_mla_m
    # The priors weigh against the corners' noise: first taken as the thin-lens fit's RMS, then as that
    # of a mid-sized model (the thin lens's includes the lens's departure from it).
    first = fit_polynomial(
        observed,
        capacity=Capacity(5, 5, symmetric=True),
        aperture_norm_m=r_norm,
        slope_norm=t_norm,
        poses=start.poses,
        noise_m=start.rms_m,
    )
    fit, scores = choose_capacity(
        observed,
        aperture_norm_m=r_norm,
        slope_norm=t_norm,
        poses=first.poses,
        noise_m=first.rms_m,
        capacities=capacities,
        progress=progress,
    )
    return CameraCalibration(
        camera=camera,
        correction=fit.correction,
        ray_rms_m=fit.rms_m,
        initial_ray_rms_m=start.rms_m,
        per_view_rms_m=fit.per_capture_rms_m,
        correction_std=tuple(float(x) for x in np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))),
        correction_covariance=fit.covariance,
        clustered_std=tuple(float(x) for x in np.sqrt(np.maximum(np.diag(fit.clustered), 0.0))),
        held=(),
        poses=tuple(tuple(float(x) for x in pose) for pose in fit.poses),
        spread=_coefficient_spread(fit),
        capacity_scores=scores,
    )


def _coefficient_spread(fit: PolynomialFit) -> np.ndarray:
    """The polynomial fit's spread as directions of its coefficients (flattened row by row)."""
    factors = spread_factors(larger_covariance(fit.covariance, fit.clustered))  # (k, P), free basis
    norms = np.array([fit.correction.aperture_norm_m] * 2 + [fit.correction.slope_norm] * 2)
    return np.stack([((fit.basis @ f).reshape(-1, 4) * norms).ravel() for f in factors])


_PUPIL = PARAMETERS.index("pupil_scale")
_SLOPE = PARAMETERS.index("slope_scale")


@dataclass(frozen=True, eq=False)
class _Fit:
    """One least-squares fit of :func:`calibrate_camera` (``x``: the free parameters, then the poses)."""

    x: np.ndarray
    correction: np.ndarray  # (5,) every parameter, held ones at their values
    poses: np.ndarray  # (n, 6)
    rms_m: float
    per_capture_rms_m: tuple[float, ...]
    covariance: np.ndarray  # (5, 5) from the Jacobian; a held parameter's variance HELD_SLOPE_SCALE_STD**2
    clustered: np.ndarray  # (5, 5) clustered by capture; 0 for a held parameter


def _fit(observed: list, nominal: np.ndarray, free: np.ndarray, start: np.ndarray) -> _Fit:
    """Fit the parameters marked ``free`` (the others held at ``nominal``) and one pose per capture.

    The free parameters start at ``nominal``, the poses at the last ``6 n`` values of ``start`` (``n``
    captures). Returns the fit with its covariances (the parameters' block, marginal over the poses).
    """
    n_free = int(free.sum())
    n = len(observed)
    poses0 = start[-6 * n :]

    def correction(q: np.ndarray) -> np.ndarray:
        p = nominal.copy()
        p[free] = q[:n_free]
        return p

    def per_capture(q: np.ndarray) -> list[np.ndarray]:
        p = correction(q)
        return [
            _distances(p, q[n_free + 6 * k : n_free + 6 * k + 6], points, a, t).ravel()
            for k, (points, a, t) in enumerate(observed)
        ]

    solution = least_squares(
        lambda q: np.concatenate(per_capture(q)),
        np.concatenate([nominal[free], poses0]),
        x_scale="jac",
        method="lm",
    )
    parts = per_capture(solution.x)
    rms = [math.sqrt(np.mean(r**2) * 3.0) for r in parts]  # |d x u|^2 is the squared distance: 3 components
    covariance = np.zeros((len(nominal), len(nominal)))
    clustered = np.zeros_like(covariance)
    if n_free:
        jac, fun = solution.jac, solution.fun
        dof = max(1, len(fun) - len(solution.x))
        try:
            bread = np.linalg.pinv(jac.T @ jac)
        except np.linalg.LinAlgError:
            raise CalibrationError("the board captures do not determine the camera's ray model") from None
        # Each capture's corners as one sample: the sum over captures of the outer products of their
        # score vectors J_k^T r_k, between two of the Jacobian's information (with n / (n - 1)).
        bounds = np.cumsum([0, *(len(r) for r in parts)])
        scores = np.stack([jac[bounds[k] : bounds[k + 1]].T @ fun[bounds[k] : bounds[k + 1]] for k in range(n)])
        meat = scores.T @ scores * (n / max(1, n - 1))
        index = np.flatnonzero(free)
        block = np.ix_(index, index)
        covariance[block] = (bread * (float(np.sum(fun**2)) / dof))[:n_free, :n_free]
        clustered[block] = (bread @ meat @ bread)[:n_free, :n_free]
    covariance = (covariance + covariance.T) / 2.0
    clustered = (clustered + clustered.T) / 2.0
    if not free[_SLOPE]:
        covariance[_SLOPE, _SLOPE] = HELD_SLOPE_SCALE_STD**2
    return _Fit(
        x=solution.x,
        correction=correction(solution.x),
        poses=solution.x[n_free:].reshape(n, 6),
        rms_m=math.sqrt(np.mean(solution.fun**2) * 3.0),
        per_capture_rms_m=tuple(rms),
        covariance=covariance,
        clustered=clustered,
    )


def _spread(fit: _Fit) -> np.ndarray:
    """Each parameter's standard deviation, the larger of the Jacobian's and the capture-clustered one."""
    return np.sqrt(np.maximum(np.diag(fit.covariance), np.diag(fit.clustered)))


def corrected_view(view: BoardView, correction: Correction, pinhole: PinholeCamera) -> BoardView:
    """A board view's corners as the calibrated camera sees them: each observation's thin-lens ray
    (its view centre on z = 0 and the line of sight of its pixel in ``pinhole``) corrected, and
    expressed again as a centre and a pixel of ``pinhole``. The port calibration
    (:func:`lfrefract.calibration.calibrate_port`) then works on the calibrated model unchanged.
    Observations whose ray the model's lens stops (a traced lens: NaN) are left out.
    """
    if not isinstance(view, BoardView):
        raise ParameterError(f"view must be a BoardView, got {type(view).__name__}")
    a, t = observed_rays(view, np.linalg.inv(pinhole.K))
    origins, directions = correction.apply(a, t)
    pixels = (directions / directions[:, 2:3]) @ pinhole.K.T
    kept = np.all(np.isfinite(origins), axis=1) & np.all(np.isfinite(pixels), axis=1)
    central = view.central[kept]
    if np.count_nonzero(central) < MIN_BOARD_CORNERS:
        raise ParameterError(
            f"the camera's lens stops {len(kept) - np.count_nonzero(kept)} of a board view's "
            f"{len(kept)} observations (rays outside its lens), leaving {np.count_nonzero(central)} corners "
            f"seen from the lens's centre; a board view needs {MIN_BOARD_CORNERS}"
        )
    return BoardView(
        corners_px=pixels[kept, :2],
        board_points_m=view.board_points_m[kept],
        centres_m=origins[kept],
        central_rows=central,
    )
