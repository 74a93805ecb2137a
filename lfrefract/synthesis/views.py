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

A view stack (:func:`subaperture_stack`) is a regular ``grid x grid`` set of sub-aperture views,
offsets ``((column - h) s, (row - h) s)`` with ``h = (grid - 1) / 2``: its centres of projection
form a regular grid on the main-lens plane, ``baseline = s * pixel_pitch * f' / f_mla`` apart, and
every view has the same K and orientation, so it is the input that light-field depth-estimation
methods expect (``lfrefract.formats.viewstack.write_view_stack`` writes it in the HCI benchmark layout).

A calibrated camera (a :class:`lfrefract.optics.camera_model.CameraModel` whose ``correction`` is
a :class:`lfrefract.optics.ray_correction.RayCorrection`, from ``lfrefract calibrate camera``) moves
every ray: the thin-lens slope ``t`` becomes ``t' = s t (1 + k1 |t|^2 + k2 |t|^4)`` and the aperture
point ``a`` becomes ``m a``. Every function here takes such a model in place of a bare camera: a
lens then lands at ``K (t', 1)`` (the main lens's distortion removed) and a sub-aperture view's
centre of projection is ``m h``, so the views are again pinholes of one K and
the stack's baseline is ``m`` times the thin lens's. The pupil's drift ``d`` is left out: the rays of
slope ``t'`` cross the axis at ``z = d |t'|^2`` rather than 0, which moves a point at depth ``Z`` by
about ``f_px d |t'|^3 / Z`` pixels in the views (0.01 px for the tiny camera's corner at 0.3 m with
d = 1 mm); the refraction-free synthesis uses every ray's exact origin.

Unrecorded raw pixels (NaN, inf or negative values a capture was told to mask,
:func:`lfrefract.formats.capture.read_capture`) are excluded with ``recorded``, an (H, W) bool mask of the
raw image: every sample then averages the recorded pixels only, with its weights renormalised over
them, and a sample with no recorded pixel has no value (NaN), which the resampling onto the pinhole
image skips in turn (its barycentric weights renormalised over the lenses that have a value).
Without ``recorded`` every raw value is used as it is.

Every function that allocates an image first checks its estimated peak memory against the memory
available (:func:`naive_view_bytes`, :func:`view_stack_bytes`), so that a size typed wrong is
refused at once, naming the estimate.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage, sparse
from scipy.spatial import Delaunay

from lfrefract._memory import require_memory
from lfrefract.errors import ParameterError
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.camera_model import CameraModel, as_camera_model
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.ray_correction import UNSTRUCTURED, Correction, RayCorrection
from lfrefract.synthesis.empty import masked_reason, output_geometry, require_a_value
from lfrefract.validate import finite_vector, one_of, positive_float

__all__ = [
    "VIEW_KINDS",
    "ViewStack",
    "apply_resampling",
    "finite_pixels",
    "lens_count",
    "micro_image_samples",
    "naive_view",
    "naive_view_bytes",
    "raw_channels",
    "recorded_mask",
    "resampling_bytes",
    "resampling_matrix",
    "subaperture_centre_m",
    "subaperture_limit_px",
    "subaperture_slope_shift",
    "subaperture_stack",
    "subaperture_view",
    "view_stack_bytes",
]

VIEW_KINDS = ("central", "full")

#: Bytes per output pixel that resampling per-lens values onto a pinhole image allocates besides the
#: image: the interpolation weights, their sort and the sparse matrix (measured with tracemalloc: 120 B
#: at 0.1 to 7 Mpx on tiny, tiny-2x and the Illum; see :func:`resampling_bytes` for the rest).
RESAMPLING_BYTES_PER_PIXEL = 150

#: Bytes per lens of the resampling: the Delaunay triangulation (qhull's working memory, which
#: tracemalloc does not see: 950 B per lens of resident memory at the Illum's 233 171 lenses) and the
#: triangles' arrays (about 300 B).
RESAMPLING_BYTES_PER_LENS = 1500

#: Rows and candidate pixels the resampling's rasterisation (:func:`_linear_weights`) handles at once,
#: so that its temporaries stay bounded (:data:`RESAMPLING_BYTES_PER_CHUNK_ITEM` each, about 6 MiB)
#: and a signal (SIGTERM) is handled between chunks.
RESAMPLING_CHUNK = 1 << 16

#: Bytes of temporaries per row and candidate pixel of a rasterisation chunk, beyond the pixels it finds
#: (measured 70-110 B).
RESAMPLING_BYTES_PER_CHUNK_ITEM = 100

#: Bytes per raw pixel of the full-aperture view's per-pixel captured rays (measured: 270 B).
FULL_VIEW_BYTES_PER_RAW_PIXEL = 300


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
    camera: LightFieldCamera,
    raw: np.ndarray,
    idx: np.ndarray,
    offset_px: tuple[float, float] = (0.0, 0.0),
    *,
    recorded: np.ndarray | None = None,
) -> np.ndarray:
    """Bilinear samples (M, C) of ``raw`` (H, W, C) at the micro-image centres of lenses ``idx``
    (M, 2) plus ``offset_px`` (sensor pixels).

    With ``recorded`` ((H, W) bool, :func:`recorded_mask`) only recorded pixels count: the bilinear
    weights are renormalised over them, and a sample with none is NaN.
    """
    points = camera.micro_image_centres_px(idx) + np.asarray(offset_px)
    planes = [raw[..., c] for c in range(raw.shape[2])]
    return _bilinear(planes, points, None if recorded is None else _weight_plane(recorded))


def _weight_plane(recorded: np.ndarray) -> np.ndarray:
    """``recorded`` (H, W) bool as float32 1 / 0, the weight plane of :func:`_bilinear`."""
    return np.ascontiguousarray(recorded, dtype=np.float32)


