"""Direct lighting samples every emitter: two point lights add no noise, and lights superpose.

Mitsuba's ``direct`` and ``path`` integrators pick one emitter at random per shadow ray; the
project's integrator (:mod:`simulator.lighting`) sends one to each. With point lights the only
noise left is where in the pixel a sample lands, so a white plane is as clean under two lamps
as under one, and the image of two lamps is the sum of the images of each (same seed, same
samples).
"""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import virtual_camera_for
from simulator import groundtruth
from simulator.config import RenderSettings
from simulator.job import render_raw
from simulator.scene import build_scene
from tests.simulator.scenes import LIGHTS, port, scene
from tests.tolerances import LIGHT_SUPERPOSITION_RELATIVE, WHITE_PLANE_NOISE_RELATIVE

pytestmark = pytest.mark.render

WHITE = [{"type": "disc", "position_m": [0.0, 0.0, 0.3], "radius_m": 0.5, "reflectance": [1.0, 1.0, 1.0]}]


def _ideal(mi, config, spp: int):
    glass_free = build_scene(mi, config, port_geometry=False)
    pinhole = virtual_camera_for(config.camera)
    return groundtruth.compute(mi, glass_free, config, pinhole, spp=spp, seed=config.render.seed, progress=False).ideal


def _relative_noise(a: np.ndarray, b: np.ndarray) -> float:
    """Per-pixel relative noise of one render from two seeds: std of their difference over sqrt(2),
    over the mean, on the brightest pixels (within 80 % of the 99th percentile: inside the lit
    plane and, in a raw image, away from the micro-images' vignetted rims)."""
    mean, diff = (a + b).mean(axis=2) / 2, (a - b).mean(axis=2)
    lit = mean > 0.8 * np.percentile(mean, 99)
    return float(np.std(diff[lit]) / np.sqrt(2) / np.mean(mean[lit]))


def test_a_white_plane_under_two_point_lights_is_as_clean_as_under_one(mi):
    spp = 8
    renders = {}
    for lights in (LIGHTS[:1], LIGHTS):
        for seed in (0, 1):
            config = scene(port=port(20.0), objects=WHITE, lights=lights, seed=seed)
            renders[len(lights), seed] = _ideal(mi, config, spp)
    one, two = _relative_noise(renders[1, 0], renders[1, 1]), _relative_noise(renders[2, 0], renders[2, 1])
    assert one < WHITE_PLANE_NOISE_RELATIVE
    assert two < WHITE_PLANE_NOISE_RELATIVE  # picking one of the two lamps per sample: about 20 %


@pytest.mark.parametrize("port_model", ["sensor", "geometry"])
def test_the_image_of_two_lights_is_the_sum_of_the_image_of_each(mi, port_model):
    images = {}
    for name, lights in {"first": LIGHTS[:1], "second": LIGHTS[1:], "both": LIGHTS}.items():
        config = scene(port=port(20.0), objects=WHITE, lights=lights)
        config = config.with_overrides(render=RenderSettings(spp=2, seed=4, port_model=port_model))
        images[name] = (render_raw(mi, config, progress=False), _ideal(mi, config, 2))
    for k, kind in enumerate(("raw", "ideal")):
        first, second, both = (images[name][k] for name in ("first", "second", "both"))
        tolerance = LIGHT_SUPERPOSITION_RELATIVE * float(np.max(both))
        assert tolerance > 0.0, kind
        np.testing.assert_allclose(both, first + second, rtol=0, atol=tolerance, err_msg=kind)
