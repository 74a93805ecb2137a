"""The PNG previews of a render (``lfsim render``, ``lfsim rig``): the depth figure follows the figure
rule (its long title ran under its colour bar, it had no set-up and no pixel axes), and pixels with no
surface are drawn grey, as in every figure of the project (they were white)."""

from __future__ import annotations

import matplotlib.image
import numpy as np

from lfrefract import FlatPort, camera_preset, virtual_camera_for
from lfrefract.figures import NO_VALUE_RGB
from simulator.previews import depth_figure, write_all
from tests.figure_rules import assert_follows_the_figure_rules, image_pixels_in_png

TINY = camera_preset("tiny")
PORT = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.006, tilt_x_deg=20.0)
#: A PNG stores 8-bit colours: a saved grey is within one step of NO_VALUE_RGB.
PNG_STEP = 1.5 / 255


def _depth() -> np.ndarray:
    """The ideal image's depth, metres: a plane at 0.3-0.5 m, no surface (+inf) in the top third."""
    output = virtual_camera_for(TINY)
    depth = np.tile(np.linspace(0.3, 0.5, output.width_px, dtype=np.float32), (output.height_px, 1))
    depth[: output.height_px // 3] = np.inf
    return depth


def test_the_depth_preview_follows_the_figure_rules():
    fig = depth_figure(_depth(), setup="default scene, tiny camera behind a port tilted 20 deg")
    assert_follows_the_figure_rules(fig)
    labels = [t.get_text() for legend in fig.legends for t in legend.get_texts()]
    assert "no surface" in labels


def test_the_depth_preview_draws_pixels_with_no_surface_grey(tmp_path):
    depth = _depth()
    rng = np.random.default_rng(0)
    raw = rng.random((TINY.sensor.height_px, TINY.sensor.width_px, 3)).astype(np.float32)
    ideal = rng.random((*depth.shape, 3)).astype(np.float32)
    written = write_all(tmp_path, raw=raw, ideal=ideal, depth_m=depth, camera=TINY, port=PORT)
    assert tmp_path / "depth.png" in written
    png = matplotlib.image.imread(tmp_path / "depth.png")
    fig = depth_figure(depth, setup="x")  # the same layout: the title's text does not move the axes
    shown = image_pixels_in_png(fig, fig.axes[0], png, depth.shape)
    none = ~np.isfinite(depth).ravel()
    assert np.abs(shown[none] - NO_VALUE_RGB).max() <= PNG_STEP
    assert np.abs(shown[~none] - NO_VALUE_RGB).max(axis=1).min() > PNG_STEP  # the plane is in colour
