"""The pipeline experiment at tiny scale: from Lytro files alone, against the oracle (issue: real captures in).

One run (about 8 minutes on two cores) renders through the double Gauss and the sensor model, hands the
core only the Lytro files and checks: nothing but a camera's files reached the core, every command of the
data-only chains read only those files, and the calibrated chain's figures stay near the oracle's.
"""

from __future__ import annotations

import math
import shlex

import pytest

from lfrefract.formats.jsonio import read_json
from simulator.experiments import ExperimentOptions
from simulator.experiments.pipeline import LYTRO_SUFFIXES, MEASURES, METHODS, run_pipeline
from tests.tolerances import (
    PIPELINE_CORNER_GAIN,
    PIPELINE_CORNER_RATIO,
    PIPELINE_PLANE_RATIO,
    PIPELINE_PORT_NORMAL_DEG,
)

#: A user's files in the renders folder, under the names of the run's own working folders (an early
#: version deleted and remade ``delivered/`` and ``core/`` there).
USER_FILES = ("delivered/notes.txt", "core/notes.txt", "notes.txt")

pytestmark = pytest.mark.minutes


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory):
    root = tmp_path_factory.mktemp("pipeline")
    out, renders = root / "out", root / "renders"
    for name in USER_FILES:
        (renders / name).parent.mkdir(parents=True, exist_ok=True)
        (renders / name).write_text(f"the user's {name}")
    out.mkdir()
    result = run_pipeline(out, options=ExperimentOptions(scale="tiny"), progress=False, renders_dir=renders)
    return out, result, renders


@pytest.mark.render
def test_only_a_cameras_files_reach_the_core(pipeline):
    out, result, _ = pipeline
    delivered = result.parameters["delivered"]
    assert delivered
    assert all(name.endswith(LYTRO_SUFFIXES) for name in delivered)
    assert not any("meta.json" in name or "lenses" in name for name in delivered)
    commands = (out / "commands.txt").read_text().splitlines()
    assert len(commands) == result.parameters["commands"]
    data_only = [c for c in commands if "renders/" not in c]
    assert len(data_only) > len(commands) / 2  # the oracle's synths read the thin-lens renders
    for command in data_only:
        for arg in shlex.split(command):
            if "/" in arg:  # every path is a delivered file, the core's own output or the experiment's
                assert arg.startswith(("delivered/", "core/", "out/")), command


@pytest.mark.render
def test_the_data_only_chain_stays_near_the_oracle_and_far_below_the_thin_lens_chain(pipeline):
    out, result, _ = pipeline
    rows = {row["method"]: row for row in result.rows}
    assert tuple(rows) == METHODS
    assert all(row["status"] == "ok" for row in rows.values()), [r["error"] for r in rows.values()]
    assert all(math.isfinite(rows[m][k]) for m in METHODS for k in MEASURES)
    oracle, data, thin = rows["oracle"], rows["data-only"], rows["thin-lens-assumed"]
    true_rays = rows["true-rays"]
    # Against the oracle of a real-lens capture (its lens traced, the true port: the same images), and the
    # error to the true plane against the thin-lens oracle's too; the plane fit's RMSE is not held to the
    # thin-lens oracle's (tests/tolerances.py: it also carries the real lens's image formation).
    for key in ("plane_rmse_mm", "truth_error_mm"):
        assert data[key] < PIPELINE_PLANE_RATIO * true_rays[key], key
    assert data["truth_error_mm"] < PIPELINE_PLANE_RATIO * oracle["truth_error_mm"]
    assert data["corner_rms_px"] < PIPELINE_CORNER_RATIO * oracle["corner_rms_px"]
    # the real captures with the lens traced and the true port: the oracle of a real-lens capture
    assert data["corner_rms_px"] < PIPELINE_CORNER_RATIO * true_rays["corner_rms_px"]
    assert true_rays["ray_rms_mm"] < 1e-9
    assert true_rays["port_normal_err_deg"] < 1e-5
    assert true_rays["ray_model"] == "left traced double-gauss, right traced double-gauss"
    # at tiny the test boards lie inside the exact cone of the thin lens and of the double Gauss's true rays
    assert oracle["corners_exact_share"] == true_rays["corners_exact_share"] == 1.0
    assert data["corner_rms_px"] < PIPELINE_CORNER_GAIN * thin["corner_rms_px"]
    assert data["port_normal_err_deg"] < PIPELINE_PORT_NORMAL_DEG < thin["port_normal_err_deg"]
    assert data["ray_rms_mm"] < thin["ray_rms_mm"]
    assert oracle["ray_rms_mm"] < 1e-9
    # up to a shift along the axis (what in-air boards leave free), never worse than without it
    assert data["ray_rms_aligned_mm"] <= data["ray_rms_mm"]
    assert oracle["ray_rms_aligned_mm"] < 1e-9
    assert abs(oracle["frame_shift_mm"]) < 1e-6
    assert oracle["port_normal_err_deg"] < 1e-5
    assert data["boards_left_out"] == thin["boards_left_out"] == ""  # every tiny board is located
    for name in ("planes.csv", "pipeline_summary.png", "commands.txt"):
        assert (out / name).is_file()
    for camera in ("left", "right"):
        for name in ("mla.json", "camera.json", "camera-refined.json", "port.json", "port-thin-lens.json"):
            assert (out / "calibration" / camera / name).is_file()
        # The data-only port was fitted with the refined ray model, which started from the in-air one, where
        # the held-back boards accepted the refinement; else on the in-air model, which the file keeps.
        files = {name: read_json(out / "calibration" / camera / f"{name}.json") for name in ("camera", "port")}
        refined = read_json(out / "calibration" / camera / "camera-refined.json")
        if refined["refinement"]["accepted"]:
            assert refined["refinement"]["in_air_correction"] == files["camera"]["correction"]
            assert files["port"]["ray_model"]["correction"] == refined["correction"] != files["camera"]["correction"]
        else:
            assert refined["correction"] == files["camera"]["correction"] == files["port"]["ray_model"]["correction"]
            assert refined["refinement"]["rejected_correction"] != files["camera"]["correction"]


@pytest.mark.render
def test_a_renders_folder_keeps_what_it_held_and_gets_the_renders(pipeline):
    _, _, renders = pipeline
    for name in USER_FILES:
        assert (renders / name).read_text() == f"the user's {name}"
    assert sorted(p.name for p in (renders / "delivered").iterdir()) == ["notes.txt"]
    assert any((renders / "renders" / "real").iterdir())
