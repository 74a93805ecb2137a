"""Regenerate the figures in docs/figures/ from fresh renders (a few minutes on 2 cores).

    python docs/make_figures.py [--camera f01] [--spp 16]

Renders the embedded default scene with the given camera and the white scene with the same
camera, then writes: raw_crop.png (raw lenslet image at native resolution, centre crop),
raw_full.png (downsampled), ideal.png, depth.png, white_crop.png (white image with the model's
micro-image centres), readme.png (the README's banner).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import matplotlib as mpl
import numpy as np

mpl.use("Agg")
import matplotlib.pyplot as plt

from lfrefract import camera_preset
from lfrefract.io import read_exr, read_json
from simulator.config import RenderSettings, embedded_scenes, load_scene
from simulator.job import render_job
from simulator.previews import display_rgb, downsample, white_level

FIGURES = Path(__file__).resolve().parent / "figures"


def _crop(img: np.ndarray, centre: tuple[int, int], half: int) -> np.ndarray:
    cy, cx = centre
    return img[cy - half : cy + half, cx - half : cx + half]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--camera", default="f01")
    parser.add_argument("--spp", type=int, default=16)
    args = parser.parse_args()
    FIGURES.mkdir(exist_ok=True)
    camera = camera_preset(args.camera)
    with tempfile.TemporaryDirectory() as tmp:
        scene = load_scene().with_overrides(camera=camera, render=RenderSettings(spp=args.spp, seed=0))
        render_job(scene, Path(tmp) / "scene", write_previews=False)
        white = load_scene(embedded_scenes()["white"]).with_overrides(
            camera=camera, render=RenderSettings(spp=args.spp, seed=0)
        )
        render_job(white, Path(tmp) / "white", write_previews=False)
        raw = read_exr(Path(tmp) / "scene" / "raw.exr", role="raw")
        ideal = read_exr(Path(tmp) / "scene" / "ideal.exr", role="ideal")
        depth = read_exr(Path(tmp) / "scene" / "depth.exr", role="depth")
        white_raw = read_exr(Path(tmp) / "white" / "raw.exr", role="raw").mean(axis=2)
        lenses = np.load(Path(tmp) / "white" / "lenses.npz")
        meta = read_json(Path(tmp) / "scene" / "meta.json")

    level = white_level(raw)
    h, w = raw.shape[:2]
    half = int(12 * camera.micro_image_pitch_px)
    crop = _crop(raw, (h // 2, w // 2), half)
    plt.imsave(FIGURES / "raw_crop.png", display_rgb(crop, white=level))
    small = downsample(raw, 800)
    plt.imsave(FIGURES / "raw_full.png", display_rgb(small, white=level))
    plt.imsave(FIGURES / "ideal.png", display_rgb(ideal))

    fig, ax = plt.subplots(figsize=(5.5, 5.0), dpi=110)
    im = ax.imshow(np.where(np.isfinite(depth), depth, np.nan), cmap="viridis")
    ax.set_title("ground-truth depth, camera-frame z [m]")
    ax.set_axis_off()
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    fig.savefig(FIGURES / "depth.png", bbox_inches="tight")
    plt.close(fig)

    # White image near the top-left corner, where micro-image centres are far from lens centres.
    centres = lenses["micro_image_centre_px"]
    corner = (int(6 * camera.micro_image_pitch_px), int(6 * camera.micro_image_pitch_px))
    wh = int(4 * camera.micro_image_pitch_px)
    patch = white_raw[corner[0] - wh : corner[0] + wh, corner[1] - wh : corner[1] + wh]
    fig, ax = plt.subplots(figsize=(5, 5), dpi=110)
    ax.imshow(
        patch,
        cmap="gray",
        extent=(corner[1] - wh - 0.5, corner[1] + wh - 0.5, corner[0] + wh - 0.5, corner[0] - wh - 0.5),
    )
    lens_px = camera.sensor.image_plane_to_pixels(lenses["lens_centre_m"])
    sel = (np.abs(centres[:, 0] - corner[1]) < wh) & (np.abs(centres[:, 1] - corner[0]) < wh)
    ax.plot(centres[sel, 0], centres[sel, 1], "r+", ms=9, label="micro-image centre (model)")
    ax.plot(lens_px[sel, 0], lens_px[sel, 1], "c.", ms=5, label="below the lens centre")
    ax.set_xlim(corner[1] - wh - 0.5, corner[1] + wh - 0.5)
    ax.set_ylim(corner[0] + wh - 0.5, corner[0] - wh - 0.5)
    ax.legend(loc="lower right", fontsize=8, framealpha=0.9)
    ax.set_title(f"white image, {args.camera}, near the top-left corner")
    fig.savefig(FIGURES / "white_crop.png", bbox_inches="tight")
    plt.close(fig)

    fig, axes = plt.subplots(1, 3, figsize=(12, 4.2), dpi=100)
    axes[0].imshow(display_rgb(_crop(raw, (h // 2, w // 2), int(6 * camera.micro_image_pitch_px)), white=level))
    axes[0].set_title("raw lenslet image (centre crop)")
    axes[1].imshow(display_rgb(ideal))
    axes[1].set_title("ideal refraction-free image")
    axes[2].imshow(np.where(np.isfinite(depth), depth, np.nan), cmap="viridis")
    axes[2].set_title("ground-truth depth")
    for ax in axes:
        ax.set_axis_off()
    fig.suptitle(f"{args.camera} camera behind a {meta['port']['total_tilt_deg']:.0f} deg port, {args.spp} spp")
    fig.savefig(FIGURES / "readme.png", bbox_inches="tight")
    plt.close(fig)
    print(f"wrote figures to {FIGURES}")


if __name__ == "__main__":
    main()
