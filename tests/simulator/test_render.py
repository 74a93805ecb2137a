"""Render jobs: reproducibility, the files written, the CLI, and bad input that writes nothing."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from lfrefract import ParameterError, virtual_camera_for
from lfrefract.errors import FileFormatError
from lfrefract.formats.capture import (
    DEPTH_NAME,
    IDEAL_NAME,
    LENSES_NAME,
    RAW_NAME,
    SIDECAR_NAME,
    read_capture,
    read_ground_truth,
)
from lfrefract.formats.exr import read_exr
from lfrefract.formats.jsonio import read_json
from lfrefract.formats.outputs import output_manifest
from simulator import cli, groundtruth
from simulator.config import DEFAULT_IDEAL_SPP, RenderSettings, embedded_scenes, load_scene, parse_scene
from simulator.groundtruth import lens_table
from simulator.job import RENDER_KIND, render_job, render_raw
from simulator.scene import build_scene, check_geometry
from tests.simulator.scenes import port, scene

PLANE = {"type": "textured_plane", "position_m": [0.0, 0.0, 0.5], "size_m": [1.0, 1.0], "texture_px": 128}


def _raw(mi, config, seed, band_pixels=60_000):
    config = config.with_overrides(render=RenderSettings(spp=4, seed=seed))
    return render_raw(mi, config, max_band_pixels=band_pixels, progress=False)


@pytest.mark.render
def test_same_seed_is_bit_identical_and_another_seed_is_not(mi):
    config = scene(port=port(20.0), objects=[PLANE])
    a, b, c = _raw(mi, config, 5), _raw(mi, config, 5), _raw(mi, config, 6)
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)
    assert np.mean(a) > 0.01  # the image is not black


@pytest.mark.render
def test_render_job_writes_every_file_with_its_parameters(tmp_path):
    out = tmp_path / "run"
    config = load_scene(embedded_scenes()["white"]).with_overrides(render=RenderSettings(spp=8, seed=3))
    result = render_job(config, out, progress=False)
    names = {p.name for p in out.iterdir()}
    assert {"raw.exr", "ideal.exr", "depth.exr", "lenses.npz", "meta.json", "previews"} <= names
    meta = read_json(out / "meta.json")
    cam = config.camera
    assert read_exr(out / "raw.exr", role="raw").shape == (cam.sensor.height_px, cam.sensor.width_px, 3)
    ideal = meta["ideal"]
    assert read_exr(out / "ideal.exr", role="ideal").shape == (ideal["height_px"], ideal["width_px"], 3)
    depth = read_exr(out / "depth.exr", role="depth")
    assert np.all(np.isinf(depth))  # nothing but the environment
    assert meta["render"]["seed"] == config.render.seed
    assert meta["render"]["spp"] == config.render.spp
    assert meta["render"]["ideal_spp"] == config.render.ideal_spp == DEFAULT_IDEAL_SPP
    assert meta["render"]["mitsuba"] == "3.9.1"
    assert meta["render"]["variant"] == "llvm_ad_rgb"
    assert meta["camera"] == cam.to_dict()
    assert meta["port"] is None
    assert json.loads((out / "meta.json").read_text()) == {"schema_version": 1, **result.metadata}
    lenses = np.load(out / "lenses.npz")
    assert len(lenses["lens_index"]) == meta["derived"]["lens_count"]
    assert {p.name for p in (out / "previews").iterdir()} == {"raw.png", "raw_crop.png", "ideal.png", "depth.png"}


@pytest.mark.render
def test_a_render_is_a_capture_folder_the_core_reads_back(tmp_path):
    config = load_scene().with_overrides(render=RenderSettings(spp=1, seed=0))
    out = render_job(config, tmp_path / "run", progress=False, write_previews=False).out_dir
    assert output_manifest(out)["kind"] == RENDER_KIND
    meta = read_json(out / SIDECAR_NAME)
    assert meta["files"] == {"raw": RAW_NAME, "ideal": IDEAL_NAME, "depth": DEPTH_NAME, "lenses": LENSES_NAME}
    capture = read_capture(out)
    assert (capture.camera, capture.port, capture.pose) == (config.camera, config.port, config.pose)
    assert capture.ideal == virtual_camera_for(config.camera)
    truth = read_ground_truth(out)
    assert truth.ideal.shape == (capture.ideal.height_px, capture.ideal.width_px, 3)
    assert np.isfinite(truth.depth_m).any()
    for key, value in lens_table(config.camera).items():
        np.testing.assert_array_equal(truth.lenses[key], value)


@pytest.mark.render
def test_cli_renders_default_scene(tmp_path, capsys):
    out = tmp_path / "default"
    assert cli.main(["render", "--out", str(out), "--spp", "2", "--quiet", "--no-previews"]) == 0
    meta = read_json(out / "meta.json")
    assert meta["scene"]["name"] == "default"
    assert meta["render"]["spp"] == 2
    assert math.isclose(meta["port"]["total_tilt_deg"], 20.0)
    assert "rendered 'default'" in capsys.readouterr().out


@pytest.mark.render
def test_the_ideal_image_is_rendered_at_its_own_spp(mi, tmp_path):
    config = load_scene().with_overrides(render=RenderSettings(spp=1, ideal_spp=8, seed=2))
    out = render_job(config, tmp_path / "run", progress=False, write_previews=False).out_dir
    assert read_json(out / SIDECAR_NAME)["render"]["ideal_spp"] == 8
    glass_free = build_scene(mi, config, port_geometry=False)
    pinhole = virtual_camera_for(config.camera)
    at_8 = groundtruth.compute(mi, glass_free, config, pinhole, seed=2, progress=False).ideal
    at_1 = groundtruth.compute(mi, glass_free, config, pinhole, spp=1, seed=2, progress=False).ideal
    written = read_ground_truth(out).ideal
    assert written.tobytes() == at_8.tobytes()
    assert not np.array_equal(written, at_1)


@pytest.mark.render
def test_cli_sets_the_ideal_spp(tmp_path):
    out = tmp_path / "white"
    argv = ["render", "white", "--out", str(out), "--spp", "1", "--ideal-spp", "3", "--quiet", "--no-previews"]
    assert cli.main(argv) == 0
    assert read_json(out / SIDECAR_NAME)["render"]["ideal_spp"] == 3
    assert read_json(out / SIDECAR_NAME)["render"]["spp"] == 1


def test_cli_refuses_a_bad_ideal_spp_by_name(tmp_path, capsys):
    out = tmp_path / "white"
    assert cli.main(["render", "white", "--out", str(out), "--ideal-spp", "0", "--quiet"]) == 2
    assert "render.ideal_spp must be positive, got 0" in capsys.readouterr().err
    assert not out.exists()


def test_cli_refuses_non_empty_output(tmp_path, capsys):
    (tmp_path / "keep.txt").write_text("mine")
    assert cli.main(["render", "white", "--out", str(tmp_path), "--quiet"]) == 2
    assert "not empty" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


BAD_SCENES = {
    "tir-only": (
        {"port": {"distance_m": 0.02, "tilt_x_deg": 70.0, "n_air": 1.5, "n_glass": 1.5, "n_water": 1.0}},
        "totally internally reflected",
    ),
    "port-behind-camera": ({"port": {"distance_m": 0.02, "tilt_x_deg": 95.0}}, "behind the camera"),
    "port-cuts-lens": ({"port": {"distance_m": 0.0005, "tilt_x_deg": 60.0}}, "cuts the main-lens aperture"),
    "negative-size": ({"object": [PLANE | {"size_m": [-1.0, 1.0]}]}, "size_m[0] must be positive, got -1.0"),
    "nan-distance": ({"port": {"distance_m": float("nan")}}, "port.distance_m must be finite, got nan"),
    "unknown-key": ({"object": [PLANE | {"colour": 1}]}, "unknown key(s) in object[0] (textured_plane): ['colour']"),
    "unknown-object": ({"object": [{"type": "teapot", "position_m": [0, 0, 1]}]}, "got 'teapot'"),
    "missing-mesh": ({"object": [{"type": "mesh", "position_m": [0, 0, 1], "path": "nowhere.obj"}]}, "does not exist"),
    "object-in-air": ({"object": [PLANE | {"position_m": [0.0, 0.0, 0.01]}]}, "reaches the camera side of the port"),
    "light-in-air": (
        {"light": [{"type": "point", "position_m": [0, 0, 0.005], "intensity_w_sr": 1}]},
        "light[0] (point) reaches the camera side of the port",
    ),
    "negative-pitch": (
        {
            "camera": {
                "focal_length_m": 0.006,
                "lens_to_mla_m": 0.006,
                "f_number": 2.2,
                "mla": {"grid": "hex", "pitch_m": -1e-4, "focal_length_m": 2e-4},
                "sensor": {"width_px": 10, "height_px": 10, "pixel_pitch_m": 1e-5},
            }
        },
        "mla.pitch_m must be positive, got -0.0001",
    ),
    "zero-spp": ({"render": {"spp": 0, "seed": 0}}, "render.spp must be positive, got 0"),
    "negative-seed": ({"render": {"spp": 4, "seed": -3}}, "render.seed must be an integer in [0, 2**31), got -3"),
    "huge-texture": ({"object": [PLANE | {"texture_px": 100_000}]}, "texture_px must be at most 8192, got 100000"),
    "nan-position": (
        {"object": [PLANE | {"position_m": [float("nan"), 0.0, 0.5]}]},
        "object[0] (textured_plane): position_m[0] must be finite, got nan",
    ),
    "camera-missing-key": (
        {
            "camera": {
                "focal_length_m": 0.006,
                "lens_to_mla_m": 0.006,
                "mla": {"grid": "hex", "pitch_m": 1e-4, "focal_length_m": 2e-4},
                "sensor": {"width_px": 10, "height_px": 10, "pixel_pitch_m": 1e-5},
            }
        },
        "missing key(s) in camera: ['f_number']",
    ),
    "port-missing-distance": ({"port": {"tilt_x_deg": 10.0}}, "missing key(s) in port: ['distance_m']"),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scenes_are_rejected_by_name_and_write_nothing(tmp_path, case):
    changes, message = BAD_SCENES[case]
    data = {
        "camera": {"preset": "tiny"},
        "port": port(10.0),
        "light": [{"type": "point", "position_m": [0.1, -0.2, 0.2], "intensity_w_sr": 0.3}],
        "object": [PLANE],
    } | changes
    out = tmp_path / "out"

    def parse_and_render():
        render_job(parse_scene(data, base_dir=tmp_path), out, progress=False)

    with pytest.raises(ParameterError) as err:
        parse_and_render()
    assert message in str(err.value)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_scene_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera\npreset = 'tiny'")
    with pytest.raises(ParameterError, match=r"bad\.toml.*not valid TOML"):
        load_scene(bad)
    with pytest.raises(FileNotFoundError, match=r"missing\.toml"):
        load_scene(tmp_path / "missing.toml")


def test_failure_during_render_leaves_nothing(tmp_path, monkeypatch):
    import simulator.job as job

    def explode(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(job.groundtruth, "compute", explode)
    out = tmp_path / "out"
    with pytest.raises(RuntimeError, match="disk full"):
        render_job(load_scene(embedded_scenes()["white"]), out, progress=False)
    assert list(tmp_path.iterdir()) == []


def test_tir_fraction_reported_for_partial_tir():
    data = {
        "camera": {"preset": "tiny"},
        "port": {"distance_m": 0.02, "tilt_x_deg": 35.0, "n_air": 1.5, "n_glass": 1.5, "n_water": 1.0},
        "light": [{"type": "point", "position_m": [0.0, 0.3, 0.4], "intensity_w_sr": 0.3}],
    }
    figures = check_geometry(parse_scene(data))
    assert 0.0 < figures["tir_fraction"] < 1.0


def _mesh_scene(tmp_path, mesh_text: str, position_m):
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    (meshes / "thing.obj").write_text(mesh_text)
    data = {
        "camera": {"preset": "tiny"},
        "port": port(10.0),
        "light": [{"type": "point", "position_m": [0.1, -0.2, 0.2], "intensity_w_sr": 0.3}],
        "object": [{"type": "mesh", "path": "thing.obj", "position_m": position_m}],
    }
    return parse_scene(data, base_dir=meshes)


@pytest.mark.render
def test_user_mesh_reaching_through_the_glass_is_refused(tmp_path):
    # Its placement is 0.4 m away, but one vertex reaches back to z = 0.01 m, below the port.
    sliver = "v -0.1 -0.1 0\nv 0.1 -0.1 0\nv 0 1 -0.39\nf 1 2 3\n"
    config = _mesh_scene(tmp_path, sliver, [0.0, 0.0, 0.4])
    with pytest.raises(ParameterError, match=r"object\[0\] \(mesh thing\.obj\) reaches the camera side"):
        render_job(config, tmp_path / "out", progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["meshes"]


@pytest.mark.render
def test_corrupt_user_mesh_is_a_clear_error(tmp_path):
    config = _mesh_scene(tmp_path, "v 1 2\nf 1 2 9\n", [0.0, 0.0, 0.4])
    with pytest.raises(FileFormatError, match=r"object\[0\] \(mesh\): cannot load '.*thing\.obj'"):
        render_job(config, tmp_path / "out", progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["meshes"]


def test_cli_never_replaces_a_foreign_directory(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("mine")
    assert cli.main(["render", "white", "--out", str(tmp_path), "--overwrite", "--quiet"]) == 2
    assert "is not an lfrefract output" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]
