"""Experiment ``averaging`` (paper Fig. 9): how many captured rays to average per necessary ray.

The synthesis averages the ``k`` captured rays nearest to each necessary ray (weights ``1 / D``).
More rays average out the noise of the capture but reach further from the necessary ray (into
neighbouring pixels and microlenses), which blurs. The paper shows k = 1, 8, 64 side by side; this
experiment measures the trade-off against the simulator's ideal image.

Set-up: the embedded default scene (textured backdrop, chessboard, bowl, figurine behind a 20 deg
port, 20 mm away, 6 mm glass) with the ``tiny`` camera (scale ``tiny``) or the Lytro ``illum``
preset (scale ``illum``). The raw image is rendered at :attr:`Setup.spp` samples per pixel at two
seeds (0 and 1): Monte Carlo noise stands in for the capture noise of a real camera. The ideal image
(the same scene without the port, seen by the virtual pinhole ``virtual_camera_for(camera)``, which
is also the synthesis output geometry) is rendered at :attr:`Setup.ideal_spp` at two seeds too.
Warp maps are built with the default :class:`~lfrefract.synthesis.warp_map.SynthesisOptions` (lambda 0.3
m/rad, super-sampling 2) and k in :data:`K_VALUES`; the paper's k = 1, 8, 64 are in the figure.

Every measure is taken on channel means inside the exact coverage (``WarpMap.exact``, the same for
every k: pixels whose necessary rays the camera records), with ``S0, S1`` the images synthesized
from the two raw renders, ``G0, G1`` the two ideal renders, ``G = (G0 + G1) / 2`` the reference and
``peak`` its 99.5th percentile (the data range, as in the synthesis tests):

- ``psnr_db``, ``ssim``: :func:`lfrefract.metrics.psnr` and :func:`~lfrefract.metrics.ssim` of
  ``S0`` against ``G`` (render noise included, as a capture would have it).
- ``sharpness_ratio``: :func:`sharpness_ratio`, ``sqrt(E(S0, S1) / E(G0, G1))`` with
  ``E(a, b)`` the mean over neighbouring pixel pairs of the product of the finite differences of
  ``a`` and ``b`` along x plus that along y (:func:`gradient_energy`). Taking the product across
  independent seeds removes the render noise from the gradient energy (its expectation is the
  energy of the noise-free image), so the ratio is the fraction of the ideal image's gradient
  amplitude that survives: 1 as sharp as the ideal image, below 1 blurred. The light field samples
  the scene once per microlens (about two output pixels), so even k = 1 stays below 1.
- ``noise_rel``: :func:`noise_rel`, the render noise left in the synthesized image,
  ``std(S0 - S1) / sqrt(2) / peak`` (averaging n independent rays would divide it by sqrt(n)).
- ``psnr_noise_free_db``: :func:`noise_free_psnr`, the PSNR of the deterministic error alone,
  ``10 log10(peak^2 / mean((S0 - G0) (S1 - G1)))``: the cross-seed product keeps the squared error
  that does not depend on the seed (blur, misplaced rays) and removes the noise of both renders.
- ``raw_px_per_px``: mean number of distinct raw pixels feeding an output pixel of the exact
  coverage (k rays for each of the s^2 sub-pixel rays, less duplicates).
- ``map_build_s``: seconds to build the warp map (``build_warp_map``).
"""

from __future__ import annotations

import dataclasses
import io
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfrefract import camera_preset, virtual_camera_for
from lfrefract.figures import (
    DISPLAY_GAMMA,
    EXACT_EDGE_COLOUR,
    NO_VALUE_RGB,
    display_image,
    new_figure,
    pixel_axes,
    port_setup,
    save_figure,
)
from lfrefract.metrics import psnr, ssim
from lfrefract.synthesis.warp_map import SynthesisOptions, build_warp_map
from simulator.experiments import ExperimentOptions, ExperimentResult, check_scale, register

__all__ = [
    "FIGURE_K",
    "K_VALUES",
    "SEEDS",
    "SETUPS",
    "Setup",
    "crop_window",
    "crops_figure",
    "curves_figure",
    "gradient_energy",
    "noise_free_psnr",
    "noise_rel",
    "run",
    "sharpness_ratio",
]

#: Rays averaged per necessary ray: rows of the table and points of the curves.
K_VALUES = (1, 2, 4, 8, 16, 32, 64)
#: The k shown side by side with the ideal image (paper Fig. 9).
FIGURE_K = (1, 8, 64)
#: Render seeds of the raw image and of the ideal image (independent streams of one seed).
SEEDS = (0, 1)
#: Largest crop shown in the side-by-side figure, output pixels (height, width).
MAX_CROP_PX = (150, 220)
#: Resolution of the figures, dots per inch.
FIGURE_DPI = 90


