"""Which raw pixel records the ray from a point in the water to a point of the main-lens aperture.

The first building block of depth-aware synthesis: given points ``X`` in the water and aperture
points ``a`` on the main-lens plane, find, for every pair, the raw pixel of a thin-lens
:class:`~lfrefract.optics.camera.LightFieldCamera` on which the light from ``X`` arriving at ``a``
lands (:func:`pixels_seeing_points`).

Derivation (camera frame, metres; image-plane coordinates are ``(xi, eta) = -(x, y)``)
-----------------------------------------------------------------------------------------
1. Object side: :func:`~lfrefract.optics.forward.forward_project` from the centre ``(a, 0)``
   gives the air ray ``d`` that reaches ``X`` through the port (without a port, ``d = X - (a, 0)``);
   its slope is ``s_obj = d_xy / d_z``.
2. The thin main lens: :meth:`LightFieldCamera.rays_through_lenses` bends an image-side slope
   ``s_in`` at ``a`` into ``s_obj = s_in - a / f``, so ``s_in = s_obj + a / f``. Followed back to
   the MLA plane (``z = -f'``) the ray crosses it at ``m = a - f' s_in`` (camera frame), image-plane
   point ``-m``.
3. The microlens is the one whose cell holds ``-m``: ``c = mla.nearest_indices(-m)``, the camera's
   own lattice lookup; the ray crosses it at image-plane offset ``o = -m - c``.
4. The camera's forward model (:meth:`LightFieldCamera.paths_leaving_mla`) maps a sensor point
   ``p`` (image plane) under lens ``c`` to the slope ``(p - c) / f_mla`` of every path leaving that
   lens (the sensor is its focal plane), so the path through ``-m`` reaches the main lens at
   ``m + f' (p - c) / f_mla``. Setting that to ``a`` is linear in ``p``::

       p = c + f_mla (a - m) / f'          (the pixel that records the ray; uv_px)

   and ``camera.rays_through_lenses(uv_px, lens_offsets_m=o)`` reproduces the ray exactly.
5. The synthesis core's captured-ray model keeps only each pixel's chief ray, through the lens
   centre (``o = 0``: ``m = -c``). The pixel whose captured ray leaves the main lens at ``a`` is::

       p_chief = c + f_mla (a + c) / f' = p - f_mla o / f'     (uv_chief_px)

   so ``camera.captured_rays(uv_chief_px)`` starts exactly at ``a``; it passes ``X`` only up to the
   microlens quantisation (the object-side image of the offset ``o``), since it crosses the MLA at
   the lens centre rather than where the ray from ``X`` does. ``p`` and ``p_chief`` differ by
   ``f_mla |o| / f'``, at most ``f_mla pitch / (sqrt(3) f')`` (hexagonal) or
   ``f_mla pitch / (sqrt(2) f')`` (square): a fraction of a pixel.

Both positions are continuous (sub-pixel) raw-pixel coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.forward import forward_project
from lfrefract.optics.port import FlatPort
from lfrefract.validate import as_points, non_negative_float

__all__ = ["SeenBy", "pixels_seeing_points"]


@dataclass(frozen=True)
class SeenBy:
    """The raw pixels that record points through aperture points (see :func:`pixels_seeing_points`).

    Shapes are (N, M, ...) for N points and M aperture points. Invalid entries hold NaN (floats)
    and -1 (lens indices).

    Attributes
    ----------
    uv_px : ndarray, shape (N, M, 2)
        Raw-pixel coordinates (column, row; pixel centres at integers), sub-pixel, where the ray from
        point ``n`` through aperture point ``m`` lands on the sensor.
    uv_chief_px : ndarray, shape (N, M, 2)
        Raw-pixel coordinates of the sensor point under the same microlens whose captured (chief)
        ray, pixel -> lens centre -> main lens, leaves the main lens exactly at aperture point ``m``.
    lens_index : ndarray of int64, shape (N, M, 2)
        Lattice index of the microlens the ray crosses.
    lens_offset_m : ndarray, shape (N, M, 2)
        Image-plane offset, metres, from that lens's centre to where the ray crosses the MLA
        (``lens_offsets_m`` of :meth:`LightFieldCamera.rays_through_lenses`).
    valid : ndarray of bool, shape (N, M)
        The point is visible from the aperture point through the port (beyond the glass, no
        grazing ray; in front of the lens without a port), the aperture point lies inside the
        usable aperture, and both sensor positions lie on the sensor inside the micro-image of the
        lens (the camera's pixel -> lens assignment gives the same lens back).
    """

    uv_px: np.ndarray
    uv_chief_px: np.ndarray
    lens_index: np.ndarray
    lens_offset_m: np.ndarray
    valid: np.ndarray


def pixels_seeing_points(
    camera: LightFieldCamera,
    port: FlatPort | None,
    points_cam: np.ndarray,
    aperture_points_m: np.ndarray,
    *,
    rim_margin_px: float = 0.0,
) -> SeenBy:
    """Raw pixels that record each point in the water through each aperture point (thin lens).

    See the module docstring for the derivation: the air ray from aperture point ``a`` to ``X``
    through the port (:func:`~lfrefract.optics.forward.forward_project`), the thin main lens, the
    MLA crossing and its microlens (``camera.mla.nearest_indices``), and the inverted forward model
    of the camera, linear per microlens.

    Parameters
    ----------
    camera : LightFieldCamera
        A thin-lens light-field camera.
    port : FlatPort or None
        The flat port in front of the camera; None for straight rays (a camera in air).
    points_cam : array_like, shape (N, 3) or (3,)
        Points, camera frame, metres.
    aperture_points_m : array_like, shape (M, 2) or (2,)
        Points ``(x, y)`` on the main-lens plane z = 0, camera frame, metres.
    rim_margin_px : float
        Pixels of margin from the micro-image rim: aperture points beyond
        ``camera.usable_aperture_radius_m(rim_margin_px)`` are invalid. Default 0: the whole aperture.

    Returns
    -------
    SeenBy
        Raw-pixel positions (N, M, 2), lens indices (N, M, 2), MLA offsets (N, M, 2) and the
        validity mask (N, M).

    Raises
    ------
    ParameterError
        If ``camera`` is not a LightFieldCamera, ``port`` is neither None nor a FlatPort, an array
        has the wrong shape or a non-finite value, or ``rim_margin_px`` is negative or leaves no
        aperture.
    """
    if not isinstance(camera, LightFieldCamera):
        raise ParameterError(f"camera must be a LightFieldCamera, got {camera!r}")
    if port is not None and not isinstance(port, FlatPort):
        raise ParameterError(f"port must be a FlatPort or None, got {port!r}")
    x = as_points("points_cam", points_cam, 3)
    ap = as_points("aperture_points_m", aperture_points_m, 2)
    non_negative_float("rim_margin_px", rim_margin_px)
    radius = camera.usable_aperture_radius_m(rim_margin_px)
    n_pts, n_ap = x.shape[0], ap.shape[0]
    shape = (n_pts, n_ap)

    # Every (point, aperture point) pair as a row, point-major.
    in_aperture = np.sum(ap**2, axis=1) <= radius**2
    # Aperture points outside the aperture are flagged, not traced: the lens centre stands in.
    a = np.where(in_aperture[:, None], ap, 0.0)
    a_rows = np.tile(a, (n_pts, 1))
    x_rows = np.repeat(x, n_ap, axis=0)
    ok = np.tile(in_aperture, n_pts)
    centres = np.concatenate([a_rows, np.zeros((a_rows.shape[0], 1))], axis=1)

    if port is None:
        d = x_rows - centres
        ok &= d[:, 2] > 0.0
    else:
        d = forward_project(port, centres, x_rows).directions_cam if x_rows.shape[0] else np.zeros((0, 3))
        with np.errstate(invalid="ignore"):
            ok &= np.isfinite(d[:, 2]) & (d[:, 2] > 0.0)
    d = np.where(ok[:, None], d, np.array([0.0, 0.0, 1.0]))

    # Object-side slope -> image-side slope at a (thin lens) -> crossing of the MLA plane.
    f, f_prime, f_mla = camera.focal_length_m, camera.lens_to_mla_m, camera.mla.focal_length_m
    slope_in = d[:, :2] / d[:, 2:3] + a_rows / f
    m_cam = a_rows - f_prime * slope_in
    m_img = -m_cam
    idx = camera.mla.nearest_indices(m_img)
    c_img = camera.mla.centres_m(idx)
    offset = m_img - c_img
    # Inverted forward model: sensor point p under lens c whose path through m reaches a.
    p_img = c_img + f_mla * (a_rows - m_cam) / f_prime
    p_chief_img = c_img + f_mla * (a_rows + c_img) / f_prime
    uv = camera.sensor.image_plane_to_pixels(p_img)
    uv_chief = camera.sensor.image_plane_to_pixels(p_chief_img)

    width, height = camera.sensor.width_px, camera.sensor.height_px
    for pos in (uv, uv_chief):
        ok &= (pos[:, 0] >= -0.5) & (pos[:, 0] <= width - 0.5) & (pos[:, 1] >= -0.5) & (pos[:, 1] <= height - 0.5)
        ok &= np.all(camera.lens_indices_for_pixels(pos) == idx, axis=1)

    uv[~ok] = np.nan
    uv_chief[~ok] = np.nan
    offset[~ok] = np.nan
    idx[~ok] = -1
    return SeenBy(
        uv_px=uv.reshape(*shape, 2),
        uv_chief_px=uv_chief.reshape(*shape, 2),
        lens_index=idx.reshape(*shape, 2),
        lens_offset_m=offset.reshape(*shape, 2),
        valid=ok.reshape(shape),
    )
