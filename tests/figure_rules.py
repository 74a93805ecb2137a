"""The project's rule for every figure, as checks on a matplotlib Figure before it is saved: each
image has a colour bar with a label (its units), its axes are labelled, a title (of the axes or the
figure) says what it shows, and no title, label or legend overlaps a colour bar or another text."""

from __future__ import annotations

import itertools

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg


def _extent(artist, renderer):
    return artist.get_window_extent(renderer)


def assert_follows_the_figure_rules(fig) -> None:
    """Assert the rule above on ``fig`` (drawn once to lay it out)."""
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    suptitle = fig._suptitle.get_text() if fig._suptitle is not None else ""
    colorbars = [ax for ax in fig.axes if hasattr(ax, "_colorbar")]
    plots = [ax for ax in fig.axes if ax not in colorbars and ax.get_visible()]
    assert plots, "the figure has no axes"
    assert suptitle or all(ax.get_title() for ax in plots), "no title"
    texts = [t for t in (fig._suptitle, *fig.legends) if t is not None]
    for ax in plots:
        if ax.images:  # a colour bar made for this axes (an RGB image's shows its display scale)
            bars = [bar for bar in colorbars if ax in bar._colorbar_info["parents"]]
            assert bars, f"the image of {ax.get_title()!r} has no colour bar"
            assert all(bar.get_ylabel() or bar.get_xlabel() for bar in bars), "a colour bar has no label"
        if ax.images or ax.lines or ax.patches or ax.collections:
            assert ax.get_xlabel() or ax.get_ylabel() or ax.get_xticklabels(), f"{ax.get_title()!r}: unlabelled axes"
        texts += [t for t in (ax.title, ax.xaxis.label, ax.yaxis.label) if t.get_text()]
        if ax.get_legend() is not None:
            texts.append(ax.get_legend())
    for bar in colorbars:
        texts.append(bar.yaxis.label if bar.get_ylabel() else bar.xaxis.label)
    boxes = [(t, _extent(t, renderer)) for t in texts]
    for text, box in boxes:
        for bar in colorbars:
            if text in (bar.yaxis.label, bar.xaxis.label):
                continue
            overlap = box.overlaps(bar.get_window_extent(renderer))
            assert not overlap, f"{text} runs under a colour bar"
    for (a, box_a), (b, box_b) in itertools.combinations(boxes, 2):
        assert not box_a.overlaps(box_b), f"{a} overlaps {b}"
    width, height = fig.canvas.get_width_height()
    for _, box in boxes:  # inside the saved figure
        assert min(box.x0, box.y0) >= -1, box
        assert box.x1 <= width + 1, box
        assert box.y1 <= height + 1, box


def image_pixels_in_png(fig, ax, png: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The colours (N, 3) the saved ``png`` (of ``fig`` saved at its own size) shows at the centre of
    each data pixel of ``ax``'s image of ``shape`` (H, W), row-major."""
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    fig.canvas.draw()  # lays it out as saving did
    box = ax.get_window_extent(fig.canvas.get_renderer())
    h, w = shape
    x0, x1 = ax.get_xlim()  # data coordinates: -0.5 .. W - 0.5
    y1, y0 = ax.get_ylim()  # image axes run downward: ylim = (H - 0.5, -0.5)
    v, u = np.mgrid[0:h, 0:w]
    px = box.x0 + (u - x0) / (x1 - x0) * box.width
    py = box.y1 - (v - y0) / (y1 - y0) * box.height  # from the bottom of the figure
    rows = np.clip((png.shape[0] - py).astype(int), 0, png.shape[0] - 1)
    cols = np.clip(px.astype(int), 0, png.shape[1] - 1)
    return png[rows, cols, :3].reshape(-1, 3)
