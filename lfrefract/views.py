"""Conventional views of a raw lenslet image, with no refraction handling (the baselines' input).

``central``: the central sub-aperture image, one sample per microlens at its micro-image centre
(the ray through the main-lens centre). ``full``: the full-aperture image, each microlens's
micro-image averaged (what a conventional camera focused on the MLA's conjugate plane records).
Either is resampled onto a pinhole image: the ray through the main-lens centre and a lens centre
``c`` (image plane) leaves along ``(c_xi, c_eta, f')``, so lens ``c`` lands at pixel
``K @ (c_xi / f', c_eta / f', 1)``; values between lens positions are interpolated linearly.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.interpolate import LinearNDInterpolator

from lfrefract._validate import ParameterError, one_of
from lfrefract.camera import LightFieldCamera
from lfrefract.pinhole import PinholeCamera, virtual_camera_for

__all__ = ["VIEW_KINDS", "naive_view"]

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


def _per_lens_values(camera: LightFieldCamera, raw: np.ndarray, kind: str) -> tuple[np.ndarray, np.ndarray]:
    idx = camera.lens_indices_on_sensor()
    if kind == "central":
        centres = camera.micro_image_centres_px(idx)
        values = np.stack(
            [
                ndimage.map_coordinates(raw[..., c], [centres[:, 1], centres[:, 0]], order=1, mode="nearest")
                for c in range(raw.shape[2])
            ],
            axis=1,
        )
        return idx, values
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
    arr = np.asarray(raw, dtype=np.float32)
    if arr.shape[:2] != (camera.sensor.height_px, camera.sensor.width_px) or arr.ndim not in (2, 3):
        raise ParameterError(
            f"raw must have shape ({camera.sensor.height_px}, {camera.sensor.width_px}) (+ channels), got {arr.shape}"
        )
    output = output if output is not None else virtual_camera_for(camera)
    image = arr[..., None] if arr.ndim == 2 else arr
    idx, values = _per_lens_values(camera, image, kind)
    centres = camera.mla.centres_m(idx)
    positions = output.focal_px * centres / camera.lens_to_mla_m + np.array([output.cx_px, output.cy_px])
    interp = LinearNDInterpolator(positions, values, fill_value=np.nan)
    vv, uu = np.mgrid[0 : output.height_px, 0 : output.width_px]
    out = interp(uu.ravel(), vv.ravel()).reshape(output.height_px, output.width_px, -1).astype(np.float32)
    return out[..., 0] if arr.ndim == 2 else out
