"""lfrefract.formats.paramfile: camera and port files in TOML (and JSON, and the flat-port text), written and
read back equal, every bad file a FileFormatError naming the file and the key; the example files of docs/examples."""

from __future__ import annotations

import dataclasses
import math
import os
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from lfrefract import FlatPort, ParameterError, camera_preset
from lfrefract.calibration.mla import LENS_STATUS, MlaCalibration
from lfrefract.errors import FileFormatError
from lfrefract.formats.capture import camera_model_from_option, port_from_file
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.formats.paramfile import (
    CAMERA_FILE_KIND,
    MAX_PARAMETER_FILE_BYTES,
    PORT_FILE_KIND,
    read_camera_file,
    read_port_file,
    write_camera_file,
    write_port_file,
)
from lfrefract.optics.presets import PRESETS

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
TILTED = FlatPort.from_degrees(distance_m=0.02, thickness_m=0.005, tilt_x_deg=10.0, tilt_y_deg=-5.0)
PORTS = [
    TILTED,
    FlatPort(distance_m=0.003, thickness_m=0.0, n_water=1.34),
    FlatPort(distance_m=99.0, thickness_m=1.0, tilt_x_rad=-1.2, tilt_y_rad=1.4, n_air=1.0003, n_glass=1.77),
    FlatPort.from_normal(np.array([0.3, -0.1, 0.2]), distance_m=0.05, thickness_m=0.01),
]


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


# =============================================================================== round trips
@pytest.mark.parametrize("name", sorted(PRESETS))
@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_every_preset_camera_reads_back_equal(tmp_path, name, suffix):
    camera = camera_preset(name)
    path = write_camera_file(tmp_path / f"camera{suffix}", camera)
    back = read_camera_file(path)
    assert back == camera
    assert back.to_dict() == camera.to_dict()
    assert camera_model_from_option(path).camera == camera  # so every --camera takes it


def test_a_camera_with_every_field_changed_reads_back_equal(tmp_path):
    tiny = camera_preset("tiny")
    mla = dataclasses.replace(tiny.mla, grid="square", rotation_rad=0.0123456789, offset_m=(1.5e-6, -2.25e-6))
    camera = dataclasses.replace(tiny, name="mine é", mla=mla, f_number=4.1)
    path = write_camera_file(tmp_path / "c.toml", camera)
    assert read_camera_file(path) == camera
    assert tomllib.loads(path.read_text(encoding="utf-8"))["camera"] == camera.to_dict()


@pytest.mark.parametrize("index", range(len(PORTS)))
@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_ports_read_back_bit_for_bit(tmp_path, index, suffix):
    port = PORTS[index]
    path = write_port_file(tmp_path / f"port{suffix}", port)
    back = read_port_file(path)
    assert back == port
    assert back.to_dict() == port.to_dict()
    assert port_from_file(path) == port  # so every --port takes it


def test_a_flat_port_text_file_reads_back_to_rounding(tmp_path):
    path = write_port_file(tmp_path / "port.txt", TILTED)
    back = read_port_file(path)
    np.testing.assert_allclose(back.normal, TILTED.normal, atol=1e-15)
    assert (back.distance_m, back.thickness_m, back.n_water) == (TILTED.distance_m, TILTED.thickness_m, 1.333)


def test_json_files_carry_their_kind_and_the_table_of_to_dict(tmp_path):
    camera = camera_preset("tiny")
    data = read_json(write_camera_file(tmp_path / "c.json", camera))
    assert data == {"schema_version": 1, "kind": CAMERA_FILE_KIND, "camera": camera.to_dict()}
    data = read_json(write_port_file(tmp_path / "p.json", TILTED))
    assert data["kind"] == PORT_FILE_KIND
    assert FlatPort.from_dict(data["port"]) == TILTED


def test_a_port_toml_gives_its_tilt_in_radians_and_says_the_degrees(tmp_path):
    text = write_port_file(tmp_path / "p.toml", TILTED).read_text(encoding="utf-8")
    table = tomllib.loads(text)["port"]
    assert sorted(table) == sorted(
        ["distance_m", "thickness_m", "tilt_x_rad", "tilt_y_rad", "n_air", "n_glass", "n_water"]
    )
    assert "x 10 deg, y -5 deg" in text


