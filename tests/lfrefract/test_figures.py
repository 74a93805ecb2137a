"""The figure ``lfrefract synth`` writes: colour bars with units, labelled axes, a legend, the set-up in
the title, no text under a colour bar, and pixels with no value drawn grey (they were white, and the
uncovered third of the tiny camera's image looked like an empty panel)."""

from __future__ import annotations

import io

import matplotlib.image
import numpy as np
import pytest

from lfrefract import virtual_camera_for
from lfrefract.cli import main
from lfrefract.figures import NO_VALUE_RGB, save_figure, synth_figure, synth_setup
from lfrefract.formats.exr import read_exr
from tests.figure_rules import assert_follows_the_figure_rules, image_pixels_in_png
from tests.lfrefract.test_cli import PORT, TINY, make_capture

#: A PNG stores 8-bit colours: a saved grey is within one step of NO_VALUE_RGB.
PNG_STEP = 1.5 / 255


def _image_with_an_empty_third(channels: int | None = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    shape = (69, 92) if channels is None else (69, 92, channels)
    image = 0.4 + 0.2 * rng.random(shape)
    image[46:] = np.nan  # no captured ray
    coverage = np.zeros((69, 92))
    coverage[10:30, 20:70] = 1.0
    return image, coverage


def _saved(fig) -> np.ndarray:
    buffer = io.BytesIO()
    save_figure(fig, buffer)
    buffer.seek(0)
    return matplotlib.image.imread(buffer, format="png")


@pytest.mark.parametrize("depth", [False, True])
def test_the_synth_figure_follows_the_figure_rules(depth):
    image, coverage = _image_with_an_empty_third()
    depth_m = np.where(np.isfinite(image[..., 0]), 0.5, np.nan) if depth else None
    fig = synth_figure(
        image, coverage, setup=synth_setup(TINY, PORT, virtual_camera_for(TINY), method="proposed"), depth_m=depth_m
    )
    assert_follows_the_figure_rules(fig)
    assert "tiny camera behind a port tilted 20 deg" in fig._suptitle.get_text()
    labels = [t.get_text() for legend in fig.legends for t in legend.get_texts()]
    assert "edge of the exact coverage" in labels
    assert any(label.startswith("no captured ray") for label in labels)


@pytest.mark.parametrize("channels", [None, 1, 3])
def test_the_synth_figure_draws_pixels_without_a_value_grey(channels):
    image, coverage = _image_with_an_empty_third(channels)
    fig = synth_figure(image, coverage, setup="set-up")
    png = _saved(fig)
    shown = image_pixels_in_png(fig, fig.axes[0], png, coverage.shape)
    empty = ~np.isfinite(image if image.ndim == 2 else image[..., 0]).ravel()
    assert np.abs(shown[empty] - NO_VALUE_RGB).max() <= PNG_STEP


def test_synth_writes_the_figure_with_unrecorded_pixels_grey(tmp_path, capsys):
    raw = make_capture(tmp_path / "R")
    out = tmp_path / "s.exr"
    assert main(["synth", str(raw), "--out", str(out), "--quiet"]) == 0
    image = read_exr(out, role="refraction_free")
    coverage = read_exr(out.with_suffix(".coverage.exr"), role="coverage")
    empty = ~np.isfinite(image[..., 0]).ravel()
    assert empty.mean() > 0.2  # the tiny camera's uncovered lower part
    fig = synth_figure(image, coverage, setup=synth_setup(TINY, PORT, virtual_camera_for(TINY), method="proposed"))
    png = matplotlib.image.imread(out.with_suffix(".png"))
    assert png.shape[:2] == tuple(reversed(fig.canvas.get_width_height()))
    shown = image_pixels_in_png(fig, fig.axes[0], png, coverage.shape)
    assert np.abs(shown[empty] - NO_VALUE_RGB).max() <= PNG_STEP
    assert not np.all(shown[empty] >= 1.0 - PNG_STEP, axis=1).any()  # never white
