"""Experiment ``fov`` (paper section 6): the field of view of the perfect refraction-free image.

A pixel of the refraction-free image is *exact* when the camera records its necessary ray usably:
for each of its ``s x s`` sub-pixel lines of sight (``s`` = :attr:`SynthesisOptions.supersample`)
the light arriving along it, traced back through the port into the air
(:func:`~lfrefract.synthesis.warp_map.necessary_air_rays`) and continued to the main-lens plane, crosses it
inside the usable aperture (:meth:`LightFieldCamera.usable_aperture_radius_m`, the aperture less
``rim_margin_px``) and, followed through the thin lens, lands on the sensor. This is exactly
:attr:`WarpMap.exact <lfrefract.synthesis.warp_map.WarpMap.exact>` without building the map: the ray trace
and the sensor test do not depend on the f-number, so each pixel gets one *required aperture
radius* (the largest lens-plane radius among its sub-pixel rays; infinite where one of them is
lost to the port or misses the sensor), and the pixel is exact at f-number ``N`` when that radius
is within the usable radius at ``N``. One trace per port serves every f-number.

Measures of a mask of exact pixels (angles in the water, where the refraction-free image is a
pinhole image; all full angles, degrees):

- ``exact_share``: exact pixels over all pixels of the refraction-free image
  (:func:`~lfrefract.optics.pinhole.virtual_camera_for`).
- ``perfect_fov_h_deg`` / ``perfect_fov_v_deg``: the widest run of consecutive exact pixels in
  any one row / column, as the angle between the lines of sight through the outer edges of its
  end pixels (0 without exact pixels).
- ``perfect_cone_centred_deg``: apex angle of the largest cone about the optical axis that
  contains no part of a non-exact pixel and stays inside the image (0 when a pixel at the
  principal point is not exact).
- ``perfect_fov_equiv_deg``: apex angle of the cone with the solid angle of all exact pixels
  (each pixel ``cos^3(theta) / f_px^2`` sr): independent of the region's shape and position, and
  of the pinhole projection's stretching off axis (a region of fixed angular size covers more
  pixels off axis, so ``exact_share`` can rise with tilt while this does not, up to pixel rounding).
- ``original_fov_h_deg`` / ``_v_deg`` / ``_equiv_deg``: the same for the whole image: the field of
  the camera in air (the refraction-free image has the camera's own K), the paper's "original
  field of view".
- ``original_fov_water_h_deg`` / ``_v_deg``: the field the camera sees in the water through the
  port: the lines of sight through the outer edges of the image's centre row / column, refracted
  by the port, and the angle between them.
- ``given_depth_share``: the pixels that the depth-aware synthesis
  (:mod:`lfrefract.synthesis.depth_aware`) can make exact given their depth: those whose scene
  point at :data:`GIVEN_DEPTH_M` the camera records at all, i.e. that some point of the usable
  aperture sees through the port onto the sensor inside the micro-image of its lens
  (:func:`lfrefract.optics.seen_by.pixels_seeing_points` from :data:`SEEN_APERTURE_POINTS` aperture
  points: the centre and a ring at :data:`SEEN_RING` of the usable radius), over every
  :data:`SEEN_STRIDE` -th pixel in each direction (:func:`seen_share`). Exact pixels are among them.

The grid: port tilts about the camera x axis (``tilt_x_deg``, normal turned up) from 0 to 40 deg,
main-lens f-numbers from the preset's upwards (larger ones are always allowed: the image-side
f-number must not fall below the microlenses'); an untilted port at several distances, with the
usable aperture radius and with twice it (``aperture = "doubled"``: the authors' code tests a
necessary ray against a radius of ``f / N``, twice the aperture's ``f / (2 N)``); for scale
``illum`` also the reference port of the authors' code (:func:`reference_port`: 59.2 mm along the
optical axis, 52.9 mm perpendicular, normal proportional to (-0.0085, -0.5004, 1) in the camera
frame, a single air/water interface, water 1.33). The camera, port distance and glass, tilts and
f-numbers can be changed (:class:`~simulator.experiments.ExperimentOptions`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lfrefract import FlatPort, LightFieldCamera, ParameterError, PinholeCamera, camera_preset, virtual_camera_for
from lfrefract.figures import new_figure, pixel_axes, save_figure
from lfrefract.optics.lens import trace_lens
from lfrefract.optics.real_lens import RealLensCamera
from lfrefract.optics.seen_by import pixels_seeing_points
from lfrefract.synthesis.warp_map import SynthesisOptions, lens_plane_hits, mla_points_img, necessary_air_rays
from simulator.experiments import ExperimentOptions, ExperimentResult, check_scale, named_options, register

__all__ = [
    "APERTURES",
    "REFERENCE_AXIAL_DISTANCE_M",
    "REFERENCE_NORMAL",
    "FovSetup",
    "exact_mask",
    "exact_share_figure",
    "fov_measures",
    "masks_figure",
    "original_fov",
    "perfect_fov_figure",
    "reference_port",
    "required_aperture_radius",
    "run",
    "seen_share",
    "setup_for",
]

#: Resolution of the figures, dots per inch.
FIGURE_DPI = 110
#: Necessary rays per block of the trace (memory: about 1 kB per ray).
BLOCK_RAYS = 1 << 18

#: Perfect horizontal field of view quoted by the paper for its Lytro Illum set-up, degrees.
PAPER_PERFECT_FOV_DEG = 30.0
#: Original field of view quoted by the paper for the Lytro Illum, degrees.
PAPER_ORIGINAL_FOV_DEG = 60.0

#: The reference port's normal as the authors' code gives it, camera frame (OpenCV: +y down, so
#: the normal is turned up, 26.6 deg), not normalised.
REFERENCE_NORMAL = (-0.0085, -0.5004, 1.0)
#: The reference port's distance as the authors' code gives it: along the optical axis, metres.
REFERENCE_AXIAL_DISTANCE_M = 0.0592
#: The water index of the authors' code.
REFERENCE_N_WATER = 1.33

#: The apertures a distance row is evaluated with: the usable radius, and twice it.
APERTURES = {"usable": 1.0, "doubled": 2.0}

#: Depth of the scene points whose visibility ``given_depth_share`` counts, camera-frame z, metres.
GIVEN_DEPTH_M = 0.5
#: Aperture points of the visibility test: the centre and a ring of six, at SEEN_RING of the usable
#: radius (a point is recorded if any of them sees it).
SEEN_APERTURE_POINTS = 7
SEEN_RING = 0.7
#: Pixels between those tested, per direction and scale (the share is over the tested ones).
SEEN_STRIDE = {"tiny": 2, "illum": 4}


def reference_port() -> FlatPort:
    """The port of the authors' code: normal :data:`REFERENCE_NORMAL` (normalised), its plane
    :data:`REFERENCE_AXIAL_DISTANCE_M` from the main-lens centre along the optical axis, no glass
    (a single air/water interface), water :data:`REFERENCE_N_WATER`.

    The plane ``n . X = d`` (unit ``n``) meets the optical axis at ``z = d / n_z``, so the
    perpendicular distance that :class:`FlatPort` takes is ``d = z_axis * n_z``:
    59.2 mm x 0.89426 = 52.94 mm.
    """
    normal = np.asarray(REFERENCE_NORMAL) / np.linalg.norm(REFERENCE_NORMAL)
    return FlatPort.from_normal(
        normal, distance_m=REFERENCE_AXIAL_DISTANCE_M * float(normal[2]), thickness_m=0.0, n_water=REFERENCE_N_WATER
    )


@dataclass(frozen=True)
class FovSetup:
    """What one run of the experiment measures.

    Attributes
    ----------
    camera : LightFieldCamera
    distance_m, thickness_m, n_water : float
        The swept port's perpendicular distance and glass (metres) and the water's index.
    tilts_deg : tuple of float
        Tilts about the camera x axis of the tilt series, degrees.
    f_numbers : tuple of float
        Main-lens f-numbers, ascending; the first is the one of the distance series.
    distances_m : tuple of float
        Port distances of the distance series (untilted), metres.
    mask_tilts_deg : tuple of float
        Tilts whose masks are drawn.
    reference_port : FlatPort or None
        The authors' port (scale ``illum``).
    seen_stride : int
        Pixel stride of ``given_depth_share`` (:data:`SEEN_STRIDE`).
    """

    camera: LightFieldCamera
    distance_m: float
    thickness_m: float
    n_water: float
    tilts_deg: tuple[float, ...]
    f_numbers: tuple[float, ...]
    distances_m: tuple[float, ...]
    mask_tilts_deg: tuple[float, ...]
    reference_port: FlatPort | None = None
    seen_stride: int = 1

    def port(self, tilt_x_deg: float, distance_m: float | None = None) -> FlatPort:
        """The swept port, tilted ``tilt_x_deg`` about x, at ``distance_m`` (default :attr:`distance_m`)."""
        return FlatPort.from_degrees(
            distance_m=self.distance_m if distance_m is None else distance_m,
            thickness_m=self.thickness_m,
            tilt_x_deg=tilt_x_deg,
            n_water=self.n_water,
        )

    @property
    def title(self) -> str:
        """Camera, port distance and glass, for figure titles."""
        glass = "no glass" if self.thickness_m == 0 else f"{self.thickness_m * 1e3:g} mm glass"
        return f"{self.camera.name} camera, port {self.distance_m * 1e3:.4g} mm away (perpendicular), {glass}"


def setup_for(scale: str, options: ExperimentOptions | None = None) -> FovSetup:
    """The camera, port and grid of ``scale`` with ``options`` applied.

    ``tiny``: the tiny preset behind the port of the synthesis renders (12 mm, 4 mm glass, water
    1.333). ``illum``: the Illum preset behind an untilted port at the reference port's distance and
    glass (:func:`reference_port`: 52.9 mm, none), tilted about x, plus the reference port itself.
    ``options`` may replace the camera (f-numbers: its own, then the scale's larger ones), the
    port's distance and glass, the tilts and the f-numbers.
    """
    options = options if options is not None else ExperimentOptions(scale=scale)
    tilts = tuple(float(t) for t in np.arange(0.0, 40.0 + 1e-9, 2.5))
    if check_scale(scale) == "tiny":
        camera, distance, thickness, n_water = camera_preset("tiny"), 0.012, 0.004, 1.333
        f_numbers, mask_tilts = (2.2, 2.8, 4.0, 5.6), (0.0, 15.0, 30.0)
        distances = (0.004, 0.006, 0.008, 0.012, 0.016, 0.024, 0.032, 0.048)
        reference = None
    else:
        reference = reference_port()
        camera, distance, thickness, n_water = camera_preset("illum"), reference.distance_m, 0.0, REFERENCE_N_WATER
        f_numbers, mask_tilts = (2.0, 2.8, 4.0, 5.6), (0.0, 10.0, 20.0)
        distances = (0.01, 0.015, 0.02, 0.025, 0.03, 0.04, reference.distance_m, 0.08)
    if options.camera is not None:
        camera = options.camera
        f_numbers = (camera.f_number, *(n for n in f_numbers if n > camera.f_number))
    if options.f_numbers is not None:
        f_numbers = tuple(sorted(options.f_numbers))
    if options.port_distance_m is not None:
        distance = options.port_distance_m
    if options.thickness_m is not None:
        thickness = options.thickness_m
    distances = tuple(sorted({*distances, distance}))
    if options.tilts_deg is not None:
        tilts = tuple(sorted(options.tilts_deg))
        drawn = tuple(t for t in mask_tilts if t in tilts)
        mask_tilts = drawn if drawn else tuple(sorted({tilts[0], tilts[len(tilts) // 2], tilts[-1]}))
    return FovSetup(
        camera=camera,
        distance_m=distance,
        thickness_m=thickness,
        n_water=n_water,
        tilts_deg=tilts,
        f_numbers=f_numbers,
        distances_m=distances,
        mask_tilts_deg=mask_tilts,
        reference_port=reference,
        seen_stride=SEEN_STRIDE[scale],
    )


# ----------------------------------------------------------------------------- the exact mask
def _necessary_ray_blocks(port: FlatPort, output: PinholeCamera, supersample: int):
    """Blocks of output rows ``r0:r1`` with the necessary air rays of their ``s x s`` sub-pixel lines of
    sight (pixel-major, as build_warp_map: rows, columns, sub-rows, sub-columns): ``(r0, r1, points,
    dirs, valid)`` of :func:`~lfrefract.synthesis.warp_map.necessary_air_rays`."""
    s = supersample
    offsets = (np.arange(s) + 0.5) / s - 0.5
    rows = max(1, BLOCK_RAYS // (output.width_px * s * s))
    for r0 in range(0, output.height_px, rows):
        r1 = min(r0 + rows, output.height_px)
        v = np.arange(r0, r1)[:, None, None, None] + offsets[None, None, :, None]
        u = np.arange(output.width_px)[None, :, None, None] + offsets[None, None, None, :]
        uu, vv = np.broadcast_arrays(u, v)
        directions = output.pixel_directions(np.stack([uu.ravel(), vv.ravel()], 1))
        points, dirs, _, valid = necessary_air_rays(port, directions)
        yield r0, r1, points, dirs, valid


def required_aperture_radius(
    camera: LightFieldCamera, port: FlatPort, output: PinholeCamera | None = None, *, supersample: int = 2
) -> np.ndarray:
    """Per output pixel, the smallest usable aperture radius at which the pixel is exact, metres.

    The largest radius at which one of its ``supersample x supersample`` necessary rays crosses the
    main-lens plane; ``inf`` where one of them does not reach the air (port missed, total internal
    reflection) or, followed through the thin lens, misses the sensor (as in
    :func:`~lfrefract.synthesis.warp_map.build_warp_map`, whose :attr:`WarpMap.exact` is
    ``required_aperture_radius(...) <= camera.usable_aperture_radius_m(rim_margin_px)``).

    Returns
    -------
    ndarray, shape (height, width)
    """
    output = output if output is not None else virtual_camera_for(camera)
    if port.clearance_m(camera.aperture_radius_m) <= 0.0:
        raise ParameterError(f"port.distance_m={port.distance_m!r} cuts the main-lens aperture")
    s = supersample
    f, f_prime = camera.focal_length_m, camera.lens_to_mla_m
    width, height = camera.sensor.width_px, camera.sensor.height_px
    out = np.empty((output.height_px, output.width_px))
    for r0, r1, points, dirs, valid in _necessary_ray_blocks(port, output, s):
        # The lens-plane crossing and the MLA point exactly as build_warp_map computes them, then
        # the micro-image position through the main-lens centre, in sensor pixels.
        hit = lens_plane_hits(points, dirs)
        px = camera.sensor.image_plane_to_pixels(mla_points_img(hit, dirs, f, f_prime) * camera.micro_image_scale)
        with np.errstate(invalid="ignore"):
            on_sensor = (px[:, 0] >= -0.5) & (px[:, 0] <= width - 0.5) & (px[:, 1] >= -0.5) & (px[:, 1] <= height - 0.5)
        radius = np.hypot(hit[:, 0], hit[:, 1])
        radius = np.where(valid & on_sensor & np.isfinite(radius), radius, np.inf)
        out[r0:r1] = radius.reshape(r1 - r0, output.width_px, s * s).max(axis=2)
    return out


def exact_mask(
    camera: LightFieldCamera,
    port: FlatPort,
    output: PinholeCamera | None = None,
    options: SynthesisOptions | None = None,
) -> np.ndarray:
    """Output pixels whose every necessary ray the camera records usably, shape (height, width):
    :attr:`WarpMap.exact` of ``build_warp_map(camera, port, output=output, options=options)``."""
    options = options if options is not None else SynthesisOptions()
    radius = required_aperture_radius(camera, port, output, supersample=options.supersample)
    return radius <= camera.usable_aperture_radius_m(options.rim_margin_px)


def seen_share(
    camera: LightFieldCamera,
    port: FlatPort,
    output: PinholeCamera,
    *,
    depth_m: float = GIVEN_DEPTH_M,
    rim_margin_px: float = SynthesisOptions().rim_margin_px,
    stride: int = 1,
) -> float:
    """Share of output pixels whose scene point at ``depth_m`` the camera records (``given_depth_share``).

    The point on a pixel's line of sight at camera-frame z ``depth_m`` is recorded when some of the
    :data:`SEEN_APERTURE_POINTS` aperture points (centre, ring at :data:`SEEN_RING` of
    ``camera.usable_aperture_radius_m(rim_margin_px)``) sees it through ``port`` onto the sensor,
    inside the micro-image of its lens (:func:`~lfrefract.optics.seen_by.pixels_seeing_points`).

    Parameters
    ----------
    camera : LightFieldCamera
    port : FlatPort
    output : PinholeCamera
        The refraction-free image.
    depth_m : float
        Depth of the scene points, metres.
    rim_margin_px : float
        Rim margin of the usable aperture.
    stride : int
        Test every ``stride``-th pixel in each direction.

    Returns
    -------
    float
        Recorded pixels over tested pixels.
    """
    vv, uu = np.mgrid[0 : output.height_px : stride, 0 : output.width_px : stride]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
    directions = output.pixel_directions(uv)
    points = directions * (depth_m / directions[:, 2:3])
    angles = np.linspace(0.0, 2.0 * np.pi, SEEN_APERTURE_POINTS)[:-1]
    ring = SEEN_RING * camera.usable_aperture_radius_m(rim_margin_px)
    aperture = np.concatenate([[[0.0, 0.0]], ring * np.stack([np.cos(angles), np.sin(angles)], axis=1)])
    seen = pixels_seeing_points(camera, port, points, aperture, rim_margin_px=rim_margin_px).valid
    return float(np.mean(np.any(seen, axis=1)))


def real_lens_exact_mask(
    real: RealLensCamera, port: FlatPort, output: PinholeCamera | None = None, *, supersample: int = 2
) -> np.ndarray:
    """Output pixels whose every necessary ray a camera with a real main lens records, shape (height, width).

    The real lens's refraction-free image is the central projection from the centre of its
    entrance pupil (where every recorded ray's object-space line, extended, crosses the axis on
    average), with the pinhole ``output`` (default :func:`~lfrefract.optics.pinhole.virtual_camera_for`
    the camera) placed there. Each of a pixel's ``supersample x supersample`` lines of sight is
    traced back through the port into the air (:func:`~lfrefract.synthesis.warp_map.necessary_air_rays`,
    in a frame centred on the entrance pupil), then exactly through every surface of the lens
    (:func:`~lfrefract.optics.lens.trace_lens`), to the MLA; the pixel is exact when every one passes
    every clear aperture and lands, through its microlens, on the sensor. No rim margin: compare it
    with the thin lens's ``required_aperture_radius(...) <= camera.aperture_radius_m``.
    """
    camera = real.camera
    output = output if output is not None else virtual_camera_for(camera)
    pupil_cam = np.array([0.0, 0.0, real.first_order.entrance_pupil_z_m])
    # The same port seen from the pupil: n . (X' + c) = d, so d' = d - n . c.
    local = dataclasses.replace(port, distance_m=port.distance_m - float(port.normal @ pupil_cam))
    s = supersample
    width, height = camera.sensor.width_px, camera.sensor.height_px
    out = np.empty((output.height_px, output.width_px), dtype=bool)
    for r0, r1, points, dirs, valid in _necessary_ray_blocks(local, output, s):
        ok = valid & np.all(np.isfinite(points), axis=1)
        passed = np.zeros(len(points), dtype=bool)
        if np.any(ok):
            trace = trace_lens(real.lens, points[ok] + pupil_cam, -dirs[ok], toward="image")
            with np.errstate(invalid="ignore", divide="ignore"):
                t = (camera.mla_z_m - trace.points_cam[:, 2]) / trace.directions_cam[:, 2]
                mla_xy = trace.points_cam[:, :2] + t[:, None] * trace.directions_cam[:, :2]
                # Image-plane coordinates are the camera frame's x, y negated (the image is inverted).
                px = camera.sensor.image_plane_to_pixels(-mla_xy * real.micro_image_scale)
                on_sensor = (
                    (px[:, 0] >= -0.5) & (px[:, 0] <= width - 0.5) & (px[:, 1] >= -0.5) & (px[:, 1] <= height - 0.5)
                )
            passed[ok] = trace.passed & on_sensor
        out[r0:r1] = passed.reshape(r1 - r0, output.width_px, s * s).all(axis=2)
    return out


# ----------------------------------------------------------------------------- angles
def _rays(output: PinholeCamera, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unnormalised lines of sight (N, 3) through image points (u, v)."""
    u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    return np.stack([(u - output.cx_px) / output.focal_px, (v - output.cy_px) / output.focal_px, np.ones(u.shape)], -1)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles between direction vectors (N, 3), degrees."""
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


def _widest_run_deg(mask: np.ndarray, output: PinholeCamera, *, vertical: bool) -> float:
    """Largest angle spanned by consecutive True pixels in one row (or column)."""
    m = mask.T if vertical else mask
    edges = np.diff(np.pad(m.astype(np.int8), ((0, 0), (1, 1))), axis=1)
    line, first = np.nonzero(edges == 1)  # run starts (row-major, so they pair with the ends)
    _, stop = np.nonzero(edges == -1)  # one past the run's last pixel
    if len(line) == 0:
        return 0.0
    lo, hi = first - 0.5, stop - 0.5  # outer edges of the end pixels
    if vertical:
        a, b = _rays(output, line, lo), _rays(output, line, hi)
    else:
        a, b = _rays(output, lo, line), _rays(output, hi, line)
    return float(_angle_deg(a, b).max())


def _pixel_solid_angles(output: PinholeCamera) -> np.ndarray:
    """Solid angle of each pixel (height, width), steradians (``cos^3 theta / f_px^2``)."""
    vv, uu = np.mgrid[0 : output.height_px, 0 : output.width_px]
    r2 = ((uu - output.cx_px) ** 2 + (vv - output.cy_px) ** 2) / output.focal_px**2
    return (1.0 + r2) ** -1.5 / output.focal_px**2


def _cone_deg(solid_angle_sr: float) -> float:
    """Apex angle of the cone of the given solid angle, degrees."""
    return math.degrees(2.0 * math.acos(max(-1.0, 1.0 - solid_angle_sr / (2.0 * math.pi))))


def fov_measures(mask: np.ndarray, output: PinholeCamera) -> dict[str, float]:
    """``perfect_fov_h_deg``, ``perfect_fov_v_deg``, ``perfect_cone_centred_deg`` and
    ``perfect_fov_equiv_deg`` of a mask of exact pixels (module docstring)."""
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != (output.height_px, output.width_px):
        raise ParameterError(f"mask must have shape {(output.height_px, output.width_px)}, got {mask.shape}")
    # Centred cone: nearest point of a non-exact pixel's square, or of the image's edge, to the axis.
    vv, uu = np.mgrid[0 : output.height_px, 0 : output.width_px]
    du = np.maximum(np.abs(uu - output.cx_px) - 0.5, 0.0)
    dv = np.maximum(np.abs(vv - output.cy_px) - 0.5, 0.0)
    reach = np.hypot(du, dv)[~mask]
    edge = min(output.cx_px + 0.5, output.width_px - 0.5 - output.cx_px)
    edge = min(edge, output.cy_px + 0.5, output.height_px - 0.5 - output.cy_px)
    nearest = min(edge, float(reach.min()) if reach.size else math.inf)
    return {
        "perfect_fov_h_deg": _widest_run_deg(mask, output, vertical=False),
        "perfect_fov_v_deg": _widest_run_deg(mask, output, vertical=True),
        "perfect_cone_centred_deg": math.degrees(2.0 * math.atan(max(nearest, 0.0) / output.focal_px)),
        "perfect_fov_equiv_deg": _cone_deg(float(_pixel_solid_angles(output)[mask].sum())),
    }


def original_fov(output: PinholeCamera, port: FlatPort) -> dict[str, float]:
    """The whole image's field in air (h, v, equivalent cone) and in the water through ``port``
    (h, v: the edge lines of sight of the centre row / column refracted; NaN if one is lost)."""
    w, h = output.width_px, output.height_px
    a = _rays(output, [-0.5, w - 0.5, output.cx_px, output.cx_px], [output.cy_px, output.cy_px, -0.5, h - 0.5])
    air = _angle_deg(a[[0, 2]], a[[1, 3]])
    d = a / np.linalg.norm(a, axis=1, keepdims=True)
    trace = port.trace_from_air(np.zeros_like(d), d)
    water = np.where(
        trace.valid[[0, 2]] & trace.valid[[1, 3]],
        _angle_deg(trace.directions_cam[[0, 2]], trace.directions_cam[[1, 3]]),
        np.nan,
    )
    return {
        "original_fov_h_deg": float(air[0]),
        "original_fov_v_deg": float(air[1]),
        "original_fov_equiv_deg": _cone_deg(float(_pixel_solid_angles(output).sum())),
        "original_fov_water_h_deg": float(water[0]),
        "original_fov_water_v_deg": float(water[1]),
    }


# ----------------------------------------------------------------------------- the experiment
def _rows_for(
    series: str,
    setup: FovSetup,
    port: FlatPort,
    radius: np.ndarray,
    output: PinholeCamera,
    f_numbers: tuple[float, ...],
    options: SynthesisOptions,
    aperture: str = "usable",
    tilt_deg: float | None = None,
) -> tuple[list[dict], dict[float, np.ndarray]]:
    """One row per f-number; ``tilt_deg``: the signed tilt of the sweep (default the total tilt)."""
    tilt = round(math.degrees(port.total_tilt_rad), 4) if tilt_deg is None else tilt_deg
    rows, masks = [], {}
    original = original_fov(output, port)
    for n in f_numbers:
        camera = dataclasses.replace(setup.camera, f_number=n)
        usable = camera.usable_aperture_radius_m(options.rim_margin_px) * APERTURES[aperture]
        given = (
            seen_share(camera, port, output, rim_margin_px=options.rim_margin_px, stride=setup.seen_stride)
            if aperture == "usable"
            else math.nan  # a doubled aperture is a what-if of the paper's code, not a camera
        )
        mask = radius <= usable
        masks[n] = mask
        rows.append(
            {
                "series": series,
                "tilt_deg": tilt,
                "distance_mm": round(port.distance_m * 1e3, 4),
                "f_number": n,
                "aperture": aperture,
                "usable_aperture_radius_mm": usable * 1e3,
                "exact_share": float(mask.mean()),
                "given_depth_share": given,
                **fov_measures(mask, output),
                **original,
            }
        )
    return rows, masks


def _crossing(x: np.ndarray, y: np.ndarray, level: float) -> float:
    """First x where the piecewise linear y(x) reaches ``level`` (NaN if it never does)."""
    for i in range(len(x) - 1):
        if (y[i] - level) * (y[i + 1] - level) <= 0 and y[i] != y[i + 1]:  # first sign change
            return float(x[i] + (level - y[i]) * (x[i + 1] - x[i]) / (y[i + 1] - y[i]))
    return math.nan


def _radius_for_fov(radius: np.ndarray, output: PinholeCamera, fov_deg: float) -> float:
    """Smallest usable aperture radius at which the widest exact row spans ``fov_deg`` (metres)."""
    finite = np.unique(radius[np.isfinite(radius)])
    lo, hi = 0, len(finite) - 1
    if hi < 0 or _widest_run_deg(radius <= finite[hi], output, vertical=False) < fov_deg:
        return math.nan
    while lo < hi:
        mid = (lo + hi) // 2
        if _widest_run_deg(radius <= finite[mid], output, vertical=False) >= fov_deg:
            hi = mid
        else:
            lo = mid + 1
    return float(finite[lo])


def _figures(out_dir: Path, setup: FovSetup, rows: list[dict], masks: dict, reference_mask, output) -> list[Path]:
    """Write ``fov_exact_share.png``, ``fov_perfect_fov.png`` and ``fov_masks.png``; the paths."""
    figures = (
        ("fov_exact_share.png", exact_share_figure(setup, rows)),
        ("fov_perfect_fov.png", perfect_fov_figure(setup, rows)),
        ("fov_masks.png", masks_figure(setup, masks, reference_mask, output)),
    )
    paths = []
    for name, fig in figures:
        paths.append(out_dir / name)
        save_figure(fig, paths[-1])
    return paths


def _figure_setup(setup: FovSetup) -> str:
    """The set-up line of the figures' titles: camera, port distance and glass, water."""
    return f"{setup.title}, water n = {setup.n_water:.4g}"


def _colours(setup: FovSetup) -> list[str]:
    """A colour per f-number (cycled)."""
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:olive", "tab:cyan", "tab:pink"]
    return (colours * (len(setup.f_numbers) // len(colours) + 1))[: len(setup.f_numbers)]


def exact_share_figure(setup: FovSetup, rows: list[dict]):
    """The exact share and the share recorded at a given depth against port tilt, a line per f-number,
    as a Figure (the set-up in the title).

    Parameters
    ----------
    setup : FovSetup
    rows : list of dict
        The experiment's rows (those of the ``tilt`` series are drawn).

    Returns
    -------
    matplotlib.figure.Figure
    """
    tilt_rows = [r for r in rows if r["series"] == "tilt"]
    fig = new_figure(8.4, 4.6, dpi=FIGURE_DPI)
    ax = fig.subplots()
    for colour, n in zip(_colours(setup), setup.f_numbers, strict=True):
        sel = [r for r in tilt_rows if r["f_number"] == n]
        for column, style, what in (
            ("exact_share", "o-", "exact"),
            ("given_depth_share", "x--", f"exact given depth ({GIVEN_DEPTH_M:g} m)"),
        ):
            tilts = [r["tilt_deg"] for r in sel]
            ax.plot(tilts, [100 * r[column] for r in sel], style, ms=3, color=colour, label=f"f/{n:g}, {what}")
    ax.set_xlabel("port tilt about x (deg)")
    ax.set_ylabel("pixels (% of the refraction-free image)")
    ax.set_title("exact share (paper's method) and recorded share (depth-aware)", fontsize=9)
    ax.grid(alpha=0.3)
    fig.legend(title="main lens", fontsize=7, loc="outside lower center", ncols=min(len(setup.f_numbers), 4))
    fig.suptitle(_figure_setup(setup), fontsize=9)
    return fig


def perfect_fov_figure(setup: FovSetup, rows: list[dict]):
    """The perfect field of view (every pixel exact) against port tilt and against port distance, with
    the original field of view, as a Figure (the set-up in the title).

    Parameters
    ----------
    setup : FovSetup
    rows : list of dict
        The experiment's rows (``tilt``, ``distance`` and ``reference`` series).

    Returns
    -------
    matplotlib.figure.Figure
    """
    tilt_rows = [r for r in rows if r["series"] == "tilt"]
    colours = _colours(setup)
    n0 = setup.f_numbers[0]
    first = min(tilt_rows, key=lambda r: abs(r["tilt_deg"]))
    ref = [r for r in rows if r["series"] == "reference" and r["f_number"] == n0]
    fig = new_figure(11.5, 6.4, dpi=FIGURE_DPI)
    ax, bx = fig.subplots(1, 2)
    for colour, n in zip(colours, setup.f_numbers, strict=True):
        sel = [r for r in tilt_rows if r["f_number"] == n]
        t = [r["tilt_deg"] for r in sel]
        ax.plot(t, [r["perfect_fov_h_deg"] for r in sel], "o-", ms=3, color=colour, label=f"f/{n:g} horizontal")
        ax.plot(t, [r["perfect_fov_v_deg"] for r in sel], "s--", ms=3, color=colour, label=f"f/{n:g} vertical")
    ax.axhline(first["original_fov_h_deg"], color="k", lw=1, label="original FOV, horizontal (in air)")
    ax.axhline(first["original_fov_v_deg"], color="k", lw=1, ls="--", label="original FOV, vertical (in air)")
    ax.axhline(
        first["original_fov_water_h_deg"],
        color="grey",
        lw=1,
        ls=":",
        label=f"original FOV, horizontal (in water, {first['tilt_deg']:g} deg)",
    )
    if ref:
        ax.axhline(PAPER_PERFECT_FOV_DEG, color="tab:brown", lw=2, alpha=0.4, label="paper: perfect FOV, about 30 deg")
        ax.plot([ref[0]["tilt_deg"]], [ref[0]["perfect_fov_h_deg"]], "k*", ms=10, label=f"reference port, f/{n0:g} (h)")
    ax.set_xlabel("port tilt about x (deg)")
    ax.set_ylabel("field of view (deg)")
    ax.set_title("perfect (all pixels exact) against original field of view", fontsize=9)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.14))
    styles = {"usable": ("o-", "s--", "tab:blue"), "doubled": ("^-", "v--", "tab:red")}
    for aperture, (h_style, v_style, colour) in styles.items():
        dist_rows = [r for r in rows if r["series"] == "distance" and r["aperture"] == aperture]
        if not dist_rows:
            continue
        d = [r["distance_mm"] for r in dist_rows]
        radius = dist_rows[0]["usable_aperture_radius_mm"]
        what = "usable aperture" if aperture == "usable" else "twice the usable aperture (the authors' f/N)"
        bx.plot(
            d,
            [r["perfect_fov_h_deg"] for r in dist_rows],
            h_style,
            ms=3,
            color=colour,
            label=f"perfect, horizontal: {what}, radius {radius:.2f} mm",
        )
        bx.plot(
            d,
            [r["perfect_fov_v_deg"] for r in dist_rows],
            v_style,
            ms=3,
            color=colour,
            alpha=0.6,
            label=f"perfect, vertical: {what}",
        )
    bx.axhline(first["original_fov_h_deg"], color="k", lw=1, label="original FOV, horizontal (in air)")
    bx.axhline(
        first["original_fov_water_h_deg"], color="grey", lw=1, ls=":", label="original FOV, horizontal (in water)"
    )
    if ref:
        bx.axhline(PAPER_PERFECT_FOV_DEG, color="tab:brown", lw=2, alpha=0.4, label="paper: perfect FOV, about 30 deg")
    bx.axvline(
        setup.distance_m * 1e3, color="k", lw=0.5, ls="-.", label=f"this set-up's port: {setup.distance_m * 1e3:.4g} mm"
    )
    bx.set_xlabel("port distance (mm; untilted port, perpendicular)")
    bx.set_ylabel("field of view (deg)")
    bx.set_title(f"untilted port, f/{n0:g}", fontsize=9)
    bx.set_ylim(bottom=0)
    bx.grid(alpha=0.3)
    bx.legend(fontsize=7, ncol=1, loc="upper center", bbox_to_anchor=(0.5, -0.14))
    fig.suptitle(f"perfect field of view: {_figure_setup(setup)}", fontsize=10)
    return fig


def masks_figure(setup: FovSetup, masks: dict, reference_mask, output: PinholeCamera):
    """The exact pixels at the drawn tilts (and the reference port's), nested by f-number, as a
    Figure: a colour bar naming the largest f-number at which each pixel is exact, pixel axes, the
    principal point in the legend and the set-up in the title.

    Parameters
    ----------
    setup : FovSetup
    masks : dict
        ``tilt -> {f-number -> exact mask (H, W)}`` of :attr:`FovSetup.mask_tilts_deg`.
    reference_mask : dict or None
        ``{f-number -> exact mask}`` of the reference port, or None.
    output : PinholeCamera
        The refraction-free image.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.lines import Line2D

    colours = _colours(setup)
    n0 = setup.f_numbers[0]
    panels = [(f"tilt {t:g} deg", masks[t]) for t in setup.mask_tilts_deg]
    if reference_mask is not None:
        tilt = math.degrees(setup.reference_port.total_tilt_rad)
        way = "up" if setup.reference_port.normal[1] < 0 else "down"
        panels.append((f"reference port ({tilt:.1f} deg, {way})", reference_mask))
    aspect = output.height_px / output.width_px
    fig = new_figure(3.8 * len(panels) + 1.6, 3.8 * aspect + 1.8, dpi=FIGURE_DPI)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    levels = len(setup.f_numbers)
    cmap = ListedColormap(["0.85", *colours])
    norm = BoundaryNorm(np.arange(-0.5, levels + 1.0), cmap.N)
    image = None
    for ax, (title, by_n) in zip(axes, panels, strict=True):
        level = sum(by_n[n].astype(int) for n in setup.f_numbers)  # nested: exact up to the level-th f-number
        image = ax.imshow(level, cmap=cmap, norm=norm, interpolation="nearest")
        ax.plot([output.cx_px], [output.cy_px], "k+", ms=8)
        share = 100 * by_n[n0].mean()
        ax.set_title(f"{title}: {share:.{1 if share >= 1 else 2}f} % exact at f/{n0:g}", fontsize=8)
        pixel_axes(ax)
    bar = fig.colorbar(image, ax=axes, shrink=0.9, ticks=np.arange(levels + 1))
    bar.ax.set_yticklabels(["not exact", *(f"f/{n:g}" for n in setup.f_numbers)])
    bar.set_label("largest main-lens f-number at which the pixel is exact")
    principal = Line2D([], [], color="k", marker="+", ls="", ms=8, label="principal point")
    fig.legend(handles=[principal], loc="outside lower center", fontsize=8)
    fig.suptitle(f"exact pixels by main-lens f-number: {_figure_setup(setup)}", fontsize=9)
    return fig


@register("fov", options=("camera", "port_distance_m", "thickness_m", "tilts_deg", "f_numbers"))
def run(out_dir: Path, options: ExperimentOptions, *, progress: bool) -> ExperimentResult:
    """Exact share and perfect field of view against port tilt, f-number and port distance (paper section 6)."""
    setup = setup_for(options.scale, options)
    out_dir = Path(out_dir)
    synthesis = SynthesisOptions()
    output = virtual_camera_for(setup.camera)
    with named_options(options, "camera", "f_numbers"):
        for n in setup.f_numbers:  # the camera validates each f-number (no overlapping micro-images)
            dataclasses.replace(setup.camera, f_number=n)
    n0 = setup.f_numbers[0]
    jobs = [("tilt", t, setup.distance_m) for t in setup.tilts_deg]
    jobs += [("distance", 0.0, d) for d in setup.distances_m]
    for series, tilt, distance in jobs:  # every port clears the lens, checked before any work
        made_by = ("camera", "port_distance_m", "tilts_deg") if series == "tilt" else ("camera", "port_distance_m")
        with named_options(options, *made_by):
            port = setup.port(tilt, distance)
            if port.clearance_m(setup.camera.aperture_radius_m) <= 0.0:
                raise ParameterError(
                    f"port.distance_m={port.distance_m!r} at tilt {tilt:g} deg cuts the main-lens aperture "
                    f"(radius {setup.camera.aperture_radius_m:.4g} m)"
                )
    if setup.reference_port is not None:
        jobs.append(("reference", None, setup.distance_m))
    rows: list[dict] = []
    masks: dict[float, dict[float, np.ndarray]] = {}
    reference_mask = None
    untilted_radius = None
    for series, tilt, distance in tqdm(jobs, desc="fov", unit="port", disable=not progress):
        port = setup.reference_port if series == "reference" else setup.port(tilt, distance)
        radius = required_aperture_radius(setup.camera, port, output, supersample=synthesis.supersample)
        if series == "distance":
            for aperture in APERTURES:
                rows += _rows_for(series, setup, port, radius, output, (n0,), synthesis, aperture)[0]
            if distance == setup.distance_m:
                untilted_radius = radius
            continue
        signed = tilt if series == "tilt" else None  # a tilt row keeps the sweep's sign (negative: normal down)
        new, by_n = _rows_for(series, setup, port, radius, output, setup.f_numbers, synthesis, tilt_deg=signed)
        rows += new
        if series == "tilt" and tilt in setup.mask_tilts_deg:
            masks[tilt] = by_n
        elif series == "reference":
            reference_mask = by_n
    figures = _figures(out_dir, setup, rows, masks, reference_mask, output)
    summary = _summary(setup, rows, untilted_radius, output, synthesis)
    parameters = {
        "camera": setup.camera.to_dict(),
        "port": {"distance_m": setup.distance_m, "thickness_m": setup.thickness_m, "n_water": setup.n_water},
        "tilts_deg": list(setup.tilts_deg),
        "tilt_axis": "x (tilt_x_deg: normal turned up)",
        "f_numbers": list(setup.f_numbers),
        "distances_m": list(setup.distances_m),
        "apertures": dict(APERTURES),
        "reference_port": None if setup.reference_port is None else setup.reference_port.to_dict(),
        "reference_port_axial_distance_m": None if setup.reference_port is None else REFERENCE_AXIAL_DISTANCE_M,
        "output": output.to_dict(),
        "supersample": synthesis.supersample,
        "rim_margin_px": synthesis.rim_margin_px,
        "given_depth_m": GIVEN_DEPTH_M,
        "given_depth_stride_px": setup.seen_stride,
    }
    return ExperimentResult(
        name="fov",
        scale=options.scale,
        rows=tuple(rows),
        figures=tuple(figures),
        summary=summary,
        parameters=parameters,
    )


def _summary(setup: FovSetup, rows: list[dict], untilted_radius, output: PinholeCamera, options) -> str:
    n0, n1 = setup.f_numbers[0], setup.f_numbers[-1]
    tilt_rows = [r for r in rows if r["series"] == "tilt"]
    zero_tilt = min((r["tilt_deg"] for r in tilt_rows), key=abs)

    def row(series: str, tilt: float | None = None, n: float = n0, aperture: str = "usable") -> dict:
        return next(
            r
            for r in rows
            if r["series"] == series
            and r["f_number"] == n
            and r["aperture"] == aperture
            and (tilt is None or r["tilt_deg"] == tilt)
        )

    def fov(r: dict) -> str:
        return (
            f"{100 * r['exact_share']:.2f} % exact, perfect FOV {r['perfect_fov_h_deg']:.1f} x "
            f"{r['perfect_fov_v_deg']:.1f} deg (equivalent cone {r['perfect_fov_equiv_deg']:.1f} deg)"
        )

    zero, slow = row("tilt", zero_tilt), row("tilt", zero_tilt, n1)
    mid = row("tilt", setup.mask_tilts_deg[len(setup.mask_tilts_deg) // 2])
    gone = next((r["tilt_deg"] for r in tilt_rows if r["f_number"] == n0 and r["exact_share"] == 0), None)
    sensor_limited = zero["perfect_fov_h_deg"] >= zero["original_fov_water_h_deg"] - 0.5
    here = round(setup.distance_m * 1e3, 4)
    untilted, doubled = (
        next(r for r in rows if r["series"] == "distance" and r["aperture"] == a and r["distance_mm"] == here)
        for a in ("usable", "doubled")
    )
    lines = [
        f"- {setup.title}, water {setup.n_water:g}; refraction-free image {output.width_px} x {output.height_px} px, "
        f"original FOV {zero['original_fov_h_deg']:.1f} x {zero['original_fov_v_deg']:.1f} deg in air ("
        f"{zero['original_fov_water_h_deg']:.1f} x {zero['original_fov_water_v_deg']:.1f} deg in the water at "
        f"{zero_tilt:g} deg).",
        f"- Tilt {zero_tilt:g} deg, f/{n0:g}: {fov(zero)}"
        + (
            ": the camera's whole field in the water (limited by the sensor, not the aperture)."
            if sensor_limited
            else "."
        )
        + f" At f/{n1:g}: {fov(slow)}. A larger f-number means a smaller usable aperture, so fewer necessary rays "
        "are recorded: the exact region at a larger f-number lies inside the one at a smaller f-number.",
        f"- Untilted, f/{n0:g}, usable aperture radius {untilted['usable_aperture_radius_mm']:.2f} mm: perfect FOV "
        f"{untilted['perfect_fov_h_deg']:.1f} deg; with twice that radius ({doubled['usable_aperture_radius_mm']:.2f} "
        f"mm, as the authors' code tests the aperture: radius f/N): {doubled['perfect_fov_h_deg']:.1f} deg.",
        f"- Tilted {mid['tilt_deg']:g} deg, f/{n0:g}: {fov(mid)}"
        + (f"; no exact pixel from {gone:g} deg on" if gone is not None else "")
        + ". The exact region is a cone of lines of sight about the port normal (undeviated there): tilt hardly "
        "changes its angular size but moves it towards the image edge and out of the image (the pixel share can "
        "first rise a little, as a cone off axis covers more pixels).",
    ]
    if setup.reference_port is None or untilted_radius is None:
        return "\n".join(lines)
    ref = row("reference")
    dist_rows = sorted(
        (r for r in rows if r["series"] == "distance" and r["aperture"] == "usable"), key=lambda r: r["distance_mm"]
    )
    d30 = _crossing(
        np.array([r["distance_mm"] for r in dist_rows]),
        np.array([r["perfect_fov_h_deg"] for r in dist_rows]),
        PAPER_PERFECT_FOV_DEG,
    )
    aperture = dataclasses.replace(setup.camera, f_number=n0).aperture_radius_m
    whole = fov_measures(untilted_radius <= aperture, output)["perfect_fov_h_deg"]
    whole2 = fov_measures(untilted_radius <= 2 * aperture, output)["perfect_fov_h_deg"]
    r30 = _radius_for_fov(untilted_radius, output, PAPER_PERFECT_FOV_DEG)
    way = "up" if setup.reference_port.normal[1] < 0 else "down"
    lines += [
        f"- Reference port of the authors' code ({ref['tilt_deg']:.1f} deg, normal {way}, "
        f"{REFERENCE_AXIAL_DISTANCE_M * 1e3:g} mm along the axis = {setup.reference_port.distance_m * 1e3:.1f} mm "
        f"perpendicular, no glass), f/{n0:g}: {fov(ref)}.",
        f"- Paper (section 6): perfect FOV about {PAPER_PERFECT_FOV_DEG:g} deg against about "
        f"{PAPER_ORIGINAL_FOV_DEG:g} deg original. The original agrees ({zero['original_fov_h_deg']:.1f} deg "
        f"horizontally in air). The perfect FOV untilted at {setup.distance_m * 1e3:.1f} mm: "
        f"{untilted['perfect_fov_h_deg']:.1f} deg with the usable f/{n0:g} aperture (radius "
        f"{untilted['usable_aperture_radius_mm']:.2f} mm), {whole:.1f} deg with the whole aperture (radius "
        f"{aperture * 1e3:.2f} mm, no rim margin); with those radii doubled (the authors' code tests radius f/N): "
        f"{doubled['perfect_fov_h_deg']:.1f} and {whole2:.1f} deg. {PAPER_PERFECT_FOV_DEG:g} deg would need a usable "
        f"radius of {r30 * 1e3:.2f} mm, or the port at about {d30:.0f} mm.",
    ]
    return "\n".join(lines)