@dataclass(frozen=True)
class Setup:
    """What a scale renders: the camera preset, raw samples per pixel, ideal samples per pixel."""

    camera: str
    spp: int
    ideal_spp: int


#: Per scale. ``tiny``: 480 x 360 raw px, 92 x 69 output px, seconds. ``illum``: 7728 x 5368 raw px,
#: 1078 x 748 output px, minutes. The ideal image gets many more samples than the raw image so that
#: its own noise stays well below the synthesized image's (its pixels integrate a larger footprint
#: than a raw pixel's).
SETUPS = {"tiny": Setup("tiny", 16, 1024), "illum": Setup("illum", 16, 256)}


# ------------------------------------------------------------------------------------ measures
def _grey(image: np.ndarray) -> np.ndarray:
    x = np.asarray(image, dtype=np.float64)
    return x.mean(axis=2) if x.ndim == 3 else x


def gradient_energy(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    """Mean product of the finite differences of ``a`` and ``b`` (channel means): along x over the
    horizontally neighbouring pixel pairs inside ``mask``, plus the same along y.

    With ``a is b`` the mean squared gradient; with two renders of one image at independent seeds
    an estimate of the noise-free image's, since the noise terms have zero mean in the product.
    """
    x, y, m = _grey(a), _grey(b), np.asarray(mask, dtype=bool)
    pairs_x, pairs_y = m[:, 1:] & m[:, :-1], m[1:] & m[:-1]
    if not pairs_x.any() or not pairs_y.any():
        raise ValueError("the mask holds no pair of neighbouring pixels along x and along y")
    ex = np.mean((np.diff(x, axis=1) * np.diff(y, axis=1))[pairs_x])
    ey = np.mean((np.diff(x, axis=0) * np.diff(y, axis=0))[pairs_y])
    return float(ex + ey)


def sharpness_ratio(s0: np.ndarray, s1: np.ndarray, g0: np.ndarray, g1: np.ndarray, mask: np.ndarray) -> float:
    """``sqrt(gradient_energy(s0, s1) / gradient_energy(g0, g1))``: the gradient amplitude of an image
    (rendered at two seeds) relative to the reference's, render noise removed; below 1 is blur."""
    return math.sqrt(max(gradient_energy(s0, s1, mask), 0.0) / gradient_energy(g0, g1, mask))


def noise_rel(s0: np.ndarray, s1: np.ndarray, mask: np.ndarray, peak: float) -> float:
    """Per-pixel noise of one render, ``std(s0 - s1) / sqrt(2)`` inside ``mask``, relative to ``peak``."""
    d = (_grey(s0) - _grey(s1))[np.asarray(mask, dtype=bool)]
    return float(np.std(d) / math.sqrt(2.0) / peak)


def noise_free_psnr(
    s0: np.ndarray, s1: np.ndarray, g0: np.ndarray, g1: np.ndarray, mask: np.ndarray, peak: float
) -> float:
    """PSNR (dB) of the error that does not depend on the render seed:
    ``10 log10(peak^2 / mean((s0 - g0) (s1 - g1)))`` inside ``mask`` (inf if that mean is not positive)."""
    m = np.asarray(mask, dtype=bool)
    cross = float(np.mean(((_grey(s0) - _grey(g0)) * (_grey(s1) - _grey(g1)))[m]))
    return float("inf") if cross <= 0.0 else 10.0 * math.log10(peak**2 / cross)


def crop_window(
    exact: np.ndarray, reference: np.ndarray, max_shape: tuple[int, int] = MAX_CROP_PX
) -> tuple[slice, slice]:
    """The crop of the side-by-side figure: the exact coverage's bounding box (2 px margin) if it
    fits ``max_shape``; else the window of that size (at most) with the most gradient energy of
    ``reference`` among those at least 90 % (of the best possible fraction) inside the exact coverage."""
    m = np.asarray(exact, dtype=bool)
    h, w = m.shape
    rows, cols = np.nonzero(m)
    top, bottom = max(int(rows.min()) - 2, 0), min(int(rows.max()) + 3, h)
    left, right = max(int(cols.min()) - 2, 0), min(int(cols.max()) + 3, w)
    wh, ww = min(bottom - top, max_shape[0]), min(right - left, max_shape[1])
    if (wh, ww) == (bottom - top, right - left):
        return slice(top, bottom), slice(left, right)

    def window_sums(values: np.ndarray) -> np.ndarray:  # sum over every wh x ww window, by top-left corner
        s = np.zeros((h + 1, w + 1))
        s[1:, 1:] = np.cumsum(np.cumsum(values, axis=0), axis=1)
        return s[wh:, ww:] - s[:-wh, ww:] - s[wh:, :-ww] + s[:-wh, :-ww]

    g = _grey(reference)
    energy = np.zeros((h, w))
    energy[:, 1:] += np.diff(g, axis=1) ** 2
    energy[1:, :] += np.diff(g, axis=0) ** 2
    inside = window_sums(m.astype(np.float64)) / (wh * ww)
    score = np.where(inside >= 0.9 * inside.max(), window_sums(energy * m), -np.inf)
    r, c = np.unravel_index(int(np.argmax(score)), score.shape)
    return slice(int(r), int(r) + wh), slice(int(c), int(c) + ww)


# ------------------------------------------------------------------------------------ figures
def _save(fig, path: Path) -> Path:
    """Save ``fig`` (:func:`lfrefract.figures.save_figure`) as a palette PNG (much smaller than RGB, no
    visible loss)."""
    from PIL import Image

    buffer = io.BytesIO()
    save_figure(fig, buffer)
    buffer.seek(0)
    image = Image.open(buffer).convert("RGB")
    palette = image.quantize(colors=256, method=Image.Quantize.FASTOCTREE)
    image.quantize(palette=palette, dither=Image.Dither.FLOYDSTEINBERG).save(path, optimize=True)
    return path


def crops_figure(
    images: dict[int, tuple[np.ndarray, np.ndarray]],
    ideal: np.ndarray,
    exact: np.ndarray,
    rows: list[dict],
    peak: float,
    *,
    setup: str,
):
    """Side by side over the crop (:func:`crop_window`): each k's image, then the ideal image, with the
    edge of the exact coverage, a colour bar of the display scale, pixel axes (the output image's),
    pixels with no captured ray grey (legend) and the set-up in the title.

    Parameters
    ----------
    images : dict
        ``k -> (image (H, W, 3), filled (H, W))``: the synthesized image and where it has a value.
    ideal : ndarray, shape (H, W, 3)
        The ideal image.
    exact : ndarray, shape (H, W)
        The exact coverage.
    rows : list of dict
        The rows (their scores go into the panels' titles).
    peak : float
        The radiance shown as white.
    setup : str
        The set-up, for the title.

    Returns
    -------
    (matplotlib.figure.Figure, (slice, slice))
        The figure and the crop (rows, columns).
    """
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import PowerNorm
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    crop = crop_window(exact, ideal)
    by_k = {row["k"]: row for row in rows}
    panels = [
        (
            np.where(filled[..., None], image, np.nan),
            f"k = {k}\nPSNR {by_k[k]['psnr_db']:.1f} dB, SSIM {by_k[k]['ssim']:.3f}\n"
            f"sharpness {by_k[k]['sharpness_ratio']:.2f}, noise {by_k[k]['noise_rel']:.3f}",
        )
        for k, (image, filled) in images.items()
    ]
    panels.append((ideal, "ideal image\n(no port, pinhole)\n"))
    (r0, r1), (c0, c1) = (crop[0].start, crop[0].stop), (crop[1].start, crop[1].stop)
    panel_w = 4.0
    fig = new_figure(panel_w * len(panels) + 1.2, panel_w * (r1 - r0) / (c1 - c0) + 2.6, dpi=FIGURE_DPI)
    axes = fig.subplots(1, len(panels))
    extent = (c0 - 0.5, c1 - 0.5, r1 - 0.5, r0 - 0.5)  # the output image's pixel coordinates
    for ax, (image, title) in zip(axes, panels, strict=True):
        ax.imshow(display_image(image, white=peak)[crop], extent=extent, interpolation="nearest")
        ax.contour(
            np.arange(c0, c1),
            np.arange(r0, r1),
            exact[crop].astype(float),
            [0.5],
            colors=EXACT_EDGE_COLOUR,
            linewidths=0.8,
            linestyles="dashed",
        )
        ax.set_title(title, fontsize=10)
        pixel_axes(ax)
    scale = ScalarMappable(norm=PowerNorm(1.0 / DISPLAY_GAMMA, vmin=0.0, vmax=peak), cmap="gray")
    fig.colorbar(scale, ax=axes, shrink=0.9).set_label("radiance per channel (the render's units)")
    handles = [
        Line2D([], [], color=EXACT_EDGE_COLOUR, ls="--", label="edge of the exact coverage"),
        Patch(facecolor=NO_VALUE_RGB, edgecolor="0.3", label="no captured ray"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncols=2, fontsize=9)
    fig.suptitle(
        f"k nearest captured rays averaged (paper Fig. 9): {setup}\n"
        f"crop rows {r0}-{r1 - 1}, columns {c0}-{c1 - 1}; scores over the whole exact coverage",
        fontsize=10,
    )
    return fig, crop


def curves_figure(rows: list[dict], *, setup: str):
    """PSNR (with and without render noise), sharpness ratio and render noise against k, as a Figure
    (a legend in every panel, the set-up in the title).

    Parameters
    ----------
    rows : list of dict
        The rows, one per k.
    setup : str
        The set-up, for the title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    k = np.array([row["k"] for row in rows], dtype=float)

    def column(name: str) -> np.ndarray:
        return np.array([row[name] for row in rows], dtype=float)

    fig = new_figure(13.5, 4.4, dpi=FIGURE_DPI)
    a, b, c = fig.subplots(1, 3)
    a.plot(k, column("psnr_db"), "o-", label="PSNR (render noise included)")
    a.plot(k, column("psnr_noise_free_db"), "s--", label="PSNR of the noise-free error")
    a.set_ylabel("PSNR against the ideal image (dB)")
    a.set_title("PSNR", fontsize=10)
    b.plot(k, column("sharpness_ratio"), "o-", color="C2", label="measured")
    b.axhline(1.0, color="grey", lw=0.8, ls=":", label="as sharp as the ideal image")
    b.set_ylabel("sharpness ratio (gradient amplitude / ideal's)")
    b.set_title("sharpness", fontsize=10)
    c.plot(k, column("noise_rel"), "o-", color="C3", label="measured")
    c.plot(k, column("noise_rel")[0] / np.sqrt(k), ":", color="grey", label="k = 1 value / sqrt(k)")
    c.set_yscale("log")
    c.set_ylabel("render noise (std / data range)")
    c.set_title("render noise", fontsize=10)
    for ax in (a, b, c):
        ax.set_xscale("log", base=2)
        ax.set_xticks(k, [str(int(v)) for v in k])
        ax.set_xlabel("k (captured rays averaged per necessary ray)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"averaging k rays: {setup}; inside the exact coverage", fontsize=10)
    return fig


# ------------------------------------------------------------------------------------ the run
def _summary(rows: list[dict], exact: np.ndarray) -> str:
    by_k = {row["k"]: row for row in rows}
    best = max(rows, key=lambda row: row["psnr_db"])
    first, last = by_k[K_VALUES[0]], by_k[K_VALUES[-1]]
    return "\n".join(
        [
            f"- exact coverage: {exact.mean():.1%} of the output pixels ({int(exact.sum())} px), "
            "where everything is measured",
            f"- PSNR peaks at k = {best['k']}: {best['psnr_db']:.2f} dB (k = 1: {first['psnr_db']:.2f} dB, "
            f"k = {last['k']}: {last['psnr_db']:.2f} dB); SSIM {first['ssim']:.3f} / {best['ssim']:.3f} / "
            f"{last['ssim']:.3f}",
            f"- render noise falls with k: {first['noise_rel']:.4f} -> {last['noise_rel']:.4f} of the data range "
            f"(x{last['noise_rel'] / first['noise_rel']:.2f}; the raw pixels averaged per output pixel grow "
            f"{first['raw_px_per_px']:.1f} -> {last['raw_px_per_px']:.1f}, 1/sqrt of their ratio: "
            f"{math.sqrt(first['raw_px_per_px'] / last['raw_px_per_px']):.2f})",
            f"- sharpness ratio {first['sharpness_ratio']:.2f} (k = 1) -> {best['sharpness_ratio']:.2f} "
            f"(k = {best['k']}) -> {last['sharpness_ratio']:.2f} (k = {last['k']}); the noise-free error's PSNR "
            f"{first['psnr_noise_free_db']:.2f} -> {best['psnr_noise_free_db']:.2f} -> "
            f"{last['psnr_noise_free_db']:.2f} dB: few rays are noisy, many rays blur",
        ]
    )


@register("averaging", options=("camera", "port_distance_m", "thickness_m"))
def run(out_dir: Path, options: ExperimentOptions, *, progress: bool) -> ExperimentResult:
    """How many captured rays to average per necessary ray: k = 1 to 64 against the ideal image (paper Fig. 9)."""
    from simulator import groundtruth
    from simulator.backend import load_mitsuba, versions
    from simulator.config import RenderSettings, load_scene
    from simulator.job import render_raw
    from simulator.scene import build_scene

    scale = options.scale
    setup = SETUPS[check_scale(scale)]
    out = Path(out_dir)
    timings: dict[str, float] = {}
    scene = load_scene()
    camera = camera_preset(setup.camera) if options.camera is None else options.camera
    port_changes = {
        key: value
        for key, value in (("distance_m", options.port_distance_m), ("thickness_m", options.thickness_m))
        if value is not None
    }
    port = dataclasses.replace(scene.port, **port_changes) if port_changes else scene.port
    scene = scene.with_overrides(camera=camera, port=port)
    mi = load_mitsuba()
    camera, port = scene.camera, scene.port
    pinhole = virtual_camera_for(camera)
    glass_free = build_scene(mi, scene, port_geometry=False)

    raws, ideals = [], []
    for seed in SEEDS:
        config = scene.with_overrides(render=RenderSettings(spp=setup.spp, seed=seed))
        start = time.perf_counter()
        raws.append(render_raw(mi, config, glass_free_scene=glass_free, progress=progress))
        timings[f"raw_seed{seed}_s"] = time.perf_counter() - start
        start = time.perf_counter()
        truth = groundtruth.compute(mi, glass_free, config, pinhole, spp=setup.ideal_spp, seed=seed, progress=progress)
        ideals.append(truth.ideal)
        timings[f"ideal_seed{seed}_s"] = time.perf_counter() - start
    del glass_free
    g0, g1 = ideals
    ideal = (g0 + g1) / 2.0
    peak = float(np.percentile(ideal, 99.5))

    exact = None
    results: dict[int, tuple] = {}
    for k in K_VALUES:
        start = time.perf_counter()
        warp = build_warp_map(camera, port, output=pinhole, options=SynthesisOptions(k=k), progress=progress)
        built = time.perf_counter() - start
        if exact is None:
            exact = warp.exact
            if exact.sum() < 4:
                raise RuntimeError(f"the exact coverage holds {int(exact.sum())} output pixels: nothing to measure")
        elif not np.array_equal(warp.exact, exact):
            raise RuntimeError(f"the exact coverage changed with k = {k}; it should not depend on k")
        s0, s1 = warp.apply(raws[0]), warp.apply(raws[1])
        per_px = np.diff(warp.indptr).reshape(exact.shape)
        results[k] = (s0, s1, warp.filled, built, float(per_px[exact].mean()))
        del warp
    del raws

    rows = []
    for k, (s0, s1, _, built, per_px) in results.items():
        rows.append(
            {
                "k": k,
                "psnr_db": psnr(s0, ideal, data_range=peak, mask=exact),
                "ssim": ssim(s0, ideal, data_range=peak, mask=exact),
                "sharpness_ratio": sharpness_ratio(s0, s1, g0, g1, exact),
                "noise_rel": noise_rel(s0, s1, exact, peak),
                "psnr_noise_free_db": noise_free_psnr(s0, s1, g0, g1, exact, peak),
                "raw_px_per_px": per_px,
                "map_build_s": built,
            }
        )

    label = f"{scene.name!r} scene, {port_setup(camera, port)}, {setup.spp} spp (ideal {2 * setup.ideal_spp} spp)"
    fig, crop = crops_figure(
        {k: (results[k][0], results[k][2]) for k in FIGURE_K},
        ideal,
        exact,
        rows,
        peak,
        setup=label,
    )
    crops_png = _save(fig, out / "averaging_crops.png")
    curves_png = _save(curves_figure(rows, setup=label), out / "averaging_curves.png")

    parameters = {
        "scene": scene.name,
        "camera": camera.name,
        "raw_px": [camera.sensor.width_px, camera.sensor.height_px],
        "output": pinhole.to_dict(),
        "port": port.to_dict(),
        "spp": setup.spp,
        "ideal_spp": setup.ideal_spp,
        "seeds": list(SEEDS),
        "k_values": list(K_VALUES),
        "figure_k": list(FIGURE_K),
        "options": {key: v for key, v in SynthesisOptions().to_dict().items() if key != "k"},
        "data_range": peak,
        "exact_px": int(exact.sum()),
        "exact_fraction": float(exact.mean()),
        "crop": {"rows": [crop[0].start, crop[0].stop], "cols": [crop[1].start, crop[1].stop]},
        "timings_s": timings,
        **versions(),
    }
    return ExperimentResult(
        name="averaging",
        scale=scale,
        rows=tuple(rows),
        figures=(crops_png, curves_png),
        summary=_summary(rows, exact),
        parameters=parameters,
    )
