"""Two-view stereo on refraction-free images: calibration, rectification, matching, triangulation.

Refraction-free images are exact, distortion-free pinhole images (:class:`~lfrefract.pinhole.PinholeCamera`),
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

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from lfrefract._validate import (
    ParameterError,
    as_points,
    finite_float,
    finite_vector,
    non_negative_float,
    one_of,
    positive_int,
    reject_unknown_keys,
    require_keys,
)
from lfrefract.pinhole import PinholeCamera

__all__ = [
    "SGBM_MODES",
    "Rectification",
    "StereoCalibration",
    "calibrate_stereo",
    "disparity_to_depth",
    "disparity_to_points",
    "rectify",
    "sgbm_disparity",
    "zncc_disparity",
]

#: Largest deviation of ``R @ R.T`` from the identity accepted for a rotation matrix.
_ROTATION_TOLERANCE = 1e-6

_ZERO_DISPARITY = getattr(cv2, "STEREO_ZERO_DISPARITY", cv2.CALIB_ZERO_DISPARITY)

#: OpenCV StereoSGBM modes by name.
SGBM_MODES = {
    "sgbm": cv2.STEREO_SGBM_MODE_SGBM,
    "hh": cv2.STEREO_SGBM_MODE_HH,
    "sgbm_3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    "hh4": cv2.STEREO_SGBM_MODE_HH4,
}


def _readonly(value: Any, dtype: type = np.float64) -> np.ndarray:
    out = np.array(value, dtype=dtype, copy=True)
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
def _grey_pair(left: Any, right: Any) -> tuple[np.ndarray, np.ndarray]:
    out = []
    for name, image in (("left", left), ("right", right)):
        arr = np.asarray(image)
        if arr.dtype.kind not in "fiu":
            raise ParameterError(f"{name} must hold real numbers, got dtype {arr.dtype}")
        if arr.ndim != 2:
            raise ParameterError(f"{name} must be a grey image of shape (H, W), got shape {arr.shape}")
        out.append(arr.astype(np.float64))
    if out[0].shape != out[1].shape:
        raise ParameterError(f"left and right must have the same shape, got {out[0].shape} and {out[1].shape}")
    return out[0], out[1]


def _integer(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(f"{name} must be an integer, got {value!r}")
    return int(value)


def _odd_window(name: str, value: Any, minimum: int) -> int:
    w = positive_int(name, value)
    if w % 2 == 0 or w < minimum:
        raise ParameterError(f"{name} must be an odd integer >= {minimum}, got {value!r}")
    return w


def _robust_range(*images: np.ndarray) -> tuple[float, float]:
    """1st and 99th percentile of the finite values of ``images`` (0, 0 if there are none)."""
    values = np.concatenate([im[np.isfinite(im)] for im in images])
    if values.size == 0:
        return 0.0, 0.0
    lo, hi = np.percentile(values, [1.0, 99.0])
    return float(lo), float(hi)


def _shift_columns(a: np.ndarray, d: int, fill: Any) -> np.ndarray:
    """``out[..., x] = a[..., x - d]``, ``fill`` where ``x - d`` is outside the image."""
    out = np.full_like(a, fill)
    w = a.shape[-1]
    if d >= 0:
        if d < w:
            out[..., d:] = a[..., : w - d]
    elif -d < w:
        out[..., :d] = a[..., -d:]
    return out


def _window_inside(ok: np.ndarray, window: int) -> np.ndarray:
    """True where the ``window`` x ``window`` square around a pixel lies in the image and in ``ok``."""
    kernel = np.ones((window, window), np.uint8)
    return cv2.erode(ok.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)


def _winner(volume: np.ndarray, subpixel: bool) -> np.ndarray:
    """Winner-take-all index (float, sub-pixel refined) per pixel of a (D, H, W) cost volume; NaN if
    the winner's cost is infinite or either neighbour in the volume is missing or infinite."""
    n = volume.shape[0]
    idx = np.argmin(volume, axis=0)
    best = np.take_along_axis(volume, idx[None], axis=0)[0]
    below = np.take_along_axis(volume, np.clip(idx - 1, 0, n - 1)[None], axis=0)[0]
    above = np.take_along_axis(volume, np.clip(idx + 1, 0, n - 1)[None], axis=0)[0]
    ok = np.isfinite(best) & np.isfinite(below) & np.isfinite(above) & (idx > 0) & (idx < n - 1)
    out = idx.astype(np.float64)
    if subpixel:
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            curvature = below.astype(np.float64) - 2.0 * best + above
            offset = np.where(curvature > 0.0, 0.5 * (below.astype(np.float64) - above) / curvature, 0.0)
        out = out + np.where(ok, offset, 0.0)
    out[~ok] = np.nan
    return out


