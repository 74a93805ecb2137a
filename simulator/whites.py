"""White images as a Lytro camera ships them: one per zoom and focus setting, through the sensor model.

A light-field camera's micro-image centres move with the main lens's exit pupil, so Lytro's
factory calibration holds a white image (a diffuser in front of the lens, many exposures averaged)
for each of a grid of zoom and focus settings, and a decoder picks the one that matches a capture's.
:func:`render_whites` renders that set for a simulated camera: for every focal length (zoom) and
focus distance, the white scene (uniform radiance, no port) through the camera's main lens (thin or
a preset, rescaled to the focal length), turned into counts by the sensor model with ``frames``
exposures averaged, and written as the camera writes it: a bare 10-bit ``.raw`` with its JSON in a
``.txt`` (the Illum's factory white images) or a 12-bit ``.raw`` with a ``.json`` (the F01's). Each
white's true micro-image centres go beside it (``*.lenses.npz``), and ``whites.json`` lists the
settings.

Frames and units: focal lengths and distances in metres; a focus distance is measured from the main
lens (its thin-lens model: ``lens_to_mla_m = 1 / (1 / f - 1 / d)``) in air.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import lfrefract
from lfrefract import LightFieldCamera
from lfrefract.errors import ParameterError
from lfrefract.formats.jsonio import write_json
from lfrefract.formats.lytro import write_f01_raw, write_illum_raw
from lfrefract.formats.outputs import staged_directory
from lfrefract.optics.lens import LENS_PRESETS, LensPrescription
from lfrefract.optics.real_lens import RealLensCamera
from lfrefract.validate import bounded_float, bounded_int, shown
from simulator import backend, groundtruth
from simulator.config import RenderSettings, SensorSettings, embedded_scenes, lens_record, load_scene, main_lens
from simulator.detector import lytro_settings
from simulator.job import lens_steps, render_raw, sensor_mosaic

__all__ = ["WHITES_INDEX_NAME", "WHITES_KIND", "WhiteSetting", "check_white_seed", "render_whites", "white_settings"]

#: Kind of a white-image set's output directory.
WHITES_KIND = "lfsim.whites"
#: The set's index: one entry per white image (its files, settings and steps).
WHITES_INDEX_NAME = "whites.json"
#: Most settings one set may hold (each is a render and ``frames`` sensor exposures).
MAX_WHITE_SETTINGS = 256
#: Nearest focus distance, in focal lengths (closer would put the MLA far behind the lens).
_MIN_FOCUS_FOCAL_LENGTHS = 2.0


@dataclass(frozen=True, kw_only=True)
class WhiteSetting:
    """One zoom and focus setting of the main lens.

    Parameters
    ----------
    focal_length_m : float
        The main lens's focal length (zoom), metres, > 0.
    focus_distance_m : float
        Distance from the lens it focuses on, metres; ``math.inf`` for infinity focus, else at least
        2 focal lengths.
    """

    focal_length_m: float
    focus_distance_m: float

    def __post_init__(self) -> None:
        f = bounded_float("focal_length_m", self.focal_length_m, 0.0, 10.0, low_open=True, unit="m")
        object.__setattr__(self, "focal_length_m", f)
        d = self.focus_distance_m
        if not (isinstance(d, (int, float)) and not isinstance(d, bool) and d == math.inf):
            d = bounded_float("focus_distance_m", d, _MIN_FOCUS_FOCAL_LENGTHS * f, 1e6, unit="m")
        object.__setattr__(self, "focus_distance_m", float(d))

    @property
    def lens_to_mla_m(self) -> float:
        """Lens-to-MLA distance that focuses at :attr:`focus_distance_m`: ``1 / (1 / f - 1 / d)``, metres."""
        return 1.0 / (1.0 / self.focal_length_m - 1.0 / self.focus_distance_m)

    def camera(self, base: LightFieldCamera) -> LightFieldCamera:
        """``base`` at this setting: its focal length and lens-to-MLA distance replaced, the rest kept."""
        return dataclasses.replace(base, focal_length_m=self.focal_length_m, lens_to_mla_m=self.lens_to_mla_m)


def white_settings(
    camera: LightFieldCamera,
    *,
    focal_lengths_m: Sequence[float] | None = None,
    focus_distances_m: Sequence[float] = (math.inf,),
) -> list[WhiteSetting]:
    """The grid of settings: every focal length (default the camera's) with every focus distance.

    Raises
    ------
    ParameterError
        For an empty list, more than :data:`MAX_WHITE_SETTINGS` settings, or a value out of range.
    """
    zooms = [camera.focal_length_m] if focal_lengths_m is None else list(focal_lengths_m)
    focuses = list(focus_distances_m)
    if not zooms or not focuses:
        raise ParameterError("a white-image set needs at least one focal length and one focus distance")
    if len(zooms) * len(focuses) > MAX_WHITE_SETTINGS:
        raise ParameterError(
            f"{len(zooms)} focal lengths x {len(focuses)} focus distances is more than {MAX_WHITE_SETTINGS} settings"
        )
    return [WhiteSetting(focal_length_m=f, focus_distance_m=d) for f in zooms for d in focuses]


def check_white_seed(seed: int, count: int) -> int:
    """``seed`` as the render seed of a set of ``count`` settings (setting ``k`` renders with
    ``seed + k``, every one a seed of :mod:`simulator.seeds`).

    Raises
    ------
    ParameterError
        Unless ``seed`` is an integer in ``[0, 2**31 - 1 - count]``; the message names ``seed``.
    """
    return bounded_int("seed", seed, 0, 2**31 - 1 - count)


def render_whites(
    out_dir: str | Path,
    *,
    camera: LightFieldCamera,
    settings: Sequence[WhiteSetting],
    sensor: SensorSettings,
    lens: str | LensPrescription | None = None,
    spp: int = 64,
    seed: int = 0,
    variant: str | None = None,
    overwrite: bool = False,
    progress: bool = True,
) -> list[dict]:
    """Render a white image per setting, through the sensor model, into ``out_dir``.

    Parameters
    ----------
    out_dir : path-like
        Output directory (kind ``lfsim.whites``); absent or empty unless ``overwrite``.
    camera : LightFieldCamera
        The camera; each setting replaces its focal length and lens-to-MLA distance.
    settings : sequence of WhiteSetting
    sensor : SensorSettings
        The sensor (built for ``camera``, :func:`simulator.config.sensor_model`); its ``frames``
        exposures are averaged (Lytro's whites average many). 10 bits give Illum ``.raw`` +
        ``.txt`` files, 12 bits F01 ``.raw`` + ``.json``.
    lens : str or LensPrescription, optional
        A main-lens preset (``lfsim lenses``) or a design (a lens file's,
        :func:`simulator.config.lens_option`), rescaled to each setting's focal length (``whites.json``
        records a design by its table); None: the thin lens.
    spp, seed : int
        Samples per pixel of each white render and the render seed; setting ``k`` renders with
        seed ``seed + k`` and so draws its own noise.
    variant : str, optional
        Mitsuba variant.
    overwrite, progress : bool

    Returns
    -------
    list of dict
        The entries of ``whites.json``: ``file``, ``metadata_file``, ``lenses_file``,
        ``zoom_step``, ``focus_step``, ``focal_length_m``, ``focus_distance_m`` (null for
        infinity), ``lens_to_mla_m``, ``exit_pupil_offset_m``.

    Raises
    ------
    ParameterError
        Before anything is rendered, for a sensor of another bit depth than 10 or 12, an unknown
        lens, a seed range past 2**31, or a setting the camera cannot take.
    """
    bits = sensor.detector.bit_depth
    if bits not in (10, 12):
        raise ParameterError(f"sensor.bit_depth={bits}: Lytro white images hold 10-bit (Illum) or 12-bit (F01) counts")
    if isinstance(lens, str) and lens not in LENS_PRESETS:
        raise ParameterError(f"lens={lens!r} is not a lens preset ({', '.join(sorted(LENS_PRESETS))})")
    if lens is not None and not isinstance(lens, (str, LensPrescription)):
        raise ParameterError(f"lens must be a lens preset's name or a LensPrescription, got {shown(lens)}")
    check_white_seed(seed, len(settings))
    base = load_scene(embedded_scenes()["white"])
    configs = []
    for k, setting in enumerate(settings):
        cam = setting.camera(camera)
        configs.append(
            base.with_overrides(
                camera=cam,
                lens=None if lens is None else main_lens(lens, cam),
                render=RenderSettings(spp=spp, seed=seed + k),
            )
        )
    entries: list[dict] = []
    with staged_directory(out_dir, kind=WHITES_KIND, overwrite=overwrite) as stage:
        mi = backend.load_mitsuba(variant)
        for k, (setting, config) in enumerate(zip(settings, configs, strict=True)):
            cam = config.camera
            raw = render_raw(mi, config, progress=progress)
            mosaic = sensor_mosaic(raw, sensor, seed=config.render.seed)  # the settings keep the pixels and MLA
            zoom, focus = lens_steps(cam)
            pupil = None if config.lens is None else RealLensCamera(camera=cam, lens=config.lens).exit_pupil_distance_m
            lytro = lytro_settings(sensor.detector, exit_pupil_offset_m=pupil, zoom_step=zoom, focus_step=focus)
            stem = f"white_{k:03d}"
            if bits == 10:
                raw_path, meta_path = write_illum_raw(stage / f"{stem}.raw", mosaic, cam, settings=lytro)
            else:
                raw_path, meta_path = write_f01_raw(stage / f"{stem}.raw", mosaic, cam, settings=lytro)
            lenses_path = stage / f"{stem}.lenses.npz"
            with open(lenses_path, "wb") as handle:
                np.savez_compressed(handle, **groundtruth.lens_table(cam, config.lens))
            entries.append(
                {
                    "file": raw_path.name,
                    "metadata_file": meta_path.name,
                    "lenses_file": lenses_path.name,
                    "zoom_step": zoom,
                    "focus_step": focus,
                    "focal_length_m": cam.focal_length_m,
                    "focus_distance_m": None if math.isinf(setting.focus_distance_m) else setting.focus_distance_m,
                    "lens_to_mla_m": cam.lens_to_mla_m,
                    "exit_pupil_offset_m": cam.lens_to_mla_m if pupil is None else pupil,
                }
            )
        write_json(
            stage / WHITES_INDEX_NAME,
            {
                "kind": WHITES_KIND,
                "camera": camera.to_dict(),
                "lens": "thin" if lens is None else lens_record(lens),
                "sensor": sensor.to_dict(),
                "spp": spp,
                "seed": seed,
                "steps": "zoom_step: focal length in micrometres; focus_step: lens_to_mla_m - focal_length_m in "
                "micrometres (simulator.job.lens_steps)",
                "lfrefract": lfrefract.__version__,
                **backend.versions(),
                "whites": entries,
            },
        )
    return entries
