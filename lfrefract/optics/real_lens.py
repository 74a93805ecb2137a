"""A light-field camera whose main lens is a real multi-element lens, traced exactly.

:class:`RealLensCamera` pairs a :class:`~lfrefract.optics.camera.LightFieldCamera` (microlens
array, sensor, and the thin-lens equivalent of the main lens: focal length, f-number, lens-to-MLA
distance) with a :class:`~lfrefract.optics.lens.LensPrescription` that has the same first-order data:
its d-line effective focal length is the camera's ``focal_length_m`` and its paraxial f-number the
camera's ``f_number``. The lens is placed as :mod:`lfrefract.optics.lens` places every lens, rear
principal plane at ``z = 0`` of the camera frame, so ``lens_to_mla_m`` keeps its meaning (distance
from the rear principal plane to the MLA; focus is set by it) and the thin-lens camera is this
camera's paraxial model.

What changes with a real lens:

- The micro-images are images of the **exit pupil** through the microlenses, so their centres lie
  ``(D + f_mla) / D`` times further from the axis than the microlens centres, with ``D`` the exit
  pupil's distance from the MLA (``f'`` for the thin lens).
- A light path from a sensor point leaves its microlens parallel to the microlens's chief ray (the
  sensor is at the microlenses' focal plane, as for the thin lens) and is then traced exactly
  through every surface of the lens towards the object (:func:`lfrefract.optics.lens.trace_lens`):
  it is vignetted by every clear aperture, not only by one aperture disc, and it leaves the lens
  from a point on its front surface, not from the plane ``z = 0``.

This is the numpy twin of the Dr.Jit plenoptic sensor's real-lens path
(:mod:`simulator.sensor`); the tests compare the two. It also gives the ground-truth object-space
ray of every raw pixel (:meth:`RealLensCamera.chief_rays`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import CapturedRays, LightFieldCamera
from lfrefract.optics.lens import D_LINE_M, FirstOrder, LensPrescription, lens_preset, trace_lens
from lfrefract.validate import as_points, as_table, reject_unknown_keys, require_keys

__all__ = ["FIRST_ORDER_MATCH_RTOL", "TRACED_FAMILY", "RealLensCamera", "TracedLens"]

#: Relative agreement required between the lens's first-order data (d-line focal length and
#: f-number) and the camera's thin-lens equivalent. Presets are scaled and stopped to the camera
#: exactly (to rounding, ~1e-15); a prescription typed in by hand must be scaled to the camera too,
#: and 1e-6 is well below any difference a render could show (a 1e-6 change of the focal length
#: moves an Illum edge pixel by 4e-3 px).
FIRST_ORDER_MATCH_RTOL = 1e-6

_EXTENT_SAMPLES = 33  # heights per surface at which the lens's extent along z is evaluated

#: How far in front of the lens's frontmost point a ray traced back into the lens starts, metres.
_TRACE_START_GAP_M = 1e-4


@dataclass(frozen=True, kw_only=True)
class RealLensCamera:
    """A plenoptic 1.0 camera with a real main lens (see the module docstring).

    Attributes
    ----------
    camera : LightFieldCamera
        The microlens array, the sensor, and the thin-lens equivalent of the main lens.
    lens : LensPrescription
        The main lens; its d-line effective focal length and f-number must equal the camera's
        (relative :data:`FIRST_ORDER_MATCH_RTOL`). :meth:`from_preset` scales a published design.

    Raises
    ------
    ParameterError
        If the first-order data disagree, if the lens reaches back to the MLA, if its exit pupil
        lies at or behind the MLA, or if its image-side f-number is below the microlenses' (the
        micro-images would overlap, which the plenoptic 1.0 model does not represent).
    """

    camera: LightFieldCamera
    lens: LensPrescription

    def __post_init__(self) -> None:
        if not isinstance(self.camera, LightFieldCamera):
            raise ParameterError(f"camera must be a LightFieldCamera, got {self.camera!r}")
        if not isinstance(self.lens, LensPrescription):
            raise ParameterError(f"lens must be a LensPrescription, got {self.lens!r}")
        fo = self.first_order
        cam = self.camera
        for what, lens_value, camera_value in (
            ("effective focal length", fo.efl_m, cam.focal_length_m),
            ("f-number", fo.f_number, cam.f_number),
        ):
            if not math.isclose(lens_value, camera_value, rel_tol=FIRST_ORDER_MATCH_RTOL):
                raise ParameterError(
                    f"lens {self.lens.name!r}: its {what} {lens_value!r} differs from the camera's {camera_value!r} "
                    f"(camera {cam.name!r}); scale and stop the lens to the camera "
                    "(LensPrescription.scaled_to_focal_length, with_f_number, or RealLensCamera.from_preset)"
                )
        rear_z = self.extent_z_m[0]
        if rear_z <= cam.mla_z_m:
            raise ParameterError(
                f"lens {self.lens.name!r} reaches z = {rear_z!r} m, at or behind the MLA (z = {cam.mla_z_m!r} m) "
                f"of camera {cam.name!r}: lens_to_mla_m={cam.lens_to_mla_m!r} is too short for it"
            )
        if self.exit_pupil_distance_m <= 0.0:
            raise ParameterError(
                f"lens {self.lens.name!r}: its exit pupil (z = {fo.exit_pupil_z_m!r} m) lies at or behind the MLA"
            )
        if self.image_side_f_number < cam.mla.f_number * (1.0 - 1e-9):
            raise ParameterError(
                f"lens {self.lens.name!r} on camera {cam.name!r}: image-side f-number "
                f"{self.image_side_f_number:.4g} (exit pupil distance over diameter) is below the microlens "
                f"f-number {cam.mla.f_number:.4g}: micro-images would overlap"
            )

    @classmethod
    def from_preset(cls, camera: LightFieldCamera, name: str) -> RealLensCamera:
        """The published design ``name`` (:data:`lfrefract.optics.lens.LENS_PRESETS`) scaled and
        stopped to ``camera``'s focal length and f-number."""
        return cls(
            camera=camera, lens=lens_preset(name, focal_length_m=camera.focal_length_m, f_number=camera.f_number)
        )

    # ----------------------------------------------------------------- first-order quantities
    @functools.cached_property
    def first_order(self) -> FirstOrder:
        """The lens's first-order data at the d line (camera-frame positions in ``*_z_m``)."""
        return self.lens.first_order(D_LINE_M)

    @functools.cached_property
    def extent_z_m(self) -> tuple[float, float]:
        """Camera-frame z of the rearmost and the frontmost point of the lens's surfaces within their
        clear apertures, metres: a port must lie beyond the second, the MLA behind the first."""
        vertex_z = self.lens.vertex_z_m()
        z = [
            vertex_z[i] - s.sag_m(np.linspace(0.0, s.semi_aperture_m, _EXTENT_SAMPLES))
            for i, s in enumerate(self.lens.surfaces)
        ]
        stacked = np.concatenate(z)
        return float(stacked.min()), float(stacked.max())

    @property
    def exit_pupil_distance_m(self) -> float:
        """Distance ``D`` from the MLA to the exit pupil (positive: the pupil is in front), metres."""
        return self.first_order.exit_pupil_z_m - self.camera.mla_z_m

    @property
    def calibration_origin_cam(self) -> np.ndarray:
        """Where a calibration from boards in air puts this camera's origin (3,), camera frame, metres:
        on the axis at the lens's paraxial entrance pupil (:attr:`FirstOrder.entrance_pupil_z_m`).

        Views of boards in air fix a camera's frame up to a shift along its axis (moving the origin
        along the chief rays changes no image). The ray models fix it by putting the paraxial chief
        rays through the origin (:func:`lfrefract.optics.ray_correction.frame_directions`), so a
        calibrated model's rays are this lens's rays moved here: its truth (ports, boards, rays) is
        compared with a calibration in this frame.

        Examples
        --------
        >>> from lfrefract import camera_preset
        >>> real = RealLensCamera.from_preset(camera_preset("tiny-2x"), "double-gauss")
        >>> round(float(real.calibration_origin_cam[2]) * 1e3, 3)  # mm: 0.514 mm behind the origin
        -0.514
        """
        return np.array([0.0, 0.0, self.first_order.entrance_pupil_z_m])

    @property
    def image_side_f_number(self) -> float:
        """``D`` over the exit pupil's diameter: the cone of light arriving at the MLA."""
        return self.exit_pupil_distance_m / self.first_order.exit_pupil_diameter_m

    @property
    def micro_image_scale(self) -> float:
        """Micro-image centre over microlens centre, image plane: ``(D + f_mla) / D``."""
        d = self.exit_pupil_distance_m
        return (d + self.camera.mla.focal_length_m) / d

    @functools.cached_property
    def lattice_camera(self) -> LightFieldCamera:
        """The thin-lens camera whose micro-images lie where this lens's do: :attr:`camera` with the
        microlens lattice (pitch and offset) scaled by this lens's :attr:`micro_image_scale` over the
        thin lens's. What an MLA calibration from a white image of this lens measures; its thin-lens
        rays index the raw pixels by the real micro-images (:class:`TracedLens`).

        Examples
        --------
        >>> from lfrefract import camera_preset
        >>> real = RealLensCamera.from_preset(camera_preset("tiny-2x"), "double-gauss")
        >>> lattice = real.lattice_camera
        >>> centre = lattice.mla.pitch_m * lattice.micro_image_scale  # of the first lens along x
        >>> bool(np.isclose(centre, real.camera.mla.pitch_m * real.micro_image_scale))
        True
        """
        cam = self.camera
        ratio = self.micro_image_scale / cam.micro_image_scale
        offset_x, offset_y = cam.mla.offset_m
        mla = dataclasses.replace(
            cam.mla, pitch_m=cam.mla.pitch_m * ratio, offset_m=(offset_x * ratio, offset_y * ratio)
        )
        return dataclasses.replace(cam, mla=mla)

    @property
    def micro_image_radius_px(self) -> float:
        """Radius of a micro-image (the exit pupil's paraxial image through a microlens), pixels."""
        radius_m = 0.5 * self.first_order.exit_pupil_diameter_m * self.camera.mla.focal_length_m
        return radius_m / self.exit_pupil_distance_m / self.camera.sensor.pixel_pitch_m

    # ----------------------------------------------------------------- lenses and rays
    def lens_indices_for_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Lattice index (N, 2) of the microlens whose micro-image holds each raw pixel position (N, 2)."""
        pts = self.camera.sensor.pixels_to_image_plane(as_points("uv", uv, 2))
        return self.camera.mla.nearest_indices(pts / self.micro_image_scale)

    def micro_image_centres_px(self, indices: np.ndarray) -> np.ndarray:
        """Raw-pixel coordinates (N, 2) of the paraxial micro-image centres of lenses ``indices`` (N, 2)."""
        return self.camera.sensor.image_plane_to_pixels(self.camera.mla.centres_m(indices) * self.micro_image_scale)

    def rays_through_lenses(self, uv: np.ndarray, *, lens_offsets_m: np.ndarray | None = None) -> CapturedRays:
        """Trace light paths from raw-pixel positions out through a microlens and the real lens.

        Parameters
        ----------
        uv : array_like, shape (N, 2)
            Raw pixel coordinates (column, row), pixel centres at integers.
        lens_offsets_m : array_like, shape (N, 2), optional
            Image-plane offsets from the microlens centre where each path crosses the MLA, metres.
            Default: zero (the microlens's chief ray).

        Returns
        -------
        CapturedRays
            Camera frame: ``origins_cam`` on the lens's front surface, unit ``directions_cam`` into
            the scene (object space, air); ``in_aperture`` is False for paths stopped by a clear
            aperture or totally reflected inside the lens (their origin and direction are NaN).
        """
        cam = self.camera
        through_xy, slope_xy, idx = cam.paths_leaving_mla(
            uv, lens_offsets_m=lens_offsets_m, micro_image_scale=self.micro_image_scale
        )
        n = through_xy.shape[0]
        origins = np.column_stack([through_xy, np.full(n, cam.mla_z_m)])
        directions = np.column_stack([slope_xy, np.ones(n)])
        trace = trace_lens(self.lens, origins, directions, toward="object")
        return CapturedRays(
            origins_cam=trace.points_cam,
            directions_cam=trace.directions_cam,
            in_aperture=trace.passed,
            lens_indices=idx,
        )

    def chief_rays(self, uv: np.ndarray | None = None) -> CapturedRays:
        """The object-space ray of each raw pixel's chief sample (through its microlens centre).

        Parameters
        ----------
        uv : array_like, shape (N, 2), optional
            Raw pixel coordinates. Default: every pixel centre, row-major, N = W * H.
        """
        if uv is None:
            sensor = self.camera.sensor
            vv, uu = np.mgrid[0 : sensor.height_px, 0 : sensor.width_px]
            uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
        return self.rays_through_lenses(uv)

    # ----------------------------------------------------------------- files
    def to_dict(self) -> dict:
        """Plain data: ``{"camera": LightFieldCamera.to_dict(), "lens": LensPrescription.to_dict()}``."""
        return {"camera": self.camera.to_dict(), "lens": self.lens.to_dict()}

    @classmethod
    def from_dict(cls, data: Any) -> RealLensCamera:
        """Inverse of :meth:`to_dict`."""
        table = as_table("real-lens camera", data)
        reject_unknown_keys("real-lens camera", table, {"camera", "lens"})
        require_keys("real-lens camera", table, {"camera", "lens"})
        return cls(camera=LightFieldCamera.from_dict(table["camera"]), lens=LensPrescription.from_dict(table["lens"]))


#: The ``family`` a :class:`TracedLens` is written with in a ray model's table.
TRACED_FAMILY = "traced"


@dataclass(frozen=True, kw_only=True)
class TracedLens:
    """The ray model of a camera whose main lens's prescription is known: its rays traced exactly.

    The member of the ray-model family (:data:`lfrefract.optics.ray_correction.Correction`) that a
    render's ``meta.json`` gives, where the simulator records the real main lens it rendered through:
    what a calibration from data can at best reach, so the oracle a data-only calibration of a
    real-lens render is measured against. Like the calibrated models it maps the thin-lens ray of a
    raw pixel (:meth:`LightFieldCamera.captured_rays`) to the camera's ray, here by tracing: the
    thin-lens ray is followed back to its raw pixel, which :meth:`RealLensCamera.chief_rays` traces
    (through the microlens whose real micro-image holds it, which at a micro-image's rim can be the
    neighbour of the thin lens's). It has no parameters (:meth:`vector` is empty) and is not fitted.

    Attributes
    ----------
    real : RealLensCamera
        The camera and its main lens.
    camera : LightFieldCamera, optional
        The thin-lens camera whose rays it maps (:class:`lfrefract.optics.camera_model.CameraModel`
        checks that it is the model's): its pixel grid must be ``real``'s. Default
        :attr:`RealLensCamera.lattice_camera`, whose micro-images are the lens's, so that the thin-lens
        model's rim and coverage follow the real micro-images.

    Examples
    --------
    >>> import numpy as np
    >>> from lfrefract import camera_preset
    >>> real = RealLensCamera.from_preset(camera_preset("tiny-2x"), "double-gauss")
    >>> model = TracedLens(real=real)
    >>> uv = np.array([[50.0, 90.0], [56.0, 90.0], [57.0, 90.0]])
    >>> traced = model.corrected(model.camera.captured_rays(uv))
    >>> traced.in_aperture.tolist()  # the first is vignetted by the lens (its ray is NaN)
    [False, True, True]
    >>> bool(np.allclose(traced.directions_cam, real.chief_rays(uv).directions_cam, equal_nan=True))
    True
    """

    real: RealLensCamera
    camera: LightFieldCamera = None  # type: ignore[assignment]  # None: real.lattice_camera (__post_init__)

    def __post_init__(self) -> None:
        if not isinstance(self.real, RealLensCamera):
            raise ParameterError(f"real must be a RealLensCamera, got {type(self.real).__name__}")
        if self.camera is None:
            object.__setattr__(self, "camera", self.real.lattice_camera)
        if not isinstance(self.camera, LightFieldCamera):
            raise ParameterError(f"camera must be a LightFieldCamera or None, got {type(self.camera).__name__}")
        if self.camera.sensor != self.real.camera.sensor:
            raise ParameterError(
                f"camera {self.camera.name!r} has another sensor than the traced camera {self.real.camera.name!r}: "
                "its thin-lens rays index other pixels"
            )

    @property
    def name(self) -> str:
        """How reports name the model: ``"traced <lens name>"``."""
        return f"{TRACED_FAMILY} {self.real.lens.name}"

    @functools.cached_property
    def _mla_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(A (2, 2), b (2,), A^-1)``: the affine map of camera-frame points on the MLA plane from
        :attr:`camera`'s lattice to the traced camera's, each microlens centre to the same lens's."""
        idx = np.array([[0, 0], [1, 0], [0, 1]])
        thin, true = -self.camera.mla.centres_m(idx), -self.real.camera.mla.centres_m(idx)  # camera frame
        a = (true[1:] - true[0]).T @ np.linalg.inv((thin[1:] - thin[0]).T)
        return a, true[0] - a @ thin[0], np.linalg.inv(a)

    def apply(self, aperture_points_m: np.ndarray, slopes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The traced rays of thin-lens rays (aperture points (N, 2), slopes (N, 2)): origins (N, 3)
        where they cross z = 0 and unit directions (N, 3), as the calibrated models give them; NaN
        where the real lens stops the ray (a clear aperture, total reflection).

        A thin-lens ray leaves the MLA plane at ``q`` with slope ``s``; its traced ray leaves the
        traced camera's MLA plane at ``r = A q + b`` (:attr:`_mla_map`: each microlens centre to the
        same lens's) with the slope that keeps the point ``q - s f`` it continues to on the sensor
        (``f`` the microlenses' focal length). On a pixel's own ray (through its microlens's centre,
        continuing to the pixel) that is the pixel's true chief ray; between pixels, a smooth map
        (a board corner's observation from a point of the aperture lies between them)."""
        cam, true = self.camera, self.real.camera
        a, t = np.asarray(aperture_points_m, dtype=np.float64), np.asarray(slopes, dtype=np.float64)
        slope_in = t + a / cam.focal_length_m  # before the thin main lens, towards +z
        q = a - slope_in * cam.lens_to_mla_m  # on the MLA plane, camera frame
        matrix, offset, _ = self._mla_map
        r = q @ matrix.T + offset
        slope = slope_in + (r - q) / true.mla.focal_length_m
        n = len(r)
        trace = trace_lens(
            self.real.lens,
            np.column_stack([r, np.full(n, true.mla_z_m)]),
            np.column_stack([slope, np.ones(n)]),
            toward="object",
        )
        o, d = trace.points_cam, trace.directions_cam
        with np.errstate(invalid="ignore"):
            origins = o - (o[:, 2:3] / d[:, 2:3]) * d
        origins[:, 2] = 0.0
        return origins, d

    def thin_lens_rays(
        self, points_cam: np.ndarray, directions_cam: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The thin-lens rays that :meth:`apply` maps to the given rays (its inverse): each ray traced
        back through the lens to the MLA plane and mapped there as :meth:`apply` maps the other way.

        Parameters
        ----------
        points_cam : ndarray, shape (N, 3)
            A point on each ray, camera frame, metres.
        directions_cam : ndarray, shape (N, 3)
            Their directions (any length, ``z > 0``).

        Returns
        -------
        aperture_points_m : ndarray, shape (N, 2)
            The thin-lens rays' points on the plane z = 0, metres.
        slopes : ndarray, shape (N, 2)
            Their slopes.
        found : ndarray of bool, shape (N,)
            The ray passes the lens (not stopped by a clear aperture nor totally reflected, and not
            NaN); both outputs are NaN where not.
        """
        p = np.asarray(points_cam, dtype=np.float64)
        d = np.asarray(directions_cam, dtype=np.float64)
        n = len(p)
        a, t = np.full((n, 2), np.nan), np.full((n, 2), np.nan)
        live = (
            np.all(np.isfinite(p), axis=1) & np.all(np.isfinite(d), axis=1) & (d[:, 2] > 0.0)
            if n
            else np.zeros(0, bool)
        )
        found = np.zeros(n, dtype=bool)
        if not np.any(live):
            return a, t, found
        cam, true = self.camera, self.real.camera
        start_z = self.real.extent_z_m[1] + _TRACE_START_GAP_M  # in front of the lens, in air
        pl, dl = p[live], d[live]
        start = pl + dl * ((start_z - pl[:, 2]) / dl[:, 2])[:, None]
        trace = trace_lens(self.real.lens, start, -dl, toward="image")
        back, e = trace.points_cam, trace.directions_cam
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = e[:, :2] / e[:, 2:3]  # the same line towards +z
            r = back[:, :2] + slope * (true.mla_z_m - back[:, 2:3])  # on the traced camera's MLA plane
        _, offset, inverse = self._mla_map
        q = (r - offset) @ inverse.T
        slope_in = slope - (r - q) / true.mla.focal_length_m
        aperture = q + slope_in * cam.lens_to_mla_m
        ok = trace.passed & np.all(np.isfinite(aperture), axis=1) & np.all(np.isfinite(slope_in), axis=1)
        rows = np.flatnonzero(live)[ok]
        a[rows] = aperture[ok]
        t[rows] = slope_in[ok] - aperture[ok] / cam.focal_length_m
        found[rows] = True
        return a, t, found

    def corrected(self, rays: CapturedRays) -> CapturedRays:
        """``rays`` (thin-lens captured rays of :attr:`camera`) traced; ``in_aperture`` also
        False where the real lens stops a ray; the lens indices kept."""
        d = rays.directions_cam
        origins, directions = self.apply(rays.origins_cam[:, :2], d[:, :2] / d[:, 2:3])
        passed = np.all(np.isfinite(directions), axis=1)
        return CapturedRays(
            origins_cam=origins,
            directions_cam=directions,
            in_aperture=rays.in_aperture & passed,
            lens_indices=rays.lens_indices,
        )

    def vector(self) -> np.ndarray:
        """No parameters: an empty array (0,)."""
        return np.zeros(0)

    def on_camera(self, camera: LightFieldCamera) -> TracedLens:
        """The same true rays mapped from the thin-lens rays of ``camera`` (an MLA calibration's, a
        capture's own geometry, of the same pixel grid)."""
        return self if camera == self.camera else TracedLens(real=self.real, camera=camera)

    def to_dict(self) -> dict:
        """Plain data: ``family`` ``"traced"``, the traced camera and its lens
        (:meth:`RealLensCamera.to_dict`) and ``thin_lens_camera``, :attr:`camera`."""
        return {"family": TRACED_FAMILY, **self.real.to_dict(), "thin_lens_camera": self.camera.to_dict()}

    @classmethod
    def from_dict(cls, data: Any, *, where: str = "correction") -> TracedLens:
        """From :meth:`to_dict`'s data."""
        table = as_table(where, data)
        keys = {"family", "camera", "lens", "thin_lens_camera"}
        reject_unknown_keys(where, table, keys)
        require_keys(where, table, keys)
        if table["family"] != TRACED_FAMILY:
            raise ParameterError(f"{where}.family must be {TRACED_FAMILY!r}, got {table['family']!r}")
        real = RealLensCamera.from_dict({"camera": table["camera"], "lens": table["lens"]})
        return cls(real=real, camera=LightFieldCamera.from_dict(table["thin_lens_camera"]))
