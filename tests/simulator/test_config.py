"""Scene and rig files against hostile input (issue 12): encodings, file kinds, wrong TOML types
and out-of-range numbers are clear errors naming the file or the key, the type and the value."""

from __future__ import annotations

import contextlib
import copy
import math
import os
import signal
import time
import tomllib

import numpy as np
import pytest

import simulator.config as config
from lfrefract import ParameterError
from simulator.config import default_scene_path, load_scene, parse_scene
from simulator.rig import embedded_rigs, load_rig, parse_rig
from tests.tolerances import FILE_SIZE_REFUSAL_SECONDS

DEFAULT = tomllib.loads(default_scene_path().read_text(encoding="utf-8"))


@contextlib.contextmanager
def _deadline(seconds: float):
    """Fail (rather than hang the suite) if the block takes longer than ``seconds``."""

    def expire(signum, frame):
        raise AssertionError(f"took more than {seconds} s (blocked?)")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _scene(**changes):
    data = copy.deepcopy(DEFAULT)
    data.update(changes)
    return data


def _object(index: int, **changes):
    data = copy.deepcopy(DEFAULT)
    data["object"][index].update(changes)
    return data


def _light(index: int, **changes):
    data = copy.deepcopy(DEFAULT)
    data["light"][index].update(changes)
    return data


# ----------------------------------------------------------------------------- encodings and file kinds

SCENE_TEXT = default_scene_path().read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("encoded", "message"),
    [
        (SCENE_TEXT.encode("utf-16"), "starts with a UTF-16 byte-order mark"),  # with its BOM
        (SCENE_TEXT.encode("utf-16-le"), "is not UTF-8 text: it holds NUL bytes"),  # no BOM
        (SCENE_TEXT.encode("utf-16-be"), "is not UTF-8 text: it holds NUL bytes"),
        (("# café au lait\n" + SCENE_TEXT).encode("latin-1"), "is not UTF-8 text: byte 0xe9 on line 1"),
        (b"\xef\xbb\xbf" + SCENE_TEXT.encode(), "starts with a UTF-8 byte-order mark"),
    ],
    ids=["utf16-bom", "utf16le", "utf16be", "latin1", "utf8-bom"],
)
def test_scene_file_that_is_not_utf8_is_a_clear_error(tmp_path, encoded, message):
    path = tmp_path / "scene.toml"
    path.write_bytes(encoded)
    with pytest.raises(ParameterError) as err:
        load_scene(path)
    assert f"scene file {str(path)!r}" in str(err.value)
    assert message in str(err.value)
    assert "TOML must be UTF-8" in str(err.value)