def _bilinear(planes: list[np.ndarray], points: np.ndarray, weight: np.ndarray | None) -> np.ndarray:
    """Bilinear samples (M, C) of the channel ``planes`` (each (H, W)) at pixel ``points`` (M, 2).

    ``weight`` ((H, W), 1 where recorded, 0 where not) renormalises the bilinear weights over the
    recorded pixels: ``sum w_i r_i v_i / sum w_i r_i``, NaN where that sum is 0.
    """
    coords = [points[:, 1], points[:, 0]]
    if weight is None:
        return np.stack([ndimage.map_coordinates(p, coords, order=1, mode="nearest") for p in planes], axis=1)
    total = ndimage.map_coordinates(weight, coords, order=1, mode="nearest")
    values = np.stack(
        [ndimage.map_coordinates(np.where(weight > 0, p, 0.0), coords, order=1, mode="nearest") for p in planes],
        axis=1,
    )
    has = total > 0
    out = np.full(values.shape, np.nan, dtype=values.dtype)
    out[has] = values[has] / total[has, None]
    return out


def _per_lens_values(
    camera: LightFieldCamera, raw: np.ndarray, kind: str, recorded: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    idx = camera.lens_indices_on_sensor()
    if kind == "central":
        return idx, micro_image_samples(camera, raw, idx, (0.0, 0.0), recorded=recorded)
    rays = camera.captured_rays()
    lens_of_pixel = _row_of(idx, rays.lens_indices)
    use = rays.in_aperture & (lens_of_pixel >= 0)
    keep = np.bincount(lens_of_pixel[use], minlength=len(idx)) > 0  # lenses with a pixel in the aperture
    if recorded is not None:
        use &= recorded.ravel()
    counts = np.bincount(lens_of_pixel[use], minlength=len(idx))
    flat = raw.reshape(-1, raw.shape[2])
    sums = np.stack(
        [np.bincount(lens_of_pixel[use], weights=flat[use, c], minlength=len(idx)) for c in range(raw.shape[2])], axis=1
    )
    with np.errstate(invalid="ignore", divide="ignore"):  # a lens with no recorded pixel: NaN, no value
        return idx[keep], sums[keep] / counts[keep, None]


def naive_view(
    camera: LightFieldCamera | CameraModel,
    raw: np.ndarray,
    *,
    output: PinholeCamera | None = None,
    kind: str = "central",
    recorded: np.ndarray | None = None,
) -> np.ndarray:
    """Resample a conventional view of ``raw`` onto a pinhole image, ignoring any port.

    Parameters
    ----------
    camera : LightFieldCamera or CameraModel
        The camera and its ray model: a calibrated radial model's rays (see the module docstring),
        else (a bare camera) the thin lens's.
    raw : ndarray, shape (H, W) or (H, W, C)
        Raw lenslet image of ``camera``'s sensor size.
    output : PinholeCamera, optional
        Output geometry; default :func:`virtual_camera_for` ``(camera)``.
    kind : {"central", "full"}
        Central sub-aperture or full-aperture view.
    recorded : ndarray of bool, shape (H, W), optional
        Raw pixels that hold a recorded value; the others are not used (see the module docstring).
        Default: all.

    Returns
    -------
    ndarray, float32, shape (height, width) or (height, width, C)
        NaN outside the lenses' hull, and where no recorded pixel contributes.

    Raises
    ------
    ParameterError
        For a raw image of another size, an unknown ``kind``, the polynomial ray model, or an output
        whose estimated memory (:func:`naive_view_bytes`) exceeds the memory available.
    """
    one_of("kind", kind, VIEW_KINDS)
    camera, ray_correction = _unpacked(camera)
    output = output if output is not None else virtual_camera_for(camera)
    if not isinstance(output, PinholeCamera):
        raise ParameterError(f"output must be a PinholeCamera, got {output!r}")
    image = raw_channels(camera, raw)
    recorded = recorded_mask(camera, recorded)
    require_memory(
        f"a {kind} view of {output.width_px} x {output.height_px} px",
        naive_view_bytes(camera, output, kind=kind, channels=image.shape[2]),
    )
    idx, values = _per_lens_values(camera, image, kind, recorded)
    return _resample(
        camera, idx, values, output, (0.0, 0.0), ray_correction, grey=np.ndim(raw) == 2, masked=recorded is not None
    )


def naive_view_bytes(camera: LightFieldCamera, output: PinholeCamera, *, kind: str, channels: int) -> int:
    """Estimated peak memory of :func:`naive_view`, bytes (see :mod:`lfrefract._memory`).

    The float32 raw copy, and the larger of: the resampling (:func:`resampling_bytes`) and the image
    (float64 product and float32 result, 12 bytes per channel and output pixel); for
    ``kind="full"`` the captured rays of every raw pixel (:data:`FULL_VIEW_BYTES_PER_RAW_PIXEL`),
    freed before the resampling. Measured with tracemalloc, plus qhull's memory, on tiny and tiny-2x
    at 6 000 to 240 000 output pixels: 0.5-0.6 of the estimate for the central view (a float32 raw
    is not copied), 0.6-0.8 for the full view.
    """
    raw_pixels = camera.sensor.width_px * camera.sensor.height_px
    pixels = output.width_px * output.height_px
    resampling = resampling_bytes(lenses=lens_count(camera), pixels=pixels) + 12 * channels * pixels
    rays = FULL_VIEW_BYTES_PER_RAW_PIXEL * raw_pixels if kind == "full" else 0
    return int(4 * channels * raw_pixels + max(resampling, rays))


def resampling_bytes(*, lenses: int, pixels: int) -> int:
    """Estimated peak memory of :func:`resampling_matrix` over ``lenses`` lenses onto ``pixels`` output
    pixels, bytes (see :mod:`lfrefract._memory`).

    :data:`RESAMPLING_BYTES_PER_PIXEL` per pixel, :data:`RESAMPLING_BYTES_PER_LENS` per lens and one
    chunk of the rasterisation (:data:`RESAMPLING_CHUNK` rows and candidates, fewer for small images).
    Its work is bounded whatever the lenses' positions (a calibrated camera's distortion included).
    Measured with tracemalloc, plus qhull's 950 B per lens that it does not see, on tiny, tiny-2x and
    the Illum at 54 px to 7 Mpx, thin-lens and k1 = 0.05 lens fields: 0.65-0.9 of the estimate.
    """
    chunk = min(RESAMPLING_CHUNK, pixels + 2 * lenses)
    return int(
        RESAMPLING_BYTES_PER_PIXEL * pixels
        + RESAMPLING_BYTES_PER_LENS * lenses
        + RESAMPLING_BYTES_PER_CHUNK_ITEM * chunk
    )


def lens_count(camera: LightFieldCamera) -> int:
    """About how many lenses have their micro-image centre on ``camera``'s sensor (what
    :meth:`LightFieldCamera.lens_indices_on_sensor` lists), from the areas alone, erring high by the
    lenses along the rim: for a memory estimate, without listing them."""
    scale = camera.micro_image_scale
    cell = abs(float(np.linalg.det(camera.mla.basis_m))) * scale * scale
    width, height = camera.sensor.size_m
    pitch = math.sqrt(cell)
    return math.ceil((width + 2 * pitch) * (height + 2 * pitch) / cell)


def view_stack_bytes(
    camera: LightFieldCamera, output: PinholeCamera, *, grid: int, channels: int, exported: bool = False
) -> int:
    """Estimated peak memory of :func:`subaperture_stack`, bytes (see :mod:`lfrefract._memory`).

    The views, ``grid^2`` float32 images of ``channels`` channels; the contiguous channel planes of
    the raw image; one resampling (:func:`resampling_bytes`) and one view's product (12 bytes per
    channel and output pixel). ``exported`` adds what ``lfrefract.formats.viewstack.write_view_stack``
    allocates over the whole stack: one byte per value (its mask of finite values). Measured with
    tracemalloc, plus qhull's memory, on tiny and tiny-2x (3 x 3 and 9 x 9 views of 6 000 to 240 000
    pixels): 0.55-0.9 of the estimate.
    """
    raw_pixels = camera.sensor.width_px * camera.sensor.height_px
    pixels = output.width_px * output.height_px
    values = grid * grid * pixels * channels
    total = (5 if exported else 4) * values + 8 * channels * raw_pixels
    total += resampling_bytes(lenses=lens_count(camera), pixels=pixels) + 12 * channels * pixels
    return int(total)


def raw_channels(camera: LightFieldCamera, raw: np.ndarray) -> np.ndarray:
    """``raw`` (H, W) or (H, W, C) as float32 (H, W, C), checked against the camera's sensor size."""
    arr = np.asarray(raw, dtype=np.float32)
    if arr.shape[:2] != (camera.sensor.height_px, camera.sensor.width_px) or arr.ndim not in (2, 3):
        raise ParameterError(
            f"raw must have shape ({camera.sensor.height_px}, {camera.sensor.width_px}) (+ channels), got {arr.shape}"
        )
    return arr[..., None] if arr.ndim == 2 else arr


def finite_pixels(raw: np.ndarray) -> np.ndarray | None:
    """The pixels of ``raw`` ((H, W) or (H, W, C)) holding a finite value in every channel, as the
    ``recorded`` mask of the views (bool (H, W)); None where all do.

    A board capture marks what it did not record as NaN (what its white image does not light); given
    as ``recorded``, the views leave those pixels out rather than letting each spoil the micro-image
    sample it falls in.
    """
    finite = np.isfinite(raw)
    if finite.ndim == 3:
        finite = finite.all(axis=2)
    return None if finite.all() else finite


def recorded_mask(camera: LightFieldCamera, recorded: np.ndarray | None) -> np.ndarray | None:
    """``recorded`` as a bool (H, W) array of the camera's sensor size, or None (every pixel recorded).

    Raises
    ------
    ParameterError
        If it is not a bool array of the sensor's shape.
    """
    if recorded is None:
        return None
    arr = np.asarray(recorded)
    if arr.dtype != np.bool_ or arr.shape != (camera.sensor.height_px, camera.sensor.width_px):
        raise ParameterError(
            f"recorded must be a bool array of shape ({camera.sensor.height_px}, {camera.sensor.width_px}), "
            f"got {arr.dtype} {arr.shape}"
        )
    return arr


def _resample(
    camera: LightFieldCamera,
    idx: np.ndarray,
    values: np.ndarray,
    output: PinholeCamera | None,
    slope_shift: tuple[float, float],
    ray_correction: RayCorrection | None,
    *,
    grey: bool,
    masked: bool = False,
) -> np.ndarray:
    """Per-lens values (M, C) onto the pinhole image: lens ``c`` at ``K (c / f' + slope_shift, 1)``
    (its slope corrected by ``ray_correction``); ``masked``: lenses without a value (NaN) are skipped
    (:func:`_apply_resampling_masked`)."""
    output = output if output is not None else virtual_camera_for(camera)
    if len(idx) == len(camera.lens_indices_on_sensor()):  # every lens (a subset keeps the order)
        matrix, inside = _sensor_resampling(camera, output, tuple(slope_shift), ray_correction)
    else:
        _, matrix, inside = _resampling_matrix(camera, ray_correction, output, slope_shift=slope_shift, lenses=idx)
    return apply_resampling(matrix, inside, values, output, grey=grey, masked=masked)


@functools.lru_cache(maxsize=2)  # an Illum's matrix is about 35 MB
def _sensor_resampling(
    camera: LightFieldCamera,
    output: PinholeCamera,
    slope_shift: tuple[float, float],
    ray_correction: RayCorrection | None,
) -> tuple[sparse.csr_matrix, np.ndarray]:
    """:func:`resampling_matrix` over every lens on the sensor, built once for all the captures of a
    camera (the central view of each board capture: 3-4 s an Illum capture when built for each)."""
    _, matrix, inside = _resampling_matrix(camera, ray_correction, output, slope_shift=slope_shift)
    inside.flags.writeable = False
    return matrix, inside


def apply_resampling(
    matrix: sparse.csr_matrix,
    inside: np.ndarray,
    values: np.ndarray,
    output: PinholeCamera,
    *,
    grey: bool,
    masked: bool = False,
) -> np.ndarray:
    """Per-lens values (M, C) through a :func:`resampling_matrix` onto the pinhole image, float32,
    NaN outside the lenses' hull; ``grey`` drops the channel axis. ``masked``: lenses without a value
    (NaN in any channel, as :func:`micro_image_samples` gives where no recorded pixel contributes)
    are skipped, each pixel's weights renormalised over the others.

    Raises
    ------
    ParameterError
        If the image would have no value anywhere (:func:`lfrefract.synthesis.empty.require_a_value`),
        naming why: no pixel of ``output`` lies among the lenses, or every lens it needs lacks a value
        (its raw pixels masked as unrecorded).
    """
    if masked:
        out = _apply_resampling_masked(matrix, inside, values, output, grey=grey)
    else:
        out = np.asarray(matrix @ values.astype(np.float64), dtype=np.float32)
        out[~inside] = np.nan
        out = out.reshape(output.height_px, output.width_px, -1)
        out = out[..., 0] if grey else out
    require_a_value(
        ~np.isnan(out),
        what=f"the {output.width_px} x {output.height_px} px view",
        because=lambda: _why_no_view(inside, output, masked=masked),
    )
    return out


def _why_no_view(inside: np.ndarray, output: PinholeCamera, *, masked: bool) -> str:
    """Why a resampled view has no value: no output pixel lies within the lenses' triangulation, or the
    lenses its pixels need have no value (masked, or not finite in the raw image)."""
    if not np.any(inside):
        return (
            f"no pixel of {output_geometry(output)} lies among the lenses' positions (their triangulation): it "
            "looks outside the camera's field; give an output geometry that sees it (the capture's ideal camera)"
        )
    if masked:
        return masked_reason()
    return "the raw values of every lens its pixels need are not finite (NaN or inf)"


def _apply_resampling_masked(
    matrix: sparse.csr_matrix, inside: np.ndarray, values: np.ndarray, output: PinholeCamera, *, grey: bool
) -> np.ndarray:
    """:func:`apply_resampling` for per-lens values (M, C) of which some have no value (NaN in any
    channel): each pixel's barycentric weights are renormalised over its lenses that have one, and a
    pixel with none is NaN, like the pixels outside the hull."""
    has = np.all(np.isfinite(values), axis=1)
    total = matrix @ has.astype(np.float64)
    summed = matrix @ np.where(has[:, None], values, 0.0).astype(np.float64)
    ok = inside & (total > 0)
    out = np.full(summed.shape, np.nan, dtype=np.float32)
    out[ok] = summed[ok] / total[ok, None]
    out = out.reshape(output.height_px, output.width_px, -1)
    return out[..., 0] if grey else out


def resampling_matrix(
    camera: LightFieldCamera | CameraModel,
    output: PinholeCamera,
    *,
    slope_shift: tuple[float, float] = (0.0, 0.0),
    lenses: np.ndarray | None = None,
) -> tuple[np.ndarray, sparse.csr_matrix, np.ndarray]:
    """Linear interpolation from per-lens samples to the pixels of a pinhole image.

    Lens ``c`` sits at ``K (t, 1)``, ``t = c / f' + slope_shift`` its thin-lens slope, or
    ``K (t', 1)`` with ``t' = correction.slopes(t)`` for a calibrated camera (a :class:`CameraModel`
    with a radial ``correction``); a pixel inside the lenses' Delaunay
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

    Raises
    ------
    ParameterError
        If its estimated memory (:func:`resampling_bytes`) exceeds the memory available, or the ray
        model is the polynomial one.
    """
    return _resampling_matrix(*_unpacked(camera), output, slope_shift=slope_shift, lenses=lenses)


def _resampling_matrix(
    camera: LightFieldCamera,
    correction: RayCorrection | None,
    output: PinholeCamera,
    *,
    slope_shift: tuple[float, float] = (0.0, 0.0),
    lenses: np.ndarray | None = None,
) -> tuple[np.ndarray, sparse.csr_matrix, np.ndarray]:
    """:func:`resampling_matrix` of a camera and its radial correction (None: the thin lens)."""
    lenses = camera.lens_indices_on_sensor() if lenses is None else lenses
    require_memory(
        f"resampling {len(lenses)} lenses onto a {output.width_px} x {output.height_px} px image",
        resampling_bytes(lenses=len(lenses), pixels=output.width_px * output.height_px),
    )
    slopes = camera.mla.centres_m(lenses) / camera.lens_to_mla_m + np.asarray(slope_shift)
    if correction is not None:
        slopes = correction.slopes(slopes)
    positions = output.focal_px * slopes + np.array([output.cx_px, output.cy_px])
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
    containing it and their barycentric weights (P, 3); a pixel on an edge two triangles share takes
    the first triangle's.

    Each triangle is rasterised row by row: on every pixel row its box spans, only the pixels
    between its edges (and one on either side, for round-off) are tested. As the triangles do not
    overlap, the work is about the pixels inside plus three per triangle row, whatever the
    triangles' shapes (a calibrated lens field's sides bow in or out, and Delaunay fills the hull
    with slivers as wide as the image). It runs in chunks of at most :data:`RESAMPLING_CHUNK` rows
    and candidates, so that its temporaries stay bounded and a signal (SIGTERM) is handled between
    them.
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
    del e0, e1, det
    last = np.array([width - 1, height - 1])
    lo = np.clip(np.ceil(corners.min(axis=1)), 0, last).astype(np.int64)  # each triangle's box, in the image
    hi = np.clip(np.floor(corners.max(axis=1)), 0, last).astype(np.int64)
    rows = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    tol = 100 * np.finfo(np.float64).eps
    found: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for t0, t1 in _chunks(rows, RESAMPLING_CHUNK):  # triangle rows, triangle by triangle
        tri = np.repeat(np.arange(t0, t1), rows[t0:t1])
        y = lo[tri, 1] + _ranks(rows[t0:t1])
        x0, x1 = _row_extent(corners[tri], y)
        x0 = np.maximum(np.clip(np.floor(x0), -1, width) - 1, lo[tri, 0]).astype(np.int64)  # a pixel's margin
        x1 = np.minimum(np.clip(np.ceil(x1), -1, width) + 1, hi[tri, 0]).astype(np.int64)
        counts = np.maximum(x1 - x0 + 1, 0)
        for r0, r1 in _chunks(counts, RESAMPLING_CHUNK):  # candidate pixels, row by row
            row = np.repeat(np.arange(r0, r1), counts[r0:r1])
            u = x0[row] + _ranks(counts[r0:r1])
            v = y[row]
            t = tri[row]
            du, dv = u - corners[t, 2, 0], v - corners[t, 2, 1]
            b0 = inverse[t, 0, 0] * du + inverse[t, 0, 1] * dv
            b1 = inverse[t, 1, 0] * du + inverse[t, 1, 1] * dv
            weights = np.stack([b0, b1, 1.0 - (b0 + b1)], axis=1)
            inside = np.all(weights >= -tol, axis=1)
            found.append((v[inside] * width + u[inside], t[inside], weights[inside]))
    if not found:
        return np.zeros(0, np.int64), np.zeros((0, 3), simplices.dtype), np.zeros((0, 3))
    pixel = np.concatenate([f[0] for f in found])
    tri_of = np.concatenate([f[1] for f in found])
    weights = np.concatenate([f[2] for f in found])
    del found
    pixel, first = np.unique(pixel, return_index=True)  # a pixel on a shared edge: the first triangle
    return pixel, simplices[tri_of[first]], weights[first]


