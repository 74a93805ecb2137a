"""Microlens-array (MLA) calibration from a white image.

A white image (the camera looking at uniform radiance, e.g. through a diffuser) shows one bright
disc per microlens: the main-lens aperture imaged through that lens. Its centre is the
**micro-image centre**, the image of the main-lens centre through the microlens centre
(``docs/conventions.md``). In the camera model the micro-image centres are the lens lattice scaled by
``(f' + f_mla) / f'`` about the optical axis, so they form a lattice of the same type and
rotation. :func:`calibrate_mla` estimates that lattice and every centre from the image alone:

1. **Lattice from the spectrum.** The strongest peak of the image's windowed power spectrum and
   the strongest one in another direction are two basis vectors of the reciprocal lattice; the
   angle between them tells hexagonal (60 deg) from square (90 deg), and their dual basis is an
   approximate pixel basis, reduced to the canonical one (``a1`` the shortest vector closest to
   +u, ``a2`` the next one counter-clockwise, i.e. +60 or +90 deg towards +v).
2. **Origin from the phases.** The micro-images are point-symmetric discs, so the phase of the
   image's Fourier coefficient at each reciprocal basis vector, summed over a tapered region around
   the sensor centre, gives the lattice's position modulo one cell.
3. **Centroids and a lattice fit, growing outwards.** Micro-images whose lattice position lies
   within a radius of the sensor centre are measured by their intensity-weighted centroid inside a
   circular window (radius half a pitch, soft-edged by pixel coverage) and the lattice (origin and
   basis) is fitted to them by linear least squares with iterative rejection of outliers; the
   radius then grows (eight pitches, then three times more each pass) until the whole sensor is
   covered, so the lattice index of every lens is certain. In the first and the last pass each
   window is re-centred on its centroid until it settles (moves less than 1e-4 px): neighbouring
   micro-images that nearly touch, or the soft edges of a real white, reach into the window and
   pull the centroid towards the window's centre, and only a window centred on a point-symmetric
   micro-image gives its centre without bias.
4. **Rejection.** A micro-image whose window leaves the sensor is not measured (``edge``); one whose
   flux is below ``min_relative_flux`` of a full one (the 90th percentile) is clipped or dimmed by
   vignetting (``dim``); one whose centroid disagrees with the fitted lattice by more than
   ``outlier_sigma`` robust standard deviations (their scale measured in the first, central pass)
   is an ``outlier``, e.g. a disc clipped on one side by a second stop of the main lens (cat's-eye
   vignetting at the border). Only the rest (``used``) enter the fit. Finally nearly every used
   micro-image must be brighter at its centre than in the gaps around it, and the residuals small
   compared with the pitch, or the image is no white image.

Frames and units: raw pixels ``(u, v)`` = (column, row), pixel centres at integers, as in OpenCV.
Lattice index ``(i, j)`` sits at ``origin_px + basis_px @ (i, j)``; ``(0, 0)`` is the lattice point
nearest the sensor centre ``((W - 1) / 2, (H - 1) / 2)``. Rotation turns from +u towards +v, like
the MLA's rotation from +xi towards +eta in image-plane coordinates (the two frames are parallel).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import GRID_TYPES, GridType, LightFieldCamera, MicrolensArray, micro_image_scale
from lfrefract.validate import finite_float, finite_vector, one_of, positive_float, reject_unknown_keys, require_keys

__all__ = ["LATTICE_MODELS", "LENS_STATUS", "MlaCalibration", "calibrate_mla"]

#: Lattice models :func:`calibrate_mla` can fit: ``"regular"`` (the camera model: origin, pitch and
#: rotation of an exact hexagonal or square lattice) or ``"affine"`` (origin and a free 2 x 2 basis:
#: also absorbs anisotropic scale and shear, e.g. of a real sensor or MLA).
LATTICE_MODELS = ("regular", "affine")

#: Meaning of :attr:`MlaCalibration.status`: index into this tuple.
LENS_STATUS = ("used", "edge", "dim", "outlier")
_USED, _EDGE, _DIM, _OUTLIER = range(4)

_SQRT3 = math.sqrt(3.0)
#: Canonical (unrotated, unit pitch) basis of each grid type, columns a1 and a2.
_UNIT_BASIS = {"hex": np.array([[1.0, 0.5], [0.0, _SQRT3 / 2.0]]), "square": np.eye(2)}
#: Angle between the two reciprocal basis vectors of each grid type, degrees.
_GRID_ANGLE_DEG: dict[GridType, float] = {"hex": 60.0, "square": 90.0}
#: The measured angle must be this close to 60 or 90 deg.
_GRID_ANGLE_TOLERANCE_DEG = 10.0
#: Spectral peak over the median power at the same spatial frequency (all directions): white and
#: blurred noise give 7-18, rendered white images 3e5 and more.
_MIN_PEAK_PROMINENCE = 200.0
#: Smallest share of the used micro-images that must be brighter at their centre than in every gap
#: (lattice hole) around it. Scale-free and decided lens by lens: a white image's micro-images are
#: brighter than their gaps however soft their edges (Lytro's whites and the sensor model's leave the
#: gaps at 20-60 % of the centres, and a fixed ratio refused the softer ones), while a smooth or noisy
#: image's centres and gaps are alike (a third of its lenses pass for a hex lattice's two
#: holes, a half for a square one's).
_MIN_BRIGHTER_SHARE = 0.9
#: The lattice is first estimated on at most this many pixels per side (the central crop).
_FFT_MAX_SIDE = 1024
#: Radius of the first fitted region, lattice pitches; the region then grows by this factor.
_FIRST_RADIUS_PITCHES = 8.0
_GROWTH = 3.0
#: Lenses measured per vectorised block (bounds memory on large sensors).
_BLOCK = 20000
#: Smallest robust residual scale the outlier test uses, pixels (noise-free synthetic images).
_MIN_SIGMA_PX = 1e-3
#: A fitted lattice whose residual RMS exceeds this fraction of the pitch is no lattice.
_MAX_RMS_PITCHES = 0.1
_MIN_USED = 10
#: Each centroid window is re-centred on its centroid until it moves less than this, pixels: each
#: step shrinks a window's remaining offset by a constant factor (a quarter or less on hard-edged
#: whites, about two thirds on soft ones, e.g. blurred by 2 px), so the centroid ends within a few
#: times this of the fixed point. A fixed 3 steps left 0.015 px RMS of bias on a soft Illum white.
_RECENTRE_TOLERANCE_PX = 1e-4
#: ... or after this many steps (reached only by windows that do not settle: they count as measured
#: where they stopped; at a factor of 0.9 per step, 150 steps leave 1e-7 of the offset).
_RECENTRE_MAX_STEPS = 150


# ================================================================================ the result
@dataclass(frozen=True, eq=False)
class MlaCalibration:
    """Micro-image lattice and centres estimated from a white image (:func:`calibrate_mla`).

    Attributes
    ----------
    grid : {"hex", "square"}
        Lattice type.
    lattice_model : {"regular", "affine"}
        The fitted model (see :data:`LATTICE_MODELS`).
    image_size_px : tuple of int
        ``(W, H)`` of the white image.
    origin_px : ndarray, shape (2,)
        Pixel position ``(u, v)`` of the micro-image centre of lattice index ``(0, 0)``, the lattice
        point nearest the sensor centre.
    basis_px : ndarray, shape (2, 2)
        Lattice basis in pixels, columns ``a1`` and ``a2``: index ``(i, j)`` is at
        ``origin_px + basis_px @ (i, j)``. ``a1`` points along +u rotated by :attr:`rotation_rad`,
        ``a2`` is 60 deg (hex) or 90 deg (square) further towards +v (exactly so for the regular
        model).
    indices : ndarray of int64, shape (N, 2)
        Lattice index ``(i, j)`` of every lens whose fitted micro-image centre lies on the sensor
        (within the outermost pixel centres), sorted row by row (by ``j``, then ``i``).
    measured_px : ndarray, shape (N, 2)
        Measured micro-image centroids, pixels; NaN where not measured (window off the sensor, or
        no light).
    status : ndarray of int8, shape (N,)
        Index into :data:`LENS_STATUS`: ``used`` in the fit, ``edge`` (window leaves the sensor),
        ``dim`` (flux below the threshold: clipped or vignetted) or ``outlier`` (rejected by the
        fit).
    window_radius_px : float
        Radius of the centroid window, pixels.
    """

    grid: GridType
    lattice_model: str
    image_size_px: tuple[int, int]
    origin_px: np.ndarray
    basis_px: np.ndarray
    indices: np.ndarray
    measured_px: np.ndarray
    status: np.ndarray
    window_radius_px: float

    def __post_init__(self) -> None:
        one_of("grid", self.grid, GRID_TYPES)
        one_of("lattice_model", self.lattice_model, LATTICE_MODELS)
        size = finite_vector("image_size_px", self.image_size_px, 2)
        if any(s != int(s) or s < 1 for s in size):
            raise ParameterError(f"image_size_px must be two positive integers, got {self.image_size_px!r}")
        positive_float("window_radius_px", self.window_radius_px)
        origin = np.array(finite_vector("origin_px", np.ravel(self.origin_px), 2))
        basis = np.array(self.basis_px, dtype=np.float64)
        if basis.shape != (2, 2) or not np.all(np.isfinite(basis)) or abs(np.linalg.det(basis)) < 1e-9:
            raise ParameterError(f"basis_px must be a finite, non-singular 2 x 2 matrix, got {self.basis_px!r}")
        indices = np.asarray(self.indices)
        if indices.ndim != 2 or indices.shape[1] != 2 or not np.issubdtype(indices.dtype, np.integer):
            raise ParameterError(f"indices must be integers of shape (N, 2), got {indices.dtype} {indices.shape}")
        n = len(indices)
        measured = np.array(self.measured_px, dtype=np.float64)
        if measured.shape != (n, 2):
            raise ParameterError(f"measured_px must have shape ({n}, 2), got {measured.shape}")
        if np.any(np.isinf(measured)):
            raise ParameterError("measured_px must be finite or NaN, got an infinite entry")
        status = np.asarray(self.status)
        if status.shape != (n,) or not np.issubdtype(status.dtype, np.integer):
            raise ParameterError(f"status must be integers of shape ({n},), got {status.dtype} {status.shape}")
        if n and (status.min() < 0 or status.max() >= len(LENS_STATUS)):
            raise ParameterError(f"status must index {list(LENS_STATUS)}, got values {np.unique(status).tolist()}")
        if np.any(np.isnan(measured[status == _USED])):
            raise ParameterError("measured_px must be given for every lens with status 'used'")
        for name, value in (
            ("image_size_px", (int(size[0]), int(size[1]))),
            ("origin_px", origin),
            ("basis_px", basis),
            ("indices", indices.astype(np.int64)),
            ("measured_px", measured),
            ("status", status.astype(np.int8)),
            ("window_radius_px", float(self.window_radius_px)),
        ):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ derived figures
    @property
    def pitch_px(self) -> float:
        """Distance between neighbouring micro-image centres, pixels.

        For the affine model: the pitch of the nearest regular lattice (the similarity part of
        ``basis_px`` against the grid's unit basis).
        """
        return float(math.hypot(*self._similarity()))

    @property
    def rotation_rad(self) -> float:
        """Rotation of the lattice from +u towards +v, radians: about (-pi/6, pi/6] (hex) or
        (-pi/4, pi/4] (square)."""
        a, b = self._similarity()
        return float(math.atan2(b, a))

    def _similarity(self) -> tuple[float, float]:
        """``(p cos r, p sin r)`` of the closest rotation-and-scale to ``basis_px @ inv(unit basis)``."""
        m = self.basis_px @ np.linalg.inv(_UNIT_BASIS[self.grid])
        return (m[0, 0] + m[1, 1]) / 2.0, (m[1, 0] - m[0, 1]) / 2.0

    @property
    def centres_px(self) -> np.ndarray:
        """Fitted micro-image centres of :attr:`indices`, shape (N, 2), pixels."""
        return self.origin_px + self.indices @ self.basis_px.T

    @property
    def used(self) -> np.ndarray:
        """Lenses whose measured centre entered the lattice fit, bool (N,)."""
        return self.status == _USED

    @property
    def residuals_px(self) -> np.ndarray:
        """Distance from each measured centre to its fitted one, pixels, shape (N,); NaN if unmeasured."""
        return np.linalg.norm(self.measured_px - self.centres_px, axis=1)

    @property
    def residual_rms_px(self) -> float:
        """Root mean square residual of the lenses used in the fit, pixels (the quality figure);
        NaN if none is used."""
        used = self.residuals_px[self.used]
        return float(np.sqrt(np.mean(used**2))) if len(used) else math.nan

    @property
    def residual_max_px(self) -> float:
        """Largest residual of the lenses used in the fit, pixels; NaN if none is used."""
        used = self.residuals_px[self.used]
        return float(np.max(used)) if len(used) else math.nan

    def status_counts(self) -> dict[str, int]:
        """Number of lenses with each status, e.g. ``{"used": 1700, "edge": 180, ...}``."""
        return {name: int(np.sum(self.status == k)) for k, name in enumerate(LENS_STATUS)}

    # ------------------------------------------------------------------ the physical MLA
    def microlens_array(
        self, *, pixel_pitch_m: float, lens_to_mla_m: float, mla_focal_length_m: float
    ) -> MicrolensArray:
        """The microlens array implied by the fitted lattice, for a sensor centred on the axis.

        Micro-image centres are the lens centres scaled by ``s = (f' + f_mla) / f'`` about the
        optical axis (the sensor centre), so the lens lattice is the micro-image lattice, moved to
        image-plane metres, divided by ``s``: ``pitch_m = pitch_px * pixel_pitch_m / s``, the same
        rotation, and lens ``(i, j)`` of :attr:`indices` is lens ``(i, j)`` of the result (its
        ``offset_m`` is lens ``(0, 0)``). For the affine model, the nearest regular lattice.

        Parameters
        ----------
        pixel_pitch_m : float
            Sensor pixel pitch, metres.
        lens_to_mla_m : float
            Main lens to MLA distance f', metres.
        mla_focal_length_m : float
            Microlens focal length f_mla (the MLA-sensor gap), metres.

        Returns
        -------
        MicrolensArray
        """
        pixel_pitch_m = positive_float("pixel_pitch_m", pixel_pitch_m)
        lens_to_mla_m = positive_float("lens_to_mla_m", lens_to_mla_m)
        mla_focal_length_m = positive_float("mla_focal_length_m", mla_focal_length_m)
        scale = micro_image_scale(lens_to_mla_m, mla_focal_length_m)
        width, height = self.image_size_px
        centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
        offset = (self.origin_px - centre) * pixel_pitch_m / scale
        return MicrolensArray(
            grid=self.grid,
            pitch_m=self.pitch_px * pixel_pitch_m / scale,
            focal_length_m=mla_focal_length_m,
            rotation_rad=self.rotation_rad,
            offset_m=(float(offset[0]), float(offset[1])),
        )

    def calibrated_camera(self, camera: LightFieldCamera) -> LightFieldCamera:
        """``camera`` with its MLA replaced by :meth:`microlens_array` (its f', f_mla and pixel pitch).

        Raises
        ------
        ParameterError
            If the camera's sensor size differs from the white image's.
        """
        if not isinstance(camera, LightFieldCamera):
            raise ParameterError(f"camera must be a LightFieldCamera, got {camera!r}")
        size = (camera.sensor.width_px, camera.sensor.height_px)
        if size != self.image_size_px:
            raise ParameterError(
                f"camera sensor is {size[0]} x {size[1]} px but the white image was "
                f"{self.image_size_px[0]} x {self.image_size_px[1]} px"
            )
        mla = self.microlens_array(
            pixel_pitch_m=camera.sensor.pixel_pitch_m,
            lens_to_mla_m=camera.lens_to_mla_m,
            mla_focal_length_m=camera.mla.focal_length_m,
        )
        return dataclasses.replace(camera, mla=mla)

    # ------------------------------------------------------------------ sidecar
    def to_dict(self) -> dict:
        """Plain data for a JSON sidecar (pixels, radians); missing measurements are ``None``.

        ``summary`` repeats derived figures for people; :meth:`from_dict` ignores it.
        """
        measured = [None if np.isnan(row).any() else row.tolist() for row in self.measured_px]
        return {
            "grid": self.grid,
            "lattice_model": self.lattice_model,
            "image_size_px": list(self.image_size_px),
            "origin_px": self.origin_px.tolist(),
            "basis_px": self.basis_px.tolist(),
            "window_radius_px": self.window_radius_px,
            "status_names": list(LENS_STATUS),
            "lenses": {
                "indices": self.indices.tolist(),
                "measured_px": measured,
                "status": self.status.tolist(),
            },
            "summary": {
                "pitch_px": self.pitch_px,
                "rotation_rad": self.rotation_rad,
                "lens_count": len(self.indices),
                "status_counts": self.status_counts(),
                "residual_rms_px": self.residual_rms_px,
                "residual_max_px": self.residual_max_px,
            },
        }

    @classmethod
    def from_dict(cls, data: dict) -> MlaCalibration:
        """Inverse of :meth:`to_dict`; unknown keys are an error (``schema_version`` is allowed)."""
        keys = {
            "grid",
            "lattice_model",
            "image_size_px",
            "origin_px",
            "basis_px",
            "window_radius_px",
            "status_names",
            "lenses",
        }
        reject_unknown_keys("mla calibration", data, keys | {"summary", "schema_version"})
        require_keys("mla calibration", data, keys)
        if list(data["status_names"]) != list(LENS_STATUS):
            raise ParameterError(f"status_names must be {list(LENS_STATUS)}, got {data['status_names']!r}")
        lenses = data["lenses"]
        if not isinstance(lenses, dict):
            raise ParameterError(f"mla calibration lenses must be a table, got {lenses!r}")
        reject_unknown_keys("mla calibration.lenses", lenses, {"indices", "measured_px", "status"})
        require_keys("mla calibration.lenses", lenses, {"indices", "measured_px", "status"})
        measured = [[math.nan, math.nan] if row is None else row for row in lenses["measured_px"]]
        indices = _numbers("mla calibration.lenses.indices", lenses["indices"])
        if indices.ndim != 2 or not np.all(np.isfinite(indices)) or np.any(indices != np.round(indices)):
            raise ParameterError("mla calibration.lenses.indices must be integer pairs")
        status = _numbers("mla calibration.lenses.status", lenses["status"])
        if np.any(status != np.round(status)):
            raise ParameterError("mla calibration.lenses.status must be integers")
        return cls(
            grid=data["grid"],
            lattice_model=data["lattice_model"],
            image_size_px=tuple(data["image_size_px"]),
            origin_px=_numbers("mla calibration.origin_px", data["origin_px"]),
            basis_px=_numbers("mla calibration.basis_px", data["basis_px"]),
            indices=indices.astype(np.int64),
            measured_px=_numbers("mla calibration.lenses.measured_px", measured),
            status=status.astype(np.int64),
            window_radius_px=data["window_radius_px"],
        )


def _numbers(name: str, value: Any) -> np.ndarray:
    """``value`` as a float64 array, or a ParameterError naming ``name``."""
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be an array of numbers, got {str(value)[:80]}") from None


# ================================================================================ the estimate
def calibrate_mla(
    white: np.ndarray,
    *,
    grid: str | None = None,
    lattice_model: str = "regular",
    window_radius_px: float | None = None,
    min_relative_flux: float = 0.5,
    outlier_sigma: float = 6.0,
    min_pitch_px: float = 3.0,
    max_pitch_px: float | None = None,
) -> MlaCalibration:
    """Estimate the micro-image lattice and every micro-image centre from a white image.

    Parameters
    ----------
    white : array_like, shape (H, W) or (H, W, 3)
        Linear white image (raw lenslet image of uniform radiance), any positive scale; colour
        channels are averaged. The gaps between micro-images should be dark (subtract a dark
        frame first). Every value must be finite.
    grid : {"hex", "square"}, optional
        Expected lattice type; detected from the image when omitted. A white image whose lattice
        is of the other type is an error.
    lattice_model : {"regular", "affine"}
        ``"regular"`` (default): an exact hexagonal or square lattice (origin, pitch, rotation),
        as in the camera model. ``"affine"``: origin and a free basis.
    window_radius_px : float, optional
        Radius of the circular centroid window around each micro-image, pixels. Default half the
        estimated pitch (the largest circle inside a lattice cell).
    min_relative_flux : float
        Micro-images whose windowed flux is below this fraction of a full one (the 90th
        percentile of all fully visible windows) count as clipped or vignetted and are not used.
        In [0, 1).
    outlier_sigma : float
        Used micro-images whose centroid lies more than this many robust standard deviations (per
        axis, from the median residual) off the fitted lattice are rejected, iteratively.
    min_pitch_px, max_pitch_px : float
        Range of micro-image pitches searched in the spectrum, pixels. Default 3 px to a quarter
        of the smaller image side.

    Returns
    -------
    MlaCalibration
        Lattice (grid, origin, basis, pitch, rotation), every on-sensor lens with its lattice
        index, fitted and measured centre and status; residuals as the quality figure.

    Raises
    ------
    ParameterError
        If ``white`` has the wrong shape, a non-finite value or no contrast, if no hexagonal or
        square lattice is found in it (e.g. uniform or noise), if ``grid`` contradicts the image,
        if fewer than 10 micro-images could be measured, or if an option is out of range.
    """
    image = _validated_white(white)
    height, width = image.shape
    if grid is not None:
        one_of("grid", grid, GRID_TYPES)
    one_of("lattice_model", lattice_model, LATTICE_MODELS)
    min_relative_flux = finite_float("min_relative_flux", min_relative_flux)
    if not 0.0 <= min_relative_flux < 1.0:
        raise ParameterError(f"min_relative_flux must be in [0, 1), got {min_relative_flux!r}")
    outlier_sigma = positive_float("outlier_sigma", outlier_sigma)
    min_pitch_px = positive_float("min_pitch_px", min_pitch_px)
    if min_pitch_px < 2.0:
        raise ParameterError(f"min_pitch_px must be at least 2 (the sampling limit), got {min_pitch_px!r}")
    if max_pitch_px is None:
        max_pitch_px = min(height, width) / 4.0
    max_pitch_px = positive_float("max_pitch_px", max_pitch_px)
    if max_pitch_px <= min_pitch_px:
        raise ParameterError(f"max_pitch_px must exceed min_pitch_px={min_pitch_px!r}, got {max_pitch_px!r}")
    if window_radius_px is not None:
        window_radius_px = positive_float("window_radius_px", window_radius_px)

    found_grid, basis = _spectral_lattice(image, grid, min_pitch_px, max_pitch_px)
    pitch = float(np.linalg.norm(basis[:, 0]))
    radius = 0.5 * pitch if window_radius_px is None else window_radius_px
    if radius >= pitch:
        raise ParameterError(
            f"window_radius_px must be below the micro-image pitch ({pitch:.3g} px), got {window_radius_px!r}"
        )
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    origin = _phase_origin(image, basis, centre, _FIRST_RADIUS_PITCHES * pitch)
    lattice = _Lattice(found_grid, lattice_model, origin, basis)

    # Fit on a region that grows until it reaches the sensor's corners, then on every lens. The
    # residual scale of the first, central region (where vignetting is least) judges outliers in
    # every later pass; only that pass and the last need the unbiased, re-centred centroids.
    reach = _FIRST_RADIUS_PITCHES * pitch
    half_diagonal = math.hypot(width, height) / 2.0
    sigma = None
    while True:
        lattice, _ = lattice.recentred(centre)
        indices = lattice.indices_on_sensor(width, height)
        final = reach >= half_diagonal
        if not final:
            indices = indices[np.linalg.norm(lattice.centres(indices) - centre, axis=1) <= reach]
        recentre = sigma is None or final
        measured, flux, inside = _centroids(image, lattice.centres(indices), radius, recentre=recentre)
        status = _classify(flux, inside, min_relative_flux)
        lattice, status, scale = _robust_fit(lattice, indices, measured, status, outlier_sigma, sigma)
        sigma = scale if sigma is None else sigma
        if final:
            break
        reach *= _GROWTH
    lattice, shift = lattice.recentred(centre)
    indices = indices - shift

    # The last fit may move a lattice point across the sensor edge: such a lens's window leaves
    # the sensor, so it is an unmeasured edge lens.
    on_sensor = lattice.indices_on_sensor(width, height)
    if not np.array_equal(on_sensor, indices):
        measured, status = _reindexed(indices, measured, status, on_sensor)
        indices = on_sensor

    calibration = MlaCalibration(
        grid=found_grid,
        lattice_model=lattice_model,
        image_size_px=(width, height),
        origin_px=lattice.origin,
        basis_px=lattice.basis,
        indices=indices,
        measured_px=measured,
        status=status,
        window_radius_px=radius,
    )
    _check_dark_gaps(image, calibration)
    if calibration.residual_rms_px > _MAX_RMS_PITCHES * calibration.pitch_px:
        raise ParameterError(
            f"white shows no consistent micro-image lattice: centroids scatter by "
            f"{calibration.residual_rms_px:.3g} px RMS about the best {found_grid} lattice of pitch "
            f"{calibration.pitch_px:.3g} px"
        )
    return calibration


# ================================================================================ helpers
def _validated_white(white: Any) -> np.ndarray:
    """``white`` as a float64 (H, W) array; colour averaged; raises on shape, NaN or no contrast."""
    arr = np.asarray(white)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise ParameterError(f"white must be a real-valued image, got dtype {arr.dtype}")
    if arr.ndim == 3 and arr.shape[2] == 3:
        arr = arr.astype(np.float64).mean(axis=2)
    elif arr.ndim != 2:
        raise ParameterError(f"white must have shape (H, W) or (H, W, 3), got shape {arr.shape}")
    arr = arr.astype(np.float64, copy=False)
    if min(arr.shape) < 16:
        raise ParameterError(f"white must be at least 16 x 16 px, got shape {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        v, u = np.argwhere(bad)[0]
        raise ParameterError(
            f"white must be finite: {int(bad.sum())} pixel(s) are not, the first at (u, v) = ({u}, {v}): {arr[v, u]}"
        )
    if arr.max() == arr.min():
        raise ParameterError(f"white has no contrast: every pixel is {float(arr.flat[0])!r}")
    return arr


@dataclass(frozen=True)
class _Lattice:
    """A micro-image lattice in pixels: index (i, j) at ``origin + basis @ (i, j)``."""

    grid: GridType
    model: str
    origin: np.ndarray
    basis: np.ndarray

    def centres(self, indices: np.ndarray) -> np.ndarray:
        return self.origin + np.asarray(indices, dtype=np.float64) @ self.basis.T

    def indices_on_sensor(self, width: int, height: int) -> np.ndarray:
        """Indices (M, 2) whose centre lies within the outermost pixel centres, row by row."""
        corners = np.array([[0.0, 0.0], [width - 1.0, 0.0], [0.0, height - 1.0], [width - 1.0, height - 1.0]])
        frac = np.linalg.solve(self.basis, (corners - self.origin).T).T
        lo = np.floor(frac.min(axis=0)) - 1
        hi = np.ceil(frac.max(axis=0)) + 1
        ii, jj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="xy")
        idx = np.stack([ii.ravel(), jj.ravel()], axis=1).astype(np.int64)
        c = self.centres(idx)
        on = (c[:, 0] >= 0) & (c[:, 0] <= width - 1) & (c[:, 1] >= 0) & (c[:, 1] <= height - 1)
        return idx[on]

    def recentred(self, centre: np.ndarray) -> tuple[_Lattice, np.ndarray]:
        """The same lattice indexed from the point nearest ``centre``; and the index shift n0
        (new index = old index - n0)."""
        frac = np.linalg.solve(self.basis, centre - self.origin)
        base = np.floor(frac)
        corners = base + np.array([(0, 0), (1, 0), (0, 1), (1, 1)], dtype=np.float64)
        d2 = np.sum((self.centres(corners) - centre) ** 2, axis=1)
        shift = corners[np.argmin(d2)].astype(np.int64)
        return dataclasses.replace(self, origin=self.origin + self.basis @ shift), shift


def _reindexed(
    indices: np.ndarray, measured: np.ndarray, status: np.ndarray, new_indices: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``measured`` and ``status`` of ``indices`` carried over to ``new_indices``; new lenses are
    unmeasured edge lenses."""
    low = np.minimum(new_indices.min(axis=0), indices.min(axis=0))
    span = int(max(new_indices[:, 0].max(), indices[:, 0].max()) - low[0] + 1)

    def key(idx: np.ndarray) -> np.ndarray:
        return (idx[:, 1] - low[1]) * span + (idx[:, 0] - low[0])

    old_keys = key(indices)
    order = np.argsort(old_keys)
    rows = order[np.clip(np.searchsorted(old_keys[order], key(new_indices)), 0, len(indices) - 1)]
    kept = old_keys[rows] == key(new_indices)
    measured_new = np.full((len(new_indices), 2), np.nan)
    measured_new[kept] = measured[rows[kept]]
    status_new = np.full(len(new_indices), _EDGE, dtype=np.int8)
    status_new[kept] = status[rows[kept]]
    return measured_new, status_new


def _check_dark_gaps(image: np.ndarray, calibration: MlaCalibration) -> None:
    """Raise unless nearly every used micro-image is brighter at its centre than in each gap around it."""
    centres = calibration.centres_px[calibration.used]
    a1, a2 = calibration.basis_px.T
    holes = [(a1 + a2) / 3.0, 2.0 * (a1 + a2) / 3.0] if calibration.grid == "hex" else [(a1 + a2) / 2.0]
    points = np.concatenate([centres] + [centres + h for h in holes])
    values = ndimage.map_coordinates(image, [points[:, 1], points[:, 0]], order=1, mode="nearest")
    at_centres = values[: len(centres)]
    at_holes = values[len(centres) :].reshape(len(holes), len(centres))
    brighter = float(np.mean(np.all(at_centres > at_holes, axis=0)))
    if not brighter >= _MIN_BRIGHTER_SHARE:
        raise ParameterError(
            f"white does not look like a white image: only {brighter:.0%} of the micro-images of the best "
            f"{calibration.grid} lattice (pitch {calibration.pitch_px:.3g} px) are brighter at their centre than in "
            f"the gaps around them (median {float(np.median(at_centres)):.3g} against "
            f"{float(np.median(at_holes)):.3g}); a white image needs {_MIN_BRIGHTER_SHARE:.0%}"
        )


def _spectral_lattice(
    image: np.ndarray, grid: str | None, min_pitch: float, max_pitch: float
) -> tuple[GridType, np.ndarray]:
    """Grid type and an approximate canonical pixel basis (2, 2) from the power spectrum."""
    height, width = image.shape
    h, w = min(height, _FFT_MAX_SIDE), min(width, _FFT_MAX_SIDE)
    top, left = (height - h) // 2, (width - w) // 2
    crop = image[top : top + h, left : left + w]
    window = np.outer(np.hanning(h), np.hanning(w))
    power = np.abs(np.fft.fft2((crop - crop.mean()) * window)) ** 2
    fv = np.fft.fftfreq(h)[:, None]
    fu = np.fft.fftfreq(w)[None, :]
    freq = np.hypot(fu, fv)
    # The first reciprocal shell lies at 1 / pitch (square) to 2 / (sqrt(3) pitch) (hex); the Hann
    # window's main lobe covers two bins around zero frequency.
    band = (freq >= 1.0 / max_pitch) & (freq <= 2.0 / (_SQRT3 * min_pitch)) & (freq >= 3.0 / min(h, w))
    if not band.any():
        raise ParameterError(f"white is too small ({width} x {height} px) for pitches of {min_pitch}-{max_pitch} px")
    masked = np.where(band, power, 0.0)
    first = np.unravel_index(np.argmax(masked), masked.shape)
    peak = masked[first]
    # A lattice's spectrum is a set of isolated peaks; noise, blur and smooth shading spread their
    # power over every direction at the same frequency.
    ring = np.abs(freq - freq[first]) <= 1.5 / min(h, w)
    floor = float(np.median(power[ring]))
    if not peak > _MIN_PEAK_PROMINENCE * floor:
        raise ParameterError(
            f"white shows no micro-image lattice: its strongest spectral peak between pitches {min_pitch:.3g} and "
            f"{max_pitch:.3g} px is {peak / max(floor, 1e-300):.3g} times the median power at its frequency "
            f"(a lattice gives over {_MIN_PEAK_PROMINENCE:.0f})"
        )
    k1 = _refined_peak(power, (int(first[0]), int(first[1])))
    maxima = (power == ndimage.maximum_filter(power, size=3, mode="wrap")) & band & (power > 0.05 * peak)
    vv, uu = np.nonzero(maxima)
    ks = np.stack([fu[0, uu], fv[vv, 0]], axis=1)
    cosine = np.abs(ks @ k1) / (np.linalg.norm(ks, axis=1) * np.linalg.norm(k1))
    other = cosine < math.cos(math.radians(20.0))
    if not other.any():
        raise ParameterError(
            "white shows no two-dimensional micro-image lattice: its spectrum has strong peaks in one direction only"
        )
    best = np.argmax(np.where(other, power[vv, uu], -np.inf))
    k2 = _refined_peak(power, (vv[best], uu[best]))
    ratio = np.linalg.norm(k2) / np.linalg.norm(k1)
    angle = math.degrees(math.acos(min(1.0, abs(k1 @ k2) / (np.linalg.norm(k1) * np.linalg.norm(k2)))))
    kinds = [g for g, a in _GRID_ANGLE_DEG.items() if abs(angle - a) <= _GRID_ANGLE_TOLERANCE_DEG]
    if not kinds or not 1 / 1.1 <= ratio <= 1.1:
        raise ParameterError(
            f"white shows no hexagonal or square micro-image lattice: its two strongest spectral directions "
            f"are {angle:.1f} deg apart (60 hex, 90 square) with lengths in the ratio {ratio:.3f} (1 expected)"
        )
    found = kinds[0]
    if grid is not None and grid != found:
        raise ParameterError(
            f"grid={grid!r} but white shows a {found} lattice (spectral directions {angle:.1f} deg apart)"
        )
    basis = _canonical_basis(np.linalg.inv(np.stack([k1, k2], axis=1)).T, found)
    pitch = float(np.linalg.norm(basis[:, 0]))
    if not min_pitch <= pitch <= max_pitch:
        raise ParameterError(f"white's micro-image pitch {pitch:.3g} px is outside [{min_pitch:.3g}, {max_pitch:.3g}]")
    return found, basis


def _refined_peak(power: np.ndarray, at: tuple[int, int]) -> np.ndarray:
    """Sub-bin frequency ``(f_u, f_v)`` (cycles per pixel) of a spectral peak: a parabola through
    the log power at the peak and its two neighbours along each axis (wrapping)."""
    h, w = power.shape
    v, u = int(at[0]), int(at[1])
    log = np.log(np.maximum(power, np.finfo(np.float64).tiny))

    def offset(lo: float, mid: float, hi: float) -> float:
        curvature = lo - 2.0 * mid + hi
        return 0.0 if curvature >= 0.0 else float(np.clip(0.5 * (lo - hi) / curvature, -0.5, 0.5))

    du = offset(log[v, (u - 1) % w], log[v, u], log[v, (u + 1) % w])
    dv = offset(log[(v - 1) % h, u], log[v, u], log[(v + 1) % h, u])
    su = u - w if u > w // 2 else u
    sv = v - h if v > h // 2 else v
    return np.array([(su + du) / w, (sv + dv) / h])


def _canonical_basis(basis: np.ndarray, grid: GridType) -> np.ndarray:
    """The canonical basis of the lattice spanned by ``basis``: ``a1`` the shortest vector within
    30 deg (hex) or 45 deg (square) of +u, ``a2`` the shortest one 60 or 90 deg further on."""
    mn = np.array([(m, n) for m in range(-2, 3) for n in range(-2, 3) if (m, n) != (0, 0)], dtype=np.float64)
    vectors = mn @ basis.T
    lengths = np.linalg.norm(vectors, axis=1)
    shell = vectors[lengths < 1.2 * lengths.min()]
    expected = 6 if grid == "hex" else 4
    if len(shell) != expected:
        raise ParameterError(
            f"white's lattice is not {grid}: {len(shell)} shortest lattice vectors instead of {expected}"
        )
    angles = np.arctan2(shell[:, 1], shell[:, 0])
    a1 = shell[np.argmin(np.abs(angles))]
    step = math.radians(_GRID_ANGLE_DEG[grid])
    turn = np.angle(np.exp(1j * (angles - math.atan2(a1[1], a1[0]) - step)))
    a2 = shell[np.argmin(np.abs(turn))]
    return np.stack([a1, a2], axis=1)


def _phase_origin(image: np.ndarray, basis: np.ndarray, centre: np.ndarray, reach: float) -> np.ndarray:
    """A lattice point from the phases of the image at the reciprocal basis vectors.

    The micro-images are point-symmetric, so the Fourier coefficient at reciprocal vector ``k_j``
    (``k_j . a_i = delta_ij``) of a region around ``centre`` has phase ``-2 pi k_j . (o - centre)``
    for any lattice point ``o``. The region is tapered (cos^2 of the distance) so that micro-images
    cut by its edge count little.
    """
    height, width = image.shape
    v0, v1 = max(int(centre[1] - reach), 0), min(int(centre[1] + reach) + 1, height)
    u0, u1 = max(int(centre[0] - reach), 0), min(int(centre[0] + reach) + 1, width)
    vv, uu = np.mgrid[v0:v1, u0:u1]
    rel = np.stack([uu - centre[0], vv - centre[1]], axis=-1).astype(np.float64)
    dist = np.linalg.norm(rel, axis=-1)
    taper = np.where(dist < reach, np.cos(0.5 * np.pi * dist / reach) ** 2, 0.0)
    reciprocal = np.linalg.inv(basis)  # rows k_1, k_2
    weighted = taper * image[v0:v1, u0:u1]
    coefficients = np.einsum("hw,hwj->j", weighted, np.exp(-2j * np.pi * (rel @ reciprocal.T)))
    frac = -np.angle(coefficients) / (2.0 * np.pi)
    return centre + basis @ frac


def _centroids(
    image: np.ndarray, start: np.ndarray, radius: float, *, recentre: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Micro-image centroids: windows from ``start`` (N, 2), re-centred until they settle if ``recentre``.

    Micro-images that nearly touch put slivers of the neighbours into a window, which pulls the
    centroid towards the window centre (by 13 % of the offset in the tiny camera, 24 % where the
    discs come within a pixel of each other, two thirds on a white blurred by 2 px); the centroid
    of a point-symmetric micro-image is unbiased only in a window centred on it, so the window
    follows the centroid until it moves less than :data:`_RECENTRE_TOLERANCE_PX` (at most
    :data:`_RECENTRE_MAX_STEPS` steps; only the windows still moving are measured again). Lenses
    whose window leaves the image at any step are not measured.
    """
    centres, flux, inside = _window_centroids(image, start, radius)
    active = np.flatnonzero(np.isfinite(centres[:, 0]))
    for _ in range(_RECENTRE_MAX_STEPS if recentre else 0):
        if len(active) == 0:
            break
        moved, moved_flux, moved_inside = _window_centroids(image, centres[active], radius)
        inside[active] &= moved_inside
        lit = np.isfinite(moved[:, 0])
        step = np.where(lit, np.linalg.norm(moved - centres[active], axis=1), 0.0)
        centres[active[lit]] = moved[lit]
        flux[active] = moved_flux
        active = active[lit & moved_inside & (step >= _RECENTRE_TOLERANCE_PX)]
    centres[~inside] = np.nan
    flux[~inside] = 0.0
    return centres, flux, inside


def _window_centroids(
    image: np.ndarray, centres: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Intensity-weighted centroids in circular windows around ``centres`` (N, 2).

    A pixel's weight is its value times its approximate coverage by the window,
    ``clip(radius + 0.5 - distance, 0, 1)``, so the centroid moves smoothly with the window.

    Returns
    -------
    centroids : (N, 2), NaN where the window leaves the image or holds no light
    flux : (N,), the window's weighted sum (0 where it leaves the image)
    inside : (N,) bool, the window lies on the image
    """
    height, width = image.shape
    n = len(centres)
    half = math.ceil(radius + 0.5)
    dv, du = np.mgrid[-half : half + 1, -half : half + 1]
    offsets = (dv * width + du).ravel()
    du, dv = du.ravel().astype(np.float64), dv.ravel().astype(np.float64)
    base = np.rint(centres).astype(np.int64)
    inside = (
        (base[:, 0] - half >= 0) & (base[:, 0] + half < width) & (base[:, 1] - half >= 0) & (base[:, 1] + half < height)
    )
    flat = image.ravel()
    centroids = np.full((n, 2), np.nan)
    flux = np.zeros(n)
    rows = np.flatnonzero(inside)
    for start in range(0, len(rows), _BLOCK):
        sel = rows[start : start + _BLOCK]
        frac = centres[sel] - base[sel]  # window centre relative to its base pixel
        values = flat[(base[sel, 1] * width + base[sel, 0])[:, None] + offsets]  # (n, K)
        distance = np.sqrt((du - frac[:, :1]) ** 2 + (dv - frac[:, 1:]) ** 2)
        weight = values * np.clip(radius + 0.5 - distance, 0.0, 1.0)
        total = weight.sum(axis=1)
        flux[sel] = total
        lit = total > 0
        moments = np.stack([weight[lit] @ du, weight[lit] @ dv], axis=1)
        centroids[sel[lit]] = base[sel[lit]] + moments / total[lit, None]
    return centroids, flux, inside


def _classify(flux: np.ndarray, inside: np.ndarray, min_relative_flux: float) -> np.ndarray:
    """Status per lens: edge (window off the image), dim (flux below the threshold) or used."""
    status = np.full(len(flux), _EDGE, dtype=np.int8)
    if not inside.any():
        raise ParameterError("white: no micro-image lies wholly on the sensor")
    full = float(np.percentile(flux[inside], 90))
    if not full > 0:
        raise ParameterError("white: the micro-images hold no light")
    status[inside] = np.where(flux[inside] >= min_relative_flux * full, _USED, _DIM)
    status[inside & ~(flux > 0)] = _DIM
    return status


def _robust_fit(
    lattice: _Lattice,
    indices: np.ndarray,
    measured: np.ndarray,
    status: np.ndarray,
    outlier_sigma: float,
    sigma: float | None,
) -> tuple[_Lattice, np.ndarray, float]:
    """Least-squares lattice through the measured centres, rejecting outliers until stable.

    Lenses with status used or outlier are candidates; the returned status marks the rejected ones
    as outliers. The residual scale per axis is ``sigma`` if given, else robust: the median
    residual distance / sqrt(2 ln 2) (the median radius of a 2-D Gaussian in units of its
    per-axis standard deviation). Returns the lattice, the status and the scale used.
    """
    candidates = (status == _USED) | (status == _OUTLIER)
    if candidates.sum() < _MIN_USED:
        raise ParameterError(
            f"white: only {int(candidates.sum())} whole, bright micro-images found; at least {_MIN_USED} are needed"
        )
    inliers = candidates.copy()
    for _ in range(50):
        lattice = _least_squares(lattice, indices[inliers], measured[inliers])
        distance = np.linalg.norm(measured - lattice.centres(indices), axis=1)
        robust = max(float(np.median(distance[inliers])) / math.sqrt(2.0 * math.log(2.0)), _MIN_SIGMA_PX)
        scale = sigma if sigma is not None else robust
        updated = candidates & (distance <= outlier_sigma * scale)
        if updated.sum() < _MIN_USED:
            raise ParameterError(
                f"white: only {int(updated.sum())} micro-images agree with a common lattice; at least {_MIN_USED} "
                "are needed"
            )
        if np.array_equal(updated, inliers):
            break
        inliers = updated
    out = status.copy()
    out[candidates] = np.where(inliers[candidates], _USED, _OUTLIER)
    return lattice, out, scale


def _least_squares(lattice: _Lattice, indices: np.ndarray, points: np.ndarray) -> _Lattice:
    """Linear least squares of origin and basis (regular: pitch and rotation) to ``points`` (N, 2)."""
    idx = indices.astype(np.float64)
    n = len(idx)
    if lattice.model == "affine":
        design = np.column_stack([np.ones(n), idx])
        coef, *_ = np.linalg.lstsq(design, points, rcond=None)  # (3, 2): origin row, then B^T rows
        return dataclasses.replace(lattice, origin=coef[0], basis=coef[1:].T.copy())
    # c = o + [[a, -b], [b, a]] @ U @ (i, j): linear in (o_u, o_v, a, b).
    unit = _UNIT_BASIS[lattice.grid]
    m = idx @ unit.T
    design = np.zeros((2 * n, 4))
    design[:n, 0] = 1.0
    design[:n, 2] = m[:, 0]
    design[:n, 3] = -m[:, 1]
    design[n:, 1] = 1.0
    design[n:, 2] = m[:, 1]
    design[n:, 3] = m[:, 0]
    coef, *_ = np.linalg.lstsq(design, np.concatenate([points[:, 0], points[:, 1]]), rcond=None)
    ou, ov, a, b = coef
    return dataclasses.replace(lattice, origin=np.array([ou, ov]), basis=np.array([[a, -b], [b, a]]) @ unit)
