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
of the four parameters and one board pose per capture, minimising the distance from each corner to
each of its rays (the ray reprojection error of Dansereau et al., CVPR 2013), in metres. Board poses
start from OpenCV's ``solvePnP`` on the central view's corners.

Frames and units: camera frame (OpenCV axes: x right, y down, z forward), metres; slopes are
dimensionless; the board's own frame has its corners on z = 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from lfrefract.calibration.port import BoardView
from lfrefract.errors import CalibrationError, ParameterError
from lfrefract.optics.camera import CapturedRays, LightFieldCamera
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.optics.ray_correction import PARAMETERS, CorrectionEstimate, RayCorrection, apply_correction

__all__ = [
    "CAMERA_CALIBRATION_KIND",
    "CameraCalibration",
    "RayCorrection",
    "calibrate_camera",
    "corrected_view",
    "observed_rays",
]

#: ``kind`` of the JSON file ``lfrefract calibrate camera`` writes.
CAMERA_CALIBRATION_KIND = "lfrefract.calibrate.camera"
#: Fewest board captures a calibration takes: one pose per capture and four shared parameters need
#: views at several distances and angles.
MIN_VIEWS = 3
#: The largest standard deviation of the pupil and slope scales accepted (relative): beyond, the
#: views do not determine the model (too few, or all alike).
MAX_SCALE_STD = 0.01