# =============================================================================== ports by angles or by normal
def test_a_port_by_degrees_radians_or_normal_is_the_same_port(tmp_path):
    common = "[port]\ndistance_m = 0.02\nthickness_m = 0.005\n"
    by_deg = read_port_file(write(tmp_path / "d.toml", common + "tilt_x_deg = 10.0\ntilt_y_deg = -5.0\n"))
    by_rad = read_port_file(
        write(tmp_path / "r.toml", common + f"tilt_x_rad = {math.radians(10)!r}\ntilt_y_rad = {math.radians(-5)!r}\n")
    )
    normal = 3.0 * TILTED.normal  # not unit: scaled on reading
    by_normal = read_port_file(write(tmp_path / "n.toml", common + f"normal = {normal.tolist()}\n"))
    assert by_deg == TILTED
    assert by_rad == TILTED
    np.testing.assert_allclose(by_normal.normal, TILTED.normal, atol=1e-15)
    assert math.isclose(by_normal.tilt_x_rad, TILTED.tilt_x_rad, abs_tol=1e-15)
    assert math.isclose(by_normal.tilt_y_rad, TILTED.tilt_y_rad, abs_tol=1e-15)
    one_angle = read_port_file(write(tmp_path / "one.toml", common + "tilt_x_deg = 10.0\n"))
    assert one_angle == dataclasses.replace(TILTED, tilt_y_rad=0.0)  # the other is 0


@pytest.mark.parametrize(
    ("orientation", "message"),
    [
        (
            "tilt_x_deg = 10.0\nnormal = [0.0, 0.0, 1.0]\n",
            "gives its orientation twice, by ['tilt_x_deg'] and by 'normal'",
        ),
        (
            "tilt_y_rad = 0.1\nnormal = [0.0, 0.0, 1.0]\n",
            "gives its orientation twice, by ['tilt_y_rad'] and by 'normal'",
        ),
        ("", "gives no orientation: add 'tilt_x_deg' and 'tilt_y_deg' (degrees) or 'normal'"),
    ],
)
def test_a_port_needs_exactly_one_of_angles_and_normal(tmp_path, orientation, message):
    path = write(tmp_path / "p.toml", "[port]\ndistance_m = 0.02\n" + orientation)
    with pytest.raises(FileFormatError, match=re.escape(f"{str(path)!r}: key 'port' {message}")):
        read_port_file(path)


# =============================================================================== bad files
CAMERA = (EXAMPLES / "camera-illum.toml").read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("extra = 1\n" + CAMERA, "has unknown top-level keys ['extra']"),
        (
            CAMERA.replace("schema_version = 1", "schema_version = 2"),
            "key 'schema_version' is 2, this lfrefract reads 1",
        ),
        (CAMERA.replace("schema_version = 1", "schema_version = true"), "key 'schema_version' is True"),
        # A float was taken for the integer version.
        (CAMERA.replace("schema_version = 1", "schema_version = 1.0"), "key 'schema_version' is 1.0"),
        (
            CAMERA.replace('name = "illum"', 'name = "illum"\nzoom = 2.0'),
            "key 'camera': unknown key(s) in camera: ['zoom']",
        ),
        (CAMERA.replace("f_number = 2.0", 'f_number = "f/2"'), "key 'camera': f_number must be a real number"),
        (CAMERA.replace("f_number = 2.0", "f_number = true"), "key 'camera': f_number must be a real number, got True"),
        (CAMERA.replace("f_number = 2.0", "f_number = 1000.0"), "key 'camera': f_number must lie in [0.5, 128]"),
        (CAMERA.replace("f_number = 2.0", "f_number = nan"), "key 'camera': f_number must be finite"),
        (CAMERA.replace("f_number = 2.0", "f_number = 1979-05-27"), "key 'camera': f_number must be a real number"),
        (CAMERA.replace("f_number = 2.0\n", ""), "key 'camera': missing key(s) in camera: ['f_number']"),
        (CAMERA.replace("width_px = 7728", "width_px = 7728.5"), "key 'camera': sensor.width_px must be an integer"),
        (CAMERA.replace("width_px = 7728", "width_px = 100000"), "key 'camera': sensor.width_px must be at most 65536"),
        (CAMERA.replace('grid = "hex"', 'grid = "round"'), "key 'camera': mla.grid must be one of"),
        (CAMERA.replace("pitch_m = 2e-05", "pitch_m = -2e-05"), "key 'camera': mla.pitch_m must be positive"),
        (CAMERA.replace("[camera.sensor]", "[camera.sensors]"), "key 'camera': unknown key(s) in camera: ['sensors']"),
        (CAMERA.replace("[camera]", "[kamera]"), "has unknown top-level keys ['kamera']"),
        ("schema_version = 1\ncamera = 3\n", "key 'camera' must be a table ([camera]), got 3"),
        ("schema_version = 1\n", "has no key 'camera' (a [camera] table): it is not a camera file"),
        ("[camera\nname = 1\n", "is not valid TOML"),
    ],
)
def test_bad_camera_files_are_refused_naming_file_and_key(tmp_path, text, message):
    path = write(tmp_path / "cam.toml", text)
    with pytest.raises(FileFormatError, match=re.escape(message)) as caught:
        read_camera_file(path)
    assert repr(str(path)) in str(caught.value)
    with pytest.raises(FileFormatError, match=re.escape(message)):
        camera_model_from_option(path)


