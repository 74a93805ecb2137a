"""Chessboard corners located in the 4D light field, from every raw pixel near them.

A sub-aperture view samples the scene once per microlens, and a corner found in it (OpenCV's
detectors) inherits that coarse sampling: 0.3-0.4 px RMS from the exact refracted projection on the
tiny-2x test camera, which does not determine a port (``docs/calibration.md``). Every raw pixel is
a sample of some sub-aperture view: its captured ray (:meth:`LightFieldCamera.captured_rays`)
leaves the main lens at the aperture point ``a`` (camera frame, metres, on the lens plane z = 0)
along direction ``d``, which is pixel ``x = K d`` of the pinhole view centred at ``a`` (the
convention of :mod:`lfrefract.synthesis.views` and :class:`~lfrefract.calibration.port.BoardView`). A board
corner appears in the view from ``a`` at ``x(a)``; over the small aperture that track is affine,

    ``x(a) = p + J a``,

(at 0.9 of the aperture radius 0.01 px from the exact refracted track behind an untilted 12 mm
port, 0.03 px behind one tilted 27 deg; boards at 0.15-0.35 m) with ``J`` the parallax: ``-f / Z``
for a central camera and a point at depth ``Z``, anisotropic behind a tilted port.

The raw pixels whose ``w = x - p - J a`` lies within a window around the corner are fitted with a
blurred X-junction,

    ``I = c0 + g . w + c1 * erf(n1 . w / s) * erf(n2 . w / s)``,

``n1, n2`` the normals of the board's two edges through the corner (angles ``theta1, theta2``),
``c0 + g . w`` the local mean with its shading gradient, ``c1`` the contrast and ``s`` the blur: 13
parameters per corner, all corners at once, by a batched Levenberg-Marquardt in numpy. A
chessboard is point-symmetric about each inner corner and so is every pixel's footprint (its
area, its microlens), so the blur's exact profile does not move the fitted centre. Starting
point: the corner found in the central view, edge normals from its neighbours in the detected
grid, and ``J = -m I`` with ``m`` the board's image scale (pixels per metre of board): a central
camera sees a point at depth ``Z`` at scale ``f / Z`` and parallax ``-f / Z``, and a flat port
changes both alike.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import erf

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.pinhole import PinholeCamera
from lfrefract.synthesis.views import raw_channels
from lfrefract.validate import as_points, finite_vector, positive_float

__all__ = ["RIM_MARGIN_PX", "CornerTracks", "light_field_corners"]

_N_PARAMS = 13  # p (2), J (4), theta1, theta2, c0, gx, gy, c1, s
_MM = 1e3  # aperture points are handled in millimetres, J in px/mm, for a well-scaled problem
_CHUNK = 64  # corners fitted together (bounds the (chunk, samples, 13) Jacobian)
#: Default margin from the micro-image rim (pixels): half a pixel diagonal, the geometric limit
#: of partial vignetting (as :class:`lfrefract.synthesis.warp_map.SynthesisOptions`).
RIM_MARGIN_PX = 0.71


@dataclass(frozen=True, eq=False)
class CornerTracks:
    """Where chessboard corners appear in every sub-aperture view of one light-field capture.

    Corner ``i`` is seen from aperture point ``a`` (camera frame, metres, main-lens plane) at pixel
    ``centre_px[i] + parallax_px_per_m[i] @ a`` of the pinhole view ``K`` it was fitted in.

    Attributes
    ----------
    centre_px : ndarray, shape (N, 2)
        The corner in the central view (``a = 0``), pixels.
    parallax_px_per_m : ndarray, shape (N, 2, 2)
        ``J``: pixels per metre of aperture offset.
    centre_std_px : ndarray, shape (N,)
        Formal standard deviation of ``centre_px`` (larger axis), from the fit's residuals.
    samples : ndarray of int, shape (N,)
        Raw pixels inside the corner's window at the solution.
    ok : ndarray of bool, shape (N,)
        False where the fit failed (no contrast, too few samples, diverged, or moved more than half
        a square): such corners must not be used.
    """

    centre_px: np.ndarray
    parallax_px_per_m: np.ndarray
    centre_std_px: np.ndarray
    samples: np.ndarray
    ok: np.ndarray

    def at(self, aperture_point_m: tuple[float, float]) -> np.ndarray:
        """Corner pixels (N, 2) in the view centred at ``aperture_point_m`` (x, y), metres."""
        a = np.asarray(finite_vector("aperture_point_m", aperture_point_m, 2))
        return self.centre_px + self.parallax_px_per_m @ a


def light_field_corners(
    camera: LightFieldCamera,
    raw: np.ndarray,
    corners_px: np.ndarray,
    *,
    pattern: tuple[int, int],
    square_size_m: float,
    view: PinholeCamera,
    window_squares: float = 0.5,
    rim_margin_px: float = RIM_MARGIN_PX,
    passes: int = 3,
    iterations: int = 8,
) -> CornerTracks:
    """Refine chessboard corners on every raw pixel around them (see the module docstring).

    Parameters
    ----------
    camera : LightFieldCamera
    raw : ndarray, shape (H, W) or (H, W, C)
        The raw lenslet image (linear radiance; channels are averaged).
    corners_px : array_like, shape (columns * rows, 2)
        The inner corners as a detector reports them in the central view resampled onto ``view``
        (:func:`lfrefract.calibration.approx.detect_chessboard`): row by row, within 1-2 px.
    pattern : (int, int)
        Inner corners per row and per column.
    square_size_m : float
        Edge of a square, metres (sets the starting parallax).
    view : PinholeCamera
        The pinhole geometry ``K`` of the views the corners are expressed in.
    window_squares : float
        Radius of each corner's window in the views, in squares (its local side in ``view``); below
        one, so that only the corner's own four squares fall inside it.
    rim_margin_px : float
        Raw pixels nearer than this to their micro-image's rim (partly vignetted) are not used.
    passes, iterations : int
        Window re-selections, and Levenberg-Marquardt steps in each.

    Returns
    -------
    CornerTracks

    Raises
    ------
    ParameterError
        If the corners do not match ``pattern`` or an option is out of range.
    """
    cols, rows = (int(n) for n in pattern)
    if cols < 2 or rows < 2:
        raise ParameterError(f"pattern must be at least (2, 2), got {pattern!r}")
    corners = as_points("corners_px", corners_px, 2)
    if len(corners) != cols * rows:
        raise ParameterError(f"corners_px must have {cols} x {rows} = {cols * rows} rows, got {len(corners)}")
    square = positive_float("square_size_m", square_size_m)
    window = positive_float("window_squares", window_squares)
    if window >= 1.0:
        raise ParameterError(f"window_squares must be below 1 (the neighbouring corners), got {window_squares!r}")
    if not isinstance(view, PinholeCamera):
        raise ParameterError(f"view must be a PinholeCamera, got {view!r}")

    # Every usable raw pixel as a light-field sample: view pixel x, aperture point a (mm), value.
    # The samples and their k-d tree depend on the camera alone and are built once (a full Illum
    # sensor: 24 million samples, 30 s; the tree alone 6 s a capture when it was built for each).
    grey = raw_channels(camera, raw).mean(axis=2, dtype=np.float64).ravel()
    samples = _light_field_samples(camera, view, float(rim_margin_px))
    x_all, a_all, i_all = samples.view_px, samples.aperture_mm, grey[samples.pixel]
    finite = np.isfinite(i_all)  # unrecorded pixels (NaN) are no samples

    # Start: edge directions and local square side from the neighbours in the grid.
    grid = corners.reshape(rows, cols, 2)
    along_row = np.gradient(grid, axis=1).reshape(-1, 2)
    along_col = np.gradient(grid, axis=0).reshape(-1, 2)
    side_px = np.minimum(np.linalg.norm(along_row, axis=1), np.linalg.norm(along_col, axis=1))
    scale_px_per_mm = np.maximum(np.linalg.norm(along_row, axis=1), np.linalg.norm(along_col, axis=1)) / square / _MM
    radius = window * side_px
    pixels_per_lens = view.focal_px * camera.mla.pitch_m / camera.lens_to_mla_m
    start = np.zeros((len(corners), _N_PARAMS))
    start[:, 0:2] = corners
    start[:, 2] = start[:, 5] = -scale_px_per_mm
    start[:, 6] = np.arctan2(along_row[:, 1], along_row[:, 0]) + math.pi / 2  # normal of the edge along a row
    start[:, 7] = np.arctan2(along_col[:, 1], along_col[:, 0]) + math.pi / 2
    start[:, 12] = 0.35 * pixels_per_lens

    reach = radius + scale_px_per_mm * camera.aperture_radius_m * _MM + 1.0
    result = np.zeros((len(corners), _N_PARAMS))
    std = np.full(len(corners), np.inf)
    counts = np.zeros(len(corners), dtype=np.int64)
    for lo in range(0, len(corners), _CHUNK):
        sl = slice(lo, lo + _CHUNK)
        neighbours = [
            np.asarray(found, dtype=np.int64)[finite[found]]
            for found in samples.tree.query_ball_point(corners[sl], reach[sl])
        ]
        width = max(max((len(n) for n in neighbours), default=0), 1)
        index = np.zeros((len(neighbours), width), dtype=np.int64)
        present = np.zeros((len(neighbours), width), dtype=bool)
        for row, found in enumerate(neighbours):  # one row per corner, not per pixel
            index[row, : len(found)] = found
            present[row, : len(found)] = True
        # Padding must hold a finite value too: the fit multiplies it by a zero weight.
        gathered = (x_all[index], a_all[index], np.where(present, i_all[index], 0.0), present)
        fit = _fit_chunk(*gathered, start[sl], radius[sl], passes=passes, iterations=iterations)
        result[sl], std[sl], counts[sl] = fit

    moved = np.linalg.norm(result[:, 0:2] - corners, axis=1)
    ok = (
        np.all(np.isfinite(result), axis=1)
        & (std < 0.5)  # a corner located worse than half a pixel is no corner
        & (moved < 0.5 * side_px)
        & (counts >= 4 * _N_PARAMS)
        & (result[:, 12] > 0.0)
        & (result[:, 12] < 2.0 * pixels_per_lens)
    )
    return CornerTracks(
        centre_px=result[:, 0:2],
        parallax_px_per_m=result[:, 2:6].reshape(-1, 2, 2) * _MM,
        centre_std_px=std,
        samples=counts,
        ok=ok,
    )


@dataclass(frozen=True, eq=False)
class _Samples:
    """The raw pixels whose chief ray passes the usable aperture, as light-field samples.

    Attributes
    ----------
    pixel : ndarray of int, shape (M,)
        Flat index (``v * W + u``) of each sample's raw pixel.
    view_px : ndarray, shape (M, 2)
        Its pixel in the view.
    aperture_mm : ndarray, shape (M, 2)
        Its aperture point (camera frame, main-lens plane), millimetres.
    tree : scipy.spatial.cKDTree
        Over ``view_px``.
    """

    pixel: np.ndarray
    view_px: np.ndarray
    aperture_mm: np.ndarray
    tree: cKDTree


@functools.lru_cache(maxsize=2)  # a stereo rig's two cameras; each entry of an Illum is about 1.5 GB
def _light_field_samples(camera: LightFieldCamera, view: PinholeCamera, rim_margin_px: float) -> _Samples:
    """The light-field samples of ``camera`` in ``view`` (the same for every capture)."""
    rays = camera.captured_rays()
    aperture = rays.origins_cam[:, :2]
    usable = rays.in_aperture & (np.hypot(*aperture.T) <= camera.usable_aperture_radius_m(rim_margin_px))
    view_px = view.project(rays.directions_cam[usable])
    samples = _Samples(
        pixel=np.flatnonzero(usable),
        view_px=view_px,
        aperture_mm=aperture[usable] * _MM,
        tree=cKDTree(view_px, balanced_tree=False, compact_nodes=False),
    )
    for array in (samples.pixel, samples.view_px, samples.aperture_mm):
        array.flags.writeable = False  # shared between calls
    return samples


def _local(params: np.ndarray, x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Local coordinates ``w = x - p - J a`` (C, M, 2) of samples ``x`` (C, M, 2) seen from ``a``."""
    jac_a = params[:, 2:6].reshape(-1, 1, 2, 2)
    return x - params[:, None, 0:2] - np.sum(jac_a * a[..., None, :], axis=3)