def _chunks(sizes: np.ndarray, limit: int) -> Iterator[tuple[int, int]]:
    """Consecutive ranges ``[i, j)`` of ``sizes`` whose sum is at most ``limit`` (or a single item)."""
    total = np.cumsum(sizes)
    start, n = 0, len(sizes)
    while start < n:
        base = int(total[start - 1]) if start else 0
        stop = max(int(np.searchsorted(total, base + limit, side="right")), start + 1)
        yield start, stop
        start = stop


def _ranks(counts: np.ndarray) -> np.ndarray:
    """``0 .. c - 1`` for each ``c`` of ``counts``, concatenated."""
    total = int(counts.sum())
    return np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)


def _row_extent(corners: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the row ``y`` (N,) crosses the triangles ``corners`` (N, 3, 2): the least and greatest
    x of its edges that span the row (every row between the lowest and highest corner is spanned by
    two edges, or by three at a corner; an edge along the row is met by the other two at its ends)."""
    lo = np.full(len(y), np.inf)
    hi = np.full(len(y), -np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, b = corners[:, i], corners[:, j]
        spans = (np.minimum(a[:, 1], b[:, 1]) <= y) & (y <= np.maximum(a[:, 1], b[:, 1])) & (a[:, 1] != b[:, 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.clip((y - a[:, 1]) / (b[:, 1] - a[:, 1]), 0.0, 1.0)
        x = a[:, 0] + t * (b[:, 0] - a[:, 0])
        lo = np.where(spans, np.minimum(lo, x), lo)
        hi = np.where(spans, np.maximum(hi, x), hi)
    return lo, hi


def subaperture_centre_m(camera: LightFieldCamera | CameraModel, offset_px: tuple[float, float]) -> np.ndarray:
    """Centre of projection (3,), camera frame, metres, of the sub-aperture view at ``offset_px``.

    ``offset_px = (du, dv)``: the sensor offset from every micro-image centre, pixels. The point
    is on the main-lens plane: ``(du, dv, 0) * pixel_pitch * f' / f_mla``, times the pupil scale
    ``m`` of a calibrated camera's radial correction (``camera`` a :class:`CameraModel`).
    """
    return _centre_m(*_unpacked(camera), offset_px)


def _centre_m(camera: LightFieldCamera, correction: RayCorrection | None, offset_px: tuple[float, float]) -> np.ndarray:
    """:func:`subaperture_centre_m` of a camera and its radial correction (None: the thin lens)."""
    du, dv = finite_vector("offset_px", offset_px, 2)
    scale = camera.sensor.pixel_pitch_m * camera.lens_to_mla_m / camera.mla.focal_length_m
    if correction is not None:
        scale *= correction.pupil_scale
    return np.array([du * scale, dv * scale, 0.0])


def checked_correction(ray_correction: object) -> RayCorrection | None:
    """``ray_correction`` if it is a :class:`RayCorrection` or None; else :class:`ParameterError`."""
    if isinstance(ray_correction, UNSTRUCTURED):
        raise ParameterError(
            f"the {ray_correction.name} ray model has no sub-aperture views: its rays of one view do not share a "
            "centre of projection (sub-aperture views and stacks take the thin lens or the radial model)"
        )
    if ray_correction is not None and not isinstance(ray_correction, RayCorrection):
        raise ParameterError(f"ray_correction must be a RayCorrection or None, got {ray_correction!r}")
    return ray_correction


def _unpacked(camera: LightFieldCamera | CameraModel) -> tuple[LightFieldCamera, RayCorrection | None]:
    """The camera and the radial correction (None: the thin lens) of a camera model (a bare camera:
    its thin lens), for the views: :func:`checked_correction` refuses the polynomial model."""
    model = as_camera_model(camera)
    return model.camera, checked_correction(model.correction)


def subaperture_view(
    camera: LightFieldCamera | CameraModel,
    raw: np.ndarray,
    offset_px: tuple[float, float],
    *,
    output: PinholeCamera | None = None,
    recorded: np.ndarray | None = None,
) -> np.ndarray:
    """The sub-aperture view at ``offset_px`` from the micro-image centres, as a pinhole image.

    Its centre of projection is :func:`subaperture_centre_m` ``(camera, offset_px)``; pixel
    ``p`` of the result looks along ``K^-1 p`` from there (camera-frame orientation), like the
    central view (``offset_px = (0, 0)``, which equals :func:`naive_view` ``kind="central"``).

    Parameters
    ----------
    camera : LightFieldCamera or CameraModel
        The camera and its ray model (see :func:`naive_view`).
    raw : ndarray, shape (H, W) or (H, W, C)
    offset_px : (float, float)
        ``(du, dv)``, pixels; at most the micro-image radius less one pixel
        (:func:`subaperture_limit_px`), so that the sample point stays a pixel inside the rim.
    output : PinholeCamera, optional
        Output geometry; default :func:`virtual_camera_for` ``(camera)``.
    recorded : ndarray of bool, shape (H, W), optional
        Raw pixels that hold a recorded value; the others are not used (see the module docstring).

    Returns
    -------
    ndarray, float32, shape (height, width) or (height, width, C)
        NaN outside the lenses' hull, and where no recorded pixel contributes.
    """
    du, dv = finite_vector("offset_px", offset_px, 2)
    camera, ray_correction = _unpacked(camera)
    limit = subaperture_limit_px(camera)
    if np.hypot(du, dv) > limit:
        raise ParameterError(
            f"offset_px={offset_px!r} reaches the micro-image rim (at most {limit:.3g} px from its centre)"
        )
    output = output if output is not None else virtual_camera_for(camera)
    if not isinstance(output, PinholeCamera):
        raise ParameterError(f"output must be a PinholeCamera, got {output!r}")
    image = raw_channels(camera, raw)
    recorded = recorded_mask(camera, recorded)
    require_memory(
        f"a sub-aperture view of {output.width_px} x {output.height_px} px",
        naive_view_bytes(camera, output, kind="central", channels=image.shape[2]),
    )
    idx = camera.lens_indices_on_sensor()
    values = micro_image_samples(camera, image, idx, (du, dv), recorded=recorded)
    shift = subaperture_slope_shift(camera, du, dv)
    return _resample(
        camera, idx, values, output, shift, ray_correction, grey=np.ndim(raw) == 2, masked=recorded is not None
    )


def subaperture_limit_px(camera: LightFieldCamera) -> float:
    """How far from its micro-image centre a sub-aperture view may sample, pixels.

    The micro-image radius less one pixel: the sample point keeps a pixel from the rim (the
    main-lens radius :meth:`LightFieldCamera.usable_aperture_radius_m` ``(1.0)``, seen from the
    sensor). Its bilinear neighbours reach up to sqrt(2) px further, so a sample at the limit may
    still give some weight to pixels beyond the rim: off the axes up to 9 % at the presets, which
    leaves the corner views of a default stack 0.5 % darker than the central one on a uniform
    field in the captured-ray model (tests/lfrefract/test_view_stack.py).
    """
    return camera.micro_image_radius_px - 1.0


def subaperture_slope_shift(camera: LightFieldCamera, du: float, dv: float) -> tuple[float, float]:
    """Principal-point shift (slope units) of the sub-aperture view at ``(du, dv)``: zero when
    ``f' = f``, else ``delta * pixel_pitch / f_mla * (1 - f' / f)`` (see the module docstring)."""
    spread = 1.0 - camera.lens_to_mla_m / camera.focal_length_m
    tilt = camera.sensor.pixel_pitch_m / camera.mla.focal_length_m * spread
    return (du * tilt, dv * tilt)


def _grid_size(name: str, value: Any) -> int:
    """``value`` as an int, or raise unless it is an odd integer >= 3 (a central view exists)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(f"{name} must be an odd integer >= 3, got {value!r}")
    if value < 3 or value % 2 != 1:
        raise ParameterError(f"{name} must be an odd integer >= 3 (a central view with neighbours), got {value!r}")
    return int(value)


