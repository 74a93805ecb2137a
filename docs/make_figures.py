"""Regenerate the figures in docs/figures/ from fresh renders (a few minutes on 2 cores).

    python docs/make_figures.py [--only readme simulator synthesis diagram mla] [--camera f01] [--spp 16]
                                [--synthesis-spp 64]

Renders the embedded default scene (and, for the simulator figures, the white scene) with the given
camera and writes:

* ``simulator``: raw_crop.png (raw lenslet image at native resolution, centre crop), raw_full.png
  (downsampled), ideal.png, depth.png, white_crop.png (white image with the model's micro-image
  centres); figures of docs/simulator.md.
* ``readme``: readme.png, the README's hero figure: raw crop, naive central view, the refraction-free
  image ``lfrefract synth`` writes from the same render (default options) and the ground-truth
  depth with a colour bar; rendered at ``--synthesis-spp``.
* ``synthesis``: synthesis_panel.png (raw crop, naive central view, synthesized image, ideal image,
  difference, coverage) and synthesis_k.png (k = 1, 8, 64 beside the ideal image, PSNR / SSIM in
  the exact coverage); figures of docs/synthesis.md. Prints the measurements and timings quoted
  there.
* ``diagram``: synthesis_diagram.png, a side view of the method (no render).
* ``mla``: mla_calibration.png, MLA calibration from a white image (detected lattice over a crop at
  the corner, errors against ground truth); figure of docs/calibration.md. Prints the accuracy.
* ``port``: port_noise.png (synthetic views, error against corner noise) and port_renders.png
  (rendered boards: light-field corners and the port at three tilts, as the tests); figures of
  docs/calibration.md. Prints the measurements.
* ``dataset``: dataset_tilt.png, a tilt sweep (0, 10, 20, 30 deg; tiny-2x camera) rendered by
  ``lfsim dataset run``'s engine on two local workers and read back with the dataset loader: raw
  image, raw crop, refraction-free image and ideal image per tilt; figure of docs/datasets.md.

By default all parts; ``--only synthesis`` regenerates just the synthesis figures.
"""

from __future__ import annotations

import argparse
import io
import math
import tempfile
import time
from pathlib import Path

import cv2
import matplotlib as mpl
import numpy as np
from PIL import Image

mpl.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.colors import ListedColormap
from matplotlib.patches import Ellipse, Patch, Polygon

from lfrefract import camera_preset
from lfrefract.calibration.mla import LENS_STATUS, calibrate_mla
from lfrefract.formats.capture import DEPTH_NAME, IDEAL_NAME, RAW_NAME
from lfrefract.formats.exr import read_exr
from lfrefract.metrics import psnr, shift_px, ssim
from lfrefract.optics.camera import LightFieldCamera, MicrolensArray, SensorGeometry
from lfrefract.optics.port import FlatPort
from lfrefract.synthesis.views import naive_view
from lfrefract.synthesis.warp_map import PAPER_K, SynthesisOptions, WarpMap, build_warp_map
from simulator.config import RenderSettings, SceneConfig, embedded_scenes, load_scene
from simulator.job import render_job
from simulator.previews import display_rgb, downsample, white_level

FIGURES = Path(__file__).resolve().parent / "figures"
PARTS = ("readme", "simulator", "synthesis", "diagram", "mla", "port", "dataset")

#: The k of the side-by-side figure (paper Fig. 9).
K_VALUES = (1, 8, 64)
#: Crop of the side-by-side figure as fractions of the output image: (top, left, height, width).
#: In the default scene it holds the chessboard's top rows and the textured backdrop above them,
#: inside the exact coverage of the 20 deg port.
K_CROP = (0.09, 0.38, 0.22, 0.3)
#: Side of the raw crop of the synthesis panel, in micro-image pitches.
RAW_CROP_MICRO_IMAGES = 16
#: Grey for output pixels that have no value (no captured ray, or outside the naive view's hull).
NO_VALUE_RGB = np.array([150, 150, 150], dtype=np.uint8)


# ----------------------------------------------------------------------------------- helpers
def _crop(img: np.ndarray, centre: tuple[int, int], half: int) -> np.ndarray:
    cy, cx = centre
    return img[max(cy - half, 0) : cy + half, max(cx - half, 0) : cx + half]


