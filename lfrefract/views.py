"""Conventional views of a raw lenslet image, with no refraction handling (the baselines' input).

``central``: the central sub-aperture image, one sample per microlens at its micro-image centre
(the ray through the main-lens centre). ``full``: the full-aperture image, each microlens's
micro-image averaged (what a conventional camera focused on the MLA's conjugate plane records).
Either is resampled onto a pinhole image: the ray through the main-lens centre and a lens centre
``c`` (image plane) leaves along ``(c_xi, c_eta, f')``, so lens ``c`` lands at pixel
``K @ (c_xi / f', c_eta / f', 1)``; values between lens positions are interpolated linearly.

Sub-aperture views (:func:`subaperture_view`) sample every micro-image at the same offset
``delta`` (pixels) from its centre. All those rays pass one point of the main lens,
``h = delta * pixel_pitch * f' / f_mla`` (:func:`subaperture_centre_m`), so the view is a pinhole
at ``h`` with the central view's orientation; with the MLA off the focal plane (``f' != f``) its
rays are also tilted by ``delta * pixel_pitch / f_mla * (1 - f' / f)``, a shift of the principal
point.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage, sparse
from scipy.spatial import Delaunay

from lfrefract._validate import ParameterError, finite_vector, one_of
from lfrefract.camera import LightFieldCamera
from lfrefract.pinhole import PinholeCamera, virtual_camera_for

__all__ = [
    "VIEW_KINDS",
    "apply_resampling",
    "micro_image_samples",
    "naive_view",
    "raw_channels",
    "resampling_matrix",
    "subaperture_centre_m",
    "subaperture_view",
]

VIEW_KINDS = ("central", "full")


def _row_of(table: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """Row of ``table`` (M, 2) holding each integer pair of ``queries`` (N, 2), or -1."""
    lo = np.minimum(table.min(axis=0), queries.min(axis=0))
    span = int(max(table.max(axis=0).max(), queries.max(axis=0).max()) - lo.min()) + 1
    keys = (table[:, 0] - lo[0]) * span + (table[:, 1] - lo[1])
    order = np.argsort(keys)
    q = (queries[:, 0] - lo[0]) * span + (queries[:, 1] - lo[1])
    pos = np.clip(np.searchsorted(keys[order], q), 0, len(keys) - 1)
    found = keys[order][pos] == q
    return np.where(found, order[pos], -1)


def micro_image_samples(
    camera: LightFieldCamera, raw: np.ndarray, idx: np.ndarray, offset_px: tuple[float, float] = (0.0, 0.0)
) -> np.ndarray:
    """Bilinear samples (M, C) of ``raw`` (H, W, C) at the micro-image centres of lenses ``idx``
    (M, 2) plus ``offset_px`` (sensor pixels)."""
    points = camera.micro_image_centres_px(idx) + np.asarray(offset_px)
    return np.stack(
        [
            ndimage.map_coordinates(raw[..., c], [points[:, 1], points[:, 0]], order=1, mode="nearest")
            for c in range(raw.shape[2])
        ],
        axis=1,
    )


def _per_lens_values(camera: LightFieldCamera, raw: np.ndarray, kind: str) -> tuple[np.ndarray, np.ndarray]:
    idx = camera.lens_indices_on_sensor()
    if kind == "central":
        return idx, micro_image_samples(camera, raw, idx, (0.0, 0.0))
    rays = camera.captured_rays()
    lens_of_pixel = _row_of(idx, rays.lens_indices)
    use = rays.in_aperture & (lens_of_pixel >= 0)
    counts = np.bincount(lens_of_pixel[use], minlength=len(idx))
    flat = raw.reshape(-1, raw.shape[2])
    sums = np.stack(
        [np.bincount(lens_of_pixel[use], weights=flat[use, c], minlength=len(idx)) for c in range(raw.shape[2])], axis=1
    )
    keep = counts > 0
    return idx[keep], sums[keep] / counts[keep, None]


def naive_view(
    camera: LightFieldCamera, raw: np.ndarray, *, output: PinholeCamera | None = None, kind: str = "central"
) -> np.ndarray:
    """Resample a conventional view of ``raw`` onto a pinhole image, ignoring any port.

    Parameters
    ----------
    camera : LightFieldCamera
    raw : ndarray, shape (H, W) or (H, W, C)
        Raw lenslet image of ``camera``'s sensor size.
    output : PinholeCamera, optional
        Output geometry; default :func:`virtual_camera_for` ``(camera)``.
    kind : {"central", "full"}
        Central sub-aperture or full-aperture view.

    Returns
    -------
    ndarray, float32, shape (height, width) or (height, width, C)
        NaN outside the lenses' hull.
    """
    one_of("kind", kind, VIEW_KINDS)
    image = raw_channels(camera, raw)
    idx, values = _per_lens_values(camera, image, kind)
    return _resample(camera, idx, values, output, (0.0, 0.0), grey=np.ndim(raw) == 2)


def raw_channels(camera: LightFieldCamera, raw: np.ndarray) -> np.ndarray:
    """``raw`` (H, W) or (H, W, C) as float32 (H, W, C), checked against the camera's sensor size."""
    arr = np.asarray(raw, dtype=np.float32)
    if arr.shape[:2] != (camera.sensor.height_px, camera.sensor.width_px) or arr.ndim not in (2, 3):
        raise ParameterError(
            f"raw must have shape ({camera.sensor.height_px}, {camera.sensor.width_px}) (+ channels), got {arr.shape}"
        )
    return arr[..., None] if arr.ndim == 2 else arr


