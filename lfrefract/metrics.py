"""Comparison metrics: images in a region (PSNR, SSIM after Wang et al. 2004, the aligning shift),
planes, depth and disparity maps (with the HCI 4D light field benchmark's scores), and ray models
against true rays."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from scipy import ndimage

from lfrefract.errors import ParameterError
from lfrefract.validate import as_points, positive_float, positive_int, shown

__all__ = [
    "HCI_BADPIX_THRESHOLDS_PX",
    "HCI_BOUNDARY_PX",
    "DepthErrors",
    "DisparityErrors",
    "HciScores",
    "PlaneFit",
    "RayErrors",
    "depth_errors",
    "disparity_errors",
    "fit_plane_ransac",
    "hci_badpix",
    "hci_mse_x100",
    "hci_scores",
    "psnr",
    "ray_errors",
    "shift_px",
    "ssim",
]


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


# =============================================================================== stereo
@dataclass(frozen=True, kw_only=True, eq=False)
class PlaneFit:
    """A plane ``{X : normal . X = offset_m}`` fitted to a point cloud, with its inliers.

    Parameters
    ----------
    normal : ndarray, shape (3,)
        Unit normal, in the points' frame, oriented so that ``offset_m >= 0`` (pointing away from
        the frame's origin; for a plane through the origin, with ``normal[2] >= 0``).
    offset_m : float
        Signed distance of the plane from the origin along ``normal``, metres.
    inliers : ndarray of bool, shape (N,)
        Points within the threshold of the final plane.
    rmse_m : float
        RMS point-to-plane distance of the inliers, metres.
    """

    normal: np.ndarray
    offset_m: float
    inliers: np.ndarray
    rmse_m: float

    def distances_m(self, points_m: np.ndarray) -> np.ndarray:
        """Signed distances (N,) of points (N, 3) from the plane, metres (positive along ``normal``)."""
        return as_points("points_m", points_m, 3) @ self.normal - self.offset_m


def _oriented_plane(normal: np.ndarray, offset: float) -> tuple[np.ndarray, float]:
    if offset < 0.0 or (offset == 0.0 and normal[2] < 0.0):
        return -normal, -offset
    return normal, offset


def _least_squares_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Total least-squares plane (orthogonal distances): normal = smallest principal axis."""
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
    normal = vt[-1] / np.linalg.norm(vt[-1])
    return _oriented_plane(normal, float(normal @ centre))