def _save(fig: plt.Figure, path: Path, *, dpi: int = 100, colours: int | None = 256) -> None:
    """Save ``fig`` as PNG; with ``colours`` as a palette image (much smaller, no visible loss)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    buffer.seek(0)
    image = Image.open(buffer).convert("RGB")
    if colours is not None:  # an octree palette, then Floyd-Steinberg dithering onto it (smooth colour bars)
        palette = image.quantize(colors=colours, method=Image.Quantize.FASTOCTREE)
        image = image.quantize(palette=palette, dither=Image.Dither.FLOYDSTEINBERG)
    image.save(path, optimize=True)
    print(f"  {path.name}: {image.size[0]} x {image.size[1]} px, {path.stat().st_size / 1024:.0f} KB")


def _render(config: SceneConfig, folder: Path) -> float:
    """Render ``config`` into ``folder`` (raw, ideal, depth, lenses, meta); return the seconds."""
    start = time.perf_counter()
    render_job(config, folder, write_previews=False, progress=False)
    return time.perf_counter() - start


def _shown(image: np.ndarray, valid: np.ndarray, white: float) -> np.ndarray:
    """Display RGB of linear ``image`` scaled to ``white``, grey where not ``valid``."""
    rgb = display_rgb(np.where(valid[..., None], image, 0.0), white=white)
    rgb[~valid] = NO_VALUE_RGB
    return rgb


# ----------------------------------------------------------------------- simulator figures
def simulator_figures(camera_name: str, spp: int) -> None:
    """raw_crop, raw_full, ideal, depth and white_crop PNGs (docs/simulator.md)."""
    camera = camera_preset(camera_name)
    with tempfile.TemporaryDirectory() as tmp:
        scene = load_scene().with_overrides(camera=camera, render=RenderSettings(spp=spp, seed=0))
        _render(scene, Path(tmp) / "scene")
        white = load_scene(embedded_scenes()["white"]).with_overrides(
            camera=camera, render=RenderSettings(spp=spp, seed=0)
        )
        _render(white, Path(tmp) / "white")
        raw = read_exr(Path(tmp) / "scene" / "raw.exr", role="raw")
        ideal = read_exr(Path(tmp) / "scene" / "ideal.exr", role="ideal")
        depth = read_exr(Path(tmp) / "scene" / "depth.exr", role="depth")
        white_raw = read_exr(Path(tmp) / "white" / "raw.exr", role="raw").mean(axis=2)
        lenses = np.load(Path(tmp) / "white" / "lenses.npz")

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
    ax.set_title(f"white image, {camera_name}, near the top-left corner")
    fig.savefig(FIGURES / "white_crop.png", bbox_inches="tight")
    plt.close(fig)


# ----------------------------------------------------------------------- README hero figure
def readme_figure(camera_name: str, spp: int) -> None:
    """readme.png, the README's hero figure: raw crop, naive central view, the refraction-free image
    that ``lfrefract synth`` writes (default options), and the ground-truth depth with a colour bar."""
    from lfrefract import cli

    camera = camera_preset(camera_name)
    scene = load_scene().with_overrides(camera=camera, render=RenderSettings(spp=spp, seed=0))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "scene"
        seconds = _render(scene, folder)
        start = time.perf_counter()
        out = Path(tmp) / "synth" / "synth.exr"
        if cli.main(["synth", str(folder / RAW_NAME), "--out", str(out), "--quiet"]) != 0:
            raise RuntimeError("lfrefract synth failed on the hero render")
        synth_seconds = time.perf_counter() - start
        synthesized = read_exr(out, role="refraction_free")
        coverage = read_exr(out.with_suffix(".coverage.exr"), role="coverage")
        raw = read_exr(folder / RAW_NAME, role="raw")
        ideal = read_exr(folder / IDEAL_NAME, role="ideal")
        depth = read_exr(folder / DEPTH_NAME, role="depth")
    port = scene.port
    print(
        f"readme: {camera_name} camera, {spp} spp, port {math.degrees(port.total_tilt_rad):.0f} deg: rendered in "
        f"{seconds:.1f} s, lfrefract synth (map build and apply) {synth_seconds:.1f} s"
    )
    peak = float(np.percentile(ideal, 99.5))  # one display scale for the three images
    filled = np.any(synthesized > 0, axis=2)
    exact = coverage >= 1.0
    naive = naive_view(camera, raw)
    naive_ok = np.all(np.isfinite(naive), axis=2)
    both = exact & naive_ok
    gain = float(ideal[both].mean() / naive[both].mean())  # radiance in air vs in the water: display only
    h, w = raw.shape[:2]
    level = white_level(raw)
    raw_crop = _crop(raw, (h // 2, w // 2), int(6 * camera.micro_image_pitch_px))

    fig, axes = plt.subplots(1, 4, figsize=(17, 4.6), dpi=100, gridspec_kw={"width_ratios": [1, 1, 1, 1.12]})
    axes[0].imshow(display_rgb(raw_crop, white=level), interpolation="nearest")
    axes[0].set_title(f"raw lenslet image, centre crop\n{raw_crop.shape[1]} x {raw_crop.shape[0]} of {w} x {h} px")
    axes[1].imshow(_shown(naive * gain, naive_ok, peak))
    axes[1].set_title("naive central view\n(no refraction handling)")
    axes[2].imshow(_shown(synthesized, filled, peak))
    axes[2].contour(exact, [0.5], colors="white", linewidths=0.8, linestyles="dashed")
    axes[2].set_title("lfrefract synth (refraction-free)\ndashed: edge of exact coverage")
    im = axes[3].imshow(np.where(np.isfinite(depth), depth, np.nan), cmap="viridis")
    axes[3].set_title("ground-truth depth\n(the output's geometry)")
    bar = fig.colorbar(im, ax=axes[3], fraction=0.046, pad=0.03)
    bar.set_label("depth: camera-frame z [m]")
    for ax in axes:
        ax.set_axis_off()
    fig.suptitle(
        f"{camera_name} camera behind a flat port tilted {math.degrees(port.total_tilt_rad):.0f} deg "
        f"({port.thickness_m * 1e3:.0f} mm glass, {port.distance_m * 1e3:.0f} mm from the lens, water n = "
        f"{port.n_water:g}), {spp} spp"
    )
    _save(fig, FIGURES / "readme.png")


# ----------------------------------------------------------------------- synthesis figures
def _row_centroids_px(warp: WarpMap) -> np.ndarray:
    """Weighted mean raw position (u, v) of each output pixel's CSR row, shape (H, W, 2); NaN if empty."""
    counts = np.diff(warp.indptr)
    rows = np.repeat(np.arange(len(counts)), counts)
    width = warp.raw_shape[1]
    u = np.bincount(rows, weights=warp.weights * (warp.indices % width), minlength=len(counts))
    v = np.bincount(rows, weights=warp.weights * (warp.indices // width), minlength=len(counts))
    total = np.bincount(rows, weights=warp.weights, minlength=len(counts))
    with np.errstate(invalid="ignore", divide="ignore"):
        uv = np.stack([u / total, v / total], axis=1)
    return uv.reshape(warp.output.height_px, warp.output.width_px, 2)


def _k_crop(shape: tuple[int, int]) -> tuple[slice, slice]:
    h, w = shape
    top, left, height, width = K_CROP
    return slice(round(top * h), round((top + height) * h)), slice(round(left * w), round((left + width) * w))


def _scores(image: np.ndarray, ideal: np.ndarray, mask: np.ndarray, peak: float) -> tuple[float, float]:
    return psnr(image, ideal, data_range=peak, mask=mask), ssim(image, ideal, data_range=peak, mask=mask)


def synthesis_figures(camera_name: str, spp: int) -> None:
    """synthesis_panel.png and synthesis_k.png from a render of the default scene; prints the numbers."""
    camera = camera_preset(camera_name)
    scene = load_scene().with_overrides(camera=camera, render=RenderSettings(spp=spp, seed=0))
    port = scene.port
    with tempfile.TemporaryDirectory() as tmp:
        seconds = _render(scene, Path(tmp) / "scene")
        raw = read_exr(Path(tmp) / "scene" / "raw.exr", role="raw")
        ideal = read_exr(Path(tmp) / "scene" / "ideal.exr", role="ideal")
    print(
        f"default scene, {camera_name} camera ({raw.shape[1]} x {raw.shape[0]} raw px, "
        f"{ideal.shape[1]} x {ideal.shape[0]} output px), {spp} spp, port {math.degrees(port.total_tilt_rad):.0f} deg "
        f"at {port.distance_m * 1e3:.0f} mm, {port.thickness_m * 1e3:.0f} mm glass: rendered in {seconds:.1f} s"
    )
    peak = float(np.percentile(ideal, 99.5))

    k_panel = PAPER_K  # the panel of docs/synthesis.md shows the paper's k
    images, filled, scores = {}, {}, {}
    for k in sorted({*K_VALUES, k_panel}):
        start = time.perf_counter()
        warp_k = build_warp_map(camera, port, options=SynthesisOptions(k=k))
        built = time.perf_counter() - start
        start = time.perf_counter()
        images[k] = warp_k.apply(raw)
        applied = time.perf_counter() - start
        filled[k] = warp_k.filled
        scores[k] = _scores(images[k], ideal, warp_k.exact, peak)
        dx, dy = shift_px(images[k], ideal, mask=warp_k.exact)
        print(
            f"  k = {k:2d}: PSNR {scores[k][0]:.2f} dB, SSIM {scores[k][1]:.3f}, shift ({dx:+.2f}, {dy:+.2f}) px "
            f"(exact coverage); map build {built:.1f} s, apply {applied * 1e3:.0f} ms, "
            f"{len(warp_k.indices) / 1e6:.1f} M non-zeros"
        )
        if k == k_panel:
            warp = warp_k
        del warp_k
    exact = warp.exact
    print(f"  coverage: exact {exact.mean():.1%} of the output pixels, filled {warp.filled.mean():.1%}")

    start = time.perf_counter()
    naive = naive_view(camera, raw)
    naive_seconds = time.perf_counter() - start
    naive_ok = np.all(np.isfinite(naive), axis=2)
    both = exact & naive_ok
    gain = float(ideal[both].mean() / naive[both].mean())
    shown = np.where(naive_ok[..., None], naive * gain, 0.0)
    p, s = _scores(shown, ideal, both, peak)
    print(
        f"  naive central view x {gain:.3f} (ideal mean / naive mean in the exact coverage): PSNR {p:.2f} dB, "
        f"SSIM {s:.3f} (exact coverage); {naive_seconds:.1f} s"
    )
    _synthesis_panel(camera, raw, ideal, images[k_panel], (naive, naive_ok, gain), warp, peak, camera_name, spp)
    _synthesis_k({k: (images[k], filled[k], scores[k]) for k in K_VALUES}, ideal, peak, camera_name, spp)


def _synthesis_panel(
    camera: LightFieldCamera,
    raw: np.ndarray,
    ideal: np.ndarray,
    synth: np.ndarray,
    naive_view_gain: tuple[np.ndarray, np.ndarray, float],
    warp: WarpMap,
    peak: float,
    camera_name: str,
    spp: int,
) -> None:
    exact, filled = warp.exact, warp.filled
    naive, naive_ok, gain = naive_view_gain
    # The raw crop: around the raw pixels that feed the strongest corner (Harris) of the ideal image
    # inside the side-by-side crop and the exact coverage.
    rows, cols = _k_crop(ideal.shape[:2])
    harris = cv2.cornerHarris(ideal.mean(axis=2).astype(np.float32), 5, 3, 0.05)
    inside = np.zeros(exact.shape, dtype=bool)
    inside[rows, cols] = True
    centre = np.unravel_index(np.argmax(np.where(inside & exact, harris, -np.inf)), exact.shape)
    centroids = _row_centroids_px(warp)
    cu, cv = centroids[centre]
    half = int(RAW_CROP_MICRO_IMAGES * camera.micro_image_pitch_px / 2)
    u0, v0 = max(round(cu) - half, 0), max(round(cv) - half, 0)
    raw_crop = raw[v0 : v0 + 2 * half, u0 : u0 + 2 * half]
    # Output pixels fed mainly from inside the raw crop.
    fed = (
        (centroids[..., 0] >= u0)
        & (centroids[..., 0] < u0 + 2 * half)
        & (centroids[..., 1] >= v0)
        & (centroids[..., 1] < v0 + 2 * half)
    )

    fig, axes = plt.subplots(2, 3, figsize=(15, 10.4))
    ax = axes[0, 0]
    ax.imshow(display_rgb(raw_crop, white=white_level(raw)), interpolation="nearest")
    ax.set_title(f"raw lenslet image, {2 * half} x {2 * half} px crop\n(native pixels; feeds the red box, top right)")
    ax = axes[0, 1]
    ax.imshow(_shown(naive * gain, naive_ok, peak))
    ax.set_title(f"naive central view (no refraction handling)\nradiance in air x {gain:.2f} (to the ideal's mean)")
    ax = axes[0, 2]
    ax.imshow(_shown(synth, filled, peak))
    ax.contour(fed, [0.5], colors="red", linewidths=1.2)
    ax.set_title(f"synthesized, k = {warp.meta['options']['k']}\n(radiance in the water)")
    ax = axes[1, 0]
    ax.imshow(_shown(ideal, np.ones(exact.shape, dtype=bool), peak))
    ax.set_title("ideal image (simulator ground truth)")

    ax = axes[1, 1]
    diff = np.abs(synth - ideal).mean(axis=2) / peak
    cmap = plt.get_cmap("magma").copy()
    cmap.set_bad(NO_VALUE_RGB / 255.0)
    im = ax.imshow(np.where(filled, diff, np.nan), cmap=cmap, vmin=0.0, vmax=0.3, interpolation="nearest")
    fig.colorbar(
        im, ax=ax, fraction=0.046, pad=0.03, extend="max", label="|synthesized - ideal| / ideal's 99.5th percentile"
    )
    ax.set_title("difference (channel mean)")

    ax = axes[1, 2]
    classes = np.where(exact, 2, np.where(filled, 1, 0))
    colours = ["#3b3b3b", "#f2b233", "#3a9bd9"]
    ax.imshow(classes, cmap=ListedColormap(colours), vmin=-0.5, vmax=2.5, interpolation="nearest")
    ax.legend(
        handles=[
            Patch(color=colours[2], label=f"exact: every necessary ray recorded ({exact.mean():.0%})"),
            Patch(color=colours[1], label=f"approximated: nearby rays ({(filled & ~exact).mean():.0%})"),
            Patch(color=colours[0], label=f"empty: no captured ray ({(~filled).mean():.0%})"),
        ],
        loc="lower center",
        fontsize=9,
        framealpha=0.95,
    )
    ax.set_title("coverage of the output pixels")
    for ax in axes.flat[1:]:
        ax.contour(exact, [0.5], colors="white", linewidths=0.8, linestyles="dashed")
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(
        f"default scene, {camera_name} camera, {spp} spp, port tilted "
        f"{warp.meta['port']['total_tilt_deg']:.0f} deg; dashed: edge of the exact coverage; grey: no value",
        fontsize=13,
    )
    fig.tight_layout()
    _save(fig, FIGURES / "synthesis_panel.png", dpi=80)


def _synthesis_k(
    results: dict[int, tuple[np.ndarray, np.ndarray, tuple[float, float]]],
    ideal: np.ndarray,
    peak: float,
    camera_name: str,
    spp: int,
) -> None:
    """``results``: per k, the synthesized image, its filled mask and (PSNR, SSIM)."""
    rows, cols = _k_crop(ideal.shape[:2])
    panels = [
        (image, valid, f"k = {k}\nPSNR {p:.1f} dB, SSIM {s:.3f}") for k, (image, valid, (p, s)) in results.items()
    ]
    panels.append((ideal, np.ones(ideal.shape[:2], dtype=bool), "ideal image"))
    aspect = (rows.stop - rows.start) / (cols.stop - cols.start)
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.2 * aspect + 0.9))
    for ax, (image, valid, title) in zip(axes, panels, strict=True):
        ax.imshow(_shown(image, valid, peak)[rows, cols], interpolation="nearest")
        ax.set_title(title)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(
        f"the k nearest captured rays averaged (default scene, {camera_name}, {spp} spp; "
        "PSNR and SSIM against the ideal image over the whole exact coverage)"
    )
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    _save(fig, FIGURES / "synthesis_k.png", dpi=90)


