"""The sensor model in a render: the [sensor] table, lfsim render --sensor / --frames / --lfr, and the files.

The Lytro files a render writes are read back by imageio's third-party readers (the F01 raw, whose
reader accepts its 3280 x 3280 sensor) and by lfrefract's own (the tiny camera's LFR, which imageio
cannot reshape): both give the counts of ``mosaic.npz`` exactly.
"""

from __future__ import annotations

import copy
import tomllib
import warnings

import imageio  # a test dependency: the third-party reader the files must satisfy
import numpy as np
import pytest

from lfrefract import camera_preset
from lfrefract.errors import ParameterError
from lfrefract.formats.jsonio import read_json
from lfrefract.formats.lytro import read_f01_raw, read_lfr
from lfrefract.formats.mosaic import read_mosaic_npz
from simulator import cli
from simulator.config import default_scene_path, embedded_scenes, parse_scene, sensor_model
from simulator.detector import DETECTOR_PRESETS, lytro_settings
from simulator.job import LFR_NAME, LYTRO_RAW_NAME, MOSAIC_NAME, lens_steps

DEFAULT = tomllib.loads(default_scene_path().read_text(encoding="utf-8"))
WHITE = tomllib.loads(embedded_scenes()["white"].read_text(encoding="utf-8"))


def _scene(base: dict, **tables) -> dict:
    data = copy.deepcopy(base)
    data.update(tables)
    return data


# ------------------------------------------------------------------ the [sensor] table
def test_a_sensor_takes_its_pixel_pitch_and_microlens_f_number_from_the_camera():
    config = parse_scene(_scene(WHITE, sensor={"preset": "illum", "iso": 320.0, "frames": 16}))
    cam = config.camera
    assert config.sensor.frames == 16
    assert config.sensor.detector.iso == 320.0
    assert config.sensor.detector.pixel_pitch_m == cam.sensor.pixel_pitch_m
    assert config.sensor.detector.microlens_f_number == pytest.approx(cam.mla.focal_length_m / cam.mla.pitch_m)
    assert config.to_dict()["sensor"]["frames"] == 16
    assert parse_scene(_scene(WHITE, sensor="tiny")).sensor.detector == DETECTOR_PRESETS["tiny"]


@pytest.mark.parametrize(
    ("table", "match"),
    [
        ({"preset": "illum", "pixel_pitch_m": 1e-6}, r"sensor\.pixel_pitch_m is the camera's"),
        ({"preset": "illum", "microlens_f_number": 2.0}, r"sensor\.microlens_f_number is the camera's"),
        ({"preset": "illum", "exposure": 2.0}, "exposure"),
        ({"preset": "canon"}, "canon"),
        ({"preset": "illum", "frames": 0}, r"sensor\.frames"),
        ({"preset": "illum", "bit_depth": 20}, "bit_depth"),
        ({"iso": 100.0}, "missing"),
    ],
)
def test_bad_sensor_tables_are_refused_by_key(table, match):
    with pytest.raises(ParameterError, match=match):
        parse_scene(_scene(WHITE, sensor=table))


def test_a_sensor_built_for_another_camera_is_refused():
    config = parse_scene(_scene(WHITE, sensor="tiny"))
    with pytest.raises(ParameterError, match=r"sensor\.pixel_pitch_m=1e-05 is not the camera's"):
        config.with_overrides(camera=camera_preset("illum"))
    moved = sensor_model(config.sensor, camera_preset("illum"))
    assert config.with_overrides(camera=camera_preset("illum"), sensor=moved).sensor.detector.pixel_pitch_m == 1.4e-6


def test_a_white_scene_takes_a_real_lens_without_a_port():
    data = _scene(WHITE)
    data["camera"] = {"preset": "tiny", "lens": "double-gauss"}
    assert parse_scene(data).lens.name == "double-gauss"
    scene = _scene(DEFAULT)
    scene["camera"] = {"preset": "tiny", "lens": "double-gauss"}
    del scene["port"]
    with pytest.raises(ParameterError, match=r"needs a \[port\]"):
        parse_scene(scene)


def test_lytro_settings_give_back_the_captures_colour_matrices():
    from simulator.detector import _F01_CCM, _ILLUM_CCM

    for name, ccm in (("illum", _ILLUM_CCM), ("f01", _F01_CCM)):
        settings = lytro_settings(DETECTOR_PRESETS[name], zoom_step=3)
        # 1e-6: the captures' matrices are float32, their rows sum to 1 only to that precision.
        np.testing.assert_allclose(np.reshape(settings.color_matrix, (3, 3)), ccm, atol=1e-6)
        np.testing.assert_allclose(np.reshape(settings.color_matrix, (3, 3)).sum(axis=1), 1.0, atol=1e-12)
        assert settings.zoom_step == 3
    illum = lytro_settings(DETECTOR_PRESETS["illum"].__class__(**{**DETECTOR_PRESETS["illum"].__dict__, "iso": 320.0}))
    assert (illum.iso, illum.base_iso) == (320, 80)
    assert illum.white_balance_gain[1:3] == (1.0, 1.0)


