"""A rendered white image: micro-image centres lie where the camera model puts them."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.config import RenderSettings, embedded_scenes, load_scene
from simulator.job import render_raw
from tests.tolerances import (
    MICRO_IMAGE_CENTRE_MAX_PX,
    MICRO_IMAGE_CENTRE_RMS_PX,
    NAIVE_CENTRE_MIN_ERROR_PX,
    WHITE_FILL_RELATIVE,
    WHITE_RADIANCE_ABS,
)

pytestmark = pytest.mark.render


def micro_image_centroids(raw: np.ndarray, predicted_px: np.ndarray, radius_px: float) -> np.ndarray:
    """Intensity centroids (N, 2) of the pixels within ``radius_px`` of each predicted centre."""
    r = int(np.ceil(radius_px)) + 1
    base = np.round(predicted_px).astype(int)
    dv, du = np.mgrid[-r : r + 1, -r : r + 1]
    u = base[:, 0, None, None] + du
    v = base[:, 1, None, None] + dv
    near = (u - predicted_px[:, 0, None, None]) ** 2 + (v - predicted_px[:, 1, None, None]) ** 2 < radius_px**2
    weight = raw[v, u] * near
    total = weight.sum(axis=(1, 2))
    return np.stack([(weight * u).sum(axis=(1, 2)) / total, (weight * v).sum(axis=(1, 2)) / total], axis=1)


@pytest.fixture(scope="module")
def white(mi):
    config = load_scene(embedded_scenes()["white"]).with_overrides(render=RenderSettings(spp=64, seed=0))
    return config.camera, render_raw(mi, config, progress=False).mean(axis=2)


def test_micro_image_centres_match_model(white):
    camera, raw = white
    idx = camera.lens_indices_on_sensor()
    predicted = camera.micro_image_centres_px(idx)
    half = camera.micro_image_pitch_px / 2
    h, w = raw.shape
    whole = (predicted[:, 0] > half + 1) & (predicted[:, 0] < w - half - 2)
    whole &= (predicted[:, 1] > half + 1) & (predicted[:, 1] < h - half - 2)
    assert whole.sum() > 1500
    found = micro_image_centroids(raw, predicted[whole], half)
    error = np.linalg.norm(found - predicted[whole], axis=1)
    assert np.sqrt(np.mean(error**2)) < MICRO_IMAGE_CENTRE_RMS_PX
    assert error.max() < MICRO_IMAGE_CENTRE_MAX_PX
    # The point straight below each lens centre is the wrong model: off by pixels at the edge.
    naive = camera.sensor.image_plane_to_pixels(camera.mla.centres_m(idx[whole]))
    naive_error = np.linalg.norm(found - naive, axis=1)
    assert naive_error.max() > NAIVE_CENTRE_MIN_ERROR_PX


def test_micro_images_are_discs_of_the_aperture(white):
    """Radiance 1 inside the aperture's image through each lens, 0 between micro-images."""
    camera, raw = white
    uv = np.stack(np.meshgrid(np.arange(raw.shape[1]), np.arange(raw.shape[0])), axis=-1).reshape(-1, 2)
    idx = camera.lens_indices_for_pixels(uv)
    dist = np.linalg.norm(uv - camera.micro_image_centres_px(idx), axis=1).reshape(raw.shape)
    r = camera.micro_image_radius_px
    np.testing.assert_allclose(
        raw[dist < r - 1.0], 1.0, atol=WHITE_RADIANCE_ABS
    )  # pixel and lens-cell blur inside: every path passes
    assert np.all(raw[dist > r + 1.0] == 0.0)  # wholly outside: vignetted
    fill = raw.mean()
    expected_fill = (
        np.pi * r**2 / (camera.mla.cell_area_m2 * camera.micro_image_scale**2 / camera.sensor.pixel_pitch_m**2)
    )
    assert fill == pytest.approx(expected_fill, rel=WHITE_FILL_RELATIVE)