def zncc_disparity(
    left: np.ndarray,
    right: np.ndarray,
    *,
    min_disparity_px: int,
    num_disparities: int,
    window_px: int = 9,
    left_right_max_diff_px: float | None = 1.0,
    subpixel: bool = True,
    min_std: float | None = None,
) -> np.ndarray:
    """Disparity of a rectified grey pair by zero-mean normalised cross-correlation (the paper's NCC).

    For every candidate disparity ``d`` in ``min_disparity_px .. min_disparity_px + num_disparities - 1``
    the cost ``1 - ZNCC`` of the ``window_px`` square windows around left pixel ``(x, y)`` and right
    pixel ``(x - d, y)`` is computed with box filters of the means, variances and cross products
    (no per-pixel loop), giving a (D, H, W) volume. Each left pixel takes the cheapest ``d``
    (winner-take-all), refined by a parabola through that cost and its two neighbours. The right
    image's disparity is taken from the same volume (``C_right[d, y, x] = C[d, y, x + d]``); a left
    pixel passes the left-right check when the right disparity at ``x - d`` agrees within
    ``left_right_max_diff_px``.

    A pixel is NaN (no estimate) when its left window holds a NaN, leaves the image or has an
    intensity standard deviation below ``min_std`` (too little texture); when the winner lies at either end
    of the search range, or a neighbour of it has no cost (its window leaves the overlap or holds a
    NaN), so the cost minimum cannot be confirmed; or when it fails the left-right check. Right
    windows that hold a NaN, leave the image or lack texture give no cost for that disparity.

    Parameters
    ----------
    left, right : ndarray, shape (H, W)
        Rectified grey images (any real dtype; computed in float64). NaN marks missing pixels.
    min_disparity_px : int
        Smallest disparity searched, pixels.
    num_disparities : int
        Number of integer disparities searched, >= 3.
    window_px : int
        Side of the square correlation window, odd, >= 3.
    left_right_max_diff_px : float or None
        Largest accepted difference between left and right disparity, pixels; None disables the check.
    subpixel : bool
        Refine by the parabola; otherwise integer disparities.
    min_std : float or None
        Smallest intensity standard deviation of a window, in image units; default, for each
        image, 1 % of its robust range (1st to 99th percentile of its finite values), so that
        the result, like ZNCC itself, does not change with the gain and offset of either image.

    Returns
    -------
    ndarray, float32, shape (H, W)
        Disparity ``x_left - x_right``, pixels; NaN where invalid.

    Notes
    -----
    Memory: two float32 volumes of ``num_disparities * H * W`` values.
    """
    lft, rgt = _grey_pair(left, right)
    d0 = _integer("min_disparity_px", min_disparity_px)
    n = positive_int("num_disparities", num_disparities)
    if n < 3:
        raise ParameterError(f"num_disparities must be >= 3 (the winner needs two neighbours), got {n}")
    w = _odd_window("window_px", window_px, 3)
    max_diff = None
    if left_right_max_diff_px is not None:
        max_diff = non_negative_float("left_right_max_diff_px", left_right_max_diff_px)
    if not isinstance(subpixel, (bool, np.bool_)):
        raise ParameterError(f"subpixel must be True or False, got {subpixel!r}")
    (lo_l, hi_l), (lo_r, hi_r) = _robust_range(lft), _robust_range(rgt)
    if min_std is None:
        min_l, min_r = 0.01 * (hi_l - lo_l), 0.01 * (hi_r - lo_r)
    else:
        min_l = min_r = non_negative_float("min_std", min_std)

    ok_l, ok_r = np.isfinite(lft), np.isfinite(rgt)
    # Remove each image's offset first: the variances are differences of mean squares.
    lc = np.where(ok_l, lft - 0.5 * (lo_l + hi_l), 0.0)
    rc = np.where(ok_r, rgt - 0.5 * (lo_r + hi_r), 0.0)

    def box(a: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(a, cv2.CV_64F, (w, w), normalize=True, borderType=cv2.BORDER_REFLECT)

    mean_l, mean_r = box(lc), box(rc)
    std_l = np.sqrt(np.maximum(box(lc * lc) - mean_l**2, 0.0))
    std_r = np.sqrt(np.maximum(box(rc * rc) - mean_r**2, 0.0))
    use_l = _window_inside(ok_l, w) & (std_l >= min_l) & (std_l > 0.0)
    use_r = _window_inside(ok_r, w) & (std_r >= min_r) & (std_r > 0.0)

    disparities = d0 + np.arange(n)
    volume = np.empty((n, *lft.shape), dtype=np.float32)
    for i, d in enumerate(disparities):
        shifted = _shift_columns(rc, int(d), 0.0)
        mean_s = _shift_columns(mean_r, int(d), 0.0)
        std_s = _shift_columns(std_r, int(d), 1.0)
        use = use_l & _shift_columns(use_r, int(d), False)
        with np.errstate(invalid="ignore", divide="ignore"):
            zncc = (box(lc * shifted) - mean_l * mean_s) / (std_l * std_s)
        volume[i] = np.where(use, 1.0 - zncc, np.inf)

    disparity = d0 + _winner(volume, subpixel)
    if max_diff is not None:
        right_volume = np.empty_like(volume)
        for i, d in enumerate(disparities):
            right_volume[i] = _shift_columns(volume[i], -int(d), np.inf)
        del volume
        right_disparity = d0 + _winner(right_volume, subpixel)
        height, width = lft.shape
        rows, cols = np.mgrid[0:height, 0:width]
        valid = np.isfinite(disparity)
        xr = np.full(disparity.shape, -1, dtype=np.int64)
        xr[valid] = np.rint(cols[valid] - disparity[valid]).astype(np.int64)
        inside = valid & (xr >= 0) & (xr < width)
        agree = np.zeros_like(inside)
        back = right_disparity[rows[inside], xr[inside]]
        agree[inside] = np.abs(back - disparity[inside]) <= max_diff  # NaN compares False
        disparity[~agree] = np.nan
    return disparity.astype(np.float32)


def sgbm_disparity(
    left: np.ndarray,
    right: np.ndarray,
    *,
    min_disparity_px: int,
    num_disparities: int,
    block_size_px: int = 5,
    p1: int | None = None,
    p2: int | None = None,
    uniqueness_ratio: int = 10,
    left_right_max_diff_px: int | None = 1,
    mode: str = "sgbm",
) -> np.ndarray:
    """Disparity of a rectified grey pair by OpenCV's semi-global block matching (``StereoSGBM``).

    The float images are mapped to 8 bits by one linear map for both, taking the pair's robust
    range (1st to 99th percentile of the finite values) to 0..255 and clipping; NaN pixels are
    set to mid-grey for the matcher and invalidate afterwards every estimate whose left block, or
    the right block it matched, holds one. OpenCV needs a multiple of 16 disparities: the search
    runs over the next multiple and estimates outside the requested range are discarded.

    Parameters
    ----------
    left, right : ndarray, shape (H, W)
        Rectified grey images; NaN marks missing pixels.
    min_disparity_px : int
        Smallest disparity searched, pixels.
    num_disparities : int
        Number of disparities searched, >= 1.
    block_size_px : int
        Matching block side, odd, >= 1.
    p1, p2 : int, optional
        Smoothness penalties for disparity changes of 1 and of more than 1 between neighbours;
        default ``8 * block_size_px**2`` and ``32 * block_size_px**2`` (OpenCV's suggestion). p2 > p1.
    uniqueness_ratio : int
        Margin in percent by which the best cost must beat the second best, >= 0.
    left_right_max_diff_px : int or None
        Largest accepted left-right disparity difference (integer pixels); None disables the check.
    mode : str
        One of :data:`SGBM_MODES` (``"sgbm"``: 5 paths; ``"hh"``: 8 paths, full two-pass).

    Returns
    -------
    ndarray, float32, shape (H, W)
        Disparity ``x_left - x_right``, pixels (1/16-pixel steps); NaN where invalid.
    """
    lft, rgt = _grey_pair(left, right)
    d0 = _integer("min_disparity_px", min_disparity_px)
    n = positive_int("num_disparities", num_disparities)
    block = _odd_window("block_size_px", block_size_px, 1)
    pen1 = 8 * block * block if p1 is None else positive_int("p1", p1)
    pen2 = 32 * block * block if p2 is None else positive_int("p2", p2)
    if pen2 <= pen1:
        raise ParameterError(f"p2 must be larger than p1, got p1={pen1!r}, p2={pen2!r}")
    unique = _integer("uniqueness_ratio", uniqueness_ratio)
    if unique < 0:
        raise ParameterError(f"uniqueness_ratio must be non-negative, got {uniqueness_ratio!r}")
    max_diff = -1
    if left_right_max_diff_px is not None:
        max_diff = _integer("left_right_max_diff_px", left_right_max_diff_px)
        if max_diff < 0:
            raise ParameterError(f"left_right_max_diff_px must be non-negative or None, got {left_right_max_diff_px!r}")
    mode_id = SGBM_MODES[one_of("mode", mode, tuple(SGBM_MODES))]

    bad_l, bad_r = ~np.isfinite(lft), ~np.isfinite(rgt)
    lo, hi = _robust_range(lft, rgt)
    if not hi > lo:
        return np.full(lft.shape, np.nan, dtype=np.float32)
    scale = 255.0 / (hi - lo)

    def to8(a: np.ndarray, bad: np.ndarray) -> np.ndarray:
        return np.where(bad, 128.0, np.clip(np.rint((a - lo) * scale), 0.0, 255.0)).astype(np.uint8)

    matcher = cv2.StereoSGBM_create(
        minDisparity=d0,
        numDisparities=16 * math.ceil(n / 16),
        blockSize=block,
        P1=pen1,
        P2=pen2,
        disp12MaxDiff=max_diff,
        uniquenessRatio=unique,
        speckleWindowSize=0,
        speckleRange=0,
        mode=mode_id,
    )
    raw = matcher.compute(to8(lft, bad_l), to8(rgt, bad_r))
    disparity = raw.astype(np.float32) / 16.0
    disparity[(raw < 16 * d0) | (disparity > d0 + n - 1)] = np.nan
    if bad_l.any() or bad_r.any():
        kernel = np.ones((block, block), np.uint8)
        near_l = cv2.dilate(bad_l.astype(np.uint8), kernel).astype(bool)
        near_r = cv2.dilate(bad_r.astype(np.uint8), kernel).astype(bool)
        height, width = lft.shape
        rows, cols = np.mgrid[0:height, 0:width]
        valid = np.isfinite(disparity) & ~near_l
        xr = np.clip(np.rint(cols[valid] - disparity[valid]).astype(np.int64), 0, width - 1)
        hit = np.zeros_like(valid)
        hit[valid] = near_r[rows[valid], xr]
        disparity[near_l | hit] = np.nan
    return disparity


# =============================================================================== triangulation
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
