"""Procedural meshes with a texture (``texture_seed``): stereo needs texture on the bowl and the figurine."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import ParameterError
from lfrefract.formats.exr import read_exr
from simulator.job import render_job
from tests.simulator.scenes import port, scene
from tests.tolerances import TEXTURED_MESH_CONTRAST_GAIN_MIN

OBJECTS = [
    {
        "type": "bowl",
        "position_m": [-0.06, 0.02, 0.3],
        "rotation_xyz_deg": [-30, 0, 0],
        "radius_m": 0.045,
        "depth_m": 0.03,
    },
    {"type": "figurine", "position_m": [0.06, 0.02, 0.32], "height_m": 0.1, "seed": 3},
]


def _object_contrast(tmp_path, name: str, texture: bool) -> float:
    objects = [dict(o, texture_seed=i + 5) if texture else dict(o) for i, o in enumerate(OBJECTS)]
    out = tmp_path / name
    config = scene(port=port(20.0), objects=objects, spp=32, camera="tiny-2x")
    render_job(config, out, progress=False, write_previews=False)
    ideal = read_exr(out / "ideal.exr", role="ideal")
    on_object = np.isfinite(read_exr(out / "depth.exr", role="depth"))
    # Local colour contrast: the mean absolute difference, per channel, of neighbouring pixels that
    # both see an object, over the mean value there.
    both = on_object[:, 1:] & on_object[:, :-1]
    steps = np.abs(np.diff(ideal, axis=1))[both]
    return float(np.mean(steps) / np.mean(ideal[on_object]))


@pytest.mark.render
def test_a_texture_seed_puts_texture_on_the_meshes(tmp_path):
    plain = _object_contrast(tmp_path, "plain", texture=False)
    textured = _object_contrast(tmp_path, "textured", texture=True)
    assert textured > TEXTURED_MESH_CONTRAST_GAIN_MIN * plain, (plain, textured)


def test_texture_options_are_checked():
    with pytest.raises(ParameterError, match="texture_px"):
        scene(port=None, objects=[dict(OBJECTS[0], texture_seed=1, texture_px=0)])
    with pytest.raises(ParameterError, match="texture_seed"):
        scene(port=None, objects=[dict(OBJECTS[1], texture_seed=-1)])
