"""Lens files in the simulator: ``camera.lens = "<path>"`` in a scene, ``--lens FILE`` on the command line.

A file lens is scaled to the camera's focal length and stopped to its f-number, as a preset is, and a
run records it by its table, not by its path.
"""

from __future__ import annotations

import copy
import json
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from lfrefract import camera_preset
from lfrefract.errors import FileFormatError, ParameterError
from lfrefract.formats.jsonio import read_json
from lfrefract.formats.paramfile import read_lens_file
from simulator import cli
from simulator.config import THIN_LENS, default_scene_path, lens_option, lens_record, load_scene, main_lens, parse_scene
from simulator.experiments import ExperimentOptions
from tests.tolerances import SENSOR_VS_NUMPY_LENS_FILE_DIRECTION, SENSOR_VS_NUMPY_LENS_FILE_ORIGIN_RELATIVE

LENS_DIR = Path(__file__).resolve().parents[2] / "scenes" / "lenses"
TESSAR = LENS_DIR / "tessar.toml"
DEFAULT = tomllib.loads(default_scene_path().read_text(encoding="utf-8"))


def _scene(lens) -> dict:
    data = copy.deepcopy(DEFAULT)
    data["camera"]["lens"] = lens
    return data


def test_a_scene_names_a_lens_file_relative_to_itself_and_records_its_table(tmp_path):
    (tmp_path / "lenses").mkdir()
    shutil.copyfile(TESSAR, tmp_path / "lenses" / "t.toml")
    tiny = camera_preset("tiny")
    expected = read_lens_file(TESSAR, focal_length_m=tiny.focal_length_m, f_number=tiny.f_number)
    config = parse_scene(_scene("lenses/t.toml"), base_dir=tmp_path)
    assert config.lens == expected
    assert config.to_dict()["lens"] == expected.to_dict()  # what meta.json and a kept render's signature hold
    scene = tmp_path / "scene.toml"
    text = default_scene_path().read_text(encoding="utf-8")
    scene.write_text(text.replace('preset = "tiny"', 'preset = "tiny"\nlens = "lenses/t.toml"', 1), encoding="utf-8")
    assert load_scene(scene).lens == expected
    # An absolute path needs no base; the table read from the file is used as it is.
    assert parse_scene(_scene(str(TESSAR))).lens == expected
    assert parse_scene(_scene(expected.to_dict())).lens == expected


def test_a_scene_lens_that_is_no_file_or_a_bad_file_is_named(tmp_path):
    with pytest.raises(
        ParameterError, match=r"camera\.lens='lenses/none\.toml' is neither 'thin', a lens preset"
    ) as info:
        parse_scene(_scene("lenses/none.toml"), base_dir=tmp_path)
    assert "no such file" in str(info.value)
    bad = tmp_path / "bad.toml"
    bad.write_text(TESSAR.read_text(encoding="utf-8").replace('medium = "F2"', 'medium = "F99"', 1))
    scene = tmp_path / "scene.toml"
    text = default_scene_path().read_text(encoding="utf-8")
    scene.write_text(text.replace('preset = "tiny"', 'preset = "tiny"\nlens = "bad.toml"', 1), encoding="utf-8")
    named = r"scene file .*: camera\.lens='bad\.toml': .*bad\.toml': key 'lens\.surfaces\[2\]': medium"
    with pytest.raises(ParameterError, match=named):
        load_scene(scene)


def test_lens_option_keeps_names_reads_files_and_names_the_flag(tmp_path):
    assert lens_option(THIN_LENS) == THIN_LENS
    assert lens_option("double-gauss") == "double-gauss"
    design = lens_option(str(TESSAR))
    assert design == read_lens_file(TESSAR)  # the design: each use scales and stops it
    tiny = camera_preset("tiny")
    assert main_lens(design, tiny) == read_lens_file(TESSAR, focal_length_m=tiny.focal_length_m, f_number=tiny.f_number)
    assert lens_record(design) == design.to_dict()
    assert lens_record("double-gauss") == "double-gauss"
    for value in ("tessar", "", str(tmp_path)):
        with pytest.raises(ParameterError, match=f"--lens {value!r} is neither 'thin', a lens preset"):
            lens_option(value)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"schema_version": 1, "lens": {"name": "x", "surfaces": [{}]}}), encoding="utf-8")
    with pytest.raises(FileFormatError, match=r"--lens: '.*bad\.json': key 'lens\.surfaces\[0\]'"):
        lens_option(str(bad))


