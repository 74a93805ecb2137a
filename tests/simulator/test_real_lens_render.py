"""A real main lens in a scene: the camera.lens key, lfsim render --lens and --rays, the rendered files."""

from __future__ import annotations

import copy
import tomllib

import numpy as np
import pytest

from lfrefract import FlatPort, camera_preset
from lfrefract.errors import ParameterError
from lfrefract.formats.jsonio import read_json
from lfrefract.optics.real_lens import RealLensCamera
from simulator import cli
from simulator.config import RenderSettings, default_scene_path, load_scene, parse_scene
from simulator.job import RAYS_NAME, render_job

DEFAULT = tomllib.loads(default_scene_path().read_text(encoding="utf-8"))


def _with_camera(**camera):
    data = copy.deepcopy(DEFAULT)
    data["camera"].update(camera)
    return data


@pytest.mark.parametrize("name", ["double-gauss", "wide-angle"])
def test_a_lens_preset_is_scaled_and_stopped_to_the_camera(name):
    data = _with_camera(lens=name)
    if name == "wide-angle":  # its front element reaches 63 mm out on the tiny camera
        data["port"]["distance_m"] = 0.08
    config = parse_scene(data)
    real = RealLensCamera(camera=config.camera, lens=config.lens)
    assert real.lens.name == name
    assert real.first_order.efl_m == pytest.approx(config.camera.focal_length_m, rel=1e-12)
    assert config.to_dict()["lens"]["name"] == name


def test_thin_is_the_default_and_written_as_such():
    assert parse_scene(_with_camera()).lens is None
    config = parse_scene(_with_camera(lens="thin"))
    assert config.lens is None
    assert config.to_dict()["lens"] == "thin"


def test_a_lens_table_must_fit_the_camera():
    lens = RealLensCamera.from_preset(camera_preset("tiny-2x"), "double-gauss").lens  # twice the focal length
    with pytest.raises(ParameterError, match="effective focal length"):
        parse_scene(_with_camera(lens=lens.to_dict()))
    ok = RealLensCamera.from_preset(camera_preset("tiny"), "double-gauss").lens
    assert parse_scene(_with_camera(lens=ok.to_dict())).lens == ok


@pytest.mark.parametrize("value", ["tessar", 3, ""])
def test_an_unknown_lens_is_refused_by_name(value):
    with pytest.raises(ParameterError, match=r"camera\.lens|\[camera\.lens\]"):
        parse_scene(_with_camera(lens=value))


def test_a_real_lens_needs_a_port_that_clears_it():
    data = _with_camera(lens="double-gauss")
    no_port = copy.deepcopy(data)
    del no_port["port"]
    with pytest.raises(ParameterError, match="needs a \\[port\\]"):
        parse_scene(no_port)
    data["port"]["distance_m"] = 0.002  # the double Gauss's front vertex is 2.1 mm out
    with pytest.raises(ParameterError, match="does not clear the main lens"):
        parse_scene(data)
    # A steep tilt brings the port's face nearer the lens's rim: 2.3 mm clears the front vertex
    # (2.12 mm) of an untilted port, not the rim under a 60 deg one (2.36 mm along its normal).
    config = parse_scene(_with_camera(lens="double-gauss"))
    config.with_overrides(port=FlatPort.from_degrees(distance_m=0.0023, thickness_m=0.001))
    steep = FlatPort.from_degrees(distance_m=0.0023, thickness_m=0.001, tilt_x_deg=60.0)
    with pytest.raises(ParameterError, match="needs distance_m >"):
        config.with_overrides(port=steep)


