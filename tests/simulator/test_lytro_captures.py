"""The core on Lytro files end to end: a rendered LFR capture and the white images of its camera, in
the core's commands, give the refraction-free image of the noiseless render."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import cli as core_cli
from lfrefract.formats.capture import read_capture
from lfrefract.formats.exr import read_exr
from lfrefract.formats.jsonio import read_json
from simulator import cli as sim_cli
from tests.tolerances import LYTRO_DEVELOPED_RATIO, LYTRO_SYNTH_RELATIVE_RMS

PORT_KEYS = ("distance_m", "thickness_m", "tilt_x_rad", "tilt_y_rad", "n_air", "n_glass", "n_water")


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    root = tmp_path_factory.mktemp("lytro")
    common = ["--quiet", "--spp", "16"]
    argv = ["render", "--camera", "tiny", "--sensor", "tiny", "--lfr", "--no-previews", "--out", str(root / "cap")]
    assert sim_cli.main([*argv, *common]) == 0
    whites = ["whites", "--camera", "tiny", "--focus-m", "0.3,inf", "--frames", "8", "--out", str(root / "whites")]
    assert sim_cli.main([*whites, *common]) == 0
    port = read_json(root / "cap" / "meta.json")["port"]
    (root / "port.toml").write_text("[port]\n" + "\n".join(f"{k} = {port[k]!r}" for k in PORT_KEYS) + "\n")
    return root


@pytest.mark.render
def test_the_capture_is_developed_with_the_white_of_its_setting(rendered):
    capture = read_capture(rendered / "cap" / "capture.lfr", white=rendered / "whites")
    lytro = capture.sidecar["lytro"]
    assert lytro["white"]["file"].endswith("white_001.raw")  # infinity focus, as the capture
    assert (lytro["white"]["zoom_step"], lytro["white"]["focus_step"]) == (lytro["zoom_step"], lytro["focus_step"])
    raw = read_exr(rendered / "cap" / "raw.exr")
    inner = np.isfinite(capture.raw).all(axis=2) & (raw.min(axis=2) > 0.2 * raw.max())
    ratio = np.median(capture.raw[inner] / raw[inner], axis=0)
    np.testing.assert_allclose(ratio, 1.0, atol=LYTRO_DEVELOPED_RATIO)
    # Nothing saturated, no bad pixel in the white, and the colour matrix's negative entries take no
    # dark pixel below 0 (they were masked as negative values, 37 765 of them at 16 spp, before): what is
    # unrecorded is what the white does not light.
    masked = capture.masked_summary()
    assert (masked["negative"], masked["posinf"], masked["neginf"]) == (0, 0, 0)
    np.testing.assert_array_equal(capture.recorded, capture.developed.lit)


@pytest.mark.render
def test_synth_takes_the_lfr_and_its_whites(rendered, capsys):
    out = rendered / "rf"
    argv = ["synth", str(rendered / "cap" / "capture.lfr"), "--white", str(rendered / "whites")]
    assert core_cli.main([*argv, "--port", str(rendered / "port.toml"), "--out", str(out / "lfr.exr"), "--quiet"]) == 0
    assert core_cli.main(["synth", str(rendered / "cap" / "raw.exr"), "--out", str(out / "raw.exr"), "--quiet"]) == 0
    capsys.readouterr()
    lfr, truth = read_exr(out / "lfr.exr"), read_exr(out / "raw.exr")
    covered = (read_exr(out / "raw.coverage.exr") > 0.999) & np.isfinite(lfr).all(axis=2)
    difference = lfr[covered] - truth[covered]
    assert np.sqrt(np.mean(difference**2)) < LYTRO_SYNTH_RELATIVE_RMS * truth[covered].mean()
    plain = ["synth", str(rendered / "cap" / "capture.lfr"), "--port", str(rendered / "port.toml")]
    assert core_cli.main([*plain, "--out", str(out / "plain.exr"), "--quiet"]) == 0
    undevignetted = read_exr(out / "plain.exr")[covered] - truth[covered]
    assert np.sqrt(np.mean(undevignetted**2)) > 3 * LYTRO_SYNTH_RELATIVE_RMS * truth[covered].mean()
    sidecar = read_json(out / "lfr.json")
    assert sidecar["camera"] == read_json(rendered / "cap" / "meta.json")["camera"]


@pytest.mark.render
def test_naive_and_views_take_the_lfr_too(rendered):
    lfr = str(rendered / "cap" / "capture.lfr")
    assert core_cli.main(["naive", lfr, "--white", str(rendered / "whites"), "--out", str(rendered / "n.exr")]) == 0
    assert read_exr(rendered / "n.exr").shape[2] == 3


@pytest.mark.render
def test_synth_gathers_colour_by_colour_when_asked(rendered, capsys):
    out = rendered / "cfa"
    lfr, port = str(rendered / "cap" / "capture.lfr"), str(rendered / "port.toml")
    argv = ["synth", lfr, "--white", str(rendered / "whites"), "--port", port, "--colour", "cfa"]
    assert core_cli.main([*argv, "--out", str(out / "cfa.exr"), "--quiet"]) == 0
    sidecar = read_json(out / "cfa.json")
    assert sidecar["colour"] == "cfa"
    assert set(sidecar["map_key"]) == {"R", "G", "B"}
    assert (
        core_cli.main(["synth", str(rendered / "cap" / "raw.exr"), "--colour", "cfa", "--out", str(out / "x.exr")]) == 2
    )
    assert "--colour cfa applies to a Lytro capture" in capsys.readouterr().err
