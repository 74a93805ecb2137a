"""Image comparison metrics in a region: PSNR, SSIM (Wang et al. 2004) and the aligning shift."""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from lfrefract._validate import ParameterError, positive_float

__all__ = ["psnr", "shift_px", "ssim"]


def _prepare(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = np.asarray(a, dtype=np.float64)
    y = np.asarray(b, dtype=np.float64)
    if x.shape != y.shape:
        raise ParameterError(f"images must have the same shape, got {x.shape} and {y.shape}")
    if x.ndim == 3:
        x, y = x.mean(axis=2), y.mean(axis=2)
    if x.ndim != 2:
        raise ParameterError(f"images must be (H, W) or (H, W, C), got shape {np.asarray(a).shape}")
    m = np.ones(x.shape, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if m.shape != x.shape:
        raise ParameterError(f"mask must have shape {x.shape}, got {m.shape}")
    if not m.any():
        raise ParameterError("mask selects no pixel")
    return x, y, m


def psnr(a: np.ndarray, b: np.ndarray, *, data_range: float, mask: np.ndarray | None = None) -> float:
    """Peak signal-to-noise ratio in dB of ``a`` against ``b`` over ``mask`` (colour: channel mean).

    Parameters
    ----------
    a, b : ndarray, shape (H, W) or (H, W, C)
    data_range : float
        The peak value (e.g. the reference's 99.5th percentile for HDR radiance).
    mask : ndarray of bool, shape (H, W), optional
        Pixels compared (default all).
    """
    x, y, m = _prepare(a, b, mask)
    mse = float(np.mean((x[m] - y[m]) ** 2))
    peak = positive_float("data_range", data_range)
    return float("inf") if mse == 0.0 else 10.0 * np.log10(peak**2 / mse)


def ssim(
    a: np.ndarray, b: np.ndarray, *, data_range: float, mask: np.ndarray | None = None, sigma_px: float = 1.5
) -> float:
    """Mean structural similarity of ``a`` and ``b`` over ``mask`` (Gaussian window, sigma 1.5 px).

    Local statistics use only pixels inside ``mask`` (normalised convolution), so pixels outside it
    do not leak into the score; the mean is taken over ``mask``.
    """
    x, y, m = _prepare(a, b, mask)
    peak = positive_float("data_range", data_range)
    positive_float("sigma_px", sigma_px)
    w = m.astype(np.float64)
    norm = ndimage.gaussian_filter(w, sigma_px)
    safe = np.where(norm > 1e-6, norm, 1.0)

    def local_mean(img: np.ndarray) -> np.ndarray:
        return ndimage.gaussian_filter(img * w, sigma_px) / safe

    mx, my = local_mean(x), local_mean(y)
    vx = local_mean(x * x) - mx**2
    vy = local_mean(y * y) - my**2
    cxy = local_mean(x * y) - mx * my
    c1, c2 = (0.01 * peak) ** 2, (0.03 * peak) ** 2
    index = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx**2 + my**2 + c1) * (vx + vy + c2))
    return float(np.mean(index[m]))


def shift_px(image: np.ndarray, reference: np.ndarray, *, mask: np.ndarray | None = None) -> tuple[float, float]:
    """Translation ``(dx, dy)``, pixels, with ``image(x + dx, y + dy) ~ reference(x, y)`` over ``mask``.

    A feature of ``reference`` appears moved by ``(dx, dy)`` in ``image``. OpenCV's ECC alignment
    (translation model, Gaussian pre-smoothing of 3 px) of the channel means; NaN in ``image``
    counts as 0.

    Parameters
    ----------
    image, reference : ndarray, shape (H, W) or (H, W, C)
    mask : ndarray of bool, shape (H, W), optional
        Pixels of ``reference`` compared (default all).
    """
    x, y, m = _prepare(np.nan_to_num(np.asarray(image, dtype=np.float64)), reference, mask)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200, 1e-6)
    _, warp = cv2.findTransformECC(
        y.astype(np.float32),
        x.astype(np.float32),
        np.eye(2, 3, dtype=np.float32),
        cv2.MOTION_TRANSLATION,
        criteria,
        m.astype(np.uint8),
        3,
    )
    return float(warp[0, 2]), float(warp[1, 2])
