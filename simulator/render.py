"""Rendering in horizontal bands: bounded memory, a progress bar, reproducible seeds.

Mitsuba's memory grows with the pixels of one ``render`` call (about 50 B per pixel on top of
about 130 MB) and not with the samples per pixel, so a large raw image is rendered as bands of
at most ``max_band_pixels`` pixels through the film's crop window, each with its own sensor and
seed, into one preallocated array.
"""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType

import numpy as np
from tqdm.auto import tqdm

from lfrefract import ParameterError

__all__ = ["DEFAULT_MAX_BAND_PIXELS", "IDEAL_STREAM", "RAW_STREAM", "band_seed", "render_bands"]

#: Pixels per band: 8 Mpx keeps Mitsuba near 0.55 GB per band, so a full Illum raw (41.5 Mpx,
#: 6 bands) stays well inside 2.5 GB with the 0.5 GB output array.
DEFAULT_MAX_BAND_PIXELS = 8_000_000

SensorFactory = Callable[[tuple[int, int, int, int]], dict]


#: Seed streams: the raw and the ideal image draw independent samples from one job seed.
RAW_STREAM, IDEAL_STREAM = 0, 1


def band_seed(seed: int, band: int, stream: int = RAW_STREAM) -> int:
    """Sampler seed (32 bits) of band ``band`` of image stream ``stream`` for job seed ``seed``.

    ``numpy.random.SeedSequence([seed, stream, band])`` mixes the three, so neighbouring bands,
    streams and seeds get unrelated sample sequences.
    """
    return int(np.random.SeedSequence([seed, stream, band]).generate_state(1, dtype=np.uint32)[0])


def render_bands(
    mi: ModuleType,
    scene,
    sensor_for_crop: SensorFactory,
    width: int,
    height: int,
    *,
    spp: int,
    seed: int,
    max_band_pixels: int = DEFAULT_MAX_BAND_PIXELS,
    progress: bool = True,
    label: str = "render",
    stream: int = RAW_STREAM,
) -> np.ndarray:
    """Render an image band by band.

    Parameters
    ----------
    mi : module
        Mitsuba with a variant set.
    scene : mitsuba.Scene
    sensor_for_crop : callable
        Maps a crop ``(x, y, width, height)`` in pixels to a sensor dict with that crop window.
    width, height : int
        Full image size, pixels.
    spp : int
        Samples per pixel.
    seed : int
        Job seed; band ``b`` uses :func:`band_seed` ``(seed, b, stream)``.
    max_band_pixels : int
        Upper bound on the pixels of one band (at least one row is rendered per band).
    progress : bool
        Show a progress bar (rows).
    label : str
        Progress bar label.
    stream : int
        Seed stream (:data:`RAW_STREAM`, :data:`IDEAL_STREAM`).

    Returns
    -------
    ndarray, float32, shape (height, width, 3)
    """
    if max_band_pixels <= 0:
        raise ParameterError(f"max_band_pixels must be positive, got {max_band_pixels!r}")
    rows = max(1, min(height, max_band_pixels // width))
    out = np.empty((height, width, 3), dtype=np.float32)
    with tqdm(total=height, desc=label, unit="row", disable=not progress, leave=False) as bar:
        for band, y0 in enumerate(range(0, height, rows)):
            h = min(rows, height - y0)
            sensor = mi.load_dict(sensor_for_crop((0, y0, width, h)))
            image = mi.render(scene, sensor=sensor, spp=spp, seed=band_seed(seed, band, stream))
            out[y0 : y0 + h] = np.asarray(image, dtype=np.float32)[:, :, :3]
            del image, sensor
            bar.update(h)
    import drjit as dr

    dr.flush_malloc_cache()  # hand the band buffers back before the caller writes files
    return out
