"""The virtual pinhole camera of refraction-free images, and its default for a light-field camera."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import MAX_IMAGE_SIDE_PX, LightFieldCamera, image_side_px
from lfrefract.validate import as_points, finite_float, positive_float, reject_unknown_keys, require_keys

__all__ = [
    "DEFAULT_PIXELS_PER_LENS",
    "MAX_FOCAL_PX",
    "MAX_IMAGE_SIDE_PX",
    "MAX_PRINCIPAL_POINT_PX",
    "PinholeCamera",
    "virtual_camera_for",
]

#: Output pixels per microlens pitch of the default refraction-free image. Two, because the
#: paper's super-sampling (s = 2) selects sub-lens rays: objects away from the plane conjugate to
#: the MLA are sampled more densely than once per lens.
DEFAULT_PIXELS_PER_LENS = 2.0


#: Largest focal length, pixels: a 65536 px image 0.4 deg across (a telescope); more is a typing error.
MAX_FOCAL_PX = 1e7
#: Largest principal-point coordinate, pixels: ten of the largest image sides off the image.
MAX_PRINCIPAL_POINT_PX = 10 * MAX_IMAGE_SIDE_PX


@dataclass(frozen=True, kw_only=True)
class PinholeCamera:
    """A central-projection camera with square pixels, OpenCV conventions.

    Parameters
    ----------
    focal_px : float
        Focal length, pixels (fx = fy).
    cx_px, cy_px : float
        Principal point, pixels; pixel centres are at integers.
    width_px, height_px : int
        Image size, each at most :data:`MAX_IMAGE_SIDE_PX` (65536) pixels.

    Raises
    ------
    ParameterError
        If a value is not finite, the focal length not positive, or a size not an integer in
        [1, :data:`MAX_IMAGE_SIDE_PX`].
    """

    focal_px: float
    cx_px: float
    cy_px: float
    width_px: int
    height_px: int

    def __post_init__(self) -> None:
        if positive_float("focal_px", self.focal_px) > MAX_FOCAL_PX:
            raise ParameterError(f"focal_px must be at most {MAX_FOCAL_PX:g} px, got {self.focal_px!r}")
        for name in ("cx_px", "cy_px"):
            if abs(finite_float(name, getattr(self, name))) > MAX_PRINCIPAL_POINT_PX:
                raise ParameterError(
                    f"{name} must lie within +-{MAX_PRINCIPAL_POINT_PX} px, got {getattr(self, name)!r}"
                )
        image_side_px("width_px", self.width_px)
        image_side_px("height_px", self.height_px)

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the conventional name
        """Intrinsic matrix (3, 3), OpenCV form."""
        return np.array([[self.focal_px, 0.0, self.cx_px], [0.0, self.focal_px, self.cy_px], [0.0, 0.0, 1.0]])

    @classmethod
    def from_K(cls, K: np.ndarray, width_px: int, height_px: int) -> PinholeCamera:  # noqa: N802, N803
        """Build from an OpenCV intrinsic matrix (3, 3) with square pixels and no skew."""
        try:
            k = np.asarray(K, dtype=np.float64)
        except (TypeError, ValueError):  # strings, ragged rows, tables: not a matrix of numbers
            raise ParameterError(f"K must be a 3 x 3 matrix of numbers, got {K!r}") from None
        if k.shape != (3, 3) or not np.allclose(k[[1, 2, 2, 2], [0, 0, 1, 2]], [0, 0, 0, 1]) or k[0, 1] != 0:
            raise ParameterError(f"K must be an upper-triangular OpenCV intrinsic matrix, got {k.tolist()}")
        if not math.isclose(k[0, 0], k[1, 1], rel_tol=1e-9):
            raise ParameterError(
                f"K must have square pixels (fx == fy), got fx={float(k[0, 0])!r}, fy={float(k[1, 1])!r}"
            )
        return cls(focal_px=k[0, 0], cx_px=k[0, 2], cy_px=k[1, 2], width_px=width_px, height_px=height_px)

    def to_dict(self) -> dict:
        """Plain-data form for JSON sidecars (K row-major, size)."""
        return {"K": self.K.tolist(), "width_px": self.width_px, "height_px": self.height_px}

    @classmethod
    def from_dict(cls, data: dict) -> PinholeCamera:
        """Inverse of :meth:`to_dict`; unknown keys are an error.

        Raises
        ------
        ParameterError
            If ``data`` is not a dict, a key is missing or unknown, or a value is of the wrong type
            or impossible; the message names the key.
        """
        if not isinstance(data, dict):
            raise ParameterError(f"pinhole must be a table (a JSON object) with K, width_px, height_px, got {data!r}")
        reject_unknown_keys("pinhole", data, {"K", "width_px", "height_px"})
        require_keys("pinhole", data, {"K", "width_px", "height_px"})
        return cls.from_K(data["K"], data["width_px"], data["height_px"])

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Project camera-frame points (N, 3) to pixels (N, 2); points with z <= 0 give NaN."""
        p = as_points("points_cam", points_cam, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = self.focal_px * p[:, :2] / p[:, 2:3] + np.array([self.cx_px, self.cy_px])
        uv[p[:, 2] <= 0] = np.nan
        return uv

    def pixel_directions(self, uv: np.ndarray | None = None) -> np.ndarray:
        """Unit viewing directions (N, 3), camera frame, for pixels (N, 2) (default: all, row-major)."""
        if uv is None:
            vv, uu = np.mgrid[0 : self.height_px, 0 : self.width_px]
            uv = np.stack([uu.ravel(), vv.ravel()], axis=1)
        q = as_points("uv", uv, 2)
        d = np.concatenate([(q - np.array([self.cx_px, self.cy_px])) / self.focal_px, np.ones((len(q), 1))], axis=1)
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def virtual_camera_for(camera: LightFieldCamera, *, pixels_per_lens: float = DEFAULT_PIXELS_PER_LENS) -> PinholeCamera:
    """The default refraction-free (and ideal) image geometry for a light-field camera.

    The centre of projection is the main-lens centre. Output pixels are square with
    ``pixels_per_lens`` of them per microlens pitch on the MLA plane, so the focal length is
    ``f' * pixels_per_lens / pitch`` pixels; the image spans the field the microlenses cover
    (the sensor scaled by ``f' / (f' + f_mla)``), with the principal point at its centre. It
    does not depend on the port: the part a port hides is the coverage mask's business.

    Parameters
    ----------
    camera : LightFieldCamera
    pixels_per_lens : float
        Output sampling density, > 0.

    Returns
    -------
    PinholeCamera
    """
    positive_float("pixels_per_lens", pixels_per_lens)
    pixel_m = camera.mla.pitch_m / pixels_per_lens
    width_m, height_m = (s / camera.micro_image_scale for s in camera.sensor.size_m)
    width = math.floor(width_m / pixel_m + 1e-9)
    height = math.floor(height_m / pixel_m + 1e-9)
    return PinholeCamera(
        focal_px=camera.lens_to_mla_m / pixel_m,
        cx_px=(width - 1) / 2.0,
        cy_px=(height - 1) / 2.0,
        width_px=width,
        height_px=height,
    )