PORT = "[port]\ndistance_m = 0.02\nthickness_m = 0.005\ntilt_x_deg = 10.0\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        # Degrees and radians mixed were "unknown key(s) in port: ['tilt_y_rad']", a key the format has.
        (PORT + "tilt_x_rad = 0.1\n", "key 'port' mixes degrees and radians (['tilt_x_deg', 'tilt_x_rad'])"),
        (PORT + "tilt_y_rad = 0.1\n", "key 'port' mixes degrees and radians (['tilt_x_deg', 'tilt_y_rad'])"),
        (PORT + "total_tilt_deg = 10.0\n", "key 'port': unknown key(s) in port: ['total_tilt_deg']"),
        (PORT.replace("distance_m = 0.02", "distance_m = 0.0"), "key 'port': port.distance_m must be positive"),
        (PORT.replace("distance_m = 0.02", "distance_m = 1000.0"), "key 'port': port.distance_m=1000.0 exceeds 100"),
        (PORT.replace("distance_m = 0.02\n", ""), "key 'port': missing key(s) in port: ['distance_m']"),
        (PORT.replace("tilt_x_deg = 10.0", "tilt_x_deg = 95.0"), "the port would be behind the camera"),
        (PORT.replace("tilt_x_deg = 10.0", 'tilt_x_deg = "10"'), "key 'port': port.tilt_x_deg must be a real number"),
        (PORT + "n_water = 0.5\n", "key 'port': port.n_water"),
        (PORT.replace("tilt_x_deg = 10.0", "normal = [0.0, 1.0]"), "key 'port': port.normal must have 3 entries"),
        (
            PORT.replace("tilt_x_deg = 10.0", "normal = [0.0, 0.0, -1.0]"),
            "key 'port': normal=[0.0, 0.0, -1.0] points towards",
        ),
        (PORT.replace("tilt_x_deg = 10.0", 'normal = "up"'), "key 'port': port.normal must be"),
        ("port = [1, 2]\n", "key 'port' must be a table ([port]), got [1, 2]"),
        (PORT + "[camera]\n", "has unknown top-level keys ['camera']"),
    ],
)
def test_bad_port_files_are_refused_naming_file_and_key(tmp_path, text, message):
    path = write(tmp_path / "port.toml", text)
    with pytest.raises(FileFormatError, match=re.escape(message)) as caught:
        read_port_file(path)
    assert repr(str(path)) in str(caught.value)


@pytest.mark.parametrize("read", [read_camera_file, read_port_file])
@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_unreadable_files_are_refused_before_they_are_parsed(tmp_path, read, suffix):
    missing = tmp_path / f"missing{suffix}"
    with pytest.raises(FileFormatError, match=re.escape(f"no such file: {str(missing)!r}")):
        read(missing)
    folder = tmp_path / f"folder{suffix}"
    folder.mkdir()
    with pytest.raises(FileFormatError, match="is a directory, not a regular file"):
        read(folder)
    utf16 = tmp_path / f"utf16{suffix}"
    utf16.write_bytes("[port]\n".encode("utf-16"))
    with pytest.raises(FileFormatError, match=re.escape(f"{str(utf16)!r} is not UTF-8 text")):
        read(utf16)
    huge = tmp_path / f"huge{suffix}"
    with huge.open("wb") as fh:
        fh.truncate(MAX_PARAMETER_FILE_BYTES + 1)  # sparse: refused by its size, never read
    with pytest.raises(FileFormatError, match=re.escape(f"holds {MAX_PARAMETER_FILE_BYTES + 1} bytes")):
        read(huge)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "cam.toml"
    os.mkfifo(fifo)
    with pytest.raises(FileFormatError, match="is a named pipe"):
        read_camera_file(fifo)


def test_json_files_without_their_table_are_refused(tmp_path):
    write_json(tmp_path / "p.json", {"port": TILTED.to_dict()})
    with pytest.raises(FileFormatError, match=re.escape("p.json' has no key 'camera': it is not a camera file")):
        read_camera_file(tmp_path / "p.json")
    write_json(tmp_path / "c.json", {"camera": camera_preset("tiny").to_dict()})
    with pytest.raises(FileFormatError, match=re.escape("c.json' has no key 'port': it is not a port file")):
        read_port_file(tmp_path / "c.json")


def test_writers_refuse_other_suffixes_and_other_objects(tmp_path):
    with pytest.raises(ParameterError, match=re.escape("a camera file must end in .toml, .json (the format)")):
        write_camera_file(tmp_path / "c.yaml", camera_preset("tiny"))
    with pytest.raises(ParameterError, match=re.escape("a port file must end in .toml, .json, .txt")):
        write_port_file(tmp_path / "p", TILTED)
    with pytest.raises(ParameterError, match="camera must be a LightFieldCamera"):
        write_camera_file(tmp_path / "c.toml", TILTED)
    with pytest.raises(ParameterError, match="port must be a FlatPort"):
        write_port_file(tmp_path / "p.toml", camera_preset("tiny"))
    assert list(tmp_path.iterdir()) == []


