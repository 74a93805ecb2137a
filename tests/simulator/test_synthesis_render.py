"""Refraction-free synthesis against the simulator's ground truth (photometry and alignment)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from lfrefract import virtual_camera_for
from lfrefract.metrics import psnr, ssim
from lfrefract.synthesis import build_warp_map
from lfrefract.views import naive_view
from simulator import groundtruth
from simulator.job import render_raw
from simulator.scene import build_scene
from tests.simulator.scenes import scene
from tests.tolerances import (
    NAIVE_SSIM_MAX,
    SYNTH_NO_PORT_PSNR_DB,
    SYNTH_NO_PORT_SSIM,
    SYNTH_PSNR_DB,
    SYNTH_SHIFT_PX,
    SYNTH_SSIM,
)

pytestmark = pytest.mark.render

PLANE = {"type": "textured_plane", "position_m": [0.0, 0.0, 0.5], "size_m": [1.5, 1.5], "texture_px": 512}
BOARD = {"type": "chessboard", "position_m": [0.0, 0.0, 0.3], "squares": [8, 6], "square_size_m": 0.012}


def _render(mi, tilt_x_deg: float, *, refracting: bool = True):
    glass, water = (1.5, 1.333) if refracting else (1.0, 1.0)
    port = {
        "distance_m": 0.012,
        "thickness_m": 0.004,
        "tilt_x_deg": tilt_x_deg,
        "n_air": 1.0,
        "n_glass": glass,
        "n_water": water,
    }
    config = scene(port=port, objects=[PLANE, BOARD], spp=32)
    raw = render_raw(mi, config, progress=False)
    pinhole = virtual_camera_for(config.camera)
    ideal = groundtruth.compute(
        mi, build_scene(mi, config, port_geometry=False), config, pinhole, spp=32, seed=0, progress=False
    ).ideal
    warp = build_warp_map(config.camera, config.port)
    return config, raw, ideal, warp


def _shift_px(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    """Translation (px) that best aligns ``a`` with ``b`` over ``mask`` (OpenCV ECC, translation)."""
    x = np.nan_to_num(a.mean(axis=2)).astype(np.float32)
    y = b.mean(axis=2).astype(np.float32)
    warp = np.eye(2, 3, dtype=np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200, 1e-6)
    _, warp = cv2.findTransformECC(y, x, warp, cv2.MOTION_TRANSLATION, criteria, mask.astype(np.uint8), 3)
    return float(np.hypot(warp[0, 2], warp[1, 2]))


@pytest.mark.parametrize("tilt_x_deg", [0.0, 15.0, 30.0])
def test_synthesis_matches_ideal_image_inside_exact_coverage(mi, tilt_x_deg):
    config, raw, ideal, warp = _render(mi, tilt_x_deg)
    image = warp.apply(raw)
    exact = warp.exact
    assert exact.sum() > 300
    peak = float(np.percentile(ideal, 99.5))
    assert psnr(image, ideal, data_range=peak, mask=exact) > SYNTH_PSNR_DB
    assert ssim(image, ideal, data_range=peak, mask=exact) > SYNTH_SSIM
    # The conventional view, with no refraction handling, does not match (the test can fail).
    naive = naive_view(config.camera, raw)
    both = exact & np.all(np.isfinite(naive), axis=2)
    gain = ideal[both].mean() / naive[both].mean()
    assert ssim(naive * gain, ideal, data_range=peak, mask=both) < NAIVE_SSIM_MAX


def test_synthesis_is_aligned_with_the_ideal_image(mi):
    config, raw, ideal, warp = _render(mi, 15.0)
    image = warp.apply(raw)
    assert _shift_px(image, ideal, warp.exact) < SYNTH_SHIFT_PX
    naive = naive_view(config.camera, raw)
    assert _shift_px(naive, ideal, warp.exact) > 5 * SYNTH_SHIFT_PX


def test_without_refraction_synthesis_is_the_central_projection(mi):
    _, raw, ideal, warp = _render(mi, 20.0, refracting=False)
    assert warp.exact.all()
    np.testing.assert_allclose(warp.gain, 1.0, rtol=1e-6)
    image = warp.apply(raw)
    peak = float(np.percentile(ideal, 99.5))
    assert psnr(image, ideal, data_range=peak) > SYNTH_NO_PORT_PSNR_DB
    assert ssim(image, ideal, data_range=peak) > SYNTH_NO_PORT_SSIM
    assert _shift_px(image, ideal, warp.exact) < SYNTH_SHIFT_PX
