"""Raw values so large that a later scaling step (a weighted sum, the port's radiometric gain, the
depth search's gain, all float32) overflows to infinity are refused where the raw image is read,
naming the file: a finite raw of 3e38 gave an all-infinite refraction-free image with exit 0."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract.cli import main
from lfrefract.errors import FileFormatError
from lfrefract.formats.capture import Capture
from lfrefract.formats.exr import write_exr
from lfrefract.optics.presets import camera_preset


@pytest.mark.parametrize("nonfinite", ["refuse", "mask"])
def test_a_raw_value_past_the_limit_is_refused_naming_the_file(nonfinite):
    camera = camera_preset("tiny")
    raw = np.full((camera.sensor.height_px, camera.sensor.width_px, 3), 0.25, dtype=np.float32)
    Capture(raw_path="raw.exr", raw=raw, camera=camera, nonfinite=nonfinite)  # an ordinary image is taken
    raw[10, 20, 1] = 3e38
    raw[11, 20, 1] = 2e31
    with pytest.raises(FileFormatError, match=r"'raw.exr' has 2 values above 1e\+30 \(the largest 3e\+38\)"):
        Capture(raw_path="raw.exr", raw=raw, camera=camera, nonfinite=nonfinite)


def test_the_command_refuses_it_in_one_line(tmp_path, capsys):
    camera = camera_preset("tiny")
    raw = np.full((camera.sensor.height_px, camera.sensor.width_px, 3), 3e38, dtype=np.float32)
    write_exr(tmp_path / "raw.exr", raw, role="raw")
    out = tmp_path / "o.exr"
    assert main(["naive", str(tmp_path / "raw.exr"), "--camera", "tiny", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "raw.exr" in err
    assert "1e+30" in err
    assert not out.exists()