@dataclass(frozen=True, eq=False, kw_only=True)
class CameraCalibration:
    """A camera's calibrated ray model (:func:`calibrate_camera`).

    Attributes
    ----------
    camera : LightFieldCamera
        The thin-lens camera the correction applies to (the nominal one the views were located with).
    correction : RayCorrection
    ray_rms_m : float
        RMS distance from each corner to each of its rays at the solution, metres.
    initial_ray_rms_m : float
        The same for the thin-lens model (correction identity) with the poses fitted to it.
    per_view_rms_m : tuple of float
        The RMS per capture, metres.
    correction_std : tuple of float
        Standard deviations of the correction's :data:`~lfrefract.optics.ray_correction.PARAMETERS`
        from the fit's Jacobian.
    correction_covariance : ndarray, shape (5, 5)
        Their covariance (marginal over the board poses), scaled by the residual variance: what a
        joint refinement with the port (:func:`lfrefract.calibration.joint.refine_camera_and_port`)
        takes as the in-air captures' say.
    poses : tuple of tuple of float
        Each capture's board pose: rotation vector (rad) and translation (m), board to camera frame.
    """

    camera: LightFieldCamera
    correction: RayCorrection
    ray_rms_m: float
    initial_ray_rms_m: float
    per_view_rms_m: tuple[float, ...]
    correction_std: tuple[float, ...]
    correction_covariance: np.ndarray
    poses: tuple[tuple[float, ...], ...]

    @property
    def estimate(self) -> CorrectionEstimate:
        """The correction with its covariance."""
        return CorrectionEstimate(correction=self.correction, covariance=self.correction_covariance)

    def captured_rays(self, uv: np.ndarray | None = None) -> CapturedRays:
        """The calibrated ray of each raw pixel (``uv`` (N, 2) or every pixel, as
        :meth:`LightFieldCamera.captured_rays`)."""
        return self.correction.corrected(self.camera.captured_rays(uv))

    def to_dict(self) -> dict:
        """Plain data for the JSON file (``kind`` :data:`CAMERA_CALIBRATION_KIND`)."""
        return {
            "kind": CAMERA_CALIBRATION_KIND,
            "camera": self.camera.to_dict(),
            "correction": self.correction.to_dict(),
            "ray_rms_m": self.ray_rms_m,
            "initial_ray_rms_m": self.initial_ray_rms_m,
            "per_view_rms_m": list(self.per_view_rms_m),
            "correction_std": dict(zip(PARAMETERS, self.correction_std, strict=True)),
            "correction_covariance": self.estimate.covariance_to_dict(),
            "poses": [list(p) for p in self.poses],
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


def calibrate_camera(camera: LightFieldCamera, views: Sequence[BoardView], *, view: PinholeCamera) -> CameraCalibration:
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

    Raises
    ------
    CalibrationError
        With fewer than :data:`MIN_VIEWS` views, when a pose cannot be started (``solvePnP`` fails),
        or when the scales are not determined (their standard deviation above :data:`MAX_SCALE_STD`).
    """
    if not isinstance(camera, LightFieldCamera):
        raise ParameterError(f"camera must be a LightFieldCamera, got {type(camera).__name__}")
    if not isinstance(view, PinholeCamera):
        raise ParameterError(f"view must be a PinholeCamera, got {type(view).__name__}")
    views = list(views)
    if not all(isinstance(v, BoardView) for v in views):
        raise ParameterError("views must be BoardView objects")
    if len(views) < MIN_VIEWS:
        raise CalibrationError(f"a camera calibration needs at least {MIN_VIEWS} board captures, got {len(views)}")
    k_matrix = view.K
    observed = [(_board_points(v), *observed_rays(v, np.linalg.inv(k_matrix))) for v in views]
    poses = []
    for k, v in enumerate(views):
        central = v.central if v.central.sum() >= 4 else np.ones(len(v.corners_px), dtype=bool)
        ok, rvec, tvec = cv2.solvePnP(_board_points(v)[central], v.corners_px[central], k_matrix, None)
        if not ok:  # OpenCV reports failure by its return value
            raise CalibrationError(f"board capture {k}: no pose from its central view's corners (cv2.solvePnP)")
        poses.append(np.concatenate([rvec.ravel(), tvec.ravel()]))
    n = len(views)
    npar = len(PARAMETERS)

    def residuals(q: np.ndarray, fixed: np.ndarray | None) -> np.ndarray:
        p = q[:npar] if fixed is None else fixed
        pose_block = q[npar:] if fixed is None else q
        parts = [
            _distances(p, pose_block[6 * k : 6 * k + 6], points, a, t).ravel()
            for k, (points, a, t) in enumerate(observed)
        ]
        return np.concatenate(parts)

    identity = RayCorrection().vector()
    # The thin-lens model's own best poses, for the starting figure and a good start.
    start = least_squares(residuals, np.concatenate(poses), args=(identity,), x_scale="jac", method="lm")
    initial_rms = math.sqrt(np.mean(start.fun**2) * 3.0)  # |d x u|^2 is the squared distance: 3 components
    solution = least_squares(residuals, np.concatenate([identity, start.x]), args=(None,), x_scale="jac", method="lm")
    p = solution.x[:npar]
    dof = max(1, len(solution.fun) - len(solution.x))
    sigma2 = float(np.sum(solution.fun**2)) / dof
    try:
        covariance = np.linalg.pinv(solution.jac.T @ solution.jac) * sigma2
        std = np.sqrt(np.clip(np.diag(covariance)[:npar], 0.0, None))
        correction_covariance = (covariance[:npar, :npar] + covariance[:npar, :npar].T) / 2.0
    except np.linalg.LinAlgError:
        raise CalibrationError("the board captures do not determine the camera's ray model") from None
    if not (std[0] <= MAX_SCALE_STD and std[1] <= MAX_SCALE_STD):
        raise CalibrationError(
            f"the board captures do not determine the camera's ray model: pupil and slope scales "
            f"{p[0]:.4f} +- {std[0]:.2g} and {p[1]:.4f} +- {std[1]:.2g} (add captures at other distances and angles)"
        )
    per_view = []
    for k, (points, a, t) in enumerate(observed):
        d = _distances(p, solution.x[npar + 6 * k : npar + 6 + 6 * k], points, a, t)
        per_view.append(math.sqrt(np.mean(d**2) * 3.0))
    return CameraCalibration(
        camera=camera,
        correction=RayCorrection.from_vector(p),
        ray_rms_m=math.sqrt(np.mean(solution.fun**2) * 3.0),
        initial_ray_rms_m=initial_rms,
        per_view_rms_m=tuple(per_view),
        correction_std=tuple(float(s) for s in std),
        correction_covariance=correction_covariance,
        poses=tuple(tuple(float(x) for x in solution.x[npar + 6 * k : npar + 6 + 6 * k]) for k in range(n)),
    )


def corrected_view(view: BoardView, correction: RayCorrection, pinhole: PinholeCamera) -> BoardView:
    """A board view's corners as the calibrated camera sees them: each observation's thin-lens ray
    (its view centre on z = 0 and the line of sight of its pixel in ``pinhole``) corrected, and
    expressed again as a centre and a pixel of ``pinhole``. The port calibration
    (:func:`lfrefract.calibration.calibrate_port`) then works on the calibrated model unchanged.
    """
    if not isinstance(view, BoardView):
        raise ParameterError(f"view must be a BoardView, got {type(view).__name__}")
    a, t = observed_rays(view, np.linalg.inv(pinhole.K))
    origins, directions = correction.apply(a, t)
    pixels = (directions / directions[:, 2:3]) @ pinhole.K.T
    return BoardView(
        corners_px=pixels[:, :2], board_points_m=view.board_points_m, centres_m=origins, central_rows=view.central
    )