def _model(params: np.ndarray, x: np.ndarray, a: np.ndarray, *, jacobian: bool = True):
    """X-junction values (C, M) at samples ``x`` seen from ``a``, and with ``jacobian`` their
    Jacobian (C, M, 13)."""
    w = _local(params, x, a)
    theta1, theta2 = params[:, 6:7], params[:, 7:8]
    c0, g, c1, s = params[:, 8:9], params[:, None, 9:11], params[:, 11:12], params[:, 12:13]
    n1 = np.stack([np.cos(theta1), np.sin(theta1)], axis=2)  # (C, 1, 2)
    n2 = np.stack([np.cos(theta2), np.sin(theta2)], axis=2)
    u, v = np.sum(w * n1, axis=2) / s, np.sum(w * n2, axis=2) / s
    eu, ev = erf(u), erf(v)
    value = c0 + np.sum(g * w, axis=2) + c1 * eu * ev
    if not jacobian:
        return value
    du, dv = 2.0 / math.sqrt(math.pi) * np.exp(-(u**2)), 2.0 / math.sqrt(math.pi) * np.exp(-(v**2))
    # d value / d w (C, M, 2): the shading gradient plus the junction's.
    d_w = g + c1[..., None] * ((du * ev)[..., None] * n1 + (eu * dv)[..., None] * n2) / s[..., None]
    jac = np.empty((*value.shape, _N_PARAMS))
    jac[..., 0:2] = -d_w
    jac[..., 2:6] = -(d_w[..., :, None] * a[..., None, :]).reshape(*value.shape, 4)
    jac[..., 6] = c1 * du * ev * (w[..., 1] * n1[..., 0] - w[..., 0] * n1[..., 1]) / s
    jac[..., 7] = c1 * eu * dv * (w[..., 1] * n2[..., 0] - w[..., 0] * n2[..., 1]) / s
    jac[..., 8] = 1.0
    jac[..., 9:11] = w
    jac[..., 11] = eu * ev
    jac[..., 12] = -c1 * (du * ev * u + eu * dv * v) / s
    return value, jac


