"""The pipeline experiment at tiny scale: from Lytro files alone, against the oracle (issue: real captures in).

One run (about 3 minutes on two cores) renders through the double Gauss and the sensor model, hands the
core only the Lytro files and checks: nothing but a camera's files reached the core, every command of the
data-only chains read only those files, and the calibrated chain's figures stay near the oracle's.
"""

from __future__ import annotations

import math
import shlex

import pytest

from simulator.experiments import run_experiment
from simulator.experiments.pipeline import LYTRO_SUFFIXES, MEASURES, METHODS
from tests.tolerances import (
    PIPELINE_CORNER_GAIN,
    PIPELINE_CORNER_RATIO,
    PIPELINE_PLANE_RATIO,
    PIPELINE_PORT_NORMAL_DEG,
)


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory):
    out = tmp_path_factory.mktemp("pipeline") / "out"
    result = run_experiment("pipeline", out=out, scale="tiny", progress=False)
    return out, result


@pytest.mark.render
def test_only_a_cameras_files_reach_the_core(pipeline):
    out, result = pipeline
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
    out, result = pipeline
    rows = {row["method"]: row for row in result.rows}
    assert tuple(rows) == METHODS
    assert all(row["status"] == "ok" for row in rows.values()), [r["error"] for r in rows.values()]
    assert all(math.isfinite(rows[m][k]) for m in METHODS for k in MEASURES)
    oracle, data, thin = rows["oracle"], rows["data-only"], rows["thin-lens-assumed"]
    for key in ("plane_rmse_mm", "truth_error_mm"):
        assert data[key] < PIPELINE_PLANE_RATIO * oracle[key], key
    assert data["corner_rms_px"] < PIPELINE_CORNER_RATIO * oracle["corner_rms_px"]
    assert data["corner_rms_px"] < PIPELINE_CORNER_GAIN * thin["corner_rms_px"]
    assert data["port_normal_err_deg"] < PIPELINE_PORT_NORMAL_DEG < thin["port_normal_err_deg"]
    assert data["ray_rms_mm"] < thin["ray_rms_mm"]
    assert oracle["ray_rms_mm"] < 1e-9
    assert oracle["port_normal_err_deg"] < 1e-5
    for name in ("table.csv", "planes.csv", "pipeline_summary.png", "commands.txt"):
        assert (out / name).is_file()
    for camera in ("left", "right"):
        for name in ("mla.json", "camera.json", "port.json", "port-thin-lens.json"):
            assert (out / "calibration" / camera / name).is_file()