def fit_plane_ransac(points_m: np.ndarray, *, threshold_m: float, iterations: int = 1000, seed: int = 0) -> PlaneFit:
    """Fit a plane to a point cloud with outliers (RANSAC, then least squares on the inliers).

    The paper's evaluation (section 5.1): a plane fitted to the reconstructed board after outlier
    removal, its residual the quality measure. ``iterations`` random triples of points propose
    planes; the one with the most points within ``threshold_m`` wins. The plane is then refitted
    by total least squares to its inliers and the inliers recomputed, until they no longer change
    (at most 10 times).

    Parameters
    ----------
    points_m : ndarray, shape (N, 3)
        Finite points, metres (any frame; the plane is returned in it). N >= 3.
    threshold_m : float
        Largest point-to-plane distance of an inlier, metres, > 0.
    iterations : int
        Number of random triples tried, > 0.
    seed : int
        Seed of the random generator (the result is deterministic for a given seed).

    Returns
    -------
    PlaneFit

    Raises
    ------
    ParameterError
        Too few or non-finite points, bad options, or every sampled triple was degenerate (collinear).
    """
    pts = as_points("points_m", points_m, 3)
    if len(pts) < 3:
        raise ParameterError(f"points_m must hold at least 3 points, got {len(pts)}")
    threshold = positive_float("threshold_m", threshold_m)
    n_iter = positive_int("iterations", iterations)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ParameterError(f"seed must be an integer, got {seed!r}")
    rng = np.random.default_rng(int(seed))
    # Three distinct indices per trial: draw the first, then offsets that cannot collide.
    n = len(pts)
    first = rng.integers(0, n, n_iter)
    second = (first + rng.integers(1, n, n_iter)) % n
    third = rng.integers(0, n - 2, n_iter)
    third += third >= np.minimum(first, second)
    third += third >= np.maximum(first, second)
    normals = np.cross(pts[second] - pts[first], pts[third] - pts[first])
    norms = np.linalg.norm(normals, axis=1)
    scale = np.max(np.ptp(pts, axis=0)) ** 2
    usable = norms > 1e-12 * max(scale, np.finfo(float).tiny)
    if not usable.any():
        raise ParameterError("points_m are collinear or coincident: no sampled triple spans a plane")
    normals = normals[usable] / norms[usable, None]
    offsets = np.einsum("ij,ij->i", normals, pts[first[usable]])
    best_count, best = -1, 0
    chunk = max(1, 4_000_000 // n)
    for start in range(0, len(normals), chunk):
        dist = np.abs(pts @ normals[start : start + chunk].T - offsets[start : start + chunk])
        counts = np.count_nonzero(dist <= threshold, axis=0)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best_count, best = int(counts[k]), start + k
    inliers = np.abs(pts @ normals[best] - offsets[best]) <= threshold
    normal, offset = _oriented_plane(normals[best], float(offsets[best]))
    for _ in range(10):
        if np.count_nonzero(inliers) < 3:
            break
        normal, offset = _least_squares_plane(pts[inliers])
        updated = np.abs(pts @ normal - offset) <= threshold
        if np.array_equal(updated, inliers):
            break
        inliers = updated
    residual = pts[inliers] @ normal - offset
    rmse = float(np.sqrt(np.mean(residual**2))) if residual.size else float("nan")
    inliers.setflags(write=False)
    normal.setflags(write=False)
    return PlaneFit(normal=normal, offset_m=float(offset), inliers=inliers, rmse_m=rmse)


@dataclass(frozen=True, kw_only=True)
class DepthErrors:
    """Depth map errors against ground truth.

    Parameters
    ----------
    mean_abs_m, rms_m, bias_m : float
        Mean absolute, RMS and mean signed (estimate - truth) error over the pixels with both a
        truth and an estimate, metres; NaN if there is no such pixel.
    completeness : float
        Fraction of the truth-valid pixels that have an estimate.
    count : int
        Number of pixels with both a truth and an estimate.
    """

    mean_abs_m: float
    rms_m: float
    bias_m: float
    completeness: float
    count: int


def _truth_mask(name: str, estimate: Any, truth: Any, valid: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    est = np.asarray(estimate, dtype=np.float64)
    ref = np.asarray(truth, dtype=np.float64)
    if est.shape != ref.shape or est.ndim != 2:
        raise ParameterError(
            f"{name} and its truth must be (H, W) arrays of the same shape, got {est.shape} and {ref.shape}"
        )
    mask = np.isfinite(ref)
    if valid is not None:
        v = np.asarray(valid)
        if v.dtype != bool or v.shape != ref.shape:
            raise ParameterError(f"valid must be a boolean array of shape {ref.shape}, got {v.dtype} {v.shape}")
        mask &= v
    if not mask.any():
        raise ParameterError("no pixel has a finite truth (inside valid): nothing to compare")
    if np.any(np.isinf(est)):
        raise ParameterError(f"{name} holds infinite values; mark missing estimates with NaN")
    return est, ref, mask


def depth_errors(depth_m: np.ndarray, truth_depth_m: np.ndarray, *, valid: np.ndarray | None = None) -> DepthErrors:
    """Compare a depth map with the ground truth depth.

    Parameters
    ----------
    depth_m : ndarray, shape (H, W)
        Estimated depth, metres; NaN where there is no estimate.
    truth_depth_m : ndarray, shape (H, W)
        True depth in the same frame, metres; non-finite (NaN, or +inf for "no surface") where
        there is no truth.
    valid : ndarray of bool, shape (H, W), optional
        Further restricts the compared pixels (e.g. a coverage mask or a region of interest).

    Returns
    -------
    DepthErrors
    """
    est, ref, mask = _truth_mask("depth_m", depth_m, truth_depth_m, valid)
    have = mask & np.isfinite(est)
    err = est[have] - ref[have]
    count = int(err.size)
    nan = float("nan")
    return DepthErrors(
        mean_abs_m=float(np.mean(np.abs(err))) if count else nan,
        rms_m=float(np.sqrt(np.mean(err**2))) if count else nan,
        bias_m=float(np.mean(err)) if count else nan,
        completeness=count / int(np.count_nonzero(mask)),
        count=count,
    )


@dataclass(frozen=True, kw_only=True)
class DisparityErrors:
    """Disparity map errors against ground truth, Middlebury style.

    Parameters
    ----------
    thresholds_px : tuple of float
        The error thresholds, pixels.
    bad_fractions : tuple of float
        For each threshold, the fraction of truth-valid pixels whose estimate is missing or off by
        more than the threshold.
    mean_abs_px, rms_px : float
        Mean absolute and RMS error over the pixels with both a truth and an estimate, pixels; NaN
        if there is none.
    completeness : float
        Fraction of the truth-valid pixels that have an estimate.
    count : int
        Number of pixels with both a truth and an estimate.
    """

    thresholds_px: tuple[float, ...]
    bad_fractions: tuple[float, ...]
    mean_abs_px: float
    rms_px: float
    completeness: float
    count: int

    def bad(self, threshold_px: float) -> float:
        """The bad-pixel fraction for one of :attr:`thresholds_px`."""
        if threshold_px not in self.thresholds_px:
            raise ParameterError(f"threshold_px must be one of {list(self.thresholds_px)}, got {threshold_px!r}")
        return self.bad_fractions[self.thresholds_px.index(threshold_px)]


def disparity_errors(
    disparity_px: np.ndarray,
    truth_px: np.ndarray,
    *,
    thresholds_px: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0),
    valid: np.ndarray | None = None,
) -> DisparityErrors:
    """Compare a disparity map with the ground truth disparity (Middlebury bad-pixel rates).

    Parameters
    ----------
    disparity_px : ndarray, shape (H, W)
        Estimated disparity, pixels; NaN where there is no estimate (counted as bad).
    truth_px : ndarray, shape (H, W)
        True disparity, pixels; non-finite where there is no truth (not counted).
    thresholds_px : tuple of float
        Error thresholds, pixels, each > 0: a pixel is bad when ``|error| > threshold``.
    valid : ndarray of bool, shape (H, W), optional
        Further restricts the compared pixels.

    Returns
    -------
    DisparityErrors
    """
    try:
        thresholds = tuple(positive_float(f"thresholds_px[{i}]", t) for i, t in enumerate(thresholds_px))
    except TypeError:
        raise ParameterError(f"thresholds_px must be a sequence of positive numbers, got {thresholds_px!r}") from None
    if not thresholds:
        raise ParameterError("thresholds_px must not be empty")
    est, ref, mask = _truth_mask("disparity_px", disparity_px, truth_px, valid)
    total = int(np.count_nonzero(mask))
    have = mask & np.isfinite(est)
    err = np.abs(est[have] - ref[have])
    count = int(err.size)
    bad = tuple((total - int(np.count_nonzero(err <= t))) / total for t in thresholds)
    nan = float("nan")
    return DisparityErrors(
        thresholds_px=thresholds,
        bad_fractions=bad,
        mean_abs_px=float(np.mean(err)) if count else nan,
        rms_px=float(np.sqrt(np.mean(err**2))) if count else nan,
        completeness=count / total,
        count=count,
    )


@dataclass(frozen=True)
class RayErrors:
    """How far a ray model's rays are from the true ones (:func:`ray_errors`).

    Attributes
    ----------
    position_rms_m, position_max_m : float
        RMS and largest distance, metres, between where the two rays of a pixel cross the plane.
    angle_rms_rad, angle_max_rad : float
        RMS and largest angle between their directions, radians.
    count : int
        Rays compared.
    axis_shift_m : float
        With ``along_axis=True``: how far the model's rays were moved along the frame's z axis before
        they were compared (metres); else 0.
    """

    position_rms_m: float
    position_max_m: float
    angle_rms_rad: float
    angle_max_rad: float
    count: int
    axis_shift_m: float = 0.0


def ray_errors(
    origins_m: np.ndarray,
    directions: np.ndarray,
    true_origins_m: np.ndarray,
    true_directions: np.ndarray,
    *,
    plane_normal: Any = (0.0, 0.0, 1.0),
    plane_distance_m: float,
    valid: Any = None,
    along_axis: bool = False,
) -> RayErrors:
    """Ray model against true rays: where each pair crosses a plane, and the angle between them.

    Boards seen in air fix a camera's rays except for a shift of all of them along the optical axis
    (every ray then meets the same boards: a calibration puts its frame's origin by a convention,
    e.g. at its model's paraxial entrance pupil). ``along_axis=True`` measures the model up to that
    shift: its rays are first moved along z by the shift that brings their crossings nearest the
    true ones' (least squares, closed form: a crossing moves linearly with the shift).

    Parameters
    ----------
    origins_m, directions : array_like, shape (N, 3)
        The model's rays (any frame, metres; directions need not be unit; NaN rows are left out).
    true_origins_m, true_directions : array_like, shape (N, 3)
        The true rays of the same pixels, same frame.
    plane_normal : array_like, shape (3,)
        The plane ``n . X = d`` where positions are compared (e.g. a port's air-side face).
    plane_distance_m : float
        Its ``d``, metres.
    valid : array_like of bool, shape (N,), optional
        The pairs to compare; pairs with a non-finite value or a ray parallel to the plane are left
        out as well.
    along_axis : bool
        Compare up to the best shift of the model's rays along z (above; :attr:`RayErrors.axis_shift_m`).
    """

    def rows(name: str, value: Any) -> np.ndarray:  # NaN allowed: vignetted pixels have no ray
        arr = np.asarray(value, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != 3:
            raise ParameterError(f"{name} must have shape (N, 3), got shape {arr.shape}")
        return arr

    o, d = rows("origins_m", origins_m), rows("directions", directions)
    to, td = rows("true_origins_m", true_origins_m), rows("true_directions", true_directions)
    if not (len(o) == len(d) == len(to) == len(td)):
        raise ParameterError(
            f"the four ray arrays must have one row per pixel, got {len(o)}, {len(d)}, {len(to)}, {len(td)}"
        )
    n = np.asarray(plane_normal, dtype=np.float64)
    if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
        raise ParameterError(f"plane_normal must be a finite non-zero 3-vector, got {plane_normal!r}")
    n = n / np.linalg.norm(n)
    keep = np.ones(len(o), dtype=bool) if valid is None else np.asarray(valid, dtype=bool).reshape(-1)
    if keep.shape != (len(o),):
        raise ParameterError(f"valid must have one entry per ray, got shape {np.shape(valid)}")

    def crossing(origins, dirs):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (plane_distance_m - origins @ n) / (dirs @ n)
        return origins + t[:, None] * dirs

    p, tp = crossing(o, d), crossing(to, td)
    keep &= np.all(np.isfinite(p), axis=1) & np.all(np.isfinite(tp), axis=1)
    if not np.any(keep):
        raise ParameterError("no pair of rays to compare (none valid, finite and crossing the plane)")
    gap = p[keep] - tp[keep]
    shift = 0.0
    if along_axis:
        # Moving a ray's origin by s along z moves its crossing by s * (z - (n_z / (d . n)) d).
        dk = d[keep]
        slope = np.array([0.0, 0.0, 1.0]) - (n[2] / (dk @ n))[:, None] * dk
        shift = -float(np.sum(gap * slope) / np.sum(slope * slope))
        gap = gap + shift * slope
    distance = np.linalg.norm(gap, axis=1)
    unit = d[keep] / np.linalg.norm(d[keep], axis=1, keepdims=True)
    true_unit = td[keep] / np.linalg.norm(td[keep], axis=1, keepdims=True)
    angle = 2.0 * np.arcsin(np.clip(np.linalg.norm(unit - true_unit, axis=1) / 2.0, 0.0, 1.0))
    return RayErrors(
        position_rms_m=float(np.sqrt(np.mean(distance**2))),
        position_max_m=float(distance.max()),
        angle_rms_rad=float(np.sqrt(np.mean(angle**2))),
        angle_max_rad=float(angle.max()),
        count=int(keep.sum()),
        axis_shift_m=shift,
    )


# =============================================================================== HCI benchmark
# The general disparity metrics of the HCI 4D light field benchmark (Honauer et al., ACCV 2016), as
# its evaluation toolkit (github.com/lightfield-analysis/evaluation-toolkit) computes them.

#: Pixels left out along each side of a disparity map: the toolkit's default ``boundary_offset`` of
#: a scene (toolkit/scenes/base_scene.py, ``BaseScene``), for the 512 x 512 low-resolution maps its
#: general metrics are computed on (at another resolution it scales with the map: 150 px at 10x).
HCI_BOUNDARY_PX = 15

#: The BadPix thresholds of the benchmark's general metrics, pixels of disparity: ``BadPix(0.01)``,
#: ``BadPix(0.03)`` and ``BadPix(0.07)`` (toolkit/utils/misc.py, ``get_general_metrics``).
HCI_BADPIX_THRESHOLDS_PX = (0.01, 0.03, 0.07)


def _hci_map(name: str, value: Any) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{name} must be an (H, W) array of real numbers: {exc}") from None
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ParameterError(f"{name} must hold real numbers (floating point or integer), got dtype {arr.dtype}")
    if arr.ndim != 2:
        raise ParameterError(f"{name} must have shape (H, W), got {arr.shape}")
    return arr


def _hci_selection(disparity_px: Any, truth_px: Any, mask: Any, boundary_px: Any) -> tuple[np.ndarray, np.ndarray]:
    """The estimate and the truth at the evaluated pixels (1-D, their own dtypes), checked."""
    est = _hci_map("disparity_px", disparity_px)
    ref = _hci_map("truth_px", truth_px)
    if est.shape != ref.shape:
        raise ParameterError(f"disparity_px and truth_px must have the same shape, got {est.shape} and {ref.shape}")
    height, width = ref.shape
    if isinstance(boundary_px, bool) or not isinstance(boundary_px, (int, np.integer)) or boundary_px < 0:
        raise ParameterError(f"boundary_px must be a non-negative integer, got {shown(boundary_px)}")
    border = int(boundary_px)
    if 2 * border >= min(height, width):
        raise ParameterError(f"boundary_px = {border} leaves no pixel of a {height} x {width} map")
    selected = np.zeros(ref.shape, dtype=bool)
    selected[border : height - border, border : width - border] = True
    if mask is not None:
        m = np.asarray(mask)
        if m.dtype != np.bool_ or m.shape != ref.shape:
            raise ParameterError(f"mask must be a boolean array of shape {ref.shape}, got {m.dtype} {m.shape}")
        selected &= m
    selected &= np.isfinite(ref)
    if not selected.any():
        raise ParameterError(
            f"no pixel to evaluate: mask, the border of boundary_px = {border} and the finite values of "
            "truth_px leave none"
        )
    return est[selected], ref[selected]


def _hci_mse_x100(est: np.ndarray, ref: np.ndarray) -> float:
    e = est.astype(np.float64)
    have = np.isfinite(e)
    if not have.any():
        return float("nan")
    with np.errstate(over="ignore"):
        return float(np.mean((e[have] - ref[have].astype(np.float64)) ** 2) * 100.0)


def _hci_badpix(est: np.ndarray, ref: np.ndarray, threshold: float) -> float:
    # The toolkit subtracts and compares in the maps' own precision: float32 for PFM maps, where
    # the threshold becomes float32 as well (so an error of exactly float32(0.07) is not bad).
    dtype = np.result_type(est.dtype, ref.dtype, np.float32)
    with np.errstate(over="ignore", invalid="ignore"):
        error = np.abs(est.astype(dtype) - ref.astype(dtype))
        good = error <= dtype.type(threshold)  # NaN (a missing estimate) is not good
    return 100.0 * float(np.count_nonzero(~good)) / float(error.size)


def hci_mse_x100(
    disparity_px: np.ndarray,
    truth_px: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    boundary_px: int = HCI_BOUNDARY_PX,
) -> float:
    """The HCI benchmark's MSE x 100: mean squared disparity error over the evaluated pixels, times 100.

    As the toolkit's ``MSE`` metric (toolkit/metrics/general_metrics.py): the mean of
    ``(truth - estimate)^2`` over the evaluation mask, multiplied by 100, leaving out pixels whose
    estimate is not finite. Computed in double precision (the toolkit computes in the maps'
    float32; the two agree to about seven significant digits, the toolkit reports two decimals).

    Parameters
    ----------
    disparity_px : ndarray, shape (H, W)
        Estimated disparity, pixels (the benchmark's convention: between adjacent views); NaN or
        +-inf where there is no estimate (left out here, counted as bad by :func:`hci_badpix`).
    truth_px : ndarray, shape (H, W)
        True disparity, pixels; pixels where it is not finite carry no truth and are left out.
    mask : ndarray of bool, shape (H, W), optional
        The evaluation mask (default all pixels), e.g. one of the benchmark's region masks.
    boundary_px : int
        Pixels left out along each side, >= 0 (default :data:`HCI_BOUNDARY_PX`, the toolkit's
        choice for its 512 x 512 maps; 0 evaluates the whole map).

    Returns
    -------
    float
        The score, squared pixels times 100; NaN if no evaluated pixel has a finite estimate.

    Raises
    ------
    ParameterError
        If a map is not an (H, W) array of real numbers, the shapes differ, ``mask`` is not a
        boolean (H, W) array, ``boundary_px`` is not a non-negative integer, or no pixel is left
        to evaluate (the message names the parameter).
    """
    est, ref = _hci_selection(disparity_px, truth_px, mask, boundary_px)
    return _hci_mse_x100(est, ref)


def hci_badpix(
    disparity_px: np.ndarray,
    truth_px: np.ndarray,
    *,
    threshold_px: float,
    mask: np.ndarray | None = None,
    boundary_px: int = HCI_BOUNDARY_PX,
) -> float:
    """The HCI benchmark's BadPix(t): the percentage of evaluated pixels off by more than ``threshold_px``.

    As the toolkit's ``BadPix`` metric (toolkit/metrics/general_metrics.py): a pixel is bad when
    ``|estimate - truth| > t``, strictly (an error of exactly ``t`` is good), and the score is
    ``100 * bad / evaluated``, a **percentage** from 0 to 100 (not a fraction, unlike
    :func:`disparity_errors`). The difference and the comparison are made in the maps' own
    precision, as in the toolkit: float32 when both maps are float32 (as read from PFM files; the
    threshold is then rounded to float32 as well), float64 otherwise.

    A pixel whose estimate is NaN or +-inf is bad (it is missing). The toolkit counts +-inf as bad
    too; a NaN it counts as good, by accident of NaN comparisons (its submissions have none).

    Parameters
    ----------
    disparity_px : ndarray, shape (H, W)
        Estimated disparity, pixels; NaN or +-inf where there is no estimate.
    truth_px : ndarray, shape (H, W)
        True disparity, pixels; pixels where it is not finite carry no truth and are left out (the
        benchmark's truth is finite everywhere).
    threshold_px : float
        The threshold ``t``, pixels, > 0; the benchmark's are :data:`HCI_BADPIX_THRESHOLDS_PX`.
    mask : ndarray of bool, shape (H, W), optional
        The evaluation mask (default all pixels).
    boundary_px : int
        Pixels left out along each side, >= 0 (default :data:`HCI_BOUNDARY_PX`).

    Returns
    -------
    float
        Percentage of the evaluated pixels that are bad, 0 to 100.

    Raises
    ------
    ParameterError
        As :func:`hci_mse_x100`, or if ``threshold_px`` is not a finite positive number.
    """
    threshold = positive_float("threshold_px", threshold_px)
    est, ref = _hci_selection(disparity_px, truth_px, mask, boundary_px)
    return _hci_badpix(est, ref, threshold)


@dataclass(frozen=True, kw_only=True)
class HciScores:
    """The HCI 4D light field benchmark's general disparity scores of one map (:func:`hci_scores`).

    Parameters
    ----------
    mse_x100 : float
        Mean squared error over the evaluated pixels with a finite estimate, squared pixels times
        100 (:func:`hci_mse_x100`); NaN if none has one.
    badpix_0_01, badpix_0_03, badpix_0_07 : float
        Percentage (0 to 100) of the evaluated pixels whose error exceeds 0.01, 0.03 and 0.07 px or
        whose estimate is missing (:func:`hci_badpix`).
    count : int
        Number of evaluated pixels (inside the mask and the border, with a finite truth).
    missing : int
        How many of them have a NaN or infinite estimate.
    """

    mse_x100: float
    badpix_0_01: float
    badpix_0_03: float
    badpix_0_07: float
    count: int
    missing: int


def hci_scores(
    disparity_px: np.ndarray,
    truth_px: np.ndarray,
    *,
    mask: np.ndarray | None = None,
    boundary_px: int = HCI_BOUNDARY_PX,
) -> HciScores:
    """The HCI benchmark's MSE x 100 and BadPix(0.01), (0.03), (0.07) of a disparity map.

    Parameters are those of :func:`hci_mse_x100`; the scores are those of :func:`hci_mse_x100` and
    :func:`hci_badpix` at :data:`HCI_BADPIX_THRESHOLDS_PX`, on the same pixels.

    Returns
    -------
    HciScores
    """
    est, ref = _hci_selection(disparity_px, truth_px, mask, boundary_px)
    fine, medium, coarse = (_hci_badpix(est, ref, t) for t in HCI_BADPIX_THRESHOLDS_PX)
    return HciScores(
        mse_x100=_hci_mse_x100(est, ref),
        badpix_0_01=fine,
        badpix_0_03=medium,
        badpix_0_07=coarse,
        count=int(est.size),
        missing=int(np.count_nonzero(~np.isfinite(est))),
    )
