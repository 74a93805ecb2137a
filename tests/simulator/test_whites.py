"""White images per zoom/focus setting (simulator.whites, lfsim whites): files as the camera ships them,
calibratable, and their micro-image centres move with the setting as the true centres do."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfrefract import camera_preset
from lfrefract.calibration import calibrate_mla
from lfrefract.errors import ParameterError
from lfrefract.formats.jsonio import read_json
from lfrefract.formats.lytro import read_illum_raw
from simulator import cli
from simulator.config import sensor_model
from simulator.detector import demosaic
from simulator.whites import WHITES_INDEX_NAME, WhiteSetting, render_whites, white_settings
from tests.tolerances import MLA_FITTED_CENTRE_MAX_PX


def test_settings_are_the_grid_and_focus_by_the_thin_lens_equation():
    cam = camera_preset("tiny")
    grid = white_settings(cam, focal_lengths_m=[6e-3, 7e-3], focus_distances_m=[math.inf, 0.3])
    assert [(s.focal_length_m, s.focus_distance_m) for s in grid] == [
        (6e-3, math.inf),
        (6e-3, 0.3),
        (7e-3, math.inf),
        (7e-3, 0.3),
    ]
    assert grid[1].lens_to_mla_m == pytest.approx(1.0 / (1.0 / 6e-3 - 1.0 / 0.3), rel=1e-15)
    assert grid[0].camera(cam).lens_to_mla_m == 6e-3
    with pytest.raises(ParameterError, match="focus_distance_m"):
        WhiteSetting(focal_length_m=6e-3, focus_distance_m=0.01)  # closer than 2 f
    with pytest.raises(ParameterError, match="at least one"):
        white_settings(cam, focus_distances_m=[])


def test_a_sensor_of_another_bit_depth_is_refused_before_rendering(tmp_path):
    cam = camera_preset("tiny")
    deep = sensor_model({"preset": "tiny", "bit_depth": 14, "white_level_dn": 16383}, cam)
    with pytest.raises(ParameterError, match="bit_depth=14"):
        render_whites(tmp_path / "w", camera=cam, settings=white_settings(cam), sensor=deep, progress=False)
    assert not (tmp_path / "w").exists()


@pytest.mark.render
def test_whites_per_focus_are_read_calibrated_and_follow_the_exit_pupil(tmp_path, capsys):
    out = tmp_path / "whites"
    # The thin lens: a real lens's white has its micro-images off the paraxial centres of lenses.npz by
    # its pupil aberration (docs/simulator.md, "White images"), which the calibration's bound would not hold.
    argv = ["whites", "--camera", "tiny", "--focus-m", "inf,0.1", "--frames", "8"]
    assert cli.main([*argv, "--spp", "16", "--out", str(out), "--quiet"]) == 0
    assert "2 white images" in capsys.readouterr().out
    index = read_json(out / WHITES_INDEX_NAME)
    entries = index["whites"]
    assert [e["focus_distance_m"] for e in entries] == [None, 0.1]
    assert entries[0]["focus_step"] == 0 < entries[1]["focus_step"]
    centres = []
    for entry in entries:
        capture = read_illum_raw(out / entry["file"])
        lens = capture.metadata["devices"]["lens"]
        assert (lens["zoomStep"], lens["focusStep"]) == (entry["zoom_step"], entry["focus_step"])
        assert lens["exitPupilOffset"]["z"] == entry["exit_pupil_offset_m"]
        truth = np.load(out / entry["lenses_file"])
        cal = calibrate_mla(demosaic(capture.mosaic).mean(axis=2))
        tree_truth = truth["micro_image_centre_px"]
        nearest = np.linalg.norm(cal.centres_px[:, None, :] - tree_truth[None, :, :], axis=2).min(axis=1)
        assert nearest.max() < MLA_FITTED_CENTRE_MAX_PX
        centres.append({tuple(i): c for i, c in zip(truth["lens_index"], tree_truth, strict=True)})
    # Refocusing moves the exit pupil away from the MLA: the micro-images move (toward the centre).
    shift = [np.linalg.norm(centres[1][key] - centre) for key, centre in centres[0].items() if key in centres[1]]
    assert max(shift) > 0.05