# ---------------------------------------------------------------------------- the diagram
def _sketch_camera() -> LightFieldCamera:
    """A camera with the microlenses, their gap and the pixels enlarged so they show in a sketch."""
    return LightFieldCamera(
        name="sketch",
        focal_length_m=6e-3,
        lens_to_mla_m=6e-3,
        f_number=2.0,
        mla=MicrolensArray(grid="square", pitch_m=0.5e-3, focal_length_m=1e-3),
        sensor=SensorGeometry(width_px=1, height_px=81, pixel_pitch_m=0.1e-3),
    )


def _face_line(port: FlatPort, offset: float, y_range: tuple[float, float]) -> np.ndarray:
    """Two (z, y) points of the port face ``n . X = offset`` in the y-z plane (n_x = 0)."""
    n = port.normal
    y = np.asarray(y_range)
    return np.stack([(offset - n[1] * y) / n[2], y], axis=1)


def diagram_figure() -> None:
    """synthesis_diagram.png: the necessary ray, its exact path back through the port, candidates."""
    camera = _sketch_camera()
    port = FlatPort.from_degrees(distance_m=5e-3, thickness_m=2.5e-3, tilt_x_deg=20.0)
    lam = SynthesisOptions().lambda_m_per_rad
    f, f_prime, f_mla = camera.focal_length_m, camera.lens_to_mla_m, camera.mla.focal_length_m
    mm = 1e3
    z_end = 15.5e-3

    def line_of_sight(y_slope: float) -> dict:
        """The necessary ray of a line of sight (0, y_slope, 1) and its exact path to the sensor."""
        r = np.array([0.0, y_slope, 1.0]) / math.hypot(y_slope, 1.0)
        q = r * (port.distance_m + port.thickness_m) / float(r @ port.normal)  # on the water face
        trace = port.trace_from_water(q[None], -r[None])
        p, r_a = trace.exit_points_cam[0], -trace.directions_cam[0]
        hit = p - (p[2] / r_a[2]) * r_a  # on the main lens, z = 0
        slope_in = r_a[1] / r_a[2] + hit[1] / f  # behind the lens, towards +z
        mla = np.array([0.0, hit[1] - slope_in * f_prime, -f_prime])
        lens = -camera.mla.centres_m(camera.mla.nearest_indices(-mla[None, :2]))[0, 1]
        sensor = np.array([0.0, lens - slope_in * f_mla, camera.sensor_z_m])
        return {"r": r, "q": q, "p": p, "r_a": r_a, "hit": hit, "mla": mla, "sensor": sensor}

    main = line_of_sight(0.12)
    missed = line_of_sight(0.36)
    if abs(main["hit"][1]) > camera.aperture_radius_m or abs(missed["hit"][1]) <= camera.aperture_radius_m:
        raise RuntimeError("the sketch's lines of sight no longer pass / miss the aperture as drawn")

    # Captured rays (pixel centre -> its microlens centre -> main lens): every pixel under the
    # necessary ray's microlens and its two neighbours; D against the necessary air ray.
    v_centre = camera.sensor.image_plane_to_pixels(-main["sensor"][None, :2])[0, 1]
    v = np.arange(round(v_centre) - 7, round(v_centre) + 8)
    uv = np.stack([np.zeros(len(v)), v], axis=1).astype(np.float64)
    rays = camera.captured_rays(uv)
    o, d = rays.origins_cam, rays.directions_cam
    p_prime = o + ((port.distance_m - o @ port.normal) / (d @ port.normal))[:, None] * d
    angle = np.arccos(np.clip(d @ main["r_a"], -1.0, 1.0))
    dist = np.linalg.norm(p_prime - main["p"], axis=1) + lam * angle
    dist[~rays.in_aperture] = np.inf
    order = np.argsort(dist)
    best = list(order[:3])  # the three nearest, then the nearest under each other microlens
    lens_key = rays.lens_indices[:, 1]
    for key in np.unique(lens_key[np.isfinite(dist)]):
        if key not in lens_key[best]:
            best.append(order[np.flatnonzero(lens_key[order] == key)[0]])

    fig, ax = plt.subplots(figsize=(13, 8.2))

    def pt(x: np.ndarray) -> tuple[float, float]:
        return x[2] * mm, -x[1] * mm

    def path(points: list[np.ndarray], **kwargs) -> None:
        zs, ys = zip(*(pt(x) for x in points), strict=True)
        ax.plot(zs, ys, **kwargs)

    # Media: the glass slab between the faces, water beyond.
    n = port.normal

    def face(offset: float, y: float) -> np.ndarray:
        return np.array([0.0, y, (offset - n[1] * y) / n[2]])

    y_top, y_bottom = -5.0e-3, 5.0e-3  # camera-frame y (down)
    air_face = [face(port.distance_m, y) for y in (y_top, y_bottom)]
    water_face = [face(port.distance_m + port.thickness_m, y) for y in (y_top, y_bottom)]
    corners = [np.array([0.0, y, z_end]) for y in (y_bottom, y_top)]
    ax.add_patch(Polygon([pt(x) for x in [*air_face, *water_face[::-1]]], color="#c9dfe3", zorder=0))
    ax.add_patch(Polygon([pt(x) for x in [*water_face, *corners]], color="#dcebfb", zorder=0))
    for line in (air_face, water_face):
        path(line, color="#4a7f8c", lw=1.5)
    ax.text(1.8, 4.4, f"air  n = {port.n_air}", fontsize=12, ha="center")
    z_glass, y_glass = pt(face(port.distance_m + port.thickness_m / 2, -3.9e-3))
    ax.text(z_glass, y_glass, f"glass\nn = {port.n_glass}", fontsize=12, ha="center", va="center")
    ax.text(12.5, 4.4, f"water  n = {port.n_water}", fontsize=12, ha="center")
    z_face, y_face = pt(face(port.distance_m, 4.6e-3))
    ax.text(z_face - 0.2, y_face, f"port, tilted {math.degrees(port.total_tilt_rad):.0f} deg", ha="right", fontsize=11)

    # Camera: sensor with its pixels, MLA, main lens with its aperture stop.
    z_s, z_m = camera.sensor_z_m * mm, camera.mla_z_m * mm
    edges = (np.arange(camera.sensor.height_px + 1) - camera.sensor.height_px / 2) * camera.sensor.pixel_pitch_m * mm
    ax.plot([z_s, z_s], [edges[0], edges[-1]], color="black", lw=2.5)
    ax.plot(np.tile([[z_s - 0.1], [z_s + 0.1]], len(edges)), np.tile(edges, (2, 1)), "k-", lw=0.4)
    ax.text(z_s - 0.15, -4.6, "sensor", ha="right", fontsize=11)
    for c in np.arange(-8, 9) * camera.mla.pitch_m * mm:
        ax.add_patch(Ellipse((z_m, c), 0.22, camera.mla.pitch_m * mm * 0.97, fc="#f3e6b0", ec="#9b7f2a", lw=0.8))
    ax.text(z_m + 0.1, -4.6, "MLA", ha="left", fontsize=11)
    r_ap = camera.aperture_radius_m * mm
    ax.add_patch(Ellipse((0, 0), 0.7, 2 * r_ap, fc="#e8e0f5", ec="#6b5a99", lw=1.2))
    ax.plot([0, 0], [r_ap, 4.2], color="#333333", lw=3)
    ax.plot([0, 0], [-r_ap, -4.2], color="#333333", lw=3)
    ax.plot(0, 0, "ko", ms=4, zorder=8)
    ax.text(-0.5, -0.15, "O", fontsize=12, weight="bold")
    ax.text(0, -4.6, "main lens, aperture", ha="center", fontsize=11)

    # Captured rays near the necessary one (under it, so it stays visible).
    greens = ["#00702f", "#2ca25f", "#74c476"]
    for rank, i in enumerate(best):
        s_pt = np.array([0.0, -camera.sensor.pixels_to_image_plane(uv[i : i + 1])[0, 1], camera.sensor_z_m])
        c_pt = np.array([0.0, -camera.mla.centres_m(rays.lens_indices[i : i + 1])[0, 1], -f_prime])
        colour = greens[rank] if rank < len(greens) else "#e6a23c"
        where = "same microlens" if rank < len(greens) else "neighbouring microlens"
        label = (
            f"captured ray ({where}): |P'-P| = {np.linalg.norm(p_prime[i] - main['p']) * mm:.2f} mm, "
            f"angle {math.degrees(angle[i]):.1f} deg, D = {dist[i] * mm:.1f} mm"
        )
        style = {"ls": "-" if rank < len(greens) else (0, (5, 2)), "lw": 1.8 if rank < len(greens) else 1.3}
        path([s_pt, c_pt, o[i], p_prime[i]], color=colour, label=label, zorder=3, **style)
        ax.plot(*pt(p_prime[i]), "o", color=colour, ms=5, zorder=4)

    # The necessary ray: the line of sight (virtual in air and glass), then the light's exact path.
    path([np.zeros(3), main["q"]], color="#d62728", lw=1.2, ls=(0, (4, 3)), zorder=5)
    path(
        [main["q"], main["r"] * (z_end / main["r"][2])],
        color="#d62728",
        lw=2.4,
        zorder=5,
        label="necessary ray: line of sight K⁻¹p of output pixel p, from O into the water",
    )
    path(
        [main["q"], main["p"], main["hit"], main["mla"], main["sensor"]],
        color="#1f3fbf",
        lw=2.2,
        zorder=6,
        label="its light traced back exactly (FlatPort.trace_from_water): necessary air ray (P, r_a)",
    )
    for key, name, dz, dy in (("q", "Q", 0.2, 0.25), ("p", "P", -0.15, -0.75), ("hit", "", 0, 0)):
        ax.plot(*pt(main[key]), "o", color="#1f3fbf", ms=6, zorder=7)
        if name:
            z, y = pt(main[key])
            ax.text(z + dz, y + dy, name, fontsize=14, color="#1f3fbf", weight="bold", zorder=9)
    z_p, y_p = pt(main["p"])
    tip = (z_p + 1.6 * main["r_a"][2], y_p - 1.6 * main["r_a"][1])
    ax.annotate("", xy=tip, xytext=(z_p, y_p), arrowprops={"arrowstyle": "-|>", "color": "#1f3fbf", "lw": 1.8})
    ax.text(tip[0] - 0.3, tip[1] - 0.55, "r_a", color="#1f3fbf", fontsize=13, weight="bold")

    # A line of sight whose light misses the aperture: not recorded (outside the exact coverage).
    path([np.zeros(3), missed["q"]], color="#8c8c8c", lw=1.0, ls=(0, (4, 3)))
    path(
        [missed["q"], missed["r"] * (z_end / missed["r"][2])],
        color="#8c8c8c",
        lw=1.6,
        label="another line of sight: its light misses the aperture (not exact; nearby rays stand in)",
    )
    path([missed["q"], missed["p"], missed["hit"]], color="#8c8c8c", lw=1.4, ls=":")
    ax.plot(*pt(missed["hit"]), "x", color="#555555", ms=10, mew=2.5, zorder=8)

    ax.set_xlim(-7.9, z_end * mm)
    ax.set_ylim(-5.0, 5.0)
    ax.set_aspect("equal")
    ax.set_xlabel("z [mm] along the optical axis")
    ax.set_ylabel("up (-y) [mm]")
    handles, labels = ax.get_legend_handles_labels()
    first = [i for i, text in enumerate(labels) if not text.startswith("captured")]
    keep = first[:2] + [i for i in range(len(labels)) if i not in first] + first[2:]
    ax.legend(
        [handles[i] for i in keep],
        [labels[i] for i in keep],
        loc="upper left",
        bbox_to_anchor=(0.0, -0.09),
        fontsize=10,
        frameon=False,
    )
    ax.set_title(
        "Side view (y-z plane) of a sketch camera, not to scale (microlenses, their gap and the pixels enlarged);\n"
        "the port refraction and all rays are computed exactly.\n"
        f"D = |P' - P| + λ · angle(r', r_a), λ = {lam} m/rad, with P', r' where a captured ray meets the air-side "
        "face;\nthe k captured rays of smallest D are averaged with weights 1/D.",
        fontsize=11.5,
    )
    _save(fig, FIGURES / "synthesis_diagram.png", dpi=110, colours=None)


