"""Disparity by block matching on rectified pairs: the paper's ZNCC cost and OpenCV's semi-global matcher.

Disparity is ``d = x_left - x_right`` (pixels, rectified images, same row), float32, NaN where there is
no estimate (``docs/stereo.md``).
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.validate import (
    non_negative_float,
    one_of,
    positive_int,
)

#: OpenCV StereoSGBM modes by name.
SGBM_MODES = {
    "sgbm": cv2.STEREO_SGBM_MODE_SGBM,
    "hh": cv2.STEREO_SGBM_MODE_HH,
    "sgbm_3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    "hh4": cv2.STEREO_SGBM_MODE_HH4,
}

__all__ = ["SGBM_MODES", "sgbm_disparity", "zncc_disparity"]


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

    matcher = cv2.StereoSGBM.create(
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
