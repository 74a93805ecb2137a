"""Two-view stereo on refraction-free images: calibration, rectification, matching, triangulation.

Refraction-free images are exact, distortion-free pinhole images (:class:`~lfrefract.optics.pinhole.PinholeCamera`),
so two of them are an ordinary stereo pair (paper section 4.2): the relative pose is calibrated
from chessboard corners with the intrinsics held fixed, the pair is rectified, a disparity map is
computed (the paper's NCC cost, :func:`zncc_disparity`, or OpenCV's semi-global matcher,
:func:`sgbm_disparity`) and triangulated back into the left camera's frame.

Frames and conventions (``docs/conventions.md``):

- Camera frames are OpenCV's: +x right, +y down, +z forward, metres; pixel centres at integers.
- :class:`StereoCalibration` maps points of the left camera frame to the right camera frame:
  ``X_r = rotation @ X_l + translation_m``. The right camera centre in the left frame is
  ``-rotation.T @ translation_m``; it must lie towards +x (to the right) for the disparity
  convention below to hold.
- Rectification rotates each camera about its centre: ``X_rect_left = R1 @ X_l`` and
  ``X_rect_right = R2 @ X_r``. The rectified left frame has its origin at the left camera centre.
- Disparity is ``d = x_left - x_right`` (pixels, rectified images, same row), float32, NaN where
  there is no estimate. With :data:`cv2.CALIB_ZERO_DISPARITY` both rectified principal points
  coincide, so a point at depth ``Z`` (rectified left frame) has ``d = f * B / Z > 0``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.validate import (
    as_points,
    finite_float,
    finite_vector,
    non_negative_float,
    one_of,
    positive_int,
    reject_unknown_keys,
    require_keys,
)

__all__ = [
    "Rectification",
    "StereoCalibration",
    "calibrate_stereo",
    "disparity_to_depth",
    "disparity_to_points",
    "rectify",
]

#: Largest deviation of ``R @ R.T`` from the identity accepted for a rotation matrix.
_ROTATION_TOLERANCE = 1e-6

_ZERO_DISPARITY = getattr(cv2, "STEREO_ZERO_DISPARITY", cv2.CALIB_ZERO_DISPARITY)


def _readonly(value: Any, dtype: type = np.float64) -> np.ndarray:
    out: np.ndarray = np.array(value, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def _rotation(name: str, value: Any) -> np.ndarray:
    r = np.asarray(value, dtype=np.float64)
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise ParameterError(f"{name} must be a finite 3x3 matrix, got {np.asarray(value).tolist()!r}")
    if np.max(np.abs(r @ r.T - np.eye(3))) > _ROTATION_TOLERANCE or np.linalg.det(r) < 0:
        raise ParameterError(f"{name} must be a proper rotation matrix, got {r.round(9).tolist()}")
    return r


def _pinhole(name: str, value: Any) -> PinholeCamera:
    if not isinstance(value, PinholeCamera):
        raise ParameterError(f"{name} must be a PinholeCamera, got {value!r}")
    return value


# =============================================================================== calibration
@dataclass(frozen=True, kw_only=True, eq=False)
class StereoCalibration:
    """Two pinhole cameras and their relative pose.

    Parameters
    ----------
    left, right : PinholeCamera
        Intrinsics and image sizes of the two (refraction-free) images.
    rotation : ndarray, shape (3, 3)
        Proper rotation ``R`` taking left-camera-frame vectors to the right camera frame.
    translation_m : ndarray, shape (3,)
        ``t`` in ``X_r = R @ X_l + t``, metres (the left camera centre seen from the right
        camera). Must not be zero.
    rms_px : float
        RMS reprojection error of the calibration that produced it, pixels (0 if not calibrated).
    """

    left: PinholeCamera
    right: PinholeCamera
    rotation: np.ndarray
    translation_m: np.ndarray
    rms_px: float = 0.0

    def __post_init__(self) -> None:
        _pinhole("left", self.left)
        _pinhole("right", self.right)
        rotation = _rotation("rotation", self.rotation)
        translation = np.array(finite_vector("translation_m", np.ravel(self.translation_m), 3))
        if not np.any(translation):
            raise ParameterError(f"translation_m must not be zero (no baseline), got {translation.tolist()}")
        object.__setattr__(self, "rotation", _readonly(rotation))
        object.__setattr__(self, "translation_m", _readonly(translation))
        object.__setattr__(self, "rms_px", non_negative_float("rms_px", self.rms_px))

    @property
    def baseline_m(self) -> float:
        """Distance between the camera centres, metres."""
        return float(np.linalg.norm(self.translation_m))

    @property
    def right_centre_m(self) -> np.ndarray:
        """Right camera centre in the left camera frame (3,), metres: ``-R.T @ t``."""
        return -self.rotation.T @ self.translation_m

    def to_dict(self) -> dict:
        """Plain-data form for JSON sidecars."""
        return {
            "left": self.left.to_dict(),
            "right": self.right.to_dict(),
            "rotation": self.rotation.tolist(),
            "translation_m": self.translation_m.tolist(),
            "rms_px": self.rms_px,
        }

    @classmethod
    def from_dict(cls, data: dict) -> StereoCalibration:
        """Inverse of :meth:`to_dict`."""
        keys = {"left", "right", "rotation", "translation_m", "rms_px"}
        require_keys("stereo calibration", data, keys)
        reject_unknown_keys("stereo calibration", data, keys)
        return cls(
            left=PinholeCamera.from_dict(data["left"]),
            right=PinholeCamera.from_dict(data["right"]),
            rotation=np.asarray(data["rotation"], dtype=np.float64),
            translation_m=np.asarray(data["translation_m"], dtype=np.float64),
            rms_px=data["rms_px"],
        )


def calibrate_stereo(
    corners_left: Sequence[np.ndarray],
    corners_right: Sequence[np.ndarray],
    board_points_m: np.ndarray | Sequence[np.ndarray],
    *,
    left: PinholeCamera,
    right: PinholeCamera,
) -> StereoCalibration:
    """Relative pose of two pinhole cameras with known intrinsics from chessboard views.

    OpenCV's ``stereoCalibrate`` with ``CALIB_FIX_INTRINSIC`` and zero distortion: refraction-free
    images are exact pinhole images, so only the rotation and translation are estimated (with the
    board poses of every view as nuisance parameters).

    Parameters
    ----------
    corners_left, corners_right : sequence of ndarray, each shape (N, 2)
        Detected corners of the same views, pixels, in the order of ``board_points_m``. At least 3
        views; both sequences equally long.
    board_points_m : ndarray, shape (N, 2), or sequence of them
        Board corner positions in the board plane (z = 0), metres, N >= 4: one board for every
        view, or one array per view (boards of different sizes).
    left, right : PinholeCamera
        Intrinsics of the two images, held fixed.

    Returns
    -------
    StereoCalibration
        With ``rms_px`` the RMS reprojection error over the corners of both images, pixels.

    Raises
    ------
    ParameterError
        Fewer than 3 views, mismatched counts or shapes, non-finite corners.
    """
    _pinhole("left", left)
    _pinhole("right", right)
    try:
        per_view = np.asarray(board_points_m, dtype=np.float64).ndim != 2
    except (TypeError, ValueError):  # ragged: boards of different sizes
        per_view = True
    if per_view:
        boards = [as_points(f"board_points_m[{i}]", b, 2) for i, b in enumerate(board_points_m)]
    else:
        boards = [as_points("board_points_m", board_points_m, 2)]
    for i, b in enumerate(boards):
        if len(b) < 4:
            raise ParameterError(f"board_points_m[{i}] must hold at least 4 points, got {len(b)}")
    views = []
    for name, corners in (("corners_left", corners_left), ("corners_right", corners_right)):
        if isinstance(corners, np.ndarray) and corners.ndim != 3:
            raise ParameterError(f"{name} must be a sequence of (N, 2) arrays, got an array of shape {corners.shape}")
        try:
            items = list(corners)
        except TypeError:
            raise ParameterError(f"{name} must be a sequence of (N, 2) arrays, got {corners!r}") from None
        checked = []
        if per_view and len(items) != len(boards):
            raise ParameterError(
                f"{name} must hold one view per board_points_m entry ({len(boards)}), got {len(items)}"
            )
        for i, c in enumerate(items):
            pts = as_points(f"{name}[{i}]", c, 2)
            board = boards[i if per_view else 0]
            if len(pts) != len(board):
                raise ParameterError(
                    f"{name}[{i}] must have one row per board point ({len(board)}), got shape {pts.shape}"
                )
            checked.append(pts.reshape(-1, 1, 2).astype(np.float32))
        views.append(checked)
    if len(views[0]) != len(views[1]):
        raise ParameterError(
            f"corners_left and corners_right must hold the same views, got {len(views[0])} and {len(views[1])}"
        )
    if len(views[0]) < 3:
        raise ParameterError(f"corners_left must hold at least 3 views, got {len(views[0])}")
    object_points = [
        np.concatenate([b, np.zeros((len(b), 1))], axis=1).reshape(-1, 1, 3).astype(np.float32) for b in boards
    ]
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    rms, _, _, _, _, rotation, translation, _, _ = cv2.stereoCalibrate(
        object_points if per_view else object_points * len(views[0]),
        views[0],
        views[1],
        left.K,
        np.zeros(5),
        right.K,
        np.zeros(5),
        (left.width_px, left.height_px),
        flags=cv2.CALIB_FIX_INTRINSIC,
        criteria=criteria,
    )
    return StereoCalibration(
        left=left, right=right, rotation=rotation, translation_m=np.ravel(translation), rms_px=float(rms)
    )


# =============================================================================== rectification
@dataclass(frozen=True, kw_only=True, eq=False)
class Rectification:
    """Rectifying rotations, rectified projections and resampling maps of a horizontal stereo pair.

    Build it with :func:`rectify`. All matrices follow ``cv2.stereoRectify``.

    Parameters
    ----------
    calibration : StereoCalibration
    R1, R2 : ndarray, shape (3, 3)
        ``X_rect_left = R1 @ X_l`` and ``X_rect_right = R2 @ X_r`` (rotations about each centre).
    P1, P2 : ndarray, shape (3, 4)
        Projections of rectified-left-frame points (metres) into the rectified left and right
        images, pixels. ``P2[0, 3] = -f * B`` (B the baseline, metres).
    Q : ndarray, shape (4, 4)
        Maps ``(u, v, d, 1)`` (rectified left pixel and disparity) to homogeneous rectified-left-frame
        points, metres.
    size_px : tuple of int
        ``(width, height)`` of the rectified images.
    left_map_x, left_map_y, right_map_x, right_map_y : ndarray, float32, shape (height, width)
        For every rectified pixel, the source pixel ``(x, y)`` in the original left / right image.
    """

    calibration: StereoCalibration
    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    size_px: tuple[int, int]
    left_map_x: np.ndarray
    left_map_y: np.ndarray
    right_map_x: np.ndarray
    right_map_y: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.calibration, StereoCalibration):
            raise ParameterError(f"calibration must be a StereoCalibration, got {self.calibration!r}")
        try:
            width, height = self.size_px
        except (TypeError, ValueError):
            raise ParameterError(f"size_px must be (width, height), got {self.size_px!r}") from None
        object.__setattr__(self, "size_px", (positive_int("size_px[0]", width), positive_int("size_px[1]", height)))
        for name, shape in (("R1", (3, 3)), ("R2", (3, 3)), ("P1", (3, 4)), ("P2", (3, 4)), ("Q", (4, 4))):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != shape or not np.all(np.isfinite(value)):
                raise ParameterError(f"{name} must be a finite {shape} matrix, got shape {value.shape}")
            object.__setattr__(self, name, _readonly(value))
        _rotation("R1", self.R1)
        _rotation("R2", self.R2)
        for name in ("left_map_x", "left_map_y", "right_map_x", "right_map_y"):
            value = np.asarray(getattr(self, name), dtype=np.float32)
            if value.shape != (height, width):
                raise ParameterError(f"{name} must have shape {(height, width)}, got {value.shape}")
            object.__setattr__(self, name, _readonly(value, np.float32))

    @property
    def focal_px(self) -> float:
        """Focal length of both rectified images, pixels."""
        return float(self.P1[0, 0])

    @property
    def baseline_m(self) -> float:
        """Baseline along the rectified x axis, metres (> 0)."""
        return float(-self.P2[0, 3] / self.P2[0, 0])

    @property
    def left_camera(self) -> PinholeCamera:
        """The rectified left image's pinhole camera (its frame is the rectified left frame)."""
        return PinholeCamera.from_K(self.P1[:, :3], *self.size_px)

    @property
    def right_camera(self) -> PinholeCamera:
        """The rectified right image's pinhole camera (its frame is the rectified right frame)."""
        return PinholeCamera.from_K(self.P2[:, :3], *self.size_px)

    def rectify_pixels(self, uv_px: np.ndarray, *, camera: str) -> np.ndarray:
        """Map pixels (N, 2) of the original ``camera`` (``"left"`` or ``"right"``) image to the
        rectified image of that camera, pixels (N, 2). Points whose ray leaves the rectified
        camera's front half-space give NaN."""
        one_of("camera", camera, ("left", "right"))
        uv = as_points("uv_px", uv_px, 2)
        if camera == "left":
            k, r, p = self.calibration.left.K, self.R1, self.P1
        else:
            k, r, p = self.calibration.right.K, self.R2, self.P2
        rays = np.linalg.solve(k, np.concatenate([uv, np.ones((len(uv), 1))], axis=1).T).T @ r.T
        with np.errstate(divide="ignore", invalid="ignore"):
            out = (rays @ p[:, :3].T)[:, :2] / rays[:, 2:3]
        out[rays[:, 2] <= 0] = np.nan
        return out

    def apply(self, left_image: np.ndarray, right_image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Resample an image pair into the rectified geometry (bilinear, ``cv2.remap``).

        Parameters
        ----------
        left_image, right_image : ndarray, shape (H, W) or (H, W, C)
            Real-valued images of the left and right camera (each its camera's size).

        Returns
        -------
        left_rect, right_rect : ndarray, float32, shape (height, width) or (height, width, C)
            ``size_px`` images. A rectified pixel is NaN (per channel) when any input pixel that
            carries interpolation weight is NaN, or when it samples outside its input image (any
            weight on a pixel beyond the border). OpenCV quantises the interpolation weights to
            1/32 pixel.
        """
        cal = self.calibration
        out = []
        for name, image, cam, mx, my in (
            ("left_image", left_image, cal.left, self.left_map_x, self.left_map_y),
            ("right_image", right_image, cal.right, self.right_map_x, self.right_map_y),
        ):
            arr = np.asarray(image)
            if arr.dtype.kind not in "fiu":
                raise ParameterError(f"{name} must hold real numbers, got dtype {arr.dtype}")
            if arr.ndim not in (2, 3) or arr.shape[:2] != (cam.height_px, cam.width_px):
                raise ParameterError(
                    f"{name} must have shape ({cam.height_px}, {cam.width_px}) or "
                    f"({cam.height_px}, {cam.width_px}, C), got {arr.shape}"
                )
            planes = arr[..., None] if arr.ndim == 2 else arr
            channels = []
            for c in range(planes.shape[2]):
                plane = planes[..., c].astype(np.float32)
                bad = ~np.isfinite(plane)
                clean = np.where(bad, np.float32(0.0), plane)
                value = cv2.remap(clean, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
                # Interpolation weight that falls on NaN pixels or beyond the border.
                spill = cv2.remap(
                    bad.astype(np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0
                )
                channels.append(np.where(spill > 0.0, np.float32(np.nan), value))
            result = np.stack(channels, axis=2)
            out.append(result[..., 0] if arr.ndim == 2 else result)
        return out[0], out[1]


def rectify(
    calibration: StereoCalibration, *, alpha: float = 0.0, size: tuple[int, int] | None = None
) -> Rectification:
    """Rectify a calibrated horizontal stereo pair (``cv2.stereoRectify`` with ``CALIB_ZERO_DISPARITY``).

    Parameters
    ----------
    calibration : StereoCalibration
        Both images must have the same size (OpenCV chooses the rectified view port from one size),
        and the right camera must lie to the right of the left one, more along x than along y.
    alpha : float
        OpenCV's free scaling in [0, 1]: 0 keeps only pixels seen by both original images
        (no empty border), 1 keeps every original pixel (empty borders).
    size : tuple of int, optional
        ``(width, height)`` of the rectified images; default the original size.

    Returns
    -------
    Rectification
    """
    if not isinstance(calibration, StereoCalibration):
        raise ParameterError(f"calibration must be a StereoCalibration, got {calibration!r}")
    a = finite_float("alpha", alpha)
    if not 0.0 <= a <= 1.0:
        raise ParameterError(f"alpha must lie in [0, 1], got {alpha!r}")
    left, right = calibration.left, calibration.right
    if (left.width_px, left.height_px) != (right.width_px, right.height_px):
        raise ParameterError(
            "calibration.left and calibration.right must have the same image size, got "
            f"{(left.width_px, left.height_px)} and {(right.width_px, right.height_px)}"
        )
    if size is None:
        out_size = (left.width_px, left.height_px)
    else:
        try:
            width, height = size
        except (TypeError, ValueError):
            raise ParameterError(f"size must be (width, height), got {size!r}") from None
        out_size = (positive_int("size[0]", width), positive_int("size[1]", height))
    centre = calibration.right_centre_m
    if abs(centre[0]) <= abs(centre[1]) or centre[0] <= 0:
        raise ParameterError(
            "calibration must describe a horizontal rig with the right camera towards +x of the left camera, "
            f"got the right camera centre at {centre.tolist()} m in the left frame"
        )
    r1, r2, p1, p2, q, _, _ = cv2.stereoRectify(
        left.K,
        np.zeros(5),
        right.K,
        np.zeros(5),
        (left.width_px, left.height_px),
        calibration.rotation,
        calibration.translation_m.reshape(3, 1),
        flags=_ZERO_DISPARITY,
        alpha=a,
        newImageSize=out_size,
    )
    if p2[1, 3] != 0.0 or p2[0, 3] >= 0.0:  # pragma: no cover - excluded by the check above
        raise ParameterError(f"rectification is not horizontal with the right camera at +x, got P2 = {p2.tolist()}")
    lx, ly = cv2.initUndistortRectifyMap(left.K, np.zeros(5), r1, p1, out_size, cv2.CV_32FC1)
    rx, ry = cv2.initUndistortRectifyMap(right.K, np.zeros(5), r2, p2, out_size, cv2.CV_32FC1)
    return Rectification(
        calibration=calibration,
        R1=r1,
        R2=r2,
        P1=p1,
        P2=p2,
        Q=q,
        size_px=out_size,
        left_map_x=lx,
        left_map_y=ly,
        right_map_x=rx,
        right_map_y=ry,
    )


# =============================================================================== matching
def _disparity_for(disparity: Any, rectification: Rectification) -> np.ndarray:
    if not isinstance(rectification, Rectification):
        raise ParameterError(f"rectification must be a Rectification, got {rectification!r}")
    d = np.asarray(disparity)
    if d.dtype.kind not in "fiu":
        raise ParameterError(f"disparity must hold real numbers, got dtype {d.dtype}")
    width, height = rectification.size_px
    if d.shape != (height, width):
        raise ParameterError(f"disparity must have the rectified shape {(height, width)}, got {d.shape}")
    return d.astype(np.float64)


def _rectified_points(disparity: np.ndarray, rectification: Rectification) -> np.ndarray:
    """Homogeneous-divided ``Q @ (u, v, d, 1)`` (H, W, 3), rectified left frame; NaN for no point."""
    height, width = disparity.shape
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    hom = np.stack([u, v, disparity, np.ones_like(u)], axis=-1) @ rectification.Q.T
    with np.errstate(invalid="ignore", divide="ignore"):
        points = hom[..., :3] / hom[..., 3:4]
    points[~(hom[..., 3] > 0.0)] = np.nan
    return points


def disparity_to_depth(disparity: np.ndarray, rectification: Rectification) -> np.ndarray:
    """Depth map of a disparity map, in the rectified left frame.

    Parameters
    ----------
    disparity : ndarray, shape (height, width)
        Disparity of the rectified pair (``x_left - x_right``, pixels), NaN where missing.
    rectification : Rectification

    Returns
    -------
    ndarray, float64, shape (height, width)
        ``Z`` of the triangulated point in the rectified left frame (``f * B / d`` with
        ``CALIB_ZERO_DISPARITY``), metres; NaN where the disparity is NaN or gives no point in
        front of the cameras (``d <= 0``). This is the depth along the rectified optical axis,
        not along the original left camera's axis (see :func:`disparity_to_points`).
    """
    d = _disparity_for(disparity, rectification)
    return _rectified_points(d, rectification)[..., 2]


def disparity_to_points(disparity: np.ndarray, rectification: Rectification) -> np.ndarray:
    """Triangulate a disparity map into a point cloud in the left (unrectified) camera frame.

    Each rectified pixel ``(u, v)`` with disparity ``d`` gives ``Q @ (u, v, d, 1)`` (what
    ``cv2.reprojectImageTo3D`` computes) in the rectified left frame, rotated back by ``R1.T``.

    Parameters
    ----------
    disparity : ndarray, shape (height, width)
        Disparity of the rectified pair, pixels, NaN where missing.
    rectification : Rectification

    Returns
    -------
    ndarray, float64, shape (N, 3)
        Points in the original left camera frame, metres, for the pixels where
        :func:`disparity_to_depth` is finite, in row-major pixel order: ``image[valid]`` with
        ``valid = np.isfinite(disparity_to_depth(disparity, rectification))`` gives their colours
        from the rectified left image.
    """
    d = _disparity_for(disparity, rectification)
    points = _rectified_points(d, rectification)
    valid = np.isfinite(points[..., 2])
    return points[valid] @ rectification.R1  # row vectors: (R1.T @ X).T = X.T @ R1