# ------------------------------------------------------------------ rendered files
def _render(tmp_path, name, *argv):
    out = tmp_path / name
    assert cli.main(["render", *argv, "--out", str(out), "--quiet", "--no-previews"]) == 0
    return out


@pytest.mark.render
def test_a_white_render_writes_its_mosaic_and_lfr_deterministically(tmp_path, capsys):
    argv = ["white", "--camera", "tiny", "--sensor", "tiny", "--frames", "4", "--lfr", "--spp", "4"]
    out = _render(tmp_path, "a", *argv)
    assert f"{LFR_NAME} " in capsys.readouterr().out
    mosaic = read_mosaic_npz(out / MOSAIC_NAME)
    assert mosaic.shape == (360, 480)
    assert (mosaic.cfa_pattern, mosaic.bit_depth, mosaic.black_level_dn, mosaic.white_level_dn) == (
        "GRBG",
        10,
        64,
        1023,
    )
    capture = read_lfr(out / LFR_NAME)
    assert np.array_equal(capture.mosaic.counts, mosaic.counts)
    assert capture.camera == camera_preset("tiny")
    lens = capture.metadata["devices"]["lens"]
    assert (lens["zoomStep"], lens["focusStep"]) == lens_steps(camera_preset("tiny")) == (6000, 0)
    expected = lytro_settings(DETECTOR_PRESETS["tiny"])
    assert capture.metadata["image"]["color"]["ccm"] == list(expected.color_matrix)
    meta = read_json(out / "meta.json")
    assert meta["scene"]["sensor"]["frames"] == 4
    assert "SeedSequence([seed, 2])" in meta["render"]["sensor_seed"]
    # Lit micro-image centres sit near black + 70 % of the range in green (the preset's exposure);
    # the gaps between micro-images, blurred by diffraction and crosstalk, within 5 % of black.
    green = mosaic.channel_index() == 1
    assert np.percentile(mosaic.counts[green], 99) == pytest.approx(64 + 0.7 * 959, rel=0.05)
    assert np.percentile(mosaic.counts[green], 1) <= 64 + 0.05 * 959
    again = read_mosaic_npz(_render(tmp_path, "b", *argv) / MOSAIC_NAME)
    assert np.array_equal(again.counts, mosaic.counts)
    other = read_mosaic_npz(_render(tmp_path, "c", *argv, "--seed", "1") / MOSAIC_NAME)
    assert not np.array_equal(other.counts, mosaic.counts)


@pytest.mark.render
def test_an_f01_render_is_read_by_imageio_exactly(tmp_path):
    out = _render(tmp_path, "f01", "--camera", "f01", "--sensor", "f01", "--lfr", "--spp", "1", "--ideal-spp", "1")
    mosaic = read_mosaic_npz(out / MOSAIC_NAME)
    with warnings.catch_warnings():  # imageio's raw reader leaves the metadata file open
        warnings.simplefilter("ignore", ResourceWarning)
        image = imageio.v2.imread(out / LYTRO_RAW_NAME, format="lytro-f01-raw")
    assert np.array_equal(image, mosaic.full_scale())
    assert image.meta["image"]["rawDetails"]["mosaic"]["upperLeftPixel"] == "b"
    back = read_f01_raw(out / LYTRO_RAW_NAME)
    assert np.array_equal(back.mosaic.counts, mosaic.counts)
    assert (back.mosaic.cfa_pattern, back.mosaic.black_level_dn, back.mosaic.white_level_dn) == ("BGGR", 168, 4095)


@pytest.mark.render
def test_a_real_lens_capture_records_its_exit_pupil(tmp_path):
    out = _render(
        tmp_path, "dg", "--camera", "tiny", "--lens", "double-gauss", "--sensor", "tiny", "--lfr", "--spp", "2"
    )
    meta = read_json(out / "meta.json")
    pupil_m = meta["derived"]["main_lens"]["exit_pupil_z_m"] + meta["camera"]["lens_to_mla_m"]  # MLA at z = -gap
    capture = read_lfr(out / LFR_NAME)
    assert capture.metadata["devices"]["lens"]["exitPupilOffset"]["z"] == pytest.approx(pupil_m, rel=1e-12)
    assert capture.metadata["devices"]["lens"]["exitPupilOffset"]["z"] != camera_preset("tiny").lens_to_mla_m


def test_lfr_refusals_name_the_cause_and_write_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["render", "white", "--lfr", "--out", str(out), "--quiet"]) == 2
    assert "needs a sensor model" in capsys.readouterr().err
    assert cli.main(["render", "white", "--frames", "4", "--out", str(out), "--quiet"]) == 2
    assert "--frames 4 needs a sensor model" in capsys.readouterr().err
    scene = tmp_path / "deep.toml"
    scene.write_text(
        (embedded_scenes()["white"].read_text(encoding="utf-8")) + '\n[sensor]\npreset = "tiny"\nbit_depth = 14\n'
        "white_level_dn = 16383\n",
        encoding="utf-8",
    )
    assert cli.main(["render", str(scene), "--lfr", "--out", str(out), "--quiet"]) == 2
    assert "sensor.bit_depth=14" in capsys.readouterr().err
    assert not out.exists()