def _resample(
    camera: LightFieldCamera,
    idx: np.ndarray,
    values: np.ndarray,
    output: PinholeCamera | None,
    slope_shift: tuple[float, float],
    *,
    grey: bool,
) -> np.ndarray:
    """Per-lens values (M, C) onto the pinhole image: lens ``c`` at ``K (c / f' + slope_shift, 1)``."""
    output = output if output is not None else virtual_camera_for(camera)
    _, matrix, inside = resampling_matrix(camera, output, slope_shift=slope_shift, lenses=idx)
    return apply_resampling(matrix, inside, values, output, grey=grey)


def apply_resampling(
    matrix: sparse.csr_matrix, inside: np.ndarray, values: np.ndarray, output: PinholeCamera, *, grey: bool
) -> np.ndarray:
    """Per-lens values (M, C) through a :func:`resampling_matrix` onto the pinhole image, float32,
    NaN outside the lenses' hull; ``grey`` drops the channel axis."""
    out = np.asarray(matrix @ values.astype(np.float64), dtype=np.float32)
    out[~inside] = np.nan
    out = out.reshape(output.height_px, output.width_px, -1)
    return out[..., 0] if grey else out


def resampling_matrix(
    camera: LightFieldCamera,
    output: PinholeCamera,
    *,
    slope_shift: tuple[float, float] = (0.0, 0.0),
    lenses: np.ndarray | None = None,
) -> tuple[np.ndarray, sparse.csr_matrix, np.ndarray]:
    """Linear interpolation from per-lens samples to the pixels of a pinhole image.

    Lens ``c`` sits at ``K (c / f' + slope_shift, 1)``; a pixel inside the lenses' Delaunay
    triangulation is the barycentric mix of its triangle's three lenses (what
    ``scipy.interpolate.LinearNDInterpolator`` does, with the weights computed once, in numpy:
    scipy's per-triangle transforms call LAPACK per triangle, which took 0.7-15 s with threaded
    OpenBLAS on a busy 2-core machine against 0.02 s single-threaded).

    Returns
    -------
    lenses : ndarray of int, shape (M, 2)
        Lattice indices of the lenses, in the matrix's column order (default: every lens on the sensor).
    matrix : scipy.sparse.csr_matrix, shape (height * width, M)
    inside : ndarray of bool, shape (height * width,)
        Pixels inside the triangulation (the others have no value).
    """
    lenses = camera.lens_indices_on_sensor() if lenses is None else lenses
    positions = output.focal_px * (camera.mla.centres_m(lenses) / camera.lens_to_mla_m + np.asarray(slope_shift))
    positions = positions + np.array([output.cx_px, output.cy_px])
    pixels, corners, weights = _linear_weights(positions, output.width_px, output.height_px)
    n_pixels = output.width_px * output.height_px
    entries = (weights.ravel(), (np.repeat(pixels, 3), corners.ravel()))
    matrix = sparse.csr_matrix(entries, shape=(n_pixels, len(lenses)))
    inside = np.zeros(n_pixels, dtype=bool)
    inside[pixels] = True
    return lenses, matrix, inside