def _regular_grid(name: str, value: Any, grid: int, dims: int) -> np.ndarray:
    """``value`` (grid, grid, dims) as read-only float64, or raise unless entry ``[r, c]`` is
    ``((c - h) s, (r - h) s, 0...)`` with a step ``s > 0`` (to 1e-9 of ``s``)."""
    arr = np.array(value, dtype=np.float64, copy=True)
    if arr.shape != (grid, grid, dims) or not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} must be a finite array of shape {(grid, grid, dims)}, got shape {arr.shape}")
    step = float(arr[0, 1, 0] - arr[0, 0, 0])
    k = np.arange(grid, dtype=np.float64) - (grid - 1) / 2.0
    expected = np.zeros_like(arr)
    expected[..., 0] = k[None, :] * step
    expected[..., 1] = k[:, None] * step
    error = np.max(np.abs(arr - expected), axis=2)
    if not step > 0.0 or np.max(error) > 1e-9 * step:
        r, c = np.unravel_index(np.argmax(error), error.shape)
        raise ParameterError(
            f"{name} must be a regular grid about 0 with a positive step s, [r, c] = ((c - h) s, (r - h) s"
            f"{', 0' if dims == 3 else ''}); got s = {step!r} and {name}[{r}, {c}] = {arr[r, c].tolist()}"
        )
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, kw_only=True, eq=False)
class ViewStack:
    """A regular grid of sub-aperture views of one raw lenslet image (:func:`subaperture_stack`).

    Indexing is ``[row v, column u]``: row 0 is the top row of centres (camera-frame -y, up),
    column 0 the leftmost (-x); the central view is ``[h, h]``, ``h = (grid - 1) / 2``. All views
    are pinholes with the same intrinsics :attr:`output` and the camera frame's orientation; only
    their centres of projection differ, by :attr:`baseline_m` between neighbours. A point at
    depth ``Z`` (camera-frame z, metres) therefore moves by the disparity
    ``d = f_px * baseline_m / Z`` pixels between neighbouring views, against the direction of the
    step: ``views[r, c + 1]`` at ``(u - d, v)`` and ``views[r + 1, c]`` at ``(u, v - d)`` show what
    ``views[r, c]`` shows at ``(u, v)``. ``d`` is zero at infinity and grows as the point nears.

    Parameters
    ----------
    views : ndarray, float32, shape (grid, grid, H, W) or (grid, grid, H, W, C)
        The views (linear radiance as in the raw image), NaN where a view has no value (outside
        the lenses' hull). ``grid`` odd, >= 3; ``(H, W)`` the size of ``output``.
    offsets_px : ndarray, shape (grid, grid, 2)
        Sensor offset ``(du, dv)`` from every micro-image centre that each view samples, pixels:
        ``((c - h) s, (r - h) s)``, ``s`` the spacing (> 0).
    centres_m : ndarray, shape (grid, grid, 3)
        Centre of projection of each view, camera frame, metres, on the main-lens plane
        (:func:`subaperture_centre_m`): ``((c - h) b, (r - h) b, 0)``, ``b`` the baseline (> 0).
    output : PinholeCamera
        Intrinsics and size shared by every view.
    camera : LightFieldCamera, optional
        The camera whose raw image the views come from; when given, ``centres_m`` must be
        :func:`subaperture_centre_m` of ``offsets_px`` and the corner views must lie within
        :func:`subaperture_limit_px`. It gives the views' physical image distance (``f'``) for
        exports.
    ray_correction : RayCorrection, optional
        The calibrated rays the views were resampled with (see the module docstring); with
        ``camera``, ``centres_m`` are then those of its pupil scale.

    Raises
    ------
    ParameterError
        If a shape, type or value breaks the above (the grids must be regular to 1e-9 of a step).
    """

    views: np.ndarray
    offsets_px: np.ndarray
    centres_m: np.ndarray
    output: PinholeCamera
    camera: LightFieldCamera | None = None
    ray_correction: Correction | None = None

    def __post_init__(self) -> None:
        checked_correction(self.ray_correction)
        if not isinstance(self.output, PinholeCamera):
            raise ParameterError(f"output must be a PinholeCamera, got {self.output!r}")
        views = np.asarray(self.views)
        if views.dtype != np.float32 or views.ndim not in (4, 5):
            raise ParameterError(
                f"views must be a float32 array of shape (grid, grid, H, W[, C]), got {views.dtype} {views.shape}"
            )
        if views.shape[0] != views.shape[1]:
            raise ParameterError(f"views must have as many rows as columns of views, got shape {views.shape}")
        grid = _grid_size("views.shape[0] (the grid)", views.shape[0])
        if views.shape[2:4] != (self.output.height_px, self.output.width_px):
            raise ParameterError(
                f"views must be {self.output.height_px} x {self.output.width_px} px (output), got shape {views.shape}"
            )
        if views.ndim == 5 and views.shape[4] < 1:
            raise ParameterError(f"views must have at least one channel, got shape {views.shape}")
        views = views.view()
        views.setflags(write=False)
        offsets = _regular_grid("offsets_px", self.offsets_px, grid, 2)
        centres = _regular_grid("centres_m", self.centres_m, grid, 3)
        if self.camera is not None:
            if not isinstance(self.camera, LightFieldCamera):
                raise ParameterError(f"camera must be a LightFieldCamera or None, got {self.camera!r}")
            corner = float(np.hypot(*offsets[0, 0]))
            if corner > subaperture_limit_px(self.camera):
                raise ParameterError(
                    f"offsets_px reach {corner:.4g} px from the micro-image centres at the corners, beyond "
                    f"camera {self.camera.name!r}'s limit of {subaperture_limit_px(self.camera):.4g} px"
                )
            step_m = _centre_m(self.camera, checked_correction(self.ray_correction), (1.0, 0.0))[0]
            expected = np.concatenate([offsets * step_m, np.zeros((grid, grid, 1))], axis=2)
            if not np.allclose(centres, expected, rtol=1e-9, atol=0.0):
                raise ParameterError(
                    f"centres_m are not subaperture_centre_m of offsets_px for camera {self.camera.name!r}: baseline "
                    f"{centres[0, 1, 0] - centres[0, 0, 0]!r} m, expected {expected[0, 1, 0] - expected[0, 0, 0]!r} m"
                )
        object.__setattr__(self, "views", views)
        object.__setattr__(self, "offsets_px", offsets)
        object.__setattr__(self, "centres_m", centres)

    @property
    def grid(self) -> int:
        """Views per row and per column (odd)."""
        return int(self.views.shape[0])

    @property
    def centre_index(self) -> int:
        """Row and column ``h = (grid - 1) / 2`` of the central view."""
        return (self.grid - 1) // 2

    @property
    def central_view(self) -> np.ndarray:
        """The view at offset (0, 0): centre of projection at the main-lens centre, shape (H, W[, C])."""
        return self.views[self.centre_index, self.centre_index]

    @property
    def spacing_px(self) -> float:
        """Sensor offset between neighbouring views' samples, pixels."""
        return float(self.offsets_px[0, 1, 0] - self.offsets_px[0, 0, 0])

    @property
    def baseline_m(self) -> float:
        """Distance between the centres of neighbouring views (along a row or a column), metres."""
        return float(self.centres_m[0, 1, 0] - self.centres_m[0, 0, 0])

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the conventional name
        """Intrinsic matrix (3, 3) of every view, OpenCV form."""
        return self.output.K

    def disparity_px(self, depth_m: float | np.ndarray) -> float | np.ndarray:
        """Disparity between neighbouring views of points at camera-frame depth ``depth_m``, pixels.

        ``f_px * baseline_m / depth_m``; ``depth_m`` > 0 (``inf`` gives 0), scalar or array.
        """
        z = np.asarray(depth_m, dtype=np.float64)
        if not np.all(z > 0.0):
            bad = z[~(z > 0.0)].ravel()[0]
            raise ParameterError(f"depth_m must be positive (inf allowed), got {float(bad)!r}")
        out = self.output.focal_px * self.baseline_m / z
        return float(out) if out.ndim == 0 else out

    def depth_m(self, disparity_px: float | np.ndarray) -> float | np.ndarray:
        """Camera-frame depth of points with disparity ``disparity_px`` between neighbouring views, metres.

        The inverse of :meth:`disparity_px`; ``disparity_px`` >= 0 (0 gives ``inf``), scalar or array.
        """
        d = np.asarray(disparity_px, dtype=np.float64)
        if not np.all(d >= 0.0) or not np.all(np.isfinite(d)):
            bad = d[~((d >= 0.0) & np.isfinite(d))].ravel()[0]
            raise ParameterError(f"disparity_px must be finite and non-negative, got {float(bad)!r}")
        with np.errstate(divide="ignore"):
            out = self.output.focal_px * self.baseline_m / d
        return float(out) if out.ndim == 0 else out


