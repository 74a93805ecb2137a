"""The render job: a scene in, a directory of raw image, ground truth and sidecar out."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np

import lfrefract
from lfrefract import LightFieldCamera, PinholeCamera, virtual_camera_for
from lfrefract.errors import ParameterError
from lfrefract.formats.capture import CaptureTruth, write_capture_files
from lfrefract.formats.lytro import write_f01_raw, write_lfr
from lfrefract.formats.mosaic import RawMosaic, write_mosaic_npz
from lfrefract.formats.outputs import staged_directory
from lfrefract.optics.real_lens import RealLensCamera
from simulator import backend, groundtruth, previews
from simulator.config import SceneConfig, SensorSettings, scene_files
from simulator.detector import lytro_settings, white_frames
from simulator.render import DEFAULT_MAX_BAND_PIXELS, render_bands
from simulator.scene import build_scene, check_geometry, integrator, water_medium
from simulator.sensor import plenoptic_sensor_dict

__all__ = [
    "LFR_NAME",
    "LYTRO_RAW_NAME",
    "MOSAIC_NAME",
    "RAYS_NAME",
    "RENDER_KIND",
    "SENSOR_NOISE_STREAM",
    "RenderResult",
    "lens_steps",
    "render_job",
    "render_raw",
    "scene_inputs",
    "sensor_mosaic",
    "write_lytro_file",
]


#: Name of the per-raw-pixel ground-truth rays written with ``write_rays``.
RAYS_NAME = "rays.npz"
#: Name of the sensor's mosaic (integer counts), written when the scene has a ``[sensor]``.
MOSAIC_NAME = "mosaic.npz"
#: The Lytro capture written with ``write_lfr``: an Illum LFR for a 10-bit sensor, ...
LFR_NAME = "capture.lfr"
#: ... an F01 frame (with ``capture.json`` beside it) for a 12-bit one.
LYTRO_RAW_NAME = "capture.raw"
#: Bit depths of the Lytro files: the Illum LFR stores 10 bits, the F01 raw 12.
_LYTRO_FILE_BITS = {10: LFR_NAME, 12: LYTRO_RAW_NAME}
#: Pixels a Lytro file packs together in a row (4 in 5 bytes at 10 bits, 2 in 3 bytes at 12 bits).
_LYTRO_PACK_GROUP = {10: 4, 12: 2}
#: The noise stream of the sensor: SeedSequence([seed, stream, frame]) (the renders use 0 and 1).
SENSOR_NOISE_STREAM = 2


def sensor_mosaic(raw: np.ndarray, sensor: SensorSettings, *, seed: int) -> RawMosaic:
    """The sensor's mosaic of a rendered raw image: ``sensor.frames`` exposures averaged.

    Parameters
    ----------
    raw : ndarray, shape (H, W, 3)
        The rendered radiance (``raw.exr``).
    sensor : SensorSettings
    seed : int
        The render seed. The noise seed is ``SeedSequence([seed, 2]).generate_state(1)[0] >> 1``
        (stream 2, :data:`SENSOR_NOISE_STREAM`, apart from the renders' streams 0 and 1), and frame
        ``k`` draws from ``SeedSequence([noise_seed, k])``.

    Returns
    -------
    RawMosaic
    """
    noise_seed = int(np.random.SeedSequence([seed, SENSOR_NOISE_STREAM]).generate_state(1)[0] >> 1)
    return white_frames(raw, sensor.detector, frames=sensor.frames, seed=noise_seed)


def lens_steps(camera: LightFieldCamera) -> tuple[int, int]:
    """The simulated lens motors' positions recorded in Lytro files: ``(zoom_step, focus_step)``.

    A simulated lens has no motors; the steps are physical instead, so that white images and
    captures of the same setting carry the same pair: zoom is the focal length in micrometres,
    focus the lens's extension beyond infinity focus (``lens_to_mla_m - focal_length_m``) in
    micrometres.
    """
    return round(camera.focal_length_m * 1e6), round((camera.lens_to_mla_m - camera.focal_length_m) * 1e6)


def _check_lytro_file(config: SceneConfig) -> None:
    """Raise before rendering if ``config``'s sensor cannot be written as a Lytro file."""
    if config.sensor is None:
        raise ParameterError("a Lytro file (--lfr) needs a sensor model: add a [sensor] table or pass --sensor NAME")
    bits = config.sensor.detector.bit_depth
    if bits not in _LYTRO_FILE_BITS:
        raise ParameterError(
            f"sensor.bit_depth={bits}: Lytro files hold 10-bit (Illum LFR) or 12-bit (F01 raw) mosaics"
        )
    width = config.camera.sensor.width_px
    if width % _LYTRO_PACK_GROUP[bits]:
        raise ParameterError(
            f"camera.sensor.width_px={width}: a {bits}-bit Lytro file packs {_LYTRO_PACK_GROUP[bits]} pixels of a row "
            "together, so the width must be a multiple of that"
        )


def write_lytro_file(
    out_dir: Path, mosaic: RawMosaic, config: SceneConfig, *, exit_pupil_offset_m: float | None = None
) -> list[Path]:
    """Write the capture as the Lytro camera of its bit depth does, in ``out_dir``.

    10 bits: ``capture.lfr`` (Illum LFR, :func:`lfrefract.formats.lytro.write_lfr`); 12 bits:
    ``capture.raw`` and ``capture.json`` (F01, :func:`lfrefract.formats.lytro.write_f01_raw`).
    The colour matrix, white balance and ISO are the sensor's
    (:func:`simulator.detector.lytro_settings`), the lens steps :func:`lens_steps`, the exit pupil
    the real lens's (or the thin lens itself when ``exit_pupil_offset_m`` is None).

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    _check_lytro_file(config)
    assert config.sensor is not None  # checked above
    zoom, focus = lens_steps(config.camera)
    settings = lytro_settings(
        config.sensor.detector, exit_pupil_offset_m=exit_pupil_offset_m, zoom_step=zoom, focus_step=focus
    )
    if config.sensor.detector.bit_depth == 10:
        return [write_lfr(out_dir / LFR_NAME, mosaic, config.camera, settings=settings)]
    return list(write_f01_raw(out_dir / LYTRO_RAW_NAME, mosaic, config.camera, settings=settings))


def _lens_summary(real: RealLensCamera) -> dict:
    fo = real.first_order
    return {
        "name": real.lens.name,
        "surfaces": len(real.lens.surfaces),
        "entrance_pupil_z_m": fo.entrance_pupil_z_m,
        "exit_pupil_z_m": fo.exit_pupil_z_m,
        "front_principal_z_m": fo.front_principal_z_m,
        "extent_z_m": list(real.extent_z_m),
    }


def write_chief_rays(path: Path, optics: LightFieldCamera | RealLensCamera) -> None:
    """Write the object-space ray of every raw pixel's chief sample (through its microlens centre).

    ``rays.npz`` holds ``origins_cam`` and ``directions_cam`` (H, W, 3) float32, camera frame, metres
    and unit vectors (origins on the thin lens's plane z = 0 or on a real lens's front surface; NaN
    where vignetted), ``passed`` (H, W) bool (the chief sample gets through the main lens) and
    ``lens_index`` (H, W, 2) int32 (the microlens of each pixel). Rays are in air, before the port.
    Float32 keeps an Illum's 41 Mpx at 1.1 GB before compression: write it for small sensors or
    when the rays are needed.
    """
    camera = optics.camera if isinstance(optics, RealLensCamera) else optics
    rays = optics.chief_rays() if isinstance(optics, RealLensCamera) else optics.captured_rays()
    h, w = camera.sensor.height_px, camera.sensor.width_px
    passed = rays.in_aperture.reshape(h, w)
    origins = np.where(rays.in_aperture[:, None], rays.origins_cam, np.nan).reshape(h, w, 3)
    directions = np.where(rays.in_aperture[:, None], rays.directions_cam, np.nan).reshape(h, w, 3)
    with open(path, "wb") as handle:
        np.savez_compressed(
            handle,
            origins_cam=origins.astype(np.float32),
            directions_cam=directions.astype(np.float32),
            passed=passed,
            lens_index=rays.lens_indices.reshape(h, w, 2).astype(np.int32),
        )


def render_raw(
    mi: ModuleType,
    config: SceneConfig,
    *,
    glass_free_scene=None,
    max_band_pixels: int = DEFAULT_MAX_BAND_PIXELS,
    progress: bool = True,
) -> np.ndarray:
    """Render the raw lenslet image of ``config`` with its spp, seed and port model.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set.
    config : SceneConfig
    glass_free_scene : mitsuba.Scene, optional
        ``config``'s scene without the port, if already built (the ``sensor`` port model renders
        the raw image from it).
    max_band_pixels : int
        Band size bound.
    progress : bool
        Show a progress bar.

    Returns
    -------
    ndarray, float32, shape (H, W, 3)
    """
    camera = config.camera
    if config.port is not None and config.render.port_model == "geometry":
        # The camera is in air; its rays enter the water (and its medium) at the port's water face.
        scene, sensor_port, medium = build_scene(mi, config, port_geometry=True), None, None
    else:
        scene = glass_free_scene if glass_free_scene is not None else build_scene(mi, config, port_geometry=False)
        sensor_port, medium = config.port, water_medium(config.water)

    def sensor(crop):
        spp = config.render.spp
        return plenoptic_sensor_dict(
            mi, camera, config.pose, spp=spp, crop=crop, port=sensor_port, medium=medium, lens=config.lens
        )

    return render_bands(
        mi,
        scene,
        sensor,
        camera.sensor.width_px,
        camera.sensor.height_px,
        spp=config.render.spp,
        seed=config.render.seed,
        max_band_pixels=max_band_pixels,
        progress=progress,
        label="raw",
    )


@dataclass(frozen=True)
class RenderResult:
    """What :func:`render_job` wrote and measured."""

    out_dir: Path
    raw_seconds: float
    ideal_seconds: float
    metadata: dict


#: Kind of a render output directory (its manifest and ``meta.json``).
RENDER_KIND = "lfsim.render"


def scene_inputs(config: SceneConfig) -> list[Path]:
    """The files a render of ``config`` reads: its scene file and its meshes (an output may hold none)."""
    files = [Path(config.source)] if Path(config.source).is_file() else []
    return files + [path for _, path in scene_files(config)]


def render_job(
    config: SceneConfig,
    out_dir: str | Path,
    *,
    variant: str | None = None,
    max_band_pixels: int = DEFAULT_MAX_BAND_PIXELS,
    ideal: PinholeCamera | None = None,
    overwrite: bool = False,
    progress: bool = True,
    write_previews: bool = True,
    write_rays: bool = False,
    write_lfr: bool = False,
) -> RenderResult:
    """Render a scene and its ground truth into ``out_dir``, a capture folder of kind ``lfsim.render``.

    Writes (:func:`lfrefract.formats.capture.write_capture_files`) ``raw.exr`` (lenslet image, RGB,
    ``config.render.spp`` samples per pixel), ``ideal.exr`` (refraction-free pinhole image, RGB,
    ``config.render.ideal_spp`` samples per pixel), ``depth.exr`` (camera-frame z of the ideal
    image's pixel centres, metres, +inf where no surface), ``lenses.npz`` (microlens ground truth),
    ``meta.json`` (every parameter, the seed, versions) and PNG previews; with ``write_rays``
    also ``rays.npz``, the object-space ray of every raw pixel (:func:`write_chief_rays`). With a
    ``[sensor]``, ``mosaic.npz`` holds the sensor's integer counts (:func:`sensor_mosaic`), and with
    ``write_lfr`` the Lytro file of its bit depth (:func:`write_lytro_file`). The directory is
    assembled in a staging directory and appears only when complete; a bad scene raises before
    anything is rendered.

    Parameters
    ----------
    config : SceneConfig
    out_dir : path-like
        Output directory; must be absent or empty unless ``overwrite``.
    variant : str, optional
        Mitsuba variant (default: CUDA if available, else LLVM).
    max_band_pixels : int
        Band size bound for the raw render.
    ideal : PinholeCamera, optional
        Geometry of the ideal image; default :func:`lfrefract.virtual_camera_for` the camera.
    overwrite : bool
        Replace a non-empty ``out_dir``.
    progress : bool
        Show progress bars.
    write_previews : bool
        Also write PNG figures under ``previews/``.
    write_rays : bool
        Also write ``rays.npz``.
    write_lfr : bool
        Also write the Lytro file (needs a ``[sensor]`` of 10 or 12 bits).

    Returns
    -------
    RenderResult
    """
    geometry = check_geometry(config)
    if write_lfr:
        _check_lytro_file(config)
    camera: LightFieldCamera = config.camera
    pinhole = ideal if ideal is not None else virtual_camera_for(camera)
    spp, ideal_spp, seed = config.render.spp, config.render.ideal_spp, config.render.seed
    port_geometry = config.port is not None and config.render.port_model == "geometry"
    with staged_directory(out_dir, kind=RENDER_KIND, overwrite=overwrite, inputs=scene_inputs(config)) as stage:
        mi = backend.load_mitsuba(variant)
        glass_free = build_scene(mi, config, port_geometry=False)
        start = time.perf_counter()
        raw = render_raw(mi, config, glass_free_scene=glass_free, max_band_pixels=max_band_pixels, progress=progress)
        raw_seconds = time.perf_counter() - start
        start = time.perf_counter()
        truth = groundtruth.compute(mi, glass_free, config, pinhole, spp=ideal_spp, seed=seed, progress=progress)
        ideal_seconds = time.perf_counter() - start
        real = None if config.lens is None else RealLensCamera(camera=camera, lens=config.lens)
        optics = camera if real is None else real
        extra = {
            "scene": {k: v for k, v in config.to_dict().items() if k not in ("camera", "pose", "port")},
            "derived": {
                "micro_image_pitch_px": camera.mla.pitch_m * optics.micro_image_scale / camera.sensor.pixel_pitch_m,
                "micro_image_radius_px": optics.micro_image_radius_px,
                "micro_image_scale": optics.micro_image_scale,
                "aperture_radius_m": camera.aperture_radius_m,
                "main_lens": None if real is None else _lens_summary(real),
                "lens_count": len(truth.lenses["lens_index"]),
                "port_radiance_scale": None if config.port is None else config.port.radiance_scale,
                **geometry,
            },
            "render": {
                "spp": spp,
                "ideal_spp": ideal_spp,
                "seed": seed,
                "band_seed": "numpy.random.SeedSequence([seed, stream, band]).generate_state(1, uint32); "
                "stream 0 raw, 1 ideal",
                "sensor_seed": None
                if config.sensor is None
                else "numpy.random.SeedSequence([seed, 2]).generate_state(1)[0] >> 1; frame k of the mosaic draws "
                "from SeedSequence([sensor_seed, k])",
                "max_band_pixels": max_band_pixels,
                "port_model": config.render.port_model,
                "integrator_raw": integrator(config.port if port_geometry else None, water=config.water),
                "integrator_ideal": integrator(None, water=config.water),
                "medium": water_medium(config.water),
                "raw_seconds": raw_seconds,
                "ideal_seconds": ideal_seconds,
                "lfrefract": lfrefract.__version__,
                **backend.versions(),
            },
            "units": {"length": "m", "angle": "rad", "depth": "camera-frame z, m; +inf where no surface"},
        }
        metadata = write_capture_files(
            stage,
            raw=raw,
            camera=camera,
            port=config.port,
            ideal=pinhole,
            pose=config.pose,
            ground_truth=CaptureTruth(ideal=truth.ideal, depth_m=truth.depth_m, lenses=truth.lenses),
            metadata=extra,
            kind=RENDER_KIND,
        )
        if write_rays:
            write_chief_rays(stage / RAYS_NAME, camera if real is None else real)
        if config.sensor is not None:
            mosaic = sensor_mosaic(raw, config.sensor, seed=seed)
            write_mosaic_npz(stage / MOSAIC_NAME, mosaic)
            if write_lfr:
                pupil = None if real is None else real.exit_pupil_distance_m
                write_lytro_file(stage, mosaic, config, exit_pupil_offset_m=pupil)
        if write_previews:
            previews.write_all(
                stage / "previews",
                raw=raw,
                ideal=truth.ideal,
                depth_m=truth.depth_m,
                camera=camera,
                port=config.port,
                scene=config.name,
            )
    return RenderResult(Path(out_dir), raw_seconds, ideal_seconds, metadata)
