"""The sensor model (simulator.detector) against theory: noise statistics, the Bayer layout, levels and
saturation, seeds, the optical blur, OpenCV's demosaicing, refused configs; and on a rendered white image,
that MLA calibration still finds the micro-image lattice (issue 14)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import integrate, special

from lfrefract.calibration import calibrate_mla
from lfrefract.errors import ParameterError
from lfrefract.formats.mosaic import CFA_PATTERNS, RawMosaic
from simulator.detector import (
    DETECTOR_PRESETS,
    DetectorConfig,
    demosaic,
    detector_preset,
    edge_width_px,
    expected_electrons,
    pixel_psf_kernel,
    radial_profile,
    simulate_mosaic,
    white_frames,
)
from tests.tolerances import (
    DETECTOR_AIRY_EDGE,
    DETECTOR_COLOUR_RELATIVE,
    DETECTOR_EDGE_WIDTH_PX,
    DETECTOR_GAUSSIAN_EDGE,
    DETECTOR_MEAN_STANDARD_ERRORS,
    DETECTOR_VARIANCE_STANDARD_ERRORS,
    MLA_FITTED_CENTRE_MAX_PX,
    MLA_PITCH_PX,
)

IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def plain(**changes) -> DetectorConfig:
    """A detector without blur or crosstalk, identity filters, 12 bits (fields replaced by ``changes``)."""
    values = dict(
        cfa_pattern="RGGB",
        cfa_response=IDENTITY,
        quantum_efficiency=0.5,
        photons_per_unit_radiance=2000.0,
        full_well_e=20000.0,
        read_noise_e=5.0,
        gain_dn_per_e=0.5,
        iso=100.0,
        base_iso=100.0,
        black_level_dn=100,
        white_level_dn=4095,
        bit_depth=12,
        pixel_pitch_m=1.4e-6,
        microlens_f_number=2.0,
        psf="none",
        crosstalk=0.0,
    )
    values.update(changes)
    return DetectorConfig(**values)


def flat(rgb, shape=(512, 512)) -> np.ndarray:
    return np.broadcast_to(np.asarray(rgb, dtype=np.float64), (*shape, 3)).copy()


# ------------------------------------------------------------------ statistics
@pytest.mark.parametrize(
    "changes",
    [
        {},  # shot noise dominates: 1000 e-, 0.5 DN/e-
        {"gain_dn_per_e": 0.1, "read_noise_e": 10.0, "photons_per_unit_radiance": 100.0},  # rounding 5.5 % of var
        {"iso": 400.0, "read_noise_e": 0.0},  # ISO 4x base: gain 2 DN/e-
    ],
    ids=["shot", "quantisation", "iso"],
)
def test_flat_field_mean_and_variance_match_poisson_read_noise_and_rounding(changes):
    config = plain(**changes)
    radiance = (1.0, 0.6, 0.3)
    mosaic = simulate_mosaic(flat(radiance), config, seed=11)
    channels = mosaic.channel_index()
    counts = mosaic.counts.astype(np.float64)
    g = config.gain_dn_per_e * config.iso / config.base_iso
    assert config.gain_effective_dn_per_e == pytest.approx(g)
    for c in range(3):
        samples = counts[channels == c]
        n = samples.size
        mean_e = config.quantum_efficiency * config.photons_per_unit_radiance * radiance[c]
        mean_dn = config.black_level_dn + g * mean_e
        var_dn = g**2 * (mean_e + config.read_noise_e**2) + 1.0 / 12.0
        assert abs(samples.mean() - mean_dn) < DETECTOR_MEAN_STANDARD_ERRORS * math.sqrt(var_dn / n)
        assert abs(samples.var(ddof=1) - var_dn) < DETECTOR_VARIANCE_STANDARD_ERRORS * var_dn * math.sqrt(2 / (n - 1))


def test_averaged_white_frames_shrink_the_noise():
    config = plain(gain_dn_per_e=1.0, read_noise_e=3.0)
    one = simulate_mosaic(flat((0.5, 0.5, 0.5), (256, 256)), config, seed=2).counts.astype(float)
    many = white_frames(flat((0.5, 0.5, 0.5), (256, 256)), config, frames=16, seed=2).counts.astype(float)
    assert many.dtype == np.float64
    assert np.all(many == np.rint(many))
    var_one = 1.0 * (500.0 + 9.0) + 1 / 12
    n = many.size
    # 16 frames: the noise variance shrinks 16-fold; rounding the mean adds 1/12 DN^2.
    var_many = var_one / 16 + 1 / 12
    assert abs(one.var() - var_one) < DETECTOR_VARIANCE_STANDARD_ERRORS * var_one * math.sqrt(2 / (n - 1))
    assert abs(many.var() - var_many) < DETECTOR_VARIANCE_STANDARD_ERRORS * var_many * math.sqrt(2 / (n - 1))
    assert abs(many.mean() - (100 + 500)) < DETECTOR_MEAN_STANDARD_ERRORS * math.sqrt(var_many / n)


# ------------------------------------------------------------------ layout, levels, saturation
@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_each_pattern_puts_r_g_b_where_it_says(pattern):
    config = plain(cfa_pattern=pattern, read_noise_e=0.0)
    for c, colour in enumerate("RGB"):
        radiance = np.zeros(3)
        radiance[c] = 1.0
        mosaic = simulate_mosaic(flat(radiance, (6, 8)), config, seed=0)
        lit = mosaic.counts > config.black_level_dn
        # No light, no read noise: exactly the black level.
        assert np.all(mosaic.counts[~lit] == config.black_level_dn)
        expected = np.zeros((6, 8), dtype=bool)
        for k, letter in enumerate(pattern):
            if letter == colour:
                expected[k // 2 :: 2, k % 2 :: 2] = True
        assert np.array_equal(lit, expected)
        assert np.array_equal(mosaic.channel_index() == c, expected)
    assert mosaic.cfa_pattern == pattern


def test_black_level_white_level_and_saturation():
    config = plain(read_noise_e=0.0)
    dark = simulate_mosaic(flat((0.0, 0.0, 0.0), (8, 8)), config, seed=0)
    assert np.all(dark.counts == config.black_level_dn)
    assert not dark.saturated.any()
    # 40 times the full well: the full well clips at 100 + 0.5 * 20000 = 10100 DN, above the 12-bit white level.
    bright = simulate_mosaic(flat((400.0, 400.0, 400.0), (8, 8)), config, seed=0)
    assert np.all(bright.counts == 4095)
    assert bright.saturated.all()
    # A gain that maps the full well below the white level: the full well is what saturates.
    low_gain = plain(read_noise_e=0.0, gain_dn_per_e=0.1)
    clipped = simulate_mosaic(flat((400.0, 400.0, 400.0), (8, 8)), low_gain, seed=0)
    assert np.all(clipped.counts == 100 + 0.1 * 20000)
    assert not clipped.saturated.any()
    # With read noise the dark level scatters about the black level; nothing is below 0.
    noisy = plain(read_noise_e=400.0, black_level_dn=10)
    counts = simulate_mosaic(flat((0.0, 0.0, 0.0), (64, 64)), noisy, seed=0).counts
    assert counts.min() == 0
    assert counts.max() > 10
    assert (
        RawMosaic(counts=counts, cfa_pattern="RGGB", black_level_dn=10, white_level_dn=4095, bit_depth=12)
        .normalised()
        .min()
        < 0
    )


def test_the_seed_decides_the_noise():
    raw = np.random.default_rng(0).uniform(0.0, 1.0, (40, 60, 3))
    config = DETECTOR_PRESETS["tiny"]
    a = simulate_mosaic(raw, config, seed=7)
    assert np.array_equal(a.counts, simulate_mosaic(raw, config, seed=7).counts)
    assert not np.array_equal(a.counts, simulate_mosaic(raw, config, seed=8).counts)
    w = white_frames(raw, config, frames=3, seed=7)
    assert np.array_equal(w.counts, white_frames(raw, config, frames=3, seed=7).counts)
    assert not np.array_equal(w.counts, white_frames(raw, config, frames=3, seed=9).counts)
    assert a.counts.dtype == np.uint16
    assert a.counts.shape == (40, 60)
    with pytest.raises(ParameterError, match="seed"):
        simulate_mosaic(raw, config, seed=-1)


# ------------------------------------------------------------------ blur
def step_profile(config: DetectorConfig, width=400, height=160, edge=200) -> np.ndarray:
    """Mean electrons along a row of an image dark left of column ``edge`` and lit from it on (grey)."""
    image = np.zeros((height, width, 3))
    image[:, edge:, :] = 1.0
    electrons = expected_electrons(image, config)
    return electrons[height // 2] / (config.quantum_efficiency * config.photons_per_unit_radiance)


def test_gaussian_blur_widens_a_hard_edge_by_the_predicted_amount():
    # sigma = 0.42 lambda N = 0.42 * 500 nm * 9.5238 = 2.0 um = 2 px at 1 um pixels.
    config = plain(
        psf="gaussian", wavelengths_m=(500e-9,) * 3, microlens_f_number=2e-6 / (0.42 * 500e-9), pixel_pitch_m=1e-6
    )
    sigma_px = config.psf_sigma_m(1) / config.pixel_pitch_m
    assert sigma_px == pytest.approx(2.0)
    profile = step_profile(config)
    u = np.arange(400)
    # The pixel-integrated PSF telescopes: pixel u of the blurred step holds Phi((u - 199.5) / sigma).
    expected = special.ndtr((u - 199.5) / sigma_px)
    assert np.max(np.abs(profile - expected)) < DETECTOR_GAUSSIAN_EDGE
    # An extra Gaussian adds in quadrature.
    wider = dataclasses.replace(config, extra_blur_sigma_m=1.5e-6)
    assert np.max(np.abs(step_profile(wider) - special.ndtr((u - 199.5) / 2.5))) < DETECTOR_GAUSSIAN_EDGE


def airy_edge_spread(x_over_lambda_n: np.ndarray) -> np.ndarray:
    """Edge spread function of the Airy PSF, from its closed-form line spread function
    (4 / pi) H1(2 v) / v^2 with v = pi x / (lambda N) (Struve H1), which integrates to 4 / pi."""

    def lsf(t):
        v = math.pi * t
        return 4.0 / math.pi * special.struve(1, 2 * v) / v**2 if v > 0 else 32.0 / (3.0 * math.pi**2)

    half = [integrate.quad(lsf, 0.0, abs(x), limit=400)[0] for x in x_over_lambda_n]
    return 0.5 + np.sign(x_over_lambda_n) * np.array(half) / (4.0 / math.pi)


def test_airy_blur_matches_the_diffraction_edge_spread_function():
    # First dark ring 1.22 lambda N = 3 px: lambda N = 2.4597 px.
    lam = 500e-9
    n = 3e-6 / (1.2196698912665045 * lam)
    config = plain(psf="airy", wavelengths_m=(lam,) * 3, microlens_f_number=n, pixel_pitch_m=1e-6)
    assert config.airy_radius_m(1) == pytest.approx(3e-6, rel=1e-12)
    profile = step_profile(config)
    u = np.arange(180, 221)
    expected = airy_edge_spread((u - 199.5) * 1e-6 / (lam * n))
    assert expected[0] < 0.05
    assert expected[-1] > 0.95
    assert np.max(np.abs(profile[u] - expected)) < DETECTOR_AIRY_EDGE
    # The Gaussian fit of the same lambda N is a different edge (no rings): the check can tell them apart.
    gaussian = step_profile(dataclasses.replace(config, psf="gaussian"))
    assert np.max(np.abs(gaussian[u] - expected)) > 4 * DETECTOR_AIRY_EDGE
    # Longer wavelengths blur more: red's kernel is wider than blue's.
    colours = dataclasses.replace(config, wavelengths_m=(650e-9, 530e-9, 450e-9))
    spread = [
        np.sum(pixel_psf_kernel(colours, c) * np.arange(-k, k + 1) ** 2)
        for c, k in ((c, pixel_psf_kernel(colours, c).shape[0] // 2) for c in range(3))
    ]
    assert spread[0] > spread[1] > spread[2]


def test_edge_width_of_a_gaussian_profile():
    r = np.arange(0.0, 30.0, 0.01) + 0.005
    profile = 1.0 - special.ndtr((r - 15.0) / 1.7)
    width, r_high, r_low = edge_width_px(r, profile, plateau_px=5.0)
    assert width == pytest.approx(2 * 1.2815515655446004 * 1.7, abs=DETECTOR_EDGE_WIDTH_PX)
    assert r_high < 15.0 < r_low


def test_crosstalk_moves_a_share_of_the_charge_to_the_four_neighbours():
    config = plain(psf="none", crosstalk=0.2)
    image = np.zeros((9, 9, 3))
    image[4, 4, :] = 1.0
    electrons = expected_electrons(image, config) / 1000.0  # 0.5 * 2000 e- per unit radiance
    assert electrons[4, 4] == pytest.approx(0.8)
    for dv, du in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        assert electrons[4 + dv, 4 + du] == pytest.approx(0.05)
    assert electrons.sum() == pytest.approx(1.0)


# ------------------------------------------------------------------ demosaicing
@pytest.mark.parametrize("method", ["bilinear", "edge_aware"])
@pytest.mark.parametrize("pattern", CFA_PATTERNS)
def test_demosaic_of_a_known_colour_returns_it(pattern, method):
    # Write the mosaic of the colour (R 300, G 500, B 700 DN) by hand from the pattern's letters.
    counts = np.zeros((12, 16), dtype=np.uint16)
    value = {"R": 300, "G": 500, "B": 700}
    for k, letter in enumerate(pattern):
        counts[k // 2 :: 2, k % 2 :: 2] = value[letter]
    mosaic = RawMosaic(counts=counts, cfa_pattern=pattern, black_level_dn=64, white_level_dn=1023, bit_depth=10)
    rgb = demosaic(mosaic, method=method)
    assert rgb.shape == (12, 16, 3)
    expected = (np.array([300, 500, 700]) - 64) / (1023 - 64)
    assert np.allclose(rgb[2:-2, 2:-2], expected, rtol=0, atol=1e-12)


def test_a_colour_through_the_whole_chain_comes_back():
    # The tiny preset without crosstalk (crosstalk mixes a pixel's colour with its neighbours').
    config = dataclasses.replace(DETECTOR_PRESETS["tiny"], crosstalk=0.0)
    colour = np.array([0.9, 0.5, 0.2])
    mosaic = white_frames(flat(colour, (64, 64)), config, frames=64, seed=4)
    radiance = config.radiance_from_camera_rgb(demosaic(mosaic))
    mean = radiance[8:-8, 8:-8].reshape(-1, 3).mean(axis=0)
    assert np.max(np.abs(mean - colour)) < DETECTOR_COLOUR_RELATIVE * colour.max()


# ------------------------------------------------------------------ configs and presets
def test_presets_carry_the_published_lytro_formats():
    illum, f01 = detector_preset("illum"), detector_preset("f01")
    assert (illum.cfa_pattern, illum.bit_depth, illum.black_level_dn, illum.white_level_dn) == ("GRBG", 10, 64, 1023)
    assert (f01.cfa_pattern, f01.bit_depth, f01.black_level_dn, f01.white_level_dn) == ("BGGR", 12, 168, 4095)
    assert illum.pixel_pitch_m == f01.pixel_pitch_m == 1.4e-6
    # Radiance 1 (a white image) fills 70 % of the full well in green, below saturation.
    for config in DETECTOR_PRESETS.values():
        assert config.electrons_per_unit_radiance * sum(config.cfa_response[1]) < config.full_well_e
        assert DetectorConfig.from_dict(config.to_dict()) == config
    assert DetectorConfig.from_dict({"preset": "illum", "iso": 320.0}) == dataclasses.replace(illum, iso=320.0)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("cfa_pattern", "RGBG"),
        ("cfa_response", ((1.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))),
        ("cfa_response", ((0.6, 0.6, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))),
        ("cfa_response", ((-0.1, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))),
        ("cfa_response", ((0.5, 0.5, 0.0), (0.5, 0.5, 0.0), (0.0, 0.0, 1.0))),
        ("quantum_efficiency", 1.5),
        ("quantum_efficiency", 0.0),
        ("photons_per_unit_radiance", -1.0),
        ("full_well_e", 0.0),
        ("read_noise_e", -1.0),
        ("read_noise_e", math.nan),
        ("gain_dn_per_e", 0.0),
        ("iso", "100"),
        ("base_iso", -80.0),
        ("bit_depth", 17),
        ("bit_depth", 10.0),
        ("white_level_dn", 4096),
        ("black_level_dn", 4095),
        ("pixel_pitch_m", 1.4),
        ("microlens_f_number", 0.0),
        ("psf", "moffat"),
        ("wavelengths_m", (600.0, 530.0, 460.0)),
        ("wavelengths_m", (600e-9, 530e-9)),
        ("extra_blur_sigma_m", -1e-6),
        ("crosstalk", 0.6),
    ],
)
def test_bad_configs_are_refused_naming_the_field(field, value):
    with pytest.raises(ParameterError, match=field):
        plain(**{field: value})


def test_bad_tables_and_images_are_refused():
    data = plain().to_dict()
    with pytest.raises(ParameterError, match="exposure"):
        DetectorConfig.from_dict({**data, "exposure": 1.0})
    del data["full_well_e"]
    with pytest.raises(ParameterError, match="full_well_e"):
        DetectorConfig.from_dict(data)
    with pytest.raises(ParameterError, match="preset"):
        DetectorConfig.from_dict({"preset": "nikon"})
    with pytest.raises(ParameterError, match="radiance_rgb"):
        simulate_mosaic(np.ones((8, 8)), plain(), seed=0)
    with pytest.raises(ParameterError, match="radiance_rgb"):
        simulate_mosaic(-np.ones((8, 8, 3)), plain(), seed=0)
    with pytest.raises(ParameterError, match="frames"):
        white_frames(np.ones((8, 8, 3)), plain(), frames=0, seed=0)
    with pytest.raises(ParameterError, match="counts"):
        RawMosaic(
            counts=np.full((4, 4), 5000, np.uint16),
            cfa_pattern="RGGB",
            black_level_dn=0,
            white_level_dn=4095,
            bit_depth=12,
        )
    with pytest.raises(ParameterError, match="method"):
        demosaic(simulate_mosaic(np.ones((8, 8, 3)), plain(), seed=0), method="vng")


# ------------------------------------------------------------------ on a rendered white image
@pytest.mark.render
def test_mla_calibration_finds_the_lattice_in_a_simulated_white_image(mi):
    from lfrefract import camera_preset
    from simulator.config import RenderSettings, embedded_scenes, load_scene
    from simulator.job import render_raw

    camera = camera_preset("tiny")
    scene = load_scene(embedded_scenes()["white"]).with_overrides(camera=camera, render=RenderSettings(spp=64, seed=0))
    raw = np.asarray(render_raw(mi, scene, progress=False), dtype=np.float64)
    white = white_frames(raw, DETECTOR_PRESETS["tiny"], frames=64, seed=1)
    green = demosaic(white)[:, :, 1]
    truth = camera.micro_image_centres_px(camera.lens_indices_on_sensor())
    # The sensor softens the micro-image edges: the 10-90 % width grows (0.83 px rendered, 1.98 px demosaiced).
    before = edge_width_px(*radial_profile(raw[:, :, 1], truth, max_radius_px=5.9), plateau_px=2.0)[0]
    after = edge_width_px(*radial_profile(green, truth, max_radius_px=5.9), plateau_px=2.0)[0]
    assert after > before + 0.5
    cal = calibrate_mla(green)
    assert cal.pitch_px == pytest.approx(camera.micro_image_pitch_px, abs=MLA_PITCH_PX)
    fitted = np.linalg.norm(
        cal.centres_px - camera.micro_image_centres_px(camera.lens_indices_for_pixels(cal.centres_px)), axis=1
    )
    assert fitted.max() < MLA_FITTED_CENTRE_MAX_PX


def test_any_finite_radiance_saturates_instead_of_failing():
    """A radiance whose mean charge passed about 1e19 electrons made numpy's Poisson raise 'lam value too large'."""
    from simulator.detector import DETECTOR_PRESETS, simulate_mosaic

    config = DETECTOR_PRESETS["illum"]
    mosaic = simulate_mosaic(np.full((4, 4, 3), 1e16), config, seed=0)
    # Full well, then read noise (2.5 e- RMS, about 0.5 DN here) on top: every pixel at the white level but a DN or two.
    assert mosaic.counts.min() >= config.white_level_dn - 3


def test_detector_types_take_keywords_only():
    from simulator.detector import DetectorConfig

    assert all(f.kw_only for cls in (DetectorConfig, RawMosaic) for f in dataclasses.fields(cls))
