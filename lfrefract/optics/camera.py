"""The physical light-field (plenoptic 1.0) camera model and its captured rays.

Frames and units (see ``docs/conventions.md``):

* **Camera frame**: OpenCV's, metres. Origin at the main-lens centre, +x right, +y down,
  +z forward into the scene. The main lens is the plane z = 0, the microlens array (MLA)
  the plane z = -f', the sensor the plane z = -(f' + f_mla).
* **Image-plane coordinates** ``(xi, eta)``, metres, used for everything behind the main lens
  (MLA and sensor). They are the camera-frame x, y rotated by 180 degrees:
  ``xi = -x``, ``eta = -y``. The real image behind a lens is inverted, so in these
  coordinates the raw image is upright: a scene point up and to the left lands up and to the
  left in the raw image.
* **Raw pixels** ``(u, v)`` = (column, row), pixel centres at integers, as in OpenCV:
  ``xi = (u - (W - 1) / 2) * pixel_pitch``, ``eta = (v - (H - 1) / 2) * pixel_pitch``.

The microlens lattice is defined in image-plane coordinates on the MLA plane:
``centre(i, j) = offset + R(rotation) @ (i * a1 + j * a2)`` with ``a1 = pitch * (1, 0)`` and
``a2 = pitch * (1/2, sqrt(3)/2)`` (hexagonal, horizontal rows) or ``pitch * (0, 1)`` (square).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.validate import (
    as_points,
    finite_float,
    finite_vector,
    non_negative_float,
    one_of,
    positive_float,
    positive_int,
    reject_unknown_keys,
    require_keys,
)

__all__ = [
    "CAMERA_RANGES",
    "GRID_TYPES",
    "MAX_IMAGE_SIDE_PX",
    "MAX_SENSOR_PIXELS",
    "CapturedRays",
    "LightFieldCamera",
    "MicrolensArray",
    "SensorGeometry",
    "micro_image_scale",
]

GRID_TYPES = ("hex", "square")
GridType = Literal["hex", "square"]

_SQRT3 = math.sqrt(3.0)

# Points per block of MicroLensArray.nearest_indices: its (n, 4, 2) temporaries stay near 16 MB, in
# cache, where one pass over an Illum sensor's 41 M pixels took 19 s against 8 s in blocks.
_NEAREST_CHUNK = 1 << 18

#: Largest width or height, pixels, of a sensor or an image (:class:`SensorGeometry`,
#: :class:`lfrefract.optics.pinhole.PinholeCamera`): 65536, the practical limit of image files and of
#: OpenCV (whose remap and PNG paths take sizes below 2^15-2^16), and 8.5 times the Illum's 7728.
#: It refuses typing errors (a 200000 x 200000 image) at once rather than after minutes of work.
MAX_IMAGE_SIDE_PX = 65536

#: Most pixels of a sensor: a warp map stores raw pixel indices as int32.
MAX_SENSOR_PIXELS = 2**31 - 1


#: Physical ranges of a camera's parameters, metres unless named otherwise: (low, high, why). Beyond
#: them a value is a typing error (a focal length of 1e300 m), not a camera; they also keep every
#: product the models form finite.
CAMERA_RANGES: dict[str, tuple[float, float, str]] = {
    "focal_length_m": (1e-4, 10.0, "a 0.1 mm micro-objective to a 10 m telescope"),
    "lens_to_mla_m": (1e-4, 10.0, "as the focal length"),
    "f_number": (0.5, 128.0, "f/0.5 is the limit of a lens in air; none is slower than f/128"),
    "mla.pitch_m": (1e-6, 1e-2, "a microlens of 1 um (two wavelengths) to 10 mm"),
    "mla.focal_length_m": (1e-6, 1e-1, "as the pitch, at f-numbers from 1 to 10"),
    "mla.rotation_rad": (-2.0 * math.pi, 2.0 * math.pi, "a whole turn either way"),
    "mla.offset_m": (-1.0, 1.0, "each coordinate: larger than any sensor"),
    "sensor.pixel_pitch_m": (1e-7, 1e-3, "0.1 um (below the diffraction limit) to 1 mm"),
}


def in_camera_range(name: str, value: object) -> float:
    """``value`` as a float, or raise unless it is finite and inside :data:`CAMERA_RANGES` ``[name]``."""
    low, high, why = CAMERA_RANGES[name]
    out = positive_float(name, value) if low > 0 else finite_float(name, value)
    if not low <= out <= high:
        raise ParameterError(f"{name} must lie in [{low:g}, {high:g}] ({why}), got {value!r}")
    return out


def image_side_px(name: str, value: object) -> int:
    """``value`` as an int, or raise unless it is an integer in [1, :data:`MAX_IMAGE_SIDE_PX`]."""
    out = positive_int(name, value)
    if out > MAX_IMAGE_SIDE_PX:
        raise ParameterError(f"{name} must be at most {MAX_IMAGE_SIDE_PX} px, got {value!r}")
    return out


def micro_image_scale(lens_to_mla_m: float, mla_focal_length_m: float) -> float:
    """Micro-image centre over microlens centre, image plane: ``(f' + f_mla) / f'``.

    A micro-image centre is the image of the main-lens centre (the exit pupil; the stop is at the
    thin lens) through the microlens centre, projected onto the sensor ``f_mla`` behind the MLA,
    which lies ``f'`` behind the main lens (metres both); so it lies this factor further from the
    axis than the microlens centre.
    """
    return (lens_to_mla_m + mla_focal_length_m) / lens_to_mla_m


@dataclass(frozen=True, kw_only=True)
class MicrolensArray:
    """A regular array of identical thin microlenses, filling its lattice cells.

    Parameters
    ----------
    grid : {"hex", "square"}
        Lattice type. ``"hex"`` has horizontal rows (Lytro).
    pitch_m : float
        Distance between neighbouring lens centres, metres.
    focal_length_m : float
        Focal length of every microlens, metres. The sensor lies at this distance behind the MLA.
    rotation_rad : float
        Rotation of the lattice in the image plane, radians, counter-clockwise from +xi
        towards +eta.
    offset_m : tuple of float
        Image-plane position ``(xi, eta)`` of lens (0, 0), metres.
    """

    grid: GridType
    pitch_m: float
    focal_length_m: float
    rotation_rad: float = 0.0
    offset_m: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        one_of("mla.grid", self.grid, GRID_TYPES)
        in_camera_range("mla.pitch_m", self.pitch_m)
        in_camera_range("mla.focal_length_m", self.focal_length_m)
        in_camera_range("mla.rotation_rad", self.rotation_rad)
        offset = finite_vector("mla.offset_m", self.offset_m, 2)
        for value in offset:
            in_camera_range("mla.offset_m", value)
        object.__setattr__(self, "offset_m", offset)

    @property
    def f_number(self) -> float:
        """Microlens f-number: focal length over pitch."""
        return self.focal_length_m / self.pitch_m

    @property
    def basis_m(self) -> np.ndarray:
        """Lattice basis, shape (2, 2): columns are ``a1`` and ``a2`` in image-plane metres."""
        c, s = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        rot = np.array([[c, -s], [s, c]])
        unrotated = np.array([[1.0, 0.5], [0.0, _SQRT3 / 2.0]]) if self.grid == "hex" else np.eye(2)
        return self.pitch_m * rot @ unrotated

    @property
    def cell_area_m2(self) -> float:
        """Area of one lattice cell (the aperture of one microlens), square metres."""
        return abs(float(np.linalg.det(self.basis_m)))

    def centres_m(self, indices: np.ndarray) -> np.ndarray:
        """Image-plane centres of lenses, shape (N, 2), metres, for integer ``indices`` (N, 2)."""
        idx = np.asarray(indices, dtype=np.float64).reshape(-1, 2)
        return np.asarray(self.offset_m) + idx @ self.basis_m.T

    def nearest_indices(self, points_m: np.ndarray) -> np.ndarray:
        """Lattice index (N, 2) of the lens centre nearest to each image-plane point (N, 2).

        The nearest point of both lattices is a corner of the lattice parallelogram that
        contains the point (for the hexagonal lattice the parallelogram is two equilateral
        Delaunay triangles), so four candidates are compared.
        """
        pts = np.asarray(points_m, dtype=np.float64).reshape(-1, 2)
        corners = np.array([(0, 0), (1, 0), (0, 1), (1, 1)], dtype=np.float64)
        corners_m = corners @ self.basis_m.T
        best = np.empty(pts.shape, dtype=np.int64)
        for lo in range(0, len(pts), _NEAREST_CHUNK):  # blocks of points, each vectorized
            block = pts[lo : lo + _NEAREST_CHUNK]
            frac = np.linalg.solve(self.basis_m, (block - np.asarray(self.offset_m)).T).T
            base = np.floor(frac)
            # Squared distance from the point to each corner of its parallelogram (n, 4); argmin
            # keeps the first corner on ties.
            residual = (frac - base) @ self.basis_m.T
            d2 = np.sum((residual[:, None, :] - corners_m[None]) ** 2, axis=2)
            best[lo : lo + _NEAREST_CHUNK] = base + corners[np.argmin(d2, axis=1)]
        return best

    def cell_offsets_m(self, samples: np.ndarray) -> np.ndarray:
        """Map unit-square samples (N, 2) uniformly onto one lens aperture (its lattice cell).

        Returns image-plane offsets from the lens centre, shape (N, 2), metres. The square cell
        maps ``(0.5, 0.5)`` to the centre. The hexagonal cell (a regular hexagon with vertices
        at distance ``pitch / sqrt(3)``, pointing along +-eta) is split into three rhombi that
        share the centre: ``3 * s0`` picks the rhombus and its fraction and ``s1`` the second
        coordinate, so ``(0, 0)`` maps to the centre.
        """
        s = np.asarray(samples, dtype=np.float64).reshape(-1, 2)
        c, sn = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        rot = np.array([[c, -sn], [sn, c]])
        if self.grid == "square":
            local = (s - 0.5) * self.pitch_m
        else:
            scaled = 3.0 * s[:, 0]
            k = np.minimum(np.floor(scaled), 2.0)
            a = scaled - k
            b = s[:, 1]
            radius = self.pitch_m / _SQRT3
            ang0 = np.pi / 6.0 + k * (2.0 * np.pi / 3.0)
            ang1 = ang0 + 2.0 * np.pi / 3.0
            local = radius * (
                a[:, None] * np.stack([np.cos(ang0), np.sin(ang0)], axis=1)
                + b[:, None] * np.stack([np.cos(ang1), np.sin(ang1)], axis=1)
            )
        return local @ rot.T


@dataclass(frozen=True, kw_only=True)
class SensorGeometry:
    """The image sensor: a grid of square pixels.

    Parameters
    ----------
    width_px, height_px : int
        Number of pixel columns and rows, each at most :data:`MAX_IMAGE_SIDE_PX`, and at most
        :data:`MAX_SENSOR_PIXELS` in all.
    pixel_pitch_m : float
        Pixel size (square pixels), metres.
    """

    width_px: int
    height_px: int
    pixel_pitch_m: float

    def __post_init__(self) -> None:
        image_side_px("sensor.width_px", self.width_px)
        image_side_px("sensor.height_px", self.height_px)
        if self.width_px * self.height_px > MAX_SENSOR_PIXELS:
            raise ParameterError(
                f"sensor.width_px x sensor.height_px must be at most {MAX_SENSOR_PIXELS} pixels (int32 raw indices), "
                f"got {self.width_px} x {self.height_px}"
            )
        in_camera_range("sensor.pixel_pitch_m", self.pixel_pitch_m)

    @property
    def size_m(self) -> tuple[float, float]:
        """Physical width and height of the pixel area, metres."""
        return (self.width_px * self.pixel_pitch_m, self.height_px * self.pixel_pitch_m)

    @property
    def centre_px(self) -> tuple[float, float]:
        """Pixel coordinates ``(u, v)`` of the sensor centre (the optical axis)."""
        return ((self.width_px - 1) / 2.0, (self.height_px - 1) / 2.0)

    def pixels_to_image_plane(self, uv: np.ndarray) -> np.ndarray:
        """Raw pixel coordinates (N, 2) to image-plane coordinates (N, 2), metres."""
        return (np.asarray(uv, dtype=np.float64) - np.asarray(self.centre_px)) * self.pixel_pitch_m

    def image_plane_to_pixels(self, points_m: np.ndarray) -> np.ndarray:
        """Image-plane coordinates (N, 2), metres, to raw pixel coordinates (N, 2)."""
        return np.asarray(points_m, dtype=np.float64) / self.pixel_pitch_m + np.asarray(self.centre_px)


@dataclass(frozen=True)
class CapturedRays:
    """Rays in the air in front of the main lens, camera frame.

    Attributes
    ----------
    origins_cam : ndarray, shape (N, 3)
        Where each ray leaves the main lens (z = 0), metres.
    directions_cam : ndarray, shape (N, 3)
        Unit directions (+z component > 0).
    in_aperture : ndarray of bool, shape (N,)
        False where the ray is blocked by the main-lens aperture (vignetted). Such rays are
        still returned so callers can see them; they carry no light.
    lens_indices : ndarray of int, shape (N, 2)
        Lattice index of the microlens each ray passes through.
    """

    origins_cam: np.ndarray
    directions_cam: np.ndarray
    in_aperture: np.ndarray
    lens_indices: np.ndarray


@dataclass(frozen=True, kw_only=True)
class LightFieldCamera:
    """A plenoptic 1.0 camera: thin main lens, microlens array, sensor (paper section 3.2).

    Parameters
    ----------
    focal_length_m : float
        Main-lens focal length f, metres.
    lens_to_mla_m : float
        Distance f' from the main lens to the MLA, metres (f' = f focuses at infinity).
    f_number : float
        Main-lens f-number N; the circular aperture at the lens has diameter f / N.
    mla : MicrolensArray
        The microlens array, at f' behind the main lens; the sensor is ``mla.focal_length_m``
        behind it.
    sensor : SensorGeometry
        The pixel grid, centred on the optical axis.
    name : str
        A label (the preset name for presets).

    Raises
    ------
    ParameterError
        If a value is non-finite or non-positive, or if the main lens's image-side f-number
        ``f' / (f / N)`` is below the microlens f-number: micro-images would then overlap
        (cross-talk), which this plenoptic 1.0 model does not represent.
    """

    focal_length_m: float
    lens_to_mla_m: float
    f_number: float
    mla: MicrolensArray
    sensor: SensorGeometry
    name: str = field(default="custom")

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise ParameterError(f"name must be a string, got {self.name!r}")
        in_camera_range("focal_length_m", self.focal_length_m)
        in_camera_range("lens_to_mla_m", self.lens_to_mla_m)
        in_camera_range("f_number", self.f_number)
        if not isinstance(self.mla, MicrolensArray):
            raise ParameterError(f"mla must be a MicrolensArray, got {self.mla!r}")
        if not isinstance(self.sensor, SensorGeometry):
            raise ParameterError(f"sensor must be a SensorGeometry, got {self.sensor!r}")
        image_side = self.image_side_f_number
        if image_side < self.mla.f_number * (1.0 - 1e-9):
            raise ParameterError(
                f"f_number={self.f_number!r} gives an image-side f-number {image_side:.4g} below the "
                f"microlens f-number {self.mla.f_number:.4g}: micro-images would overlap"
            )

    # ----------------------------------------------------------------- derived optics
    @property
    def aperture_radius_m(self) -> float:
        """Radius of the main-lens aperture, metres."""
        return self.focal_length_m / (2.0 * self.f_number)

    @property
    def image_side_f_number(self) -> float:
        """``f' / aperture diameter``: the cone angle of light arriving at the MLA."""
        return self.lens_to_mla_m / (2.0 * self.aperture_radius_m)

    @property
    def mla_z_m(self) -> float:
        """Camera-frame z of the MLA plane (negative: behind the lens)."""
        return -self.lens_to_mla_m

    @property
    def sensor_z_m(self) -> float:
        """Camera-frame z of the sensor plane."""
        return -(self.lens_to_mla_m + self.mla.focal_length_m)

    @property
    def micro_image_scale(self) -> float:
        """Micro-image centre over lens centre, image plane: :func:`micro_image_scale` of f', f_mla."""
        return micro_image_scale(self.lens_to_mla_m, self.mla.focal_length_m)

    @property
    def micro_image_pitch_px(self) -> float:
        """Distance between neighbouring micro-image centres, pixels."""
        return self.mla.pitch_m * self.micro_image_scale / self.sensor.pixel_pitch_m

    @property
    def micro_image_radius_px(self) -> float:
        """Radius of a micro-image (the aperture's image through a microlens), pixels."""
        return self.aperture_radius_m * self.mla.focal_length_m / self.lens_to_mla_m / self.sensor.pixel_pitch_m

    def usable_aperture_radius_m(self, rim_margin_px: float) -> float:
        """Radius on the main lens inside which a pixel's chief ray keeps ``rim_margin_px`` pixels
        from its micro-image's rim, metres (one sensor pixel spans ``pitch * f' / f_mla`` on the main
        lens): pixels nearer the rim are partly vignetted.

        Raises
        ------
        ParameterError
            If the margin is negative or leaves no usable aperture.
        """
        non_negative_float("rim_margin_px", rim_margin_px)
        margin_m = rim_margin_px * self.sensor.pixel_pitch_m * self.lens_to_mla_m / self.mla.focal_length_m
        if margin_m >= self.aperture_radius_m:
            raise ParameterError(
                f"rim_margin_px={rim_margin_px!r} leaves no usable aperture (micro-image radius "
                f"{self.micro_image_radius_px:.3g} px)"
            )
        return self.aperture_radius_m - margin_m

    # ----------------------------------------------------------------- lenses
    def lens_indices_for_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Lattice index (N, 2) of the microlens whose micro-image contains each pixel (N, 2).

        A sensor point belongs to the lens whose micro-image centre is nearest; micro-image
        centres form the lens lattice scaled by :attr:`micro_image_scale` about the axis.
        """
        pts = self.sensor.pixels_to_image_plane(as_points("uv", uv, 2))
        return self.mla.nearest_indices(pts / self.micro_image_scale)

    def lens_indices_on_sensor(self, *, micro_image_scale: float | None = None) -> np.ndarray:
        """Every lens whose micro-image centre lies on the sensor, lattice indices (M, 2).

        Rows are sorted by (j, i), i.e. row by row. ``micro_image_scale``: the micro-image centres'
        distance from the axis over the lens centres' (default :attr:`micro_image_scale`, the thin
        lens's; a real main lens has its own, about its exit pupil:
        :attr:`lfrefract.optics.real_lens.RealLensCamera.micro_image_scale`).
        """
        scale = (
            self.micro_image_scale
            if micro_image_scale is None
            else positive_float("micro_image_scale", micro_image_scale)
        )
        half_w, half_h = (s / 2.0 for s in self.sensor.size_m)
        corners = np.array([[-half_w, -half_h], [half_w, -half_h], [-half_w, half_h], [half_w, half_h]])
        frac = np.linalg.solve(self.mla.basis_m, (corners / scale - np.asarray(self.mla.offset_m)).T).T
        lo = np.floor(frac.min(axis=0)) - 1
        hi = np.ceil(frac.max(axis=0)) + 1
        ii, jj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="xy")
        idx = np.stack([ii.ravel(), jj.ravel()], axis=1)
        centres = self.mla.centres_m(idx) * scale
        # A centre counts as on the sensor when it lies within the outermost pixel centres.
        pitch = self.sensor.pixel_pitch_m
        inside = (np.abs(centres[:, 0]) <= half_w - pitch / 2) & (np.abs(centres[:, 1]) <= half_h - pitch / 2)
        return idx[inside].astype(np.int64)

    def micro_image_centres_px(self, indices: np.ndarray) -> np.ndarray:
        """Raw-pixel coordinates (N, 2) of the micro-image centres of lenses ``indices`` (N, 2)."""
        return self.sensor.image_plane_to_pixels(self.mla.centres_m(indices) * self.micro_image_scale)

    # ----------------------------------------------------------------- rays
    def paths_leaving_mla(
        self, uv: np.ndarray, *, lens_offsets_m: np.ndarray | None = None, micro_image_scale: float | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Light paths from raw-pixel positions as they leave their microlens, before the main lens.

        A path starts at sensor point ``uv``, passes the microlens whose micro-image holds it (the
        micro-image centres being the lens centres times ``micro_image_scale``, default
        :attr:`micro_image_scale`; a real lens's is about its exit pupil) at image-plane offset
        ``lens_offsets_m`` from that lens's centre, and leaves it parallel to the lens's chief ray
        from that sensor point (the sensor is at the microlenses' focal plane).

        Parameters
        ----------
        uv : array_like, shape (N, 2)
            Raw pixel coordinates (column, row), pixel centres at integers.
        lens_offsets_m : array_like, shape (N, 2), optional
            Image-plane offsets from the lens centre where each path crosses the MLA, metres.
            Default: zero (the chief ray of the microlens).
        micro_image_scale : float, optional
            Micro-image centre over lens centre, for assigning pixels to microlenses.

        Returns
        -------
        through_xy : ndarray, shape (N, 2)
            Camera-frame (x, y) where each path crosses the MLA plane (z = :attr:`mla_z_m`), metres.
        slope_xy : ndarray, shape (N, 2)
            Its direction's (dx/dz, dy/dz) in the camera frame, towards +z.
        lens_indices : ndarray of int, shape (N, 2)
            Lattice index of each path's microlens.
        """
        uv_arr = as_points("uv", uv, 2)
        n = uv_arr.shape[0]
        offsets = np.zeros((n, 2)) if lens_offsets_m is None else as_points("lens_offsets_m", lens_offsets_m, 2)
        if offsets.shape[0] != n:
            raise ParameterError(f"lens_offsets_m must have one row per uv row ({n}), got {offsets.shape[0]} rows")
        scale = self.micro_image_scale if micro_image_scale is None else micro_image_scale
        sensor_img = self.sensor.pixels_to_image_plane(uv_arr)
        idx = self.mla.nearest_indices(sensor_img / scale)
        centre_img = self.mla.centres_m(idx)
        # Image-plane quantities -> camera frame: x = -xi, y = -eta; after the microlens every path
        # from this sensor point is parallel to its chief ray.
        slope_xy = (sensor_img - centre_img) / self.mla.focal_length_m
        return -(centre_img + offsets), slope_xy, idx

    def rays_through_lenses(self, uv: np.ndarray, *, lens_offsets_m: np.ndarray | None = None) -> CapturedRays:
        """Trace light paths from raw-pixel positions out through the optics into the air.

        Each path starts at sensor point ``uv`` (continuous pixel coordinates), passes the
        microlens whose micro-image contains it at image-plane offset ``lens_offsets_m`` from
        that lens's centre, is bent by the thin microlens (the sensor is at its focal plane, so
        every path from one sensor point leaves the microlens parallel to the chief ray), travels
        to the main lens, and is bent by the thin main lens.

        Parameters
        ----------
        uv : array_like, shape (N, 2)
            Raw pixel coordinates (column, row), pixel centres at integers.
        lens_offsets_m : array_like, shape (N, 2), optional
            Image-plane offsets from the lens centre where each path crosses the MLA, metres.
            Default: zero (the chief ray of the microlens).

        Returns
        -------
        CapturedRays
            Rays in the camera frame leaving the main lens.
        """
        through_xy, slope_in, idx = self.paths_leaving_mla(uv, lens_offsets_m=lens_offsets_m)
        n = through_xy.shape[0]
        hit_xy = through_xy + slope_in * self.lens_to_mla_m
        in_aperture = np.sum(hit_xy**2, axis=1) <= self.aperture_radius_m**2
        slope_out = slope_in - hit_xy / self.focal_length_m
        directions = np.concatenate([slope_out, np.ones((n, 1))], axis=1)
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        origins = np.concatenate([hit_xy, np.zeros((n, 1))], axis=1)
        return CapturedRays(origins_cam=origins, directions_cam=directions, in_aperture=in_aperture, lens_indices=idx)

    def captured_rays(self, uv: np.ndarray | None = None) -> CapturedRays:
        """The captured-ray model: from each pixel centre through its microlens centre.

        Parameters
        ----------
        uv : array_like, shape (N, 2), optional
            Raw pixel coordinates. Default: every pixel centre, row-major, N = W * H.

        Returns
        -------
        CapturedRays
        """
        if uv is None:
            vv, uu = np.mgrid[0 : self.sensor.height_px, 0 : self.sensor.width_px]
            uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
        return self.rays_through_lenses(uv)

    def to_dict(self) -> dict:
        """Plain-data form (metres, radians) for JSON sidecars."""
        return {
            "name": self.name,
            "focal_length_m": self.focal_length_m,
            "lens_to_mla_m": self.lens_to_mla_m,
            "f_number": self.f_number,
            "mla": {
                "grid": self.mla.grid,
                "pitch_m": self.mla.pitch_m,
                "focal_length_m": self.mla.focal_length_m,
                "rotation_rad": self.mla.rotation_rad,
                "offset_m": list(self.mla.offset_m),
            },
            "sensor": {
                "width_px": self.sensor.width_px,
                "height_px": self.sensor.height_px,
                "pixel_pitch_m": self.sensor.pixel_pitch_m,
            },
        }

    @classmethod
    def from_dict(cls, data: dict) -> LightFieldCamera:
        """Inverse of :meth:`to_dict`.

        Raises
        ------
        ParameterError
            If ``data`` or its ``mla`` or ``sensor`` is not a dict, a key is missing or unknown, or
            a value has the wrong type or an impossible value; the message names the key.
        """
        if not isinstance(data, dict):
            raise ParameterError(f"camera must be a table (a JSON object) of camera parameters, got {data!r}")
        data = dict(data)
        reject_unknown_keys("camera", data, {"name", "focal_length_m", "lens_to_mla_m", "f_number", "mla", "sensor"})
        require_keys("camera", data, {"focal_length_m", "lens_to_mla_m", "f_number", "mla", "sensor"})
        mla, sensor = data.pop("mla"), data.pop("sensor")
        for key, table in (("mla", mla), ("sensor", sensor)):
            if not isinstance(table, dict):
                raise ParameterError(f"camera.{key} must be a table (a JSON object), got {table!r}")
        reject_unknown_keys("camera.mla", mla, {"grid", "pitch_m", "focal_length_m", "rotation_rad", "offset_m"})
        require_keys("camera.mla", mla, {"grid", "pitch_m", "focal_length_m"})
        reject_unknown_keys("camera.sensor", sensor, {"width_px", "height_px", "pixel_pitch_m"})
        require_keys("camera.sensor", sensor, {"width_px", "height_px", "pixel_pitch_m"})
        return cls(mla=MicrolensArray(**mla), sensor=SensorGeometry(**sensor), **data)