# =============================================================================== docs/examples
def test_the_illum_example_is_the_preset_as_the_writer_writes_it(tmp_path):
    example = EXAMPLES / "camera-illum.toml"
    assert read_camera_file(example) == camera_preset("illum")
    written = write_camera_file(tmp_path / "illum.toml", camera_preset("illum"))
    assert example.read_text(encoding="utf-8") == written.read_text(encoding="utf-8")


def test_the_two_port_examples_are_one_port():
    tilted = read_port_file(EXAMPLES / "port-tilted.toml")
    by_normal = read_port_file(EXAMPLES / "port-normal.toml")
    assert tilted == TILTED
    assert tomllib.loads((EXAMPLES / "port-tilted.toml").read_text(encoding="utf-8"))["port"]["tilt_x_deg"] == 10.0
    assert "normal" in tomllib.loads((EXAMPLES / "port-normal.toml").read_text(encoding="utf-8"))["port"]
    np.testing.assert_allclose(by_normal.normal, tilted.normal, atol=1e-15)
    assert by_normal == dataclasses.replace(tilted, tilt_x_rad=by_normal.tilt_x_rad)  # to the last bit of tilt_x
    assert math.isclose(by_normal.tilt_x_rad, tilted.tilt_x_rad, abs_tol=1e-15)


def test_every_example_file_reads():
    files = sorted(p for p in EXAMPLES.iterdir() if p.is_file())
    assert [p.name for p in files if p.suffix == ".toml"] == [
        "camera-illum.toml",
        "port-default-scene.toml",
        "port-normal.toml",
        "port-tilted.toml",
    ]
    for path in files:
        if path.name.startswith("camera-"):
            read_camera_file(path)
        elif path.name.startswith("port-"):
            read_port_file(path)
        else:
            pytest.fail(f"{path.name}: an example file must be a camera-*.toml or port-*.toml file")


def test_the_default_scenes_port_file_is_its_port():
    """README's Lytro example synthesizes a render of the default scene with this port file."""
    from simulator.config import default_scene_path, load_scene

    assert read_port_file(EXAMPLES / "port-default-scene.toml") == load_scene(default_scene_path()).port


def test_docs_cli_lists_every_key_of_both_files():
    text = (EXAMPLES.parent / "cli.md").read_text(encoding="utf-8")
    section = text[text.index("## Camera and port files") : text.index("## Captures: writing them")]
    rows = [line.split("|")[1] for line in section.splitlines() if line.startswith("| `")]
    documented = {key for cell in rows for key in re.findall(r"`([a-z_.]+)`", cell)}
    camera = camera_preset("tiny").to_dict()
    camera_keys = {k for k in camera if not isinstance(camera[k], dict)}
    camera_keys |= {f"{table}.{k}" for table in ("mla", "sensor") for k in camera[table]}
    port_keys = {"distance_m", "thickness_m", "tilt_x_deg", "tilt_y_deg", "tilt_x_rad", "tilt_y_rad", "normal"}
    port_keys |= {"n_air", "n_glass", "n_water"}
    assert documented == camera_keys | port_keys


def test_an_illum_mla_calibration_is_read_as_a_camera_file(tmp_path):
    # calibrate mla writes every lens's measured centre: 31 MiB for the Illum, which the first limit
    # of 16 MiB refused (the pipeline experiment's data-only chain failed on it at illum scale).
    camera = camera_preset("illum")
    indices = camera.lens_indices_on_sensor()
    centres = camera.micro_image_centres_px(indices)
    pitch = camera.mla.pitch_m / camera.sensor.pixel_pitch_m
    mla = MlaCalibration(
        grid="hex",
        lattice_model="regular",
        image_size_px=(camera.sensor.width_px, camera.sensor.height_px),
        origin_px=camera.micro_image_centres_px(np.array([[0, 0]]))[0],
        basis_px=pitch * np.array([[1.0, 0.5], [0.0, math.sqrt(3.0) / 2.0]]),
        indices=indices,
        measured_px=centres + np.random.default_rng(0).normal(0.0, 0.01, centres.shape),
        status=np.full(len(indices), LENS_STATUS.index("used"), dtype=np.int8),
        window_radius_px=0.4 * pitch,
    )
    path = tmp_path / "mla.json"
    write_json(path, {"kind": "lfrefract.calibrate.mla", "mla": mla.to_dict(), "camera": camera.to_dict()})
    assert path.stat().st_size > 16 * 2**20
    assert read_camera_file(path) == camera
    assert camera_model_from_option(path).camera == camera