def _linear_weights(positions: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Piecewise-linear interpolation weights over the Delaunay triangulation of ``positions``.

    Returns, for every pixel centre ``(u, v)`` of a ``width x height`` grid inside the
    triangulation: its flat index (``v * width + u``), the three vertices (P, 3) of a triangle
    containing it and their barycentric weights (P, 3).
    """
    simplices = Delaunay(positions).simplices
    corners = positions[simplices]  # (M, 3, 2)
    e0, e1 = corners[:, 0] - corners[:, 2], corners[:, 1] - corners[:, 2]
    det = e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0]
    scale = np.max(np.abs(positions)) + 1.0
    proper = np.abs(det) > 1e-12 * scale**2  # qhull may leave flat slivers on the hull
    proper &= np.all(corners.max(axis=1) >= 0, axis=1) & np.all(corners.min(axis=1) <= [width - 1, height - 1], axis=1)
    simplices, corners, e0, e1, det = simplices[proper], corners[proper], e0[proper], e1[proper], det[proper]
    # Inverse of the 2 x 2 matrix [e0 e1] (columns), per triangle.
    inverse = np.stack([np.stack([e1[:, 1], -e1[:, 0]], 1), np.stack([-e0[:, 1], e0[:, 0]], 1)], 1) / det[:, None, None]
    lo = np.clip(np.ceil(corners.min(axis=1)).astype(np.int64), 0, [width - 1, height - 1])
    hi = np.clip(np.floor(corners.max(axis=1)).astype(np.int64), 0, [width - 1, height - 1])
    span = int(max((hi - lo).max(initial=0), 0)) + 1
    oy, ox = np.mgrid[0:span, 0:span]
    candidates = lo[:, None, :] + np.stack([ox.ravel(), oy.ravel()], axis=1)[None]  # (M, S, 2)
    bary = np.einsum("mij,msj->msi", inverse, candidates - corners[:, None, 2])
    weights = np.concatenate([bary, 1.0 - bary.sum(axis=2, keepdims=True)], axis=2)
    tol = 100 * np.finfo(np.float64).eps
    inside = np.all(weights >= -tol, axis=2) & np.all(candidates <= hi[:, None, :], axis=2)
    tri, cand = np.nonzero(inside)
    pixel = candidates[tri, cand, 1] * width + candidates[tri, cand, 0]
    pixel, first = np.unique(pixel, return_index=True)  # a pixel on a shared edge: either triangle
    return pixel, simplices[tri[first]], weights[tri[first], cand[first]]


def subaperture_centre_m(camera: LightFieldCamera, offset_px: tuple[float, float]) -> np.ndarray:
    """Centre of projection (3,), camera frame, metres, of the sub-aperture view at ``offset_px``.

    ``offset_px = (du, dv)``: the sensor offset from every micro-image centre, pixels. The point
    is on the main-lens plane: ``(du, dv, 0) * pixel_pitch * f' / f_mla``.
    """
    du, dv = finite_vector("offset_px", offset_px, 2)
    scale = camera.sensor.pixel_pitch_m * camera.lens_to_mla_m / camera.mla.focal_length_m
    return np.array([du * scale, dv * scale, 0.0])


def subaperture_view(
    camera: LightFieldCamera,
    raw: np.ndarray,
    offset_px: tuple[float, float],
    *,
    output: PinholeCamera | None = None,
) -> np.ndarray:
    """The sub-aperture view at ``offset_px`` from the micro-image centres, as a pinhole image.

    Its centre of projection is :func:`subaperture_centre_m` ``(camera, offset_px)``; pixel
    ``p`` of the result looks along ``K^-1 p`` from there (camera-frame orientation), like the
    central view (``offset_px = (0, 0)``, which equals :func:`naive_view` ``kind="central"``).

    Parameters
    ----------
    camera : LightFieldCamera
    raw : ndarray, shape (H, W) or (H, W, C)
    offset_px : (float, float)
        ``(du, dv)``, pixels; at most the micro-image radius less one pixel, so that no sample is
        vignetted.
    output : PinholeCamera, optional
        Output geometry; default :func:`virtual_camera_for` ``(camera)``.

    Returns
    -------
    ndarray, float32, shape (height, width) or (height, width, C)
        NaN outside the lenses' hull.
    """
    du, dv = finite_vector("offset_px", offset_px, 2)
    limit = camera.micro_image_radius_px - 1.0
    if np.hypot(du, dv) > limit:
        raise ParameterError(
            f"offset_px={offset_px!r} reaches the micro-image rim (at most {limit:.3g} px from its centre)"
        )
    image = raw_channels(camera, raw)
    idx = camera.lens_indices_on_sensor()
    values = micro_image_samples(camera, image, idx, (du, dv))
    spread = 1.0 - camera.lens_to_mla_m / camera.focal_length_m
    tilt = camera.sensor.pixel_pitch_m / camera.mla.focal_length_m * spread
    return _resample(camera, idx, values, output, (du * tilt, dv * tilt), grey=np.ndim(raw) == 2)