# ---------------------------------------------------------------------------- MLA calibration
def mla_figure(camera_name: str, spp: int) -> None:
    """mla_calibration.png: the lattice calibrated from a white image; prints its accuracy."""
    camera = camera_preset(camera_name)
    white = load_scene(embedded_scenes()["white"]).with_overrides(camera=camera, render=RenderSettings(spp=spp, seed=0))
    with tempfile.TemporaryDirectory() as tmp:
        seconds = _render(white, Path(tmp) / "white")
        raw = read_exr(Path(tmp) / "white" / "raw.exr", role="raw").mean(axis=2)
    start = time.perf_counter()
    cal = calibrate_mla(raw)
    took = time.perf_counter() - start
    truth = camera.micro_image_centres_px(camera.lens_indices_for_pixels(cal.centres_px))
    fitted_error = np.linalg.norm(cal.centres_px - truth, axis=1)
    measured_error = np.linalg.norm(cal.measured_px[cal.used] - truth[cal.used], axis=1)

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(x**2)))

    print(
        f"white image, {camera_name} camera ({raw.shape[1]} x {raw.shape[0]} px), {spp} spp, "
        f"rendered in {seconds:.1f} s; calibrated in {took:.2f} s: {cal.grid}, "
        f"pitch {cal.pitch_px:.5f} px (true {camera.micro_image_pitch_px:.5f}), "
        f"rotation {math.degrees(cal.rotation_rad):.5f} deg (true {math.degrees(camera.mla.rotation_rad):.5f}), "
        f"{len(cal.indices)} lenses {cal.status_counts()}\n"
        f"  fitted centres vs truth: {rms(fitted_error):.4f} px RMS, {fitted_error.max():.4f} px max; "
        f"measured centroids: {rms(measured_error):.4f} px RMS, {measured_error.max():.4f} px max"
    )

    fig, (ax, hist) = plt.subplots(1, 2, figsize=(12, 5.4), gridspec_kw={"width_ratios": [1, 1.15]})
    pitch = cal.pitch_px
    crop = (-0.5 - 0.3 * pitch, -0.5 + 7.5 * pitch)  # u and v range at the top-left corner
    ax.imshow(raw, cmap="gray", interpolation="nearest")
    edge = cal.status == LENS_STATUS.index("edge")
    used = cal.used
    ax.plot(*cal.centres_px[~edge].T, "r+", ms=10, mew=1.5, label="fitted lattice")
    ax.plot(*cal.measured_px[used].T, "x", color="#00c8ff", ms=6, mew=1.2, label="measured centroid")
    ax.plot(*cal.centres_px[edge].T, "o", mfc="none", color="orange", ms=9, mew=1.5, label="window off the sensor")
    base = cal.centres_px[np.argmin(np.linalg.norm(cal.centres_px - 3.5 * pitch, axis=1))]
    for vector, name in zip(cal.basis_px.T, ("a1", "a2"), strict=True):
        ax.annotate("", xy=base + vector, xytext=base, arrowprops={"arrowstyle": "-|>", "color": "yellow", "lw": 1.8})
        ax.text(*(base + 1.08 * vector), name, color="yellow", fontsize=11, weight="bold")
    ax.set_xlim(*crop)
    ax.set_ylim(*crop[::-1])
    ax.legend(loc="lower right", fontsize=8, framealpha=0.9)
    ax.set_title(f"white image, {camera_name}, top-left corner ({spp} spp)")

    bins = np.logspace(-4.5, 0, 60)
    for errors, colour, name in ((fitted_error, "#d62728", "fitted lattice"), (measured_error, "#1f77b4", "measured")):
        hist.hist(errors, bins=bins, color=colour, alpha=0.75, label=f"{name}: {rms(errors):.4f} px RMS")
    hist.set_xscale("log")
    hist.set_xlabel("distance to the true micro-image centre [px]")
    hist.set_ylabel("lenses")
    hist.legend(loc="upper left", fontsize=9)
    hist.set_title(
        f"{len(cal.indices)} lenses, {cal.grid} lattice, "
        f"pitch error {cal.pitch_px - camera.micro_image_pitch_px:+.1e} px"
    )
    fig.tight_layout()
    _save(fig, FIGURES / "mla_calibration.png", dpi=90)


