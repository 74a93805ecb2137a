"""One rule for every seed (simulator.seeds): an integer in [0, 2**31), wherever it enters."""

from __future__ import annotations

import copy
import tomllib

import numpy as np
import pytest

from lfrefract import ParameterError
from simulator import assets, seeds
from simulator.config import default_scene_path, parse_scene
from simulator.dataset import parse_spec

DEFAULT = tomllib.loads(default_scene_path().read_text(encoding="utf-8"))
SWEEP = {"sweep": {"name": "t", "seed": 1, "scene": "default", "spp": 2}}


@pytest.mark.parametrize("value", [0, 1, 2**31 - 1, np.int64(5), np.uint32(2**31 - 1)])
def test_a_seed_is_an_integer_below_two_to_the_31(value):
    out = seeds.seed("s", value)
    assert out == int(value)
    assert type(out) is int


@pytest.mark.parametrize("value", [-1, 2**31, np.int64(2**31), True, np.bool_(False), 3.0, "3", None])
def test_anything_else_is_refused_naming_key_and_value(value):
    with pytest.raises(ParameterError, match=r"^s must be an integer in \[0, 2\*\*31\), got "):
        seeds.seed("s", value)


def _sweep(seed):
    data = copy.deepcopy(SWEEP)
    data["sweep"]["seed"] = seed
    return data


def test_every_entry_point_follows_the_one_rule():
    # The sweep seed accepted any integer >= 0, the asset generators any non-negative integer, and
    # the scene only a Python int: three rules for one kind of value.
    assert parse_spec(_sweep(2**31 - 1)).seed == 2**31 - 1
    with pytest.raises(ParameterError, match=r"sweep.seed must be an integer in \[0, 2\*\*31\), got 2147483648"):
        parse_spec(_sweep(2**31))
    with pytest.raises(ParameterError, match=r"seed must be an integer in \[0, 2\*\*31\), got 2147483648"):
        assets.random_texture(size_px=64, seed=2**31)
    with pytest.raises(ParameterError, match=r"seed must be an integer in \[0, 2\*\*31\), got 2147483648"):
        assets.figurine_mesh(height_m=0.1, seed=2**31)
    data = copy.deepcopy(DEFAULT)
    data["render"]["seed"] = np.int64(7)  # a numpy integer, as a script's generator draws one
    config = parse_scene(data)
    assert config.render.seed == 7
    assert type(config.render.seed) is int
