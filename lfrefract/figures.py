"""Figures for people (the PNG that ``lfrefract synth`` writes), by the project's rule for every
figure: each image has a colour bar with its units, labelled axes, a legend for every mark drawn over
it, the set-up in the title, and no value drawn in one grey (:data:`NO_VALUE_RGB`), never white.

The figures are built on :class:`matplotlib.figure.Figure` with constrained layout (titles, colour
bars and legends never overlap) and no pyplot, so building one changes no global state; the simulator's
previews use the same display conventions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = [
    "DISPLAY_GAMMA",
    "NO_VALUE_RGB",
    "WHITE_PERCENTILE",
    "display_image",
    "new_figure",
    "pixel_axes",
    "port_setup",
    "save_figure",
    "synth_figure",
    "synth_setup",
    "white_of",
]

#: The grey of pixels with no value (no captured ray, no depth, no surface), RGB in 0..1: the grey
#: of the README's and the docs' figures (150 / 255).
NO_VALUE_RGB = (150 / 255, 150 / 255, 150 / 255)
#: Display gamma of linear radiance.
DISPLAY_GAMMA = 2.2
#: The percentile of an image's finite values shown as white.
WHITE_PERCENTILE = 99.5
#: Colour of the line at the edge of the exact coverage.
EXACT_EDGE_COLOUR = "yellow"


def new_figure(width_in: float, height_in: float, *, dpi: int = 120):
    """A :class:`~matplotlib.figure.Figure` with constrained layout and an Agg canvas (no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path: str | Path) -> None:
    """Write ``fig`` as PNG to ``path`` (a path or file object), at its own size: constrained layout
    has placed everything inside it, so no ``bbox_inches="tight"`` moves anything."""
    fig.savefig(path, format="png")


def white_of(image: np.ndarray) -> float:
    """The value shown as white: :data:`WHITE_PERCENTILE` of the finite values (1.0 if none is above 0)."""
    finite = np.asarray(image)[np.isfinite(image)]
    level = float(np.percentile(finite, WHITE_PERCENTILE)) if finite.size else 0.0
    return level if level > 0.0 else 1.0


def display_image(image: np.ndarray, *, white: float) -> np.ndarray:
    """Linear radiance (H, W), (H, W, 1) or (H, W, C >= 3) as display RGB (H, W, 3) in 0..1: scaled to ``white``,
    clipped, gamma :data:`DISPLAY_GAMMA`; pixels with a non-finite channel in :data:`NO_VALUE_RGB`."""
    shown = np.asarray(image, dtype=np.float64)
    shown = shown[..., 0] if shown.ndim == 3 and shown.shape[2] == 1 else shown
    shown = np.repeat(shown[..., None], 3, axis=2) if shown.ndim == 2 else shown[..., :3]
    valid = np.all(np.isfinite(shown), axis=2)
    rgb = np.clip(np.where(valid[..., None], shown, 0.0) / white, 0.0, 1.0) ** (1.0 / DISPLAY_GAMMA)
    rgb[~valid] = NO_VALUE_RGB
    return rgb


def port_setup(camera, port) -> str:
    """The set-up of a figure in one line: the camera and, if any, its port and the water."""
    if port is None:
        return f"{camera.name} camera, no port"
    return (
        f"{camera.name} camera behind a port tilted {np.degrees(port.total_tilt_rad):.3g} deg "
        f"({port.thickness_m * 1e3:.3g} mm glass, {port.distance_m * 1e3:.3g} mm away, water n = "
        f"{port.n_water:.4g})"
    )


def synth_setup(camera, port, output, *, method: str) -> str:
    """The set-up of a ``synth`` figure, two lines: camera, port and water (:func:`port_setup`);
    method and output size."""
    return f"{port_setup(camera, port)}\n{method}, {output.width_px} x {output.height_px} px"


def pixel_axes(ax) -> None:
    """Label an image's axes in pixels (u: column, v: row, as OpenCV's)."""
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")


def synth_figure(
    image: np.ndarray,
    coverage: np.ndarray,
    *,
    setup: str,
    depth_m: np.ndarray | None = None,
    depth_range_m: tuple[float, float] | None = None,
):
    """The figure of ``lfrefract synth``: the refraction-free image with the edge of its exact
    coverage, and with ``depth_m`` (the depth-aware method) the depth found in the light field beside it.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Linear radiance; NaN where no captured ray gave a value (drawn grey).
    coverage : ndarray, shape (H, W)
        The warp map's coverage (1: exact).
    setup : str
        The set-up, for the title (:func:`synth_setup`).
    depth_m : ndarray, shape (H, W), optional
        Depth in metres, NaN where none was found (drawn grey).
    depth_range_m : (float, float), optional
        The depth colour bar's range, metres (the depth search's range).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import PowerNorm
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    height, width = np.asarray(coverage).shape
    panels = 1 if depth_m is None else 2
    fig = new_figure(6.4 * panels, 5.6 * height / width + 1.9)
    axes = fig.subplots(1, panels, squeeze=False)[0]
    white = white_of(image)
    ax = axes[0]
    ax.imshow(display_image(image, white=white), interpolation="nearest")
    ax.contour(coverage, levels=[0.999], colors=EXACT_EDGE_COLOUR, linewidths=1)
    ax.set_title("refraction-free image" if depth_m is None else "depth-aware refraction-free image")
    pixel_axes(ax)
    scale = ScalarMappable(norm=PowerNorm(1.0 / DISPLAY_GAMMA, vmin=0.0, vmax=white), cmap="gray")
    fig.colorbar(scale, ax=ax, shrink=0.9).set_label("radiance per channel (the raw's units)")
    handles = [
        Line2D([], [], color=EXACT_EDGE_COLOUR, label="edge of the exact coverage"),
        Patch(facecolor=NO_VALUE_RGB, edgecolor="0.3", label="no captured ray"),
    ]
    if depth_m is not None:
        import matplotlib as mpl

        colours = mpl.colormaps["viridis"].with_extremes(bad=NO_VALUE_RGB)
        lo, hi = depth_range_m if depth_range_m is not None else (None, None)
        shown = axes[1].imshow(depth_m, cmap=colours, vmin=lo, vmax=hi, interpolation="nearest")
        axes[1].set_title("depth found in the light field")
        pixel_axes(axes[1])
        fig.colorbar(shown, ax=axes[1], shrink=0.9).set_label("depth: camera-frame z (m)")
        handles[1] = Patch(facecolor=NO_VALUE_RGB, edgecolor="0.3", label="no captured ray / no depth")
    fig.legend(handles=handles, loc="outside lower center", ncols=2, fontsize=9)
    fig.suptitle(setup, fontsize=9)
    return fig