# ---------------------------------------------------------------------------------- main
def port_noise_figure(seeds: int = 2) -> None:
    """Port calibration error against corner noise (synthetic views, no render): port_noise.png."""
    import math

    from lfrefract import FlatPort, PinholeCamera, Pose
    from lfrefract.calibration.port import BoardView, calibrate_port, project_through_port

    camera = PinholeCamera(focal_px=600.0, cx_px=399.5, cy_px=299.5, width_px=800, height_px=600)
    xx, yy = np.meshgrid(np.arange(9) * 0.03 - 0.12, np.arange(6) * 0.03 - 0.075)
    board = np.stack([xx.ravel(), yy.ravel()], axis=1)
    noises = [0.0, 0.05, 0.1, 0.2, 0.4]
    tilts = {"0 deg": (0.0, 0.0), "15 deg": (15.0, 0.0), "30 deg": (20.0, 22.0)}
    results = {}
    for label, (tx, ty) in tilts.items():
        true = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.01, tilt_x_deg=tx, tilt_y_deg=ty)
        rows = []
        for noise in noises:
            for seed in range(seeds):
                rng = np.random.default_rng(seed)
                views = []
                while len(views) < 10:
                    pose = Pose.from_euler_xyz_deg(
                        rng.uniform(-35, 35, 3) * [1, 1, 0.3],
                        [rng.uniform(-0.1, 0.1), rng.uniform(-0.08, 0.08), rng.uniform(0.2, 0.5)],
                    )
                    uv = project_through_port(camera, true, pose.to_world(np.c_[board, np.zeros(len(board))]))
                    if np.all(np.isfinite(uv)) and np.all((uv >= 0) & (uv <= [799, 599])):
                        noisy = uv + rng.normal(scale=noise, size=uv.shape)
                        views.append(BoardView(corners_px=noisy, board_points_m=board))
                r = calibrate_port(camera, views, thickness_m=0.01, max_normal_std_deg=90.0, max_distance_std_m=1.0)
                n = r.port.normal
                sine = float(np.linalg.norm(np.cross(n, true.normal)))
                angle = math.degrees(math.atan2(sine, float(n @ true.normal)))
                rows.append((noise, angle, abs(r.port.distance_m - true.distance_m) * 1e3))
                print(f"  port {label}, noise {noise} px, seed {seed}: normal {angle:.4f} deg, {rows[-1][2]:.3f} mm")
        results[label] = np.array(rows)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), dpi=100)
    for label, rows in results.items():
        for ax, col in zip(axes, (1, 2), strict=True):
            worst = [rows[rows[:, 0] == x, col].max() for x in noises]
            ax.plot(noises, worst, "o-", label=f"port tilted {label}")
    axes[0].axhline(0.1, color="grey", ls="--", lw=1, label="issue target")
    axes[1].axhline(0.5, color="grey", ls="--", lw=1, label="issue target")
    axes[0].set(xlabel="corner noise [px] (sigma)", ylabel="normal error [deg]", title="port normal")
    axes[1].set(xlabel="corner noise [px] (sigma)", ylabel="distance error [mm]", title="port distance")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(
        f"Port calibration from 10 synthetic views (f = 600 px, 9 x 6 board 0.2-0.5 m, port 30 mm, "
        f"10 mm glass); worst of {seeds} seeds",
        fontsize=9,
    )
    _save(fig, FIGURES / "port_noise.png")


