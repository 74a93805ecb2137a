"""Refraction-free synthesis against the simulator's ground truth (photometry and alignment)."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import virtual_camera_for
from lfrefract.metrics import psnr, shift_px, ssim
from lfrefract.synthesis.views import naive_view
from lfrefract.synthesis.warp_map import PAPER_K, SynthesisOptions, build_warp_map
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
    # The paper's k, at which the tolerances were measured (the default is 8).
    warp = build_warp_map(config.camera, config.port, options=SynthesisOptions(k=PAPER_K))
    return config, raw, ideal, warp


def _shift_px(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    """Length (px) of the translation that best aligns ``a`` with ``b`` over ``mask``."""
    return float(np.hypot(*shift_px(a, b, mask=mask)))


@pytest.mark.parametrize("tilt_x_deg", [0.0, 15.0, 30.0])
def test_synthesis_matches_ideal_image_inside_exact_coverage(mi, tilt_x_deg):
    config, raw, ideal, warp = _render(mi, tilt_x_deg)
    image = warp.apply(raw)
    exact = warp.exact
    assert exact.sum() > 100  # 30 deg: 2.6 % of the 92 x 69 image
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


def test_cli_synth_and_naive_on_a_render(tmp_path, capsys):
    from lfrefract import cli as core_cli
    from lfrefract.formats.exr import read_exr
    from lfrefract.formats.jsonio import read_json
    from simulator import cli as sim_cli

    render = tmp_path / "render"
    assert sim_cli.main(["render", "--out", str(render), "--spp", "2", "--quiet", "--no-previews"]) == 0
    cache = tmp_path / "maps"
    out = tmp_path / "synth" / "frame.exr"
    for again in ([], ["--overwrite"]):  # build and cache, then load from the cache (replacing its own output)
        synth = ["synth", str(render / "raw.exr"), "--out", str(out), "--map-cache", str(cache), *again]
        assert core_cli.main(synth) == 0
    printed = capsys.readouterr().out
    assert "built, cached as" in printed
    assert "loaded" in printed
    sidecar = read_json(out.with_suffix(".json"))
    meta = read_json(render / "meta.json")
    assert sidecar["K"] == meta["ideal"]["K"]
    image = read_exr(out, role="refraction_free")
    assert image.shape == (meta["ideal"]["height_px"], meta["ideal"]["width_px"], 3)
    coverage = read_exr(out.with_suffix(".coverage.exr"), role="coverage")
    assert 0.0 < sidecar["coverage"]["exact_fraction"] == pytest.approx(float(np.mean(coverage >= 1.0)))
    assert out.with_suffix(".png").is_file()
    assert len(list(cache.iterdir())) == 1
    naive = tmp_path / "naive.exr"
    assert core_cli.main(["naive", str(render / "raw.exr"), "--out", str(naive)]) == 0
    assert read_exr(naive, role="naive_central").shape == image.shape


def test_cli_synth_refuses_a_capture_without_port(tmp_path, capsys):
    from lfrefract import cli as core_cli
    from simulator import cli as sim_cli

    render = tmp_path / "white"
    assert sim_cli.main(["render", "white", "--out", str(render), "--spp", "2", "--quiet", "--no-previews"]) == 0
    assert core_cli.main(["synth", str(render / "raw.exr"), "--out", str(tmp_path / "x.exr")]) == 2
    assert "has no port" in capsys.readouterr().err
    assert not (tmp_path / "x.exr").exists()