def _compact(keep: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """Gather each row's kept samples (C, M) to the front of narrower padded arrays; the last
    array returned is the new presence mask."""
    width = max(int(keep.sum(axis=1).max(initial=0)), 1)
    order = np.argsort(~keep, axis=1, kind="stable")[:, :width]
    rows = np.arange(len(keep))[:, None]
    return (*(arr[rows, order] for arr in arrays), keep[rows, order])


def _fit_chunk(
    x: np.ndarray,
    a: np.ndarray,
    values: np.ndarray,
    present: np.ndarray,
    start: np.ndarray,
    radius: np.ndarray,
    *,
    passes: int,
    iterations: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched Levenberg-Marquardt for C corners over padded samples (C, M).

    Each pass keeps the samples within ``radius`` of the current track and runs ``iterations``
    damped Gauss-Newton steps on them. Returns the parameters (C, 13), the centre's standard
    deviation (C,), and the sample counts (C,).
    """
    # Normalise each corner's values so that one damping schedule suits all.
    masked = np.where(present, values, np.nan)
    lo = np.nanpercentile(masked, 5, axis=1)[:, None]
    span = np.nanpercentile(masked, 95, axis=1)[:, None] - lo
    span = np.where(span > 0, span, 1.0)
    z = (values - lo) / span
    params = start.copy()
    # Photometric start: c0, g, c1 by linear least squares at the starting geometry.
    w = _local(params, x, a)
    inside = present & (np.sum(w**2, axis=2) < radius[:, None] ** 2)
    c1_only = params.copy()
    c1_only[:, 8:12] = [0.0, 0.0, 0.0, 1.0]
    junction = _model(c1_only, x, a, jacobian=False)[..., None]
    design = np.concatenate([np.ones((*z.shape, 1)), w, junction], axis=2) * inside[..., None]
    gram = design.transpose(0, 2, 1) @ design + 1e-9 * np.eye(4)
    params[:, 8:12] = np.linalg.solve(gram, (design.transpose(0, 2, 1) @ (z * inside)[..., None]))[..., 0]
    damping = np.full(len(params), 1e-3)
    eye = np.eye(_N_PARAMS)
    for _ in range(passes):
        w = _local(params, x, a)
        keep = present & (np.sum(w**2, axis=2) < radius[:, None] ** 2)
        xs, as_, zs, inside = _compact(keep, x, a, z)
        value, jac = _model(params, xs, as_)
        cost = np.sum(inside * (value - zs) ** 2, axis=1)
        for _ in range(iterations):
            jw = jac * inside[..., None]
            jw_t = jw.transpose(0, 2, 1)
            gram = jw_t @ jw
            grad = (jw_t @ ((value - zs) * inside)[..., None])[..., 0]
            lhs = gram + damping[:, None, None] * (np.einsum("cii->ci", gram)[:, :, None] * eye + 1e-12 * eye)
            with np.errstate(invalid="ignore", over="ignore"):
                step = np.linalg.solve(lhs, -grad[..., None])[..., 0]
            trial = params + np.where(np.isfinite(step), step, 0.0)
            t_value = _model(trial, xs, as_, jacobian=False)
            t_cost = np.sum(inside * (t_value - zs) ** 2, axis=1)
            better = t_cost < cost
            params = np.where(better[:, None], trial, params)
            cost = np.where(better, t_cost, cost)
            damping = np.clip(np.where(better, damping * 0.3, damping * 10.0), 1e-9, 1e9)
            value, jac = _model(params, xs, as_)
    # Formal covariance of the centre at the solution (window of the last pass).
    count = inside.sum(axis=1)
    jw = jac * inside[..., None]
    gram = jw.transpose(0, 2, 1) @ jw
    sigma2 = cost / np.maximum(count - _N_PARAMS, 1)
    std = np.full(len(params), np.inf)
    invertible = np.linalg.cond(gram) < 1e14
    if np.any(invertible):
        cov = np.linalg.inv(gram[invertible])[:, 0:2, 0:2] * sigma2[invertible, None, None]
        std[invertible] = np.sqrt(np.maximum(np.linalg.eigvalsh(cov)[:, -1], 0.0))
    params[:, 8:12] *= span  # values back to the raw image's units
    params[:, 8] += lo[:, 0]
    return params, std, count