def port_render_figure() -> None:
    """Port calibration on renders (tiny-2x, ten boards at 32 spp per tilt, as the tests):
    port_renders.png. Light-field corners against the central view's, and the port's errors."""
    from simulator.boards import port_from_renders

    tilts = {"0 deg": (0.0, 0.0), "15 deg": (12.0, -9.0), "27 deg": (25.0, 10.0)}
    fits = {}
    for label, tilt in tilts.items():
        start = time.perf_counter()
        fits[label] = fit = port_from_renders(tilt)
        c = fit.calibration
        print(
            f"  port {label}: corners {fit.light_field_rms_px:.4f} px (light field) / {fit.central_rms_px:.3f} px "
            f"(central view); normal {fit.normal_error_deg:.3f} deg (std {c.normal_std_deg:.3f}), distance "
            f"{fit.distance_error_m * 1e3:+.3f} mm (std {c.distance_std_m * 1e3:.3f}), {c.rms_px:.4f} px RMS; "
            f"{time.perf_counter() - start:.0f} s"
        )
    fig, axes = plt.subplots(
        1, 3, figsize=(13, 4.2), dpi=100, gridspec_kw={"width_ratios": [1.15, 1, 1], "wspace": 0.35}
    )
    fit = fits["27 deg"]
    for errors, colour, name in (
        (fit.central_errors_px, "tab:orange", "OpenCV, central view"),
        (fit.light_field_errors_px, "tab:blue", "light field (every raw pixel)"),
    ):
        rms = float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))
        axes[0].scatter(*errors.T, s=6, alpha=0.6, color=colour, label=f"{name}: {rms:.3f} px RMS")
    axes[0].set(xlabel="error u [px]", ylabel="error v [px]", title="corners against the exact projection (27 deg)")
    axes[0].set_aspect("equal")
    axes[0].legend(fontsize=8, loc="upper right")
    x = np.arange(len(fits))
    normal = [f.normal_error_deg for f in fits.values()]
    distance = [abs(f.distance_error_m) * 1e3 for f in fits.values()]
    axes[1].bar(x, normal, yerr=[f.calibration.normal_std_deg for f in fits.values()], capsize=4)
    axes[2].bar(x, distance, yerr=[f.calibration.distance_std_m * 1e3 for f in fits.values()], capsize=4)
    for ax, target, what in ((axes[1], 0.1, "normal error [deg]"), (axes[2], 0.5, "|distance error| [mm]")):
        ax.axhline(target, color="grey", ls="--", lw=1, label="issue target")
        ax.set(xticks=x, xticklabels=list(fits), xlabel="port tilt", ylabel=what)
        ax.legend(fontsize=8)
    axes[1].set_title("port normal (bars: reported std)")
    axes[2].set_title("port distance (12 mm; bars: reported std)")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle("Port calibration from ten rendered boards per tilt (tiny camera at twice its size, 32 spp)", size=9)
    _save(fig, FIGURES / "port_renders.png")


