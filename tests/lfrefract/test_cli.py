"""The core's command line: ``lfrefract describe``."""

from __future__ import annotations

import json
import math

import pytest

from lfrefract import FlatPort, camera_preset
from lfrefract.cli import main
from lfrefract.io import write_json


def test_describe_preset_prints_derived_optics(capsys):
    assert main(["describe", "illum", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    cam = camera_preset("illum")
    assert info["micro_image_pitch_px"] == pytest.approx(20e-6 * (1 + 36e-6 / 9.993e-3) / 1.4e-6)
    assert info["refraction_free_image"]["K"][0][0] == pytest.approx(cam.lens_to_mla_m / 10e-6)
    assert info["lens_count"] > 230_000


def test_describe_meta_json_includes_the_port(tmp_path, capsys):
    port = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.005, tilt_x_deg=20.0)
    meta = tmp_path / "meta.json"
    write_json(meta, {"camera": camera_preset("tiny").to_dict(), "port": port.to_dict()})
    assert main(["describe", str(meta)]) == 0
    out = capsys.readouterr().out
    assert "port:" in out
    assert f"total_tilt_deg: {math.degrees(port.total_tilt_rad)}" in out


def test_describe_bad_file_is_a_clear_error(tmp_path, capsys):
    assert main(["describe", str(tmp_path / "nope.json")]) == 2
    assert "no such file" in capsys.readouterr().err
