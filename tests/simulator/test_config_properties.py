"""Property-based tests of the scene parser (issue 12): randomly damaged scenes are either refused
with a ParameterError that says something, or parsed into a config whose every number is finite
(and, where Mitsuba uses it, finite in float32). No other exception may escape.

The scenes are the default scene (scenes/default.toml) and variants of it with a ``[water]`` table,
a user mesh, a full camera table and a constant light, damaged by a few random mutations: a value
replaced by a hostile one (NaN, infinities, huge, tiny, negative, a list, a table, a string, a
date, an integer beyond 64 bits), a scalar wrapped in a list, a key removed, an unknown key added,
a number scaled by a random power of ten.
"""

from __future__ import annotations

import copy
import datetime
import math
import tomllib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lfrefract import ParameterError, camera_preset
from simulator.config import default_scene_path, parse_scene

DEFAULT = tomllib.loads(default_scene_path().read_text(encoding="utf-8"))

#: Keys of the scene's to_dict() whose numbers Mitsuba receives from the scene config itself (the
#: camera's and the port's are checked by their own types, in lfrefract, in float64).
FLOAT32_SECTIONS = ("objects", "lights", "render", "water", "pose")


def _bases() -> list[dict]:
    with_water = copy.deepcopy(DEFAULT)
    del with_water["port"]["n_water"]
    with_water["water"] = {
        "salinity_psu": 35.0,
        "temperature_c": 20.0,
        "wavelength_nm": 589.3,
        "absorption_per_m": [0.4, 0.07, 0.02],
        "scattering_per_m": 0.1,
        "phase_g": 0.9,
    }
    with_mesh = copy.deepcopy(DEFAULT)
    with_mesh["object"].append(
        {"type": "mesh", "path": "thing.obj", "position_m": [0.0, 0.0, 0.5], "scale": 0.1, "reflectance": 0.5}
    )
    with_camera = copy.deepcopy(DEFAULT)
    with_camera["camera"] = camera_preset("tiny").to_dict() | {
        "pose": {"rotation_xyz_deg": [0.0, 0.0, 0.0], "position_m": [0.0, 0.0, 0.0]}
    }
    lit = copy.deepcopy(DEFAULT)
    del lit["port"]
    lit["light"] = [{"type": "constant", "radiance": 1.0}]
    lit["object"].append({"type": "disc", "position_m": [0.0, 0.0, 1.0], "radius_m": 0.1, "radiance": [1.0, 1.0, 1.0]})
    return [DEFAULT, with_water, with_mesh, with_camera, lit]


BASES = _bases()

HOSTILE = st.sampled_from(
    [
        math.nan,
        math.inf,
        -math.inf,
        1e300,
        -1e300,
        1e-300,
        3.5e38,
        1e39,
        0,
        0.0,
        -0.0,
        -1,
        1.5,
        2**31,
        2**32 + 1,
        2**64,
        2**1100,
        True,
        "",
        "text",
        "\0",
        "thing.obj",
        "/",
        [],
        [1, 2],
        [[1.0]],
        [math.nan, 0.0, 0.0],
        {},
        {"a": 1},
        {"type": "point"},
        datetime.date(2020, 1, 1),
        datetime.time(12, 0),
    ]
)
NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(min_value=-(2**80), max_value=2**80))


def _paths(node, prefix=()):
    """Every path (a tuple of keys and indices) to a value inside ``node``."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    out = []
    for key, value in items:
        out.append((*prefix, key))
        out += _paths(value, (*prefix, key))
    return out


def _parent(data, path):
    for key in path[:-1]:
        data = data[key]
    return data


@st.composite
def damaged_scenes(draw):
    data = copy.deepcopy(draw(st.sampled_from(BASES)))
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        paths = _paths(data)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent, key = _parent(data, path), path[-1]
        action = draw(st.sampled_from(["hostile", "number", "wrap", "remove", "unknown", "scale"]))
        value = parent[key]
        if action == "hostile":
            parent[key] = copy.deepcopy(draw(HOSTILE))  # a copy: later mutations must not reach HOSTILE
        elif action == "number":
            parent[key] = draw(NUMBERS)
        elif action == "wrap":
            parent[key] = [value]
        elif action == "remove":
            del parent[key]
        elif action == "unknown" and isinstance(parent, dict):
            parent[draw(st.sampled_from(["colour", "spp", "Type", "position"]))] = 1
        elif (
            action == "scale" and isinstance(value, float | int) and not isinstance(value, bool) and abs(value) < 1e300
        ):
            # 10.0 ** 308 is the largest power; the product may overflow to inf, which is a case too.
            parent[key] = float(value) * 10.0 ** draw(st.integers(min_value=-320, max_value=308))
    return data


def _numbers(node, where=""):
    """Every number in a plain-data tree, with where it is."""
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _numbers(value, f"{where}.{key}")
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            yield from _numbers(value, f"{where}[{i}]")
    elif isinstance(node, (int, float, np.number)) and not isinstance(node, bool):
        yield where, node


@pytest.fixture(scope="module")
def mesh_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("meshes")
    (folder / "thing.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    return folder


@settings(max_examples=200, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=damaged_scenes())
def test_a_damaged_scene_is_refused_clearly_or_parsed_into_finite_numbers(mesh_dir, data):
    try:
        scene = parse_scene(data, base_dir=mesh_dir)
    except ParameterError as exc:
        message = str(exc)
        scene = None
    if scene is None:
        assert message.strip(), "a ParameterError without a message"
        return
    plain = scene.to_dict()
    for where, value in _numbers(plain):
        assert math.isfinite(float(value)), f"{where} = {value!r} is not finite"
    for section in FLOAT32_SECTIONS:
        for where, value in _numbers(plain[section], section):
            with np.errstate(over="ignore"):
                assert np.isfinite(np.float32(value)), f"{where} = {value!r} is not finite in float32"


def test_the_undamaged_bases_parse(mesh_dir):
    """The property above is not vacuous: every base scene is accepted as it is."""
    for data in BASES:
        parse_scene(copy.deepcopy(data), base_dir=mesh_dir)