# ------------------------------------------------------------------------- dataset figure
def dataset_figure(spp: int) -> None:
    """dataset_tilt.png (docs/datasets.md): a tilt sweep rendered as a dataset, one column per tilt."""
    from simulator.dataset import Dataset, parse_spec, run_dataset

    tilts = [0.0, 10.0, 20.0, 30.0]
    spec = parse_spec(
        {
            "sweep": {"name": "tilt-figure", "seed": 1, "scene": "default", "spp": spp, "outputs": ["refraction_free"]},
            "grid": {"port.tilt_x_deg": tilts, "camera.preset": ["tiny-2x"]},
        },
        source="docs/make_figures.py",
    )
    with tempfile.TemporaryDirectory() as tmp:
        report = run_dataset(spec, Path(tmp) / "tilt", workers=2, progress=True)
        print(f"  dataset: {report.rendered} samples in {report.seconds:.1f} s")
        data = Dataset(Path(tmp) / "tilt")
        rows = {"raw": [], "raw crop": [], "refraction-free": [], "coverage": [], "ideal": []}
        shares = []
        for sample in data:
            raw, ideal, synth, coverage = sample.raw, sample.ideal, sample.refraction_free, sample.coverage
            h, w = raw.shape[:2]
            level = white_level(raw)
            # Coverage is the share of a pixel's sub-pixel necessary rays that the camera records: 1 is
            # exact; below 1 (0 included) the nearest captured rays stand in, so the pixel has a value
            # but an approximate one; a pixel without any captured ray stays 0 in the image.
            filled = np.any(synth > 0, axis=2)
            exact = coverage >= 1.0
            classes = np.where(exact, 2, np.where(filled, 1, 0))
            shares.append((exact.mean(), (filled & ~exact).mean(), (~filled).mean()))
            rows["raw"].append(display_rgb(downsample(raw, 320), white=level))
            rows["raw crop"].append(display_rgb(_crop(raw, (h // 3, w // 2), 40), white=level))
            rows["refraction-free"].append(_shown(synth, filled, white_level(ideal)))
            rows["coverage"].append(classes)
            rows["ideal"].append(display_rgb(ideal, white=white_level(ideal)))
    colours = ["#969696", "#e6a532", "#3c8c50"]  # no captured ray (the grey of the images), approximated, exact
    fig, axes = plt.subplots(len(rows), len(tilts), figsize=(2.6 * len(tilts), 2.2 * len(rows) + 0.5), dpi=100)
    for r, (label, images) in enumerate(rows.items()):
        for c, image in enumerate(images):
            ax = axes[r, c]
            if label == "coverage":
                ax.imshow(image, cmap=ListedColormap(colours), vmin=-0.5, vmax=2.5, interpolation="nearest")
                ax.set_xlabel("{:.0%} / {:.0%} / {:.0%}".format(*shares[c]), fontsize=9)
            else:
                ax.imshow(image, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(f"port tilt {tilts[c]:.0f} deg", fontsize=10)
            if c == 0:
                ax.set_ylabel(label, fontsize=10)
    legend = [
        Patch(color=colours[2], label="exact: every necessary ray recorded (coverage 1)"),
        Patch(color=colours[1], label="approximated: nearest captured rays stand in (coverage < 1)"),
        Patch(color=colours[0], label="no captured ray (grey in the refraction-free row)"),
    ]
    fig.suptitle(
        f"A tilt sweep as a dataset (tiny-2x camera, {spp} spp): lfsim dataset run, read with Dataset", size=10
    )
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    title = "coverage row (shares below each panel: exact / approximated / no ray)"
    fig.legend(handles=legend, loc="lower center", fontsize=9, frameon=False, title=title, title_fontsize=9)
    _save(fig, FIGURES / "dataset_tilt.png", dpi=80)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", nargs="+", choices=PARTS, default=list(PARTS), help="figures to make (default all)")
    parser.add_argument("--camera", default="f01")
    parser.add_argument("--spp", type=int, default=16, help="samples per pixel of the simulator figures")
    parser.add_argument("--synthesis-spp", type=int, default=64, help="samples per pixel of the synthesis figures")
    args = parser.parse_args()
    FIGURES.mkdir(exist_ok=True)
    if "readme" in args.only:
        readme_figure(args.camera, args.synthesis_spp)
    if "simulator" in args.only:
        simulator_figures(args.camera, args.spp)
    if "synthesis" in args.only:
        synthesis_figures(args.camera, args.synthesis_spp)
    if "diagram" in args.only:
        diagram_figure()
    if "mla" in args.only:
        mla_figure(args.camera, args.spp)
    if "port" in args.only:
        port_noise_figure()
        port_render_figure()
    if "dataset" in args.only:
        dataset_figure(args.spp)
    print(f"wrote figures to {FIGURES}")


if __name__ == "__main__":
    main()