def subaperture_stack(
    camera: LightFieldCamera | CameraModel,
    raw: np.ndarray,
    *,
    grid: int = 9,
    spacing_px: float | None = None,
    output: PinholeCamera | None = None,
    recorded: np.ndarray | None = None,
) -> ViewStack:
    """A regular ``grid x grid`` set of sub-aperture views of ``raw`` (a light-field view stack).

    View ``[r, c]`` is :func:`subaperture_view` at ``offset_px = ((c - h) s, (r - h) s)``,
    ``h = (grid - 1) / 2``, ``s = spacing_px``: a pinhole at :func:`subaperture_centre_m` of that
    offset, so the centres form a regular grid ``s * pixel_pitch * f' / f_mla`` metres apart on
    the main-lens plane, and every view shares the intrinsics of ``output`` and the camera frame's
    orientation (see :class:`ViewStack` for the disparity between neighbours). Each view is one
    vectorised gather and sparse product; the interpolation matrix is built once per distinct
    principal-point shift (once in all when ``f' = f``, once per view otherwise, each freed before
    the next is built).

    Parameters
    ----------
    camera : LightFieldCamera or CameraModel
        The camera and its ray model: a calibrated radial model's rays (see the module docstring),
        every view resampled on them and the baseline the pupil scale times the thin lens's; else
        (a bare camera) the thin lens's.
    raw : ndarray, shape (H_raw, W_raw) or (H_raw, W_raw, C)
        Raw lenslet image of ``camera``'s sensor size.
    grid : int
        Views per row and column; odd and >= 3, so that there is a central view.
    spacing_px : float, optional
        Offset between neighbouring views' samples in every micro-image, sensor pixels, > 0. The
        corner views sample ``sqrt(2) h s`` from the micro-image centres, which must stay within
        :func:`subaperture_limit_px` (every sample point a pixel inside the rim). Default: the
        largest such spacing, ``subaperture_limit_px(camera) / (sqrt(2) h)``.
    output : PinholeCamera, optional
        Geometry of every view; default :func:`virtual_camera_for` ``(camera)``.
    recorded : ndarray of bool, shape (H_raw, W_raw), optional
        Raw pixels that hold a recorded value; the others are not used (see the module docstring).
        Default: all.

    Returns
    -------
    ViewStack
        ``views`` float32, shape (grid, grid, height, width) for a 2-D ``raw``, else
        (grid, grid, height, width, C); NaN outside the lenses' hull, and where no recorded pixel
        contributes.

    Raises
    ------
    ParameterError
        If ``grid`` is not an odd integer >= 3, ``spacing_px`` is not positive and finite or puts
        the corner views beyond the limit, the camera's micro-images leave no room for any view
        but the central one, ``raw`` or ``recorded`` does not match the sensor, or the stack's
        estimated memory (:func:`view_stack_bytes`) exceeds the memory available (checked before
        any view is allocated).
    """
    camera, ray_correction = _unpacked(camera)
    grid = _grid_size("grid", grid)
    if output is None:
        output = virtual_camera_for(camera)
    elif not isinstance(output, PinholeCamera):
        raise ParameterError(f"output must be a PinholeCamera, got {output!r}")
    half = (grid - 1) // 2
    limit = subaperture_limit_px(camera)
    if limit <= 0.0:
        raise ParameterError(
            f"camera {camera.name!r} has micro-images of radius {camera.micro_image_radius_px:.3g} px: "
            "no sub-aperture view but the central one stays a pixel inside the rim"
        )
    largest = limit / (math.sqrt(2.0) * half)
    while math.hypot(half * largest, half * largest) > limit:  # round-off: the corner must pass the limit
        largest = math.nextafter(largest, 0.0)
    if spacing_px is None:
        spacing = largest
    else:
        spacing = positive_float("spacing_px", spacing_px)
        reach = math.hypot(half * spacing, half * spacing)
        if reach > limit:
            raise ParameterError(
                f"spacing_px={spacing_px!r} puts the corner views of the {grid} x {grid} grid {reach:.4g} px from "
                f"the micro-image centres, beyond the limit of {limit:.4g} px (micro-image radius less one pixel); "
                f"at most {largest:.4g} px for grid={grid}"
            )
    channels = 1 if np.ndim(raw) == 2 else int(np.shape(raw)[2]) if np.ndim(raw) == 3 else 0
    if channels:  # else raw_channels names the wrong shape
        require_memory(
            f"a {grid} x {grid} stack of {output.width_px} x {output.height_px} px views with {channels} channel(s)",
            view_stack_bytes(camera, output, grid=grid, channels=channels),
        )
    image = raw_channels(camera, raw)
    recorded = recorded_mask(camera, recorded)
    grey = np.ndim(raw) == 2
    idx = camera.lens_indices_on_sensor()
    # micro_image_samples per view, with its invariant parts hoisted: the centres, and the channels
    # as contiguous planes (map_coordinates copies a strided channel on every call otherwise).
    centres_px = camera.micro_image_centres_px(idx)
    planes = [np.ascontiguousarray(image[..., c]) for c in range(image.shape[2])]
    weight = None if recorded is None else _weight_plane(recorded)
    steps = (np.arange(grid, dtype=np.float64) - half) * spacing
    offsets = np.stack(np.broadcast_arrays(steps[None, :], steps[:, None]), axis=-1)  # [r, c] = (du_c, dv_r)
    shape = (grid, grid, output.height_px, output.width_px) + (() if grey else (image.shape[2],))
    views = np.empty(shape, dtype=np.float32)
    centres = np.empty((grid, grid, 3))
    # One matrix alive at a time: with f' = f every view shares it; off the focal plane every view has
    # its own shift, used once (keeping them all held 81 x 33 MB for an Illum 9 x 9 stack).
    cached_shift: tuple[float, float] | None = None
    cached: tuple[sparse.csr_matrix, np.ndarray] | None = None
    for r in range(grid):
        for c in range(grid):
            du, dv = float(offsets[r, c, 0]), float(offsets[r, c, 1])
            shift = subaperture_slope_shift(camera, du, dv)
            if cached is None or shift != cached_shift:
                cached = None  # release the previous matrix before building the next
                cached = _resampling_matrix(camera, ray_correction, output, slope_shift=shift, lenses=idx)[1:]
                cached_shift = shift
            values = _bilinear(planes, centres_px + np.asarray((du, dv)), weight)
            views[r, c] = apply_resampling(*cached, values, output, grey=grey, masked=weight is not None)
            centres[r, c] = _centre_m(camera, ray_correction, (du, dv))
    return ViewStack(
        views=views, offsets_px=offsets, centres_m=centres, output=output, camera=camera, ray_correction=ray_correction
    )
