"""Depth-aware refraction-free synthesis: exact wherever the scene point is seen, given its depth.

The warp map (:mod:`lfrefract.synthesis.warp_map`) is exact where the camera recorded each output
pixel's *necessary ray*, the ray through the main-lens centre: a cone about the port normal. A
scene point outside that cone is still seen, by rays through other parts of the aperture; once its
depth is known, the rays that see it are known, and its pixel can be as exact as one inside the
cone. This module finds the depth from the light field itself and renders each pixel from the rays
that see its point.

Method (camera frame, metres; output pixels of a pinhole ``K`` centred at the main-lens centre)
-------------------------------------------------------------------------------------------------
1. *Rays in the water* (:func:`trace_scene_rays`, once per camera and port): every raw pixel whose
   chief ray (pixel -> microlens centre -> main lens) passes the usable aperture is traced out
   through the port into the water (:meth:`FlatPort.trace_from_air`); its value is divided by the
   port's radiometric factor along it (Fresnel transmittance times ``(n_air / n_water)^2``), so
   every ray carries radiance in the water. Without a port the rays go on straight: the same
   estimator *without refraction handling*, for comparison.
2. *Plane sweep* (:func:`estimate_depth`): for each of ``depth_steps`` planes ``Z = z_j``, uniform
   in ``1 / z`` between ``depth_min_m`` and ``depth_max_m``, every ray is intersected with the plane
   and binned into the output pixel whose line of sight holds the crossing. The rays in a pixel's
   bin at ``z_j`` are the recorded rays that see the hypothesised point ``z_j K^-1 (u, v, 1)``
   (within the pixel): at the true depth they agree, elsewhere they see different points. The
   cost (:func:`~lfrefract.synthesis._depth_kernels.sweep_cost`) compares every ray with the
   plane's *refocused image* (each pixel's rays fitted by a plane in their landing offsets, read at
   the pixel centre, interpolated at the ray's landing point), plus the residual of each pixel's
   own fit: both vanish at the true depth for a texture smooth within a pixel, wherever in the
   pixel the rays land. *Occlusion-aware* (an option), a pixel may take the rays of one aperture
   half instead of the whole aperture's where they agree markedly better, since an occluder in
   front of a point hides it from part of the aperture only.
3. *Aggregation and refinement*: the costs are averaged over a ``(2 r + 1)^2`` window of output
   pixels (box filter; each pixel's say bounded, see :func:`_aggregate`), the least cost wins, and
   a parabola through it and its two neighbours refines the plane index below one step (in
   ``1 / z``). The *confidence* is ``1 - c_min / c_rival``, ``c_rival`` the best cost at least
   planes at least :data:`CONFIDENCE_GAP_PX` of parallax across the aperture's radius away: near 0
   where another depth fits about as well (no texture), near 1 where one depth stands out.
4. *Render given depth* (:func:`render_given_depth`): each ray goes to the first pixel, near to far,
   at whose estimated depth it lands in that pixel; the pixel's value is its rays' plane fit at the
   pixel centre. A pixel rendered so from at least ``min_rays`` rays is *exact given depth*: every
   ray in it saw its scene point, to within the pixel and the depth's error.
5. *Composition* (:class:`DepthAwareSynthesis`): pixels inside the warp map's exact coverage keep
   the warp map's value (exact at any depth); outside it, the depth-aware value where there is one
   and the depth's confidence reaches ``min_confidence`` (class :data:`FILLED_EXACT_GIVEN_DEPTH`),
   else the warp map's nearby rays (approximated) or no value.

How well the depth can be found is the light field's own parallax: a depth error ``dz`` at depth
``z`` moves the ray through aperture point ``a`` by ``f_px |a| dz / z^2`` output pixels. Between
the aperture's edges, from 0.2 m to infinity, that is 1.6 px on the tiny preset (f = 120 px,
aperture 2.7 mm) and 3.3 px on tiny-2x: such cameras tell depths apart coarsely, and need not do
better for the image, since a depth error costs it that same shift averaged over the aperture
(docs/synthesis.md gives the measured figures).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field

import numba
import numpy as np
from scipy import ndimage

from lfrefract.errors import ParameterError
from lfrefract.optics.camera import LightFieldCamera
from lfrefract.optics.camera_model import CameraModel, as_camera_model
from lfrefract.optics.pinhole import PinholeCamera, virtual_camera_for
from lfrefract.optics.port import FlatPort
from lfrefract.optics.ray_correction import Correction, correction_from_dict
from lfrefract.synthesis._depth_kernels import render_at_depth, sweep_cost
from lfrefract.synthesis.empty import masked_reason, require_a_value
from lfrefract.synthesis.warp_map import (
    FILLED_APPROXIMATED,
    FILLED_EMPTY,
    FILLED_EXACT,
    SynthesisOptions,
    WarpMap,
    build_warp_map,
)
from lfrefract.validate import bounded_float, non_negative_float, positive_float, positive_int

__all__ = [
    "FILLED_EXACT_GIVEN_DEPTH",
    "DepthAwareOptions",
    "DepthAwareResult",
    "DepthAwareSynthesis",
    "DepthEstimate",
    "SceneRays",
    "SearchImage",
    "depth_planes_m",
    "estimate_depth",
    "render_given_depth",
    "trace_scene_rays",
]

#: Class of :attr:`DepthAwareResult.classes` beside :data:`FILLED_EMPTY`, :data:`FILLED_APPROXIMATED`
#: and :data:`FILLED_EXACT`: outside the warp map's exact coverage, rendered from recorded rays that
#: see the pixel's scene point at its estimated depth.
FILLED_EXACT_GIVEN_DEPTH = 3

#: How far from the winning depth the rival that :attr:`DepthEstimate.confidence` compares it with
#: lies: this parallax (output pixels) between the lens centre and the usable aperture's rim. In
#: planes it is camera-dependent: 3 on the Illum, 8 on tiny-2x. A fixed 3 planes gave the tiny-2x
#: chessboards' correct depths a median confidence of 0.3-0.4 (their costs 3 planes away hardly
#: differ), 1 px gives 0.8-0.9.
CONFIDENCE_GAP_PX = 1.0

#: Most blocks of rays the render accumulates apart (one per thread up to this; each block holds
#: ``4 (7 + 3 C)`` float64 per output pixel: 0.4 GB at Illum size with RGB).
RENDER_CHUNKS_MAX = 4

#: Below this share of the camera's rays kept (recorded, and lit fully), an image without any depth is
#: blamed on the masks rather than on the depth range.
_FEW_RAYS_SHARE = 0.5

#: Raw pixels traced per block in :func:`trace_scene_rays` (a block's float64 buffers: about 1 kB each).
_TRACE_BLOCK = 1 << 20


@dataclass(frozen=True, eq=False, kw_only=True)
class SearchImage:
    """The image the depth search reads, where it is not the one rendered (:meth:`DepthAwareSynthesis.apply`).

    For a Lytro capture it is the mosaic, not demosaiced
    (:meth:`lfrefract.formats.whites.DevelopedCapture.grey`): the search compares rays with each
    other, and demosaicing mixes each pixel with its neighbours, other rays of the same micro-image
    (a Gaussian blur of 1 px took the median confidence from 0.80 to 0.28).

    Attributes
    ----------
    raw : ndarray, shape (H, W) or (H, W, C)
        The image, the raw images' shape.
    recorded : ndarray of bool, shape (H, W), optional
        Its pixels holding a measurement (default: every pixel): the search and the render both use the
        rays where it and the render's ``recorded`` hold.
    groups : ndarray of int, shape (H, W), optional
        A group per raw pixel whose rays the search compares only with each other (a mosaic's colours:
        :func:`estimate_depth`'s ``groups``); default one group.

    Raises
    ------
    ParameterError
        If ``raw`` is not (H, W) or (H, W, C), or ``recorded`` or ``groups`` has another (H, W) (the
        message names the field and the shapes).

    Examples
    --------
    >>> import numpy as np
    >>> mosaic = np.ones((4, 6))
    >>> SearchImage(raw=mosaic, groups=np.zeros((4, 6), dtype=int)).shape
    (4, 6)
    """

    raw: np.ndarray
    recorded: np.ndarray | None = None
    groups: np.ndarray | None = None

    def __post_init__(self) -> None:
        raw = np.asarray(self.raw)
        if raw.ndim not in (2, 3):
            raise ParameterError(f"raw must be an (H, W) or (H, W, C) image, got shape {raw.shape}")
        object.__setattr__(self, "raw", raw)
        for name, kind in (("recorded", bool), ("groups", np.int64)):
            value = getattr(self, name)
            if value is None:
                continue
            array = np.asarray(value)
            if array.shape != raw.shape[:2]:
                raise ParameterError(f"{name} must have the image's shape {raw.shape[:2]}, got {array.shape}")
            object.__setattr__(self, name, array.astype(kind, copy=False))

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the image."""
        return self.raw.shape[:2]


@dataclass(frozen=True, kw_only=True)
class DepthAwareOptions:
    """Options of the depth search and the render given depth.

    Parameters
    ----------
    depth_min_m, depth_max_m : float
        Nearest and farthest depth searched, camera-frame z, metres (``0 < min < max``). Planes in
        front of the port's water face along a line of sight get no rays there.
    depth_steps : int
        Depth planes, uniform in ``1 / z`` (at least 3, for the sub-step parabola).
    aggregation_radius_px : int
        Half-size of the square window of output pixels over which costs are averaged (0: none).
        The window must reach texture from every pixel: on tiny-2x chessboards of 9 px squares the
        share of board pixels more than 5 % off in depth was 54-82 % with 2, 12-50 % with 4 and
        6-42 % with 6 (the default), the corners 0.80 / 0.21 / 0.18 px RMS. A larger window
        spreads a depth edge further (about r pixels at an occlusion).
    min_rays : int
        Fewest rays a pixel's subset needs, at a depth plane and in the render.
    min_confidence : float
        Least :attr:`DepthEstimate.confidence` of a pixel rendered as exact given depth, in [0, 1];
        below it the warp map's value stands (approximated). Where rays are few, at the edge of
        what the camera sees in the water, the depth can be wrong and the value with it: on the
        Illum behind the reference port (a closed-form plane at 0.5 m) the RMS error of those
        pixels was 0.103 (values 0.1-0.9) with 0, 0.056 with 0.5 and 0.004 with 0.9, every pixel
        of the field's interior kept; on tiny-2x chessboards, whose corners' confidence is lower
        (less parallax), 0.7 already handed corner pixels back to the warp map (corners 0.142 ->
        0.196 px RMS) and 0.5 changed nothing. Textureless pixels have a low confidence whatever
        their depth; the warp map's nearby rays render them about as well.
    occlusion_aware : bool
        Score and render with the most consistent of the whole aperture and its halves (True; a half
        must do markedly better, :data:`~lfrefract.synthesis._depth_kernels.HALF_RATIO`) or the
        whole aperture only (the default). Measured at an occluding edge (a half-plane at 0.3 m
        before a plane at 0.6 m) on tiny-2x and the Illum and on tiny-2x chessboards, the halves
        changed no figure beyond noise (the aggregation window, not the rays' subset, decides the
        depth within a few pixels of an edge) and doubled the time (docs/synthesis.md).
    rim_margin_px : float
        Raw pixels within this many pixels of their micro-image's rim are not used (partly
        vignetted; as :attr:`SynthesisOptions.rim_margin_px`).
    compensate_port : bool
        Divide each ray's value by the port's radiometric factor along it, so values are radiance
        in the water (as :attr:`SynthesisOptions.compensate_port`).
    """

    depth_min_m: float = 0.1
    depth_max_m: float = 3.0
    depth_steps: int = 48
    aggregation_radius_px: int = 6
    min_rays: int = 4
    min_confidence: float = 0.5
    occlusion_aware: bool = False
    rim_margin_px: float = 0.71
    compensate_port: bool = True

    def __post_init__(self) -> None:
        positive_float("depth_min_m", self.depth_min_m)
        positive_float("depth_max_m", self.depth_max_m)
        if not self.depth_max_m > self.depth_min_m:
            raise ParameterError(
                f"depth_max_m must exceed depth_min_m, got depth_min_m={self.depth_min_m!r}, "
                f"depth_max_m={self.depth_max_m!r}"
            )
        if positive_int("depth_steps", self.depth_steps) < 3:
            raise ParameterError(f"depth_steps must be at least 3 (the sub-step parabola), got {self.depth_steps!r}")
        if isinstance(self.aggregation_radius_px, bool) or not isinstance(self.aggregation_radius_px, int):
            raise ParameterError(f"aggregation_radius_px must be an integer, got {self.aggregation_radius_px!r}")
        if self.aggregation_radius_px < 0:
            raise ParameterError(f"aggregation_radius_px must be non-negative, got {self.aggregation_radius_px!r}")
        positive_int("min_rays", self.min_rays)
        for name in ("occlusion_aware", "compensate_port"):
            if not isinstance(getattr(self, name), bool):
                raise ParameterError(f"{name} must be True or False, got {getattr(self, name)!r}")
        non_negative_float("rim_margin_px", self.rim_margin_px)
        bounded_float("min_confidence", self.min_confidence, 0.0, 1.0)

    def to_dict(self) -> dict:
        """Plain data for sidecars."""
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


def render_chunks() -> int:
    """Blocks of rays the render accumulates apart: the threads, at most :data:`RENDER_CHUNKS_MAX`."""
    return max(1, min(numba.get_num_threads(), RENDER_CHUNKS_MAX))


def sweep_planes_per_call() -> int:
    """Depth planes :func:`estimate_depth` sweeps in one call of the kernel: one per thread
    (:func:`numba.get_num_threads`), so that signals are handled between calls."""
    return max(1, numba.get_num_threads())


def _depth_range(options: DepthAwareOptions) -> str:
    """The options' depth range as a message names it, with its command-line option."""
    return f"depth_min_m={options.depth_min_m!r}, depth_max_m={options.depth_max_m!r} (--depth-range)"


def depth_planes_m(options: DepthAwareOptions) -> np.ndarray:
    """The depth planes searched, camera-frame z, metres, near to far, uniform in ``1 / z``, shape (D,)."""
    inverse = np.linspace(1.0 / options.depth_min_m, 1.0 / options.depth_max_m, options.depth_steps)
    return 1.0 / inverse


@dataclass(frozen=True, eq=False)
class SceneRays:
    """The captured rays of a camera as they travel in the water (or the air, without a port).

    Attributes
    ----------
    origins_cam : ndarray, float32, shape (N, 3)
        Where each ray leaves the port's water-side face (without a port: the main-lens plane),
        camera frame, metres.
    directions_cam : ndarray, float32, shape (N, 3)
        Unit directions into the scene (``z > 0``), camera frame.
    raw_index : ndarray, int64, shape (N,)
        Row-major index of the ray's raw pixel.
    quadrant : ndarray, int8, shape (N,)
        Main-lens aperture quadrant the ray passes: ``(x > 0) + 2 (y > 0)``.
    gain : ndarray, float32, shape (N,)
        Factor from the raw value to radiance in the water (1 without a port or compensation).
    raw_shape : (int, int)
        ``(height, width)`` of the raw images.
    refracted : bool
        Whether the rays were traced through a port.
    aperture_radius_m : float
        The usable main-lens radius the rays were chosen within, metres.
    """

    origins_cam: np.ndarray
    directions_cam: np.ndarray
    raw_index: np.ndarray
    quadrant: np.ndarray
    gain: np.ndarray
    raw_shape: tuple[int, int]
    refracted: bool
    aperture_radius_m: float

    def kept(self, keep: np.ndarray | None) -> SceneRays:
        """These rays where ``keep`` (bool, shape (N,)) holds; themselves if it holds everywhere or is None."""
        if keep is None or bool(np.all(keep)):
            return self
        return dataclasses.replace(
            self,
            origins_cam=self.origins_cam[keep],
            directions_cam=self.directions_cam[keep],
            raw_index=self.raw_index[keep],
            quadrant=self.quadrant[keep],
            gain=self.gain[keep],
        )

    def values(self, raw: np.ndarray, *, recorded: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The rays' values in ``raw`` and which rays hold one.

        Parameters
        ----------
        raw : ndarray, shape (H, W) or (H, W, C)
            Raw lenslet image of :attr:`raw_shape`, float or integer, finite where used.
        recorded : ndarray of bool, shape (H, W), optional
            Raw pixels that hold a measurement (saturated or flagged pixels False); default all.

        Returns
        -------
        values : ndarray, float32, shape (M, C)
            Radiance in the water along each kept ray.
        keep : ndarray of bool, shape (N,)
            Rays kept (their raw pixel recorded).

        Raises
        ------
        ParameterError
            If ``raw`` or ``recorded`` has the wrong shape or type, or a used value is not finite.
        """
        arr = np.asarray(raw)
        if arr.shape[:2] != tuple(self.raw_shape) or arr.ndim not in (2, 3):
            raise ParameterError(f"raw must have shape {tuple(self.raw_shape)} (+ channels), got {arr.shape}")
        if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
            raise ParameterError(f"raw must be a real image, got dtype {arr.dtype}")
        flat = arr.reshape(arr.shape[0] * arr.shape[1], -1)
        keep = np.ones(len(self.raw_index), dtype=bool)
        if recorded is not None:
            mask = np.asarray(recorded)
            if mask.shape != tuple(self.raw_shape) or mask.dtype != bool:
                raise ParameterError(
                    f"recorded must be a bool array of shape {tuple(self.raw_shape)}, got {mask.shape}"
                )
            keep = mask.reshape(-1)[self.raw_index]
        values = flat[self.raw_index[keep]].astype(np.float32) * self.gain[keep, None]
        if not np.all(np.isfinite(values)):
            bad = int(np.count_nonzero(~np.all(np.isfinite(values), axis=1)))
            raise ParameterError(f"raw holds {bad} non-finite values at pixels the synthesis uses")
        return values, keep


def warp_correction(warp: WarpMap) -> Correction | None:
    """The ray model a warp map was built on (its metadata's ``options.ray_correction``; None: the
    thin lens): the depth-aware rays must be that model's too."""
    recorded = warp.meta.get("options", {}).get("ray_correction")
    return None if recorded is None else correction_from_dict(recorded, where="warp map options.ray_correction")


def trace_scene_rays(
    camera: LightFieldCamera | CameraModel,
    port: FlatPort | None,
    *,
    rim_margin_px: float = 0.71,
    compensate_port: bool = True,
) -> SceneRays:
    """Trace every usable captured ray of ``camera`` into the water behind ``port``.

    Parameters
    ----------
    camera : LightFieldCamera or CameraModel
        A thin-lens light-field camera (its captured-ray model: pixel -> microlens centre -> main
        lens), or a camera model with its calibrated ray model
        (:func:`lfrefract.calibration.calibrate_camera`): each pixel's ray is then its thin-lens ray
        corrected (which pixels are usable is still decided on the thin-lens aperture point, as the
        warp map does).
    port : FlatPort or None
        The port; None continues the rays straight (the estimator without refraction handling).
    rim_margin_px : float
        Raw pixels whose chief ray passes outside ``camera.usable_aperture_radius_m(rim_margin_px)``
        are left out.
    compensate_port : bool
        Fold the port's radiometric factor into :attr:`SceneRays.gain`.

    Returns
    -------
    SceneRays
        Rays lost to the port (total internal reflection, grazing) are left out.
    """
    model = as_camera_model(camera)
    camera, correction = model.camera, model.correction
    if port is not None and not isinstance(port, FlatPort):
        raise ParameterError(f"port must be a FlatPort or None, got {port!r}")
    radius = camera.usable_aperture_radius_m(rim_margin_px)
    height, width = camera.sensor.height_px, camera.sensor.width_px
    parts: list[tuple[np.ndarray, ...]] = []
    for first in range(0, height * width, _TRACE_BLOCK):
        index = np.arange(first, min(first + _TRACE_BLOCK, height * width), dtype=np.int64)
        uv = np.stack([index % width, index // width], axis=1).astype(np.float64)
        rays = camera.captured_rays(uv)
        keep = np.sum(rays.origins_cam[:, :2] ** 2, axis=1) <= radius**2
        origins, directions, index = rays.origins_cam[keep], rays.directions_cam[keep], index[keep]
        if correction is not None:  # only the rays kept: the model costs per ray
            origins, directions = correction.apply(origins[:, :2], directions[:, :2] / directions[:, 2:3])
            passed = np.all(np.isfinite(directions), axis=1)  # a traced lens stops some (NaN)
            origins, directions, index = origins[passed], directions[passed], index[passed]
        gain = np.ones(len(index))
        if port is not None:
            trace = port.trace_from_air(origins, directions)
            ok = trace.valid
            if compensate_port:
                gain = 1.0 / np.where(ok, trace.transmittance * port.radiance_scale, 1.0)
            origins_water, directions_water = trace.exit_points_cam, trace.directions_cam
            quadrant = (origins[:, 0] > 0).astype(np.int8) + 2 * (origins[:, 1] > 0).astype(np.int8)
            origins, directions, index, gain, quadrant = (
                origins_water[ok],
                directions_water[ok],
                index[ok],
                gain[ok],
                quadrant[ok],
            )
        else:
            quadrant = (origins[:, 0] > 0).astype(np.int8) + 2 * (origins[:, 1] > 0).astype(np.int8)
        parts.append((origins, directions, index, quadrant, gain))
    origins, directions, index, quadrant, gain = (np.concatenate(column) for column in zip(*parts, strict=True))
    return SceneRays(
        origins_cam=origins.astype(np.float32),
        directions_cam=directions.astype(np.float32),
        raw_index=index,
        quadrant=quadrant.astype(np.int8),
        gain=gain.astype(np.float32),
        raw_shape=(height, width),
        refracted=port is not None,
        aperture_radius_m=radius,
    )


@dataclass(frozen=True, eq=False)
class DepthEstimate:
    """Depth of every output pixel from one light field (:func:`estimate_depth`).

    Attributes
    ----------
    depth_m : ndarray, float32, shape (H, W)
        Camera-frame z of the surface seen through each pixel, metres; NaN where no depth plane
        had ``min_rays`` rays.
    confidence : ndarray, float32, shape (H, W)
        ``1 - c_min / c_rival`` of the pixel's aggregated costs, in [0, 1], where ``c_rival`` is the
        least cost at planes a parallax of at least :data:`CONFIDENCE_GAP_PX` (across the aperture's
        radius) from the winner: near 0 where another
        depth fits about as well (no texture, repeated texture), near 1 where one depth stands out;
        NaN where no depth.
    plane_index : ndarray, int64, shape (H, W)
        The winning plane (before the sub-step refinement); -1 where no depth.
    depths_m : ndarray, shape (D,)
        The planes searched.
    """

    depth_m: np.ndarray
    confidence: np.ndarray
    plane_index: np.ndarray
    depths_m: np.ndarray


def _intrinsics(output: PinholeCamera) -> tuple[float, float, float, int, int]:
    if not isinstance(output, PinholeCamera):
        raise ParameterError(f"output must be a PinholeCamera, got {output!r}")
    return output.focal_px, output.cx_px, output.cy_px, output.width_px, output.height_px


def _aggregate(cost: np.ndarray, radius: int) -> np.ndarray:
    """Mean of the costs over a (2 r + 1)^2 window per plane, each pixel's say bounded.

    A pixel without a cost at some plane (too few rays there) counts there with its own worst cost,
    so that a plane is not made cheap by the pixels it leaves out; pixels without any cost are left
    out of the mean. A pixel whose mean cost over the planes exceeds the image's median one is
    scaled down to it: the curves of pixels that mix two surfaces (at an occluding edge every depth
    costs much there) would otherwise outweigh their neighbours' and pull them to a depth between
    (on a 0.3 m / 0.6 m edge: to 1.2 m, 10 px into the background); the pixels with less texture keep
    their small say. NaN where the window has no pixel with a cost.
    """
    valid = np.isfinite(cost)
    seen = np.any(valid, axis=0)
    worst = np.max(np.where(valid, cost, -np.inf), axis=0)
    cost = np.where(valid, cost, np.where(seen, worst, np.nan)[None]).astype(np.float32)
    scale = np.mean(np.where(seen[None], cost, 0.0), axis=0)
    positive = scale[seen & (scale > 0)]
    if positive.size:
        cost = cost / np.maximum(scale, float(np.median(positive)))[None]
    if radius == 0:
        return cost
    size = (1, 2 * radius + 1, 2 * radius + 1)
    total = ndimage.uniform_filter(np.where(seen, cost, 0.0).astype(np.float32), size=size, mode="constant")
    count = ndimage.uniform_filter(seen.astype(np.float32), size=(2 * radius + 1, 2 * radius + 1), mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count[None] > 0.5 / (2 * radius + 1) ** 2, total / count[None], np.nan).astype(np.float32)


def estimate_depth(
    rays: SceneRays,
    values: np.ndarray,
    output: PinholeCamera,
    options: DepthAwareOptions,
    *,
    keep: np.ndarray | None = None,
    groups: np.ndarray | None = None,
) -> DepthEstimate:
    """Depth per output pixel by a refraction-aware plane sweep over the light field's rays.

    Parameters
    ----------
    rays : SceneRays
        From :func:`trace_scene_rays` (through the port; without one for the comparison).
    values : ndarray, float32, shape (M, C)
        The kept rays' values (:meth:`SceneRays.values`).
    output : PinholeCamera
        Geometry of the depth map (centre of projection at the main-lens centre).
    options : DepthAwareOptions
    keep : ndarray of bool, shape (N,), optional
        Which of ``rays`` the ``values`` belong to (default: all).
    groups : ndarray of int, shape (M,), optional
        A group per kept ray (e.g. its colour on a mosaic's sites, each colour relative to its own
        bright level): rays are compared only within their group, and a plane's cost at a pixel is the
        mean of its groups' (default: one group).

    Returns
    -------
    DepthEstimate
    """
    fx, cx, cy, width, height = _intrinsics(output)
    origins, directions, quadrant = _kept(rays, keep, values)
    if groups is None:
        groups = np.zeros(len(origins), dtype=np.int64)
    groups = np.asarray(groups)
    if groups.shape != (len(origins),) or not np.issubdtype(groups.dtype, np.integer):
        raise ParameterError(f"groups must be integers of shape ({len(origins)},), got {groups.dtype} {groups.shape}")
    depths = depth_planes_m(options)
    total = np.zeros((len(depths), height, width), dtype=np.float32)
    counted = np.zeros((len(depths), height, width), dtype=np.float32)
    # Each plane is swept alone, so sweeping the planes in groups gives the same costs bit for bit; a group
    # of one plane per thread keeps the threads busy, and between groups Python runs its signal handlers
    # (SIGTERM, Ctrl-C: one call over every plane held them for the whole sweep, 39 s an Illum frame).
    per_call = sweep_planes_per_call()
    every = np.unique(groups)
    for group in every:
        if len(every) == 1:  # one group: the kept rays as they are, not copied
            o, d, v, q = origins, directions, values, quadrant
        else:
            member = groups == group
            o, d, v, q = (np.ascontiguousarray(a[member]) for a in (origins, directions, values, quadrant))
        for first in range(0, len(depths), per_call):
            part = sweep_cost(
                o, d, v, q, depths[first : first + per_call], fx, cx, cy, width, height,
                options.min_rays, options.occlusion_aware,
            )  # fmt: skip
            seen = np.isfinite(part)
            total[first : first + per_call] += np.where(seen, part, 0.0)
            counted[first : first + per_call] += seen
    with np.errstate(invalid="ignore", divide="ignore"):
        cost = np.where(counted > 0, total / counted, np.nan).astype(np.float32)
    cost = _aggregate(cost, options.aggregation_radius_px)
    has = np.any(np.isfinite(cost), axis=0)
    filled = np.where(np.isfinite(cost), cost, np.inf)
    best = np.argmin(filled, axis=0)
    rows, cols = np.indices(best.shape)
    c0 = filled[best, rows, cols]
    below = filled[np.maximum(best - 1, 0), rows, cols]
    above = filled[np.minimum(best + 1, len(depths) - 1), rows, cols]
    inner = (best > 0) & (best < len(depths) - 1) & np.isfinite(below) & np.isfinite(above)
    with np.errstate(invalid="ignore", divide="ignore"):
        curvature = below - 2.0 * c0 + above
        step = np.where(inner & (curvature > 0), 0.5 * (below - above) / curvature, 0.0)
    step = np.clip(np.nan_to_num(step), -0.5, 0.5)
    inverse = np.interp(best + step, np.arange(len(depths)), 1.0 / depths)
    # Confidence: how far the winner stands below the best rival, a parallax of at least
    # CONFIDENCE_GAP_PX away across the aperture's radius.
    gap = math.ceil(CONFIDENCE_GAP_PX / (fx * rays.aperture_radius_m * abs(1 / depths[0] - 1 / depths[1])))
    planes = np.arange(len(depths))[:, None, None]
    rival = np.min(np.where(np.abs(planes - best[None]) >= gap, filled, np.inf), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        confidence = np.where(np.isfinite(rival) & (rival > 0), 1.0 - c0 / rival, 0.0)
    confidence = np.clip(confidence, 0.0, 1.0)
    return DepthEstimate(
        depth_m=np.where(has, 1.0 / inverse, np.nan).astype(np.float32),
        confidence=np.where(has, confidence, np.nan).astype(np.float32),
        plane_index=np.where(has, best, -1).astype(np.int64),
        depths_m=depths,
    )


def _kept(rays: SceneRays, keep: np.ndarray | None, values: np.ndarray) -> tuple[np.ndarray, ...]:
    if not isinstance(rays, SceneRays):
        raise ParameterError(f"rays must be SceneRays, got {rays!r}")
    rays = rays.kept(keep)
    origins, directions, quadrant = rays.origins_cam, rays.directions_cam, rays.quadrant
    if values.ndim != 2 or values.shape[0] != origins.shape[0]:
        raise ParameterError(f"values must have shape ({origins.shape[0]}, C), got {values.shape}")
    return origins, directions, quadrant


def render_given_depth(
    rays: SceneRays,
    values: np.ndarray,
    output: PinholeCamera,
    depth_m: np.ndarray,
    options: DepthAwareOptions,
    *,
    keep: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Each output pixel rendered from the rays that see its scene point at depth ``depth_m``.

    Parameters
    ----------
    rays, values, output, options, keep
        As :func:`estimate_depth`.
    depth_m : ndarray, shape (output.height_px, output.width_px)
        Camera-frame z of each pixel's scene point, metres; NaN for none. Depths outside
        ``[depth_min_m, depth_max_m]`` get no rays.

    Returns
    -------
    image : ndarray, float32, shape (H, W, C)
        Mean radiance of the most consistent subset of the rays that see the point; NaN where fewer
        than ``options.min_rays``.
    rays_used : ndarray, int32, shape (H, W)
        Rays averaged per pixel.
    """
    fx, cx, cy, width, height = _intrinsics(output)
    depth = np.asarray(depth_m, dtype=np.float64)
    if depth.shape != (height, width):
        raise ParameterError(f"depth_m must have shape ({height}, {width}), got {depth.shape}")
    origins, directions, quadrant = _kept(rays, keep, values)
    depths = depth_planes_m(options)
    inside = np.isfinite(depth) & (depth >= depths[0]) & (depth <= depths[-1])
    plane_of = np.where(
        inside, np.clip(np.searchsorted(depths, np.where(inside, depth, 0.0)) - 1, 0, len(depths) - 2), -1
    )
    return render_at_depth(
        origins, directions, values, quadrant, depths, np.where(inside, depth, np.nan), plane_of.astype(np.int64),
        fx, cx, cy, options.min_rays, options.occlusion_aware, render_chunks(),
    )  # fmt: skip


@dataclass(frozen=True, eq=False)
class DepthAwareResult:
    """One frame of the depth-aware synthesis (:meth:`DepthAwareSynthesis.apply`).

    Attributes
    ----------
    image : ndarray, float32, shape (H, W) or (H, W, C)
        The refraction-free image; NaN where no value (class :data:`FILLED_EMPTY`).
    depth : DepthEstimate
        The depth found in the light field (every pixel, inside the exact coverage too).
    classes : ndarray, uint8, shape (H, W)
        :data:`FILLED_EMPTY`, :data:`FILLED_APPROXIMATED`, :data:`FILLED_EXACT` (the warp map's
        exact coverage) or :data:`FILLED_EXACT_GIVEN_DEPTH`.
    rays_used : ndarray, int32, shape (H, W)
        Rays averaged by the render given depth (0 where it had none).
    """

    image: np.ndarray
    depth: DepthEstimate
    classes: np.ndarray
    rays_used: np.ndarray

    @property
    def coverage(self) -> dict[str, float]:
        """Shares of the output pixels: ``exact_fraction``, ``exact_given_depth_fraction``,
        ``approximated_fraction``, ``filled_fraction``."""
        return {
            "exact_fraction": float(np.mean(self.classes == FILLED_EXACT)),
            "exact_given_depth_fraction": float(np.mean(self.classes == FILLED_EXACT_GIVEN_DEPTH)),
            "approximated_fraction": float(np.mean(self.classes == FILLED_APPROXIMATED)),
            "filled_fraction": float(np.mean(self.classes != FILLED_EMPTY)),
        }


@dataclass(frozen=True, eq=False)
class DepthAwareSynthesis:
    """The depth-aware synthesis of one camera behind one port, built once, applied per frame.

    Attributes
    ----------
    warp : WarpMap
        The paper's synthesis (:func:`build_warp_map`): its exact coverage and, outside what the
        depth-aware render fills, its approximated pixels.
    rays : SceneRays
        The camera's captured rays in the water behind the warp map's port.
    options : DepthAwareOptions
    """

    warp: WarpMap
    rays: SceneRays
    options: DepthAwareOptions = field(default_factory=DepthAwareOptions)

    def __post_init__(self) -> None:
        if not isinstance(self.warp, WarpMap):
            raise ParameterError(f"warp must be a WarpMap, got {self.warp!r}")
        if not isinstance(self.rays, SceneRays) or not self.rays.refracted:
            raise ParameterError(f"rays must be SceneRays traced through the port, got {self.rays!r}")
        if tuple(self.rays.raw_shape) != tuple(self.warp.raw_shape):
            raise ParameterError(
                f"the rays are of {tuple(self.rays.raw_shape)} raw images, the warp map of {tuple(self.warp.raw_shape)}"
            )
        if not isinstance(self.options, DepthAwareOptions):
            raise ParameterError(f"options must be DepthAwareOptions, got {self.options!r}")
        nearest = float(np.min(self.rays.origins_cam[:, 2])) if len(self.rays.origins_cam) else math.inf
        if self.options.depth_max_m <= nearest:
            raise ParameterError(
                f"{_depth_range(self.options)} lies in front of the water, where no ray is: the rays leave the "
                f"port's water face at z = {nearest:.4g} m and beyond; choose the depths of the scene behind the port"
            )

    @classmethod
    def build(
        cls,
        camera: LightFieldCamera,
        port: FlatPort,
        *,
        output: PinholeCamera | None = None,
        options: DepthAwareOptions | None = None,
        synthesis: SynthesisOptions | None = None,
        warp: WarpMap | None = None,
        progress: bool = False,
    ) -> DepthAwareSynthesis:
        """Trace the camera's rays behind ``port`` and build (or take) the warp map.

        Parameters
        ----------
        camera : LightFieldCamera
        port : FlatPort
        output : PinholeCamera, optional
            Output geometry; default :func:`virtual_camera_for` ``(camera)`` (or ``warp``'s).
        options : DepthAwareOptions, optional
        synthesis : SynthesisOptions, optional
            The warp map's options (when it is built here).
        warp : WarpMap, optional
            A prebuilt warp map of this camera and port (refused if its metadata names others).
        progress : bool
            Show the warp map build's progress.
        """
        if not isinstance(port, FlatPort):
            raise ParameterError(f"port must be a FlatPort, got {port!r}")
        options = DepthAwareOptions() if options is None else options
        if not isinstance(options, DepthAwareOptions):
            raise ParameterError(f"options must be DepthAwareOptions, got {options!r}")
        if warp is None:
            warp = build_warp_map(
                camera,
                port,
                output=output if output is not None else virtual_camera_for(camera),
                options=synthesis,
                progress=progress,
            )
        else:
            if output is not None and output != warp.output:
                raise ParameterError(f"output {output!r} differs from the warp map's {warp.output!r}")
            for what, given in (("camera", camera.to_dict()), ("port", port.to_dict())):
                if json.dumps(warp.meta.get(what), sort_keys=True) != json.dumps(given, sort_keys=True):
                    raise ParameterError(f"the warp map was built for another {what} than the one given")
        rays = trace_scene_rays(
            CameraModel(camera=camera, correction=warp_correction(warp)),
            port,
            rim_margin_px=options.rim_margin_px,
            compensate_port=options.compensate_port,
        )
        return cls(warp=warp, rays=rays, options=options)

    @property
    def output(self) -> PinholeCamera:
        """Geometry of the images and depth maps."""
        return self.warp.output

    def apply(
        self,
        raw: np.ndarray,
        *,
        recorded: np.ndarray | None = None,
        search: SearchImage | None = None,
    ) -> DepthAwareResult:
        """Depth, then the refraction-free image of one raw frame.

        Parameters
        ----------
        raw : ndarray, shape (H, W) or (H, W, C)
            Raw lenslet image.
        recorded : ndarray of bool, shape (H, W), optional
            Raw pixels holding a measurement whose ray is the camera model's; the others are used by
            neither the depth search nor the render (the warp map's pixels are the caller's to mask:
            :func:`lfrefract.formats.capture.mask_warp_map`). A developed Lytro capture's partly
            vignetted pixels belong out (:attr:`lfrefract.formats.capture.Capture.ray_recorded`;
            :func:`lfrefract.formats.capture.apply_depth_aware` passes it): a real
            lens's micro-images are smaller than the thin lens's usable disc, and the rim pixels' light
            passes the aperture elsewhere (through the double Gauss at tiny-2x, 30 % of the rays; with
            them the depth search's median confidence on a plane was 0.20, without them 0.72, the
            thin-lens render's 0.82).
        search : SearchImage, optional
            The image the depth search reads instead of ``raw`` (the render reads ``raw``), with its
            recorded pixels and the groups of rays it compares; default ``raw``, one group.

        Returns
        -------
        DepthAwareResult

        Raises
        ------
        ParameterError
            For a raw image of another shape, and for an image with no value anywhere: every ray masked as
            unrecorded (named before the depth search), or no pixel finding a depth in the range.
        """
        if search is not None and not isinstance(search, SearchImage):
            raise ParameterError(f"search must be a SearchImage or None, got {type(search).__name__}")
        if search is not None and search.shape != tuple(self.rays.raw_shape):
            raise ParameterError(
                f"search must have the raw images' shape {tuple(self.rays.raw_shape)}, got {search.shape}"
            )
        if search is not None and search.recorded is not None:
            recorded = search.recorded if recorded is None else np.asarray(recorded) & search.recorded
        values, keep = self.rays.values(raw, recorded=recorded)
        searched = values if search is None else self.rays.values(search.raw, recorded=recorded)[0]
        unrecorded = 0 if recorded is None else int(np.size(recorded) - np.count_nonzero(recorded))

        def why() -> str:
            if unrecorded:
                return masked_reason(unrecorded, self.rays.raw_shape[0] * self.rays.raw_shape[1])
            return "no captured ray of the camera reaches the water through the port, or none gave a pixel a value"

        require_a_value(keep, what="the depth-aware image", because=why)  # before the sweep: it would blame the depths
        rays = self.rays.kept(keep)  # once for the sweep and the render
        groups = None if search is None or search.groups is None else search.groups.reshape(-1)[rays.raw_index]
        depth = estimate_depth(rays, searched, self.output, self.options, groups=groups)
        if not np.any(np.isfinite(depth.depth_m)):
            used_share = np.count_nonzero(keep) / max(len(keep), 1)
            if used_share < _FEW_RAYS_SHARE:  # the masks, not the depths, left too few rays
                raise ParameterError(
                    f"no output pixel has a depth: only {100 * used_share:.0f} % of the camera's rays hold a recorded "
                    f"value whose ray is the model's ({unrecorded} raw pixels masked as unrecorded or lit only in "
                    "part: for a Lytro capture, a white image that lights few pixels fully, a lens whose micro-images "
                    f"are much smaller than the camera model's), too few for min_rays={self.options.min_rays} at any "
                    "pixel"
                )
            raise ParameterError(
                f"no output pixel has a depth: no plane of {_depth_range(self.options)} gathered "
                f"min_rays={self.options.min_rays} rays for any pixel; choose the depths of the scene behind the port"
            )
        rendered, used = render_given_depth(rays, values, self.output, depth.depth_m, self.options)
        grey = np.ndim(raw) == 2
        if self.warp.indptr[-1] > 0:
            classic = self.warp.apply(raw)
        else:  # every row masked (WarpMap.apply refuses it): the depth-aware pixels may still have values
            shape = (self.output.height_px, self.output.width_px)
            classic = np.zeros(shape if grey else (*shape, values.shape[1]), dtype=np.float32)
        classes = self.warp.filled_classes.astype(np.uint8)
        given = (
            (classes != FILLED_EXACT)
            & (used >= self.options.min_rays)
            & (depth.confidence >= self.options.min_confidence)
        )
        image = np.where(given if grey else given[..., None], rendered[..., 0] if grey else rendered, classic)
        classes[given] = FILLED_EXACT_GIVEN_DEPTH
        image = image.astype(np.float32, copy=False)
        image[classes == FILLED_EMPTY] = math.nan
        require_a_value(classes != FILLED_EMPTY, what="the depth-aware image", because=why)
        return DepthAwareResult(image=image, depth=depth, classes=classes, rays_used=used)