def test_rig_file_that_is_not_utf8_is_a_clear_error(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_bytes(embedded_rigs()["default"].read_text(encoding="utf-8").encode("utf-16"))
    with pytest.raises(ParameterError, match=r"rig file '.*rig\.toml' starts with a UTF-16 byte-order mark"):
        load_rig(path)


def test_scene_file_of_the_wrong_kind_or_size_is_refused_at_once(tmp_path):
    folder = tmp_path / "folder.toml"
    folder.mkdir()
    with pytest.raises(ParameterError, match=r"scene file '.*folder\.toml' is a directory, not a regular file"):
        load_scene(folder)
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    with _deadline(10.0), pytest.raises(ParameterError, match=r"'.*pipe\.toml' is a named pipe \(FIFO\)"):
        load_scene(fifo)
    with _deadline(10.0), pytest.raises(ParameterError, match=r"rig file '.*pipe\.toml' is a named pipe"):
        load_rig(fifo)
    huge = tmp_path / "huge.toml"
    with huge.open("wb") as fh:
        fh.truncate(64 * 2**20)  # sparse: no disk, no time
    start = time.perf_counter()
    with pytest.raises(ParameterError, match=r"'.*huge\.toml' holds 67108864 bytes \(64 MiB\), more than"):
        load_scene(huge)
    assert time.perf_counter() - start < FILE_SIZE_REFUSAL_SECONDS
    with pytest.raises(FileNotFoundError, match=r"missing\.toml' does not exist"):
        load_scene(tmp_path / "missing.toml")


@pytest.mark.parametrize(
    ("document", "message"),
    [
        ("name = " + "[" * 50_000 + "]" * 50_000, "nests arrays or tables too deeply"),
        ("name = " + "9" * 5000, "is not valid TOML: Exceeds the limit"),
    ],
    ids=["deep", "long-int"],
)
def test_pathological_toml_is_a_clear_error(tmp_path, document, message):
    path = tmp_path / "scene.toml"
    path.write_text(document, encoding="utf-8")
    with pytest.raises(ParameterError, match=message):
        load_scene(path)


# ----------------------------------------------------------------------------- wrong TOML types

WRONG_TYPES = {
    "object-type-list": (
        _object(0, type=["textured_plane"]),
        "object[0].type must be a string, one of ['bowl', 'chessboard', 'disc', 'figurine', 'mesh', "
        "'textured_plane'], got ['textured_plane']",
    ),
    "light-type-table": (_light(0, type={"point": 1}), "light[0].type must be a string, one of"),
    "object-not-table": (_scene(object=[3]), "object[0] must be a table, got 3"),
    "objects-not-array": (
        _scene(object={"type": "disc"}),
        "[[object]] must be an array of tables, got {'type': 'disc'}",
    ),
    "position-string": (_object(0, position_m="0 0 0.8"), "position_m must be a sequence of 3 numbers, got '0 0 0.8'"),
    "position-table": (_light(0, position_m={"x": 1}), "position_m must be a sequence of 3 numbers, got {'x': 1}"),
    "size-number": (_object(0, size_m=1.0), "size_m must be a sequence of 2 numbers, got 1.0"),
    "size-nested": (_object(0, size_m=[[1.2], [0.9]]), "size_m[0] must be a real number, got [1.2]"),
    "texture-px-float": (_object(0, texture_px=512.0), "texture_px must be an integer, got 512.0"),
    "squares-number": (_object(1, squares=8), "squares must be (columns, rows), a list of 2 integers, got 8"),
    "spp-string": (_scene(render={"spp": "16"}), "render.spp must be an integer, got '16'"),
    "ideal-spp-float": (_scene(render={"ideal_spp": 256.0}), "render.ideal_spp must be an integer, got 256.0"),
    "ideal-spp-bool": (_scene(render={"ideal_spp": True}), "render.ideal_spp must be an integer, got True"),
    "seed-bool": (_scene(render={"seed": True}), "render.seed must be an integer in [0, 2**31), got True"),
    "port-model-list": (_scene(render={"port_model": ["sensor"]}), "render.port_model must be a string, one of"),
    "render-number": (_scene(render=3), "render must be a table, got 3"),
    "camera-string": (_scene(camera="tiny"), "[camera] must be a table, got 'tiny'"),
    "pose-list": (_scene(camera={"preset": "tiny", "pose": [0, 0, 0]}), "[camera.pose] must be a table, got [0, 0, 0]"),
    "preset-list": (_scene(camera={"preset": ["tiny"]}), "camera preset must be a string, one of"),
    "port-list": (_scene(port=[0.02]), "[port] must be a table, got [0.02]"),
    "name-list": (_scene(name=["default"]), "name must be a string, got ['default']"),
    "reflectance-string": (_object(2, reflectance="red"), "reflectance must be one number or a list of 3 numbers"),
    "intensity-nested": (_light(1, intensity_w_sr=[[0.45, 0.45, 0.4]]), "intensity_w_sr must have 3 entries"),
    "intensity-date": (
        _light(0, intensity_w_sr=tomllib.loads("d = 2020-01-01")["d"]),
        "intensity_w_sr must be one number or a list of 3 numbers (RGB), got datetime.date(2020, 1, 1)",
    ),
    "figurine-seed-float": (_object(3, seed=3.0), "seed must be an integer in [0, 2**31), got 3.0"),
    "water-absorption-string": (_scene(water={"absorption_per_m": "0.1"}), "water.absorption_per_m must be one number"),
    "mesh-path-list": (
        _scene(object=[{"type": "mesh", "position_m": [0, 0, 1], "path": ["a.obj"]}]),
        "object[0] (mesh): path must be a string, got ['a.obj']",
    ),
    "scene-not-table": ([DEFAULT], "scene must be a table, got [{"),
}


@pytest.mark.parametrize("case", sorted(WRONG_TYPES))
def test_a_value_of_the_wrong_type_names_key_type_and_value(tmp_path, case):
    data, message = WRONG_TYPES[case]
    with pytest.raises(ParameterError) as err:
        parse_scene(data, base_dir=tmp_path)
    assert message in str(err.value)


RIG_WRONG_TYPES = {
    "name-list": ({"name": ["stereo"]}, "name must be a string, got ['stereo']"),
    "wall-number": ({"wall": 3}, "[wall] must be a table, got 3"),
    "camera-entry-number": ({"camera": [3, 4]}, "camera[0] must be a table, got 3"),
    "camera-name-number": (
        {"camera": [{"name": 5, "preset": "tiny"}, {"name": "b", "preset": "tiny"}]},
        "camera[0].name must be a string, got 5",
    ),
    "optics-string": (
        {"camera": [{"name": "a", "optics": "tiny"}, {"name": "b", "preset": "tiny"}]},
        "camera[0].optics must be a table, got 'tiny'",
    ),
}


@pytest.mark.parametrize("case", sorted(RIG_WRONG_TYPES))
def test_a_rig_value_of_the_wrong_type_names_key_type_and_value(case):
    data = tomllib.loads(embedded_rigs()["default"].read_text(encoding="utf-8"))
    changes, message = RIG_WRONG_TYPES[case]
    with pytest.raises(ParameterError) as err:
        parse_rig(data | changes)
    assert message in str(err.value)


# ----------------------------------------------------------------------------- ranges

OUT_OF_RANGE = {
    "spp-beyond-uint32": (_scene(render={"spp": 4294967297}), "render.spp must be at most 65536, got 4294967297"),
    "ideal-spp-zero": (_scene(render={"ideal_spp": 0}), "render.ideal_spp must be positive, got 0"),
    "ideal-spp-beyond": (_scene(render={"ideal_spp": 65537}), "render.ideal_spp must be at most 65536, got 65537"),
    "seed-beyond-int32": (_scene(render={"seed": 2**32}), "render.seed must be an integer in [0, 2**31)"),
    "position-1e300": (_object(0, position_m=[0.0, 0.0, 1e300]), "position_m[2] must lie in [-100, 100] m, got 1e+300"),
    "position-huge-int": (_object(0, position_m=[0, 0, 10**400]), "position_m[2] must be finite, got an integer of"),
    "light-position": (_light(0, position_m=[1e39, 0.0, 0.1]), "light[0] (point): position_m[0] must lie in"),
    "camera-position": (
        _scene(camera={"preset": "tiny", "pose": {"position_m": [0.0, -1e300, 0.0]}}),
        "camera.pose.position_m[1] must lie in [-100, 100] m, got -1e+300",
    ),
    "rotation-1e300": (_object(1, rotation_xyz_deg=[1e300, 0.0, 0.0]), "rotation_xyz_deg[0] must lie in [-360, 360]"),
    "size-1e300": (_object(0, size_m=[1e300, 0.9]), "size_m[0] must lie in [1e-05, 100] m, got 1e+300"),
    "size-1e-300": (_object(0, size_m=[1.2, 1e-300]), "size_m[1] must lie in [1e-05, 100] m, got 1e-300"),
    "square-1e300": (_object(1, square_size_m=1e300), "square_size_m must lie in [1e-05, 100] m"),
    "board-beyond-100m": (_object(1, square_size_m=20.0), "would be 200 x 160 m; at most 100 m a side"),
    "board-texture": (_object(1, squares=[1000, 8]), "would be 16032 x 160 texels; at most 8192 a side"),
    "board-margin-1e308": (_object(1, margin_squares=1e308), "margin_squares must lie in [0, 8192], got 1e+308"),
    "bowl-radius": (_object(2, radius_m=1e300), "radius_m must lie in [1e-05, 100] m"),
    "bowl-deeper-than-wide": (_object(2, depth_m=0.05), "depth_m must not exceed radius_m"),
    "figurine-height": (_object(3, height_m=1e-300), "height_m must lie in [1e-05, 100] m"),
    "texture-px-small": (_object(0, texture_px=10), "texture_px must lie in [64, 8192], got 10"),
    "intensity-1e300": (_light(0, intensity_w_sr=1e300), "intensity_w_sr[0] must lie in [0, 1e+06], got 1e+300"),
    "intensity-negative": (_light(1, intensity_w_sr=[0.1, -0.1, 0.1]), "intensity_w_sr[1] must be non-negative"),
    "disc-radiance": (
        _scene(object=[{"type": "disc", "position_m": [0, 0, 0.5], "radius_m": 0.1, "radiance": 1e300}]),
        "radiance[0] must lie in [0, 1e+08], got 1e+300",
    ),
    "disc-radius": (
        _scene(object=[{"type": "disc", "position_m": [0, 0, 0.5], "radius_m": 1e300}]),
        "radius_m must lie in [1e-05, 100] m",
    ),
    "constant-radiance": (
        {k: v for k, v in _scene(light=[{"type": "constant", "radiance": 1e39}]).items() if k != "port"},
        "radiance[0] must lie in [0, 1e+08], got 1e+39",
    ),
    "reflectance-2": (_object(3, reflectance=2.0), "reflectance[0] must lie in [0, 1], got 2.0"),
    "water-absorption": (_scene(water={"absorption_per_m": 1e300}), "water.absorption_per_m[0] must lie in [0, 1000]"),
    "water-scattering": (
        _scene(water={"absorption_per_m": 0.1, "scattering_per_m": [1, 2, 1e39]}),
        "water.scattering_per_m[2] must lie in [0, 1000]",
    ),
    "water-phase-g": (
        _scene(water={"absorption_per_m": 0.1, "scattering_per_m": 0.1, "phase_g": 0.999999999}),
        "water.phase_g must lie in [-0.99, 0.99], got 0.999999999",
    ),
}


@pytest.mark.parametrize("case", sorted(OUT_OF_RANGE))
def test_a_number_out_of_its_range_is_refused_by_name(tmp_path, case):
    data, message = OUT_OF_RANGE[case]
    with pytest.raises(ParameterError) as err:
        parse_scene(data, base_dir=tmp_path)
    assert message in str(err.value)


def test_the_bounds_themselves_are_accepted():
    spp = parse_scene(_scene(render={"spp": config.MAX_SPP, "seed": 2**31 - 1})).render
    assert (spp.spp, spp.seed) == (65536, 2**31 - 1)
    assert spp.ideal_spp == config.DEFAULT_IDEAL_SPP  # not the raw image's spp
    ideal = parse_scene(_scene(render={"spp": 1, "ideal_spp": config.MAX_SPP})).render
    assert (ideal.spp, ideal.ideal_spp) == (1, 65536)
    assert parse_scene(_scene(render={"ideal_spp": 1})).render.ideal_spp == 1
    edge = config.MAX_COORDINATE_M
    plane = parse_scene(_object(0, position_m=[edge, -edge, edge], size_m=[config.MAX_SIZE_M, config.MIN_SIZE_M]))
    assert plane.objects[0].placement.position_m == (100.0, -100.0, 100.0)
    assert plane.objects[0].size_m == (100.0, 1e-5)
    lit = parse_scene(_light(0, intensity_w_sr=config.MAX_INTENSITY_W_SR))
    assert lit.lights[0].intensity_w_sr == (1e6, 1e6, 1e6)
    assert parse_scene(_object(0, texture_px=64)).objects[0].texture_px == 64


def test_every_accepted_number_is_finite_in_float32():
    """Mitsuba computes in float32: the largest accepted values, and the products the scene forms
    from them (a plane's corner, a board's size, intensity over the squared distance of 1 mm
    summed over every sample), stay finite there."""
    limits = [
        config.MAX_COORDINATE_M + config.MAX_SIZE_M,
        config.MAX_INTENSITY_W_SR / 1e-3**2 * config.MAX_SPP,
        config.MAX_RADIANCE * config.MAX_SPP,
        config.MAX_MESH_SCALE * config.MAX_COORDINATE_M,
        config.MAX_WATER_COEFFICIENT_PER_M * config.MAX_COORDINATE_M,
    ]
    with np.errstate(over="raise"):
        assert all(math.isfinite(float(np.float32(x))) for x in limits)
    assert np.float32(1.0 - config.MAX_ABS_PHASE_G) > 0.0


# ----------------------------------------------------------------------------- user mesh files


def _mesh_scene(path, **changes):
    mesh = {"type": "mesh", "position_m": [0.0, 0.0, 0.5], "path": str(path)} | changes
    return _scene(object=[mesh])


def test_a_mesh_path_of_the_wrong_kind_or_size_is_refused_when_the_scene_is_parsed(tmp_path):
    folder = tmp_path / "folder.obj"
    folder.mkdir()
    fifo = tmp_path / "pipe.obj"
    os.mkfifo(fifo)
    sparse = tmp_path / "huge.obj"
    with sparse.open("wb") as fh:
        fh.truncate(5 * 2**30)  # 5 GiB, sparse: created instantly
    cases = [
        (folder, "is a directory, not a regular file"),
        (fifo, "is a named pipe (FIFO), not a regular file"),
        (sparse, "holds 5368709120 bytes (5120 MiB), more than the 536870912 bytes (512 MiB) accepted"),
    ]
    for path, message in cases:
        start = time.perf_counter()
        with _deadline(10.0), pytest.raises(ParameterError) as err:
            parse_scene(_mesh_scene(path), base_dir=tmp_path)
        assert time.perf_counter() - start < FILE_SIZE_REFUSAL_SECONDS
        assert str(err.value) == f"object[0] (mesh): mesh path {str(path)!r} {message}"


def test_a_mesh_scale_out_of_range_is_refused(tmp_path):
    (tmp_path / "thing.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    for scale in (1e300, 1e-300):
        with pytest.raises(ParameterError, match=r"object\[0\] \(mesh\): scale must lie in \[1e-06, 1000\]"):
            parse_scene(_mesh_scene("thing.obj", scale=scale), base_dir=tmp_path)


@pytest.mark.render
@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("", "the file is empty"),
        ("hello world\n", "line 1 ('hello world') is not an OBJ statement"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no face ('f') lines"),
    ],
    ids=["empty", "garbage", "no-faces"],
)
def test_a_bad_mesh_file_is_named_before_mitsuba_reads_it(mi, tmp_path, content, message):
    from lfrefract.errors import FileFormatError
    from simulator.scene import build_scene

    path = tmp_path / "thing.obj"
    path.write_text(content)
    scene = parse_scene(_mesh_scene(path), base_dir=tmp_path)
    with pytest.raises(FileFormatError) as err:
        build_scene(mi, scene, port_geometry=False)
    assert str(err.value).startswith(f"object[0] (mesh): cannot load {str(path)!r}: ")
    assert message in str(err.value)
    assert "Mesh" not in str(err.value)  # none of Mitsuba's internal messages


@pytest.mark.render
def test_a_mesh_scaled_beyond_the_scene_bound_is_refused_when_loaded(mi, tmp_path):
    from simulator.scene import build_scene

    (tmp_path / "thing.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = parse_scene(_mesh_scene("thing.obj", scale=1000.0), base_dir=tmp_path)  # a 1 km triangle
    with pytest.raises(ParameterError, match=r"object\[0\] \(mesh thing\.obj\): with scale=1000\.0 .* beyond"):
        build_scene(mi, scene, port_geometry=False)