def test_an_experiment_records_a_lens_file_by_its_table_and_every_rig_camera_gets_it():
    from simulator.experiments.planes import setup_for
    from simulator.experiments.rigstereo import experiment_rig

    design = read_lens_file(TESSAR)
    options = ExperimentOptions(lens=design)
    recorded = json.loads(json.dumps(options.to_dict()))
    assert recorded["lens"] == design.to_dict()
    for camera in experiment_rig(setup_for("tiny"), options).cameras:
        optics = camera.scene.camera
        assert camera.scene.lens == design.scaled_to_focal_length(optics.focal_length_m).with_f_number(optics.f_number)


def test_the_command_line_refuses_a_lens_that_is_no_file_naming_the_option(tmp_path, capsys):
    for argv in (
        ["render", "--out", str(tmp_path / "r"), "--lens", "nonesuch.toml"],
        ["whites", "--out", str(tmp_path / "w"), "--camera", "tiny", "--lens", "nonesuch.toml"],
        ["experiment", "planes", "--out", str(tmp_path / "e"), "--lens", "nonesuch.toml"],
    ):
        assert cli.main([*argv, "--quiet"]) == 2
        assert "--lens 'nonesuch.toml' is neither 'thin', a lens preset" in capsys.readouterr().err
        assert not any(tmp_path.iterdir())


@pytest.mark.render
def test_render_through_a_lens_file_records_the_scaled_table(tmp_path, capsys):
    out = tmp_path / "tessar"
    argv = ["render", "--out", str(out), "--spp", "1", "--ideal-spp", "1", "--lens", str(TESSAR)]
    assert cli.main([*argv, "--quiet", "--no-previews"]) == 0
    assert "tessar main lens" in capsys.readouterr().out
    tiny = camera_preset("tiny")
    expected = read_lens_file(TESSAR, focal_length_m=tiny.focal_length_m, f_number=tiny.f_number)
    meta = read_json(out / "meta.json")
    assert meta["scene"]["lens"] == json.loads(json.dumps(expected.to_dict()))
    assert meta["derived"]["main_lens"]["name"] == "tessar"


@pytest.mark.parametrize("camera_name", ["tiny", "square-rotated-offset"])
def test_the_sensor_traces_the_fisheye_like_numpy(mi, camera_name):
    """The Dr.Jit sensor's trace through a lens file against its numpy twin, on the fisheye: its paths
    from the sensor side meet strongly curved surfaces from beyond their spheres' centres, which both
    tracers once refused (no path got through)."""
    from lfrefract.optics.real_lens import RealLensCamera
    from simulator.sensor import plenoptic_sensor_dict
    from tests.simulator.test_sensor import CAMERAS, POSE, _arrays, _sample_random_paths

    camera = CAMERAS[camera_name]
    lens = read_lens_file(LENS_DIR / "fisheye.toml", focal_length_m=camera.focal_length_m, f_number=camera.f_number)
    real = RealLensCamera(camera=camera, lens=lens)
    sensor = mi.load_dict(plenoptic_sensor_dict(mi, camera, POSE, spp=1, lens=real.lens))
    uv, aperture, ray, weight = _sample_random_paths(mi, sensor, camera, seed=11)
    expected = real.rays_through_lenses(uv, lens_offsets_m=camera.mla.cell_offsets_m(aperture))
    inside = _arrays(weight)[:, 0] > 0
    assert (inside == expected.in_aperture).mean() > 0.995
    assert 0.5 < inside.mean() < 0.95
    ok = inside & expected.in_aperture
    world = POSE.to_world(expected.origins_cam[ok])
    error = np.linalg.norm(_arrays(ray.o)[ok] - world, axis=1) / np.linalg.norm(world, axis=1)
    assert error.max() < SENSOR_VS_NUMPY_LENS_FILE_ORIGIN_RELATIVE
    directions = expected.directions_cam[ok] @ np.asarray(POSE.rotation).T
    assert np.abs(_arrays(ray.d)[ok] - directions).max() < SENSOR_VS_NUMPY_LENS_FILE_DIRECTION
