"""PNG figures of a render for people: raw (whole and a native-resolution crop), ideal, depth."""

from __future__ import annotations

from pathlib import Path

import matplotlib as mpl
import numpy as np

from lfrefract import FlatPort, LightFieldCamera
from lfrefract.figures import NO_VALUE_RGB, new_figure, pixel_axes, port_setup, save_figure

mpl.use("Agg")
import matplotlib.pyplot as plt

__all__ = ["depth_figure", "display_rgb", "downsample", "white_level", "write_all"]

#: Longest side of the downsampled whole-raw preview, pixels.
PREVIEW_MAX_SIDE_PX = 1600
#: Side of the native-resolution raw crop, in micro-images.
CROP_MICRO_IMAGES = 24


def display_rgb(image: np.ndarray, *, white: float | None = None) -> np.ndarray:
    """Linear radiance (H, W, 3) to display sRGB-ish uint8: scale to ``white``, clip, gamma 2.2.

    ``white`` defaults to :func:`white_level` of the image.
    """
    img = np.nan_to_num(np.asarray(image, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    if white is None:
        white = white_level(img)
    return (np.clip(img / white, 0.0, 1.0) ** (1.0 / 2.2) * 255.0 + 0.5).astype(np.uint8)


def white_level(image: np.ndarray, *, max_samples: int = 1_000_000) -> float:
    """99.5th percentile of the finite values (on a regular subsample of at most ``max_samples``
    pixels, so a 41 Mpx raw needs no full-size copy); 1.0 for an image with nothing above 0."""
    step = max(1, int(np.sqrt(image.shape[0] * image.shape[1] / max_samples)))
    sample = np.asarray(image[::step, ::step], dtype=np.float32)
    sample = sample[np.isfinite(sample)]
    level = float(np.percentile(sample, 99.5)) if sample.size else 0.0
    return level if level > 0.0 else 1.0


def downsample(img: np.ndarray, max_side: int) -> np.ndarray:
    """Box-average ``img`` (H, W, C) by a whole factor so its longer side is at most ``max_side``."""
    step = int(np.ceil(max(img.shape[:2]) / max_side))
    if step <= 1:
        return img
    h, w = (img.shape[0] // step) * step, (img.shape[1] // step) * step
    return img[:h, :w].reshape(h // step, step, w // step, step, -1).mean(axis=(1, 3))


#: Smallest side of a preview of a small image (the tiny camera's ideal image is 92 x 69 px).
PREVIEW_MIN_SIDE_PX = 400


def _enlarge(img: np.ndarray, min_side: int = PREVIEW_MIN_SIDE_PX) -> np.ndarray:
    """Nearest-neighbour enlargement by a whole factor so the shorter side reaches ``min_side``."""
    factor = int(np.ceil(min_side / min(img.shape[:2])))
    return img if factor <= 1 else np.repeat(np.repeat(img, factor, axis=0), factor, axis=1)


def depth_figure(depth_m: np.ndarray, *, setup: str):
    """The ground-truth depth preview (``depth.png``) as a Figure: camera-frame z with its colour bar in
    metres, pixel axes, the set-up in the title, and pixels with no surface (+inf) grey with a legend."""
    from matplotlib.patches import Patch

    height, width = depth_m.shape
    fig = new_figure(6.4, 5.2 * height / width + 1.9)
    ax = fig.subplots()
    colours = mpl.colormaps["viridis"].with_extremes(bad=NO_VALUE_RGB)
    im = ax.imshow(np.where(np.isfinite(depth_m), depth_m, np.nan), cmap=colours, interpolation="nearest")
    ax.set_title("ground-truth depth of the ideal image")
    pixel_axes(ax)
    fig.colorbar(im, ax=ax, shrink=0.9).set_label("depth: camera-frame z (m)")
    no_surface = Patch(facecolor=NO_VALUE_RGB, edgecolor="0.3", label="no surface")
    fig.legend(handles=[no_surface], loc="outside lower center", fontsize=9)
    fig.suptitle(setup, fontsize=9)
    return fig


def write_all(
    folder: Path,
    *,
    raw: np.ndarray,
    ideal: np.ndarray,
    depth_m: np.ndarray,
    camera: LightFieldCamera,
    port: FlatPort | None = None,
    scene: str | None = None,
) -> list[Path]:
    """Write ``raw.png``, ``raw_crop.png``, ``ideal.png`` and ``depth.png`` into ``folder``; ``port``
    and ``scene`` (its name) go into the depth figure's title."""
    folder.mkdir(parents=True, exist_ok=True)
    white = white_level(raw)
    written = []
    plt.imsave(folder / "raw.png", display_rgb(downsample(raw, PREVIEW_MAX_SIDE_PX), white=white))
    written.append(folder / "raw.png")
    half = int(CROP_MICRO_IMAGES * camera.micro_image_pitch_px / 2)
    cy, cx = raw.shape[0] // 2, raw.shape[1] // 2
    crop = raw[max(0, cy - half) : cy + half, max(0, cx - half) : cx + half]
    plt.imsave(folder / "raw_crop.png", display_rgb(crop, white=white))
    written.append(folder / "raw_crop.png")
    plt.imsave(folder / "ideal.png", _enlarge(display_rgb(ideal)))
    written.append(folder / "ideal.png")
    setup = port_setup(camera, port) if scene is None else f"{scene!r} scene, {port_setup(camera, port)}"
    save_figure(depth_figure(depth_m, setup=setup), folder / "depth.png")
    written.append(folder / "depth.png")
    return written