def test_render_with_a_real_lens_writes_its_rays_and_micro_image_truth(tmp_path):
    config = parse_scene(_with_camera(lens="double-gauss")).with_overrides(render=RenderSettings(spp=2, ideal_spp=2))
    out = render_job(config, tmp_path / "run", progress=False, write_previews=False, write_rays=True).out_dir
    real = RealLensCamera(camera=config.camera, lens=config.lens)
    meta = read_json(out / "meta.json")
    assert meta["scene"]["lens"]["name"] == "double-gauss"
    assert meta["derived"]["micro_image_scale"] == pytest.approx(real.micro_image_scale)
    assert meta["derived"]["main_lens"]["surfaces"] == 11
    lenses = np.load(out / "lenses.npz")
    np.testing.assert_allclose(lenses["micro_image_centre_px"], real.micro_image_centres_px(lenses["lens_index"]))
    rays = np.load(out / RAYS_NAME)
    h, w = config.camera.sensor.height_px, config.camera.sensor.width_px
    assert rays["origins_cam"].shape == (h, w, 3)
    assert rays["origins_cam"].dtype == np.float32
    expected = real.chief_rays()
    np.testing.assert_array_equal(rays["passed"].ravel(), expected.in_aperture)
    ok = expected.in_aperture
    np.testing.assert_allclose(rays["origins_cam"].reshape(-1, 3)[ok], expected.origins_cam[ok], atol=1e-9)
    np.testing.assert_allclose(rays["directions_cam"].reshape(-1, 3)[ok], expected.directions_cam[ok], atol=1e-6)
    assert np.all(np.isnan(rays["origins_cam"].reshape(-1, 3)[~ok]))
    # A lit scene through the real lens: vignetting darkens the corners against the centre.
    from lfrefract.formats.exr import read_exr

    raw = np.asarray(read_exr(out / "raw.exr"))
    assert raw[h // 3 : 2 * h // 3, w // 3 : 2 * w // 3].mean() > 1.5 * raw[: h // 6, : w // 6].mean()


def test_cli_lens_option_and_rays(tmp_path, capsys):
    out = tmp_path / "dg"
    argv = ["render", "--out", str(out), "--spp", "1", "--ideal-spp", "1", "--lens", "double-gauss", "--rays"]
    assert cli.main([*argv, "--quiet", "--no-previews"]) == 0
    text = capsys.readouterr().out
    assert "double-gauss main lens" in text
    assert "rays.npz" in text
    assert (out / RAYS_NAME).is_file()
    assert read_json(out / "meta.json")["scene"]["lens"]["name"] == "double-gauss"
    # A thin-lens render writes no rays unless asked.
    thin = tmp_path / "thin"
    assert cli.main(["render", "--out", str(thin), "--spp", "1", "--ideal-spp", "1", "--quiet", "--no-previews"]) == 0
    assert not (thin / RAYS_NAME).exists()
    assert read_json(thin / "meta.json")["scene"]["lens"] == "thin"


def test_cli_camera_override_rescales_the_scenes_preset_lens(tmp_path):
    scene = tmp_path / "scene.toml"
    text = (
        default_scene_path()
        .read_text(encoding="utf-8")
        .replace('preset = "tiny"', 'preset = "tiny"\nlens = "double-gauss"', 1)
    )
    scene.write_text(text, encoding="utf-8")
    assert load_scene(scene).lens is not None
    out = tmp_path / "run"
    argv = ["render", str(scene), "--out", str(out), "--camera", "tiny-2x", "--spp", "1", "--ideal-spp", "1"]
    assert cli.main([*argv, "--quiet", "--no-previews"]) == 0
    lens = read_json(out / "meta.json")["scene"]["lens"]
    assert lens["name"] == "double-gauss"
    assert RealLensCamera.from_preset(camera_preset("tiny-2x"), "double-gauss").lens.to_dict() == lens


def test_an_in_air_scene_takes_a_real_lens_without_a_port(tmp_path):
    """In-air calibration captures: ``medium = "air"`` (no port, no water) lets a real lens look at
    the objects directly; in water without a port it is refused, and air refuses a port."""
    data = _with_camera(lens="double-gauss")
    del data["port"]
    with pytest.raises(ParameterError, match=r"needs a \[port\]"):
        parse_scene(data)
    data["medium"] = "air"
    config = parse_scene(data).with_overrides(render=RenderSettings(spp=1, ideal_spp=1))
    assert config.to_dict()["medium"] == "air"
    out = render_job(config, tmp_path / "air", progress=False, write_previews=False)
    assert read_json(out.out_dir / "meta.json")["scene"]["medium"] == "air"
    with pytest.raises(ParameterError, match=r'medium = "air" takes no \[port\]'):
        parse_scene(_with_camera() | {"medium": "air"})
    with pytest.raises(ParameterError, match="medium must be one of"):
        parse_scene(_with_camera() | {"medium": "oil"})
