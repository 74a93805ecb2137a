"""``lfsim experiment planes`` at the tiny scale: issue 5's regression tests on reconstruction error.

A rig of two tiny-2x cameras behind one 20 deg wall; a textured plane at 0.3, 0.45 and 0.6 m;
chessboards at 0.3 and 0.6 m (simulator/experiments/planes.py). Rendered once for the module.
"""

from __future__ import annotations

import math

import pytest

from simulator.experiments import run_experiment
from tests.tolerances import (
    PLANES_APPROX_GROWTH_MIN,
    PLANES_PROPOSED_OVER_IDEAL_RMSE,
    PLANES_PROPOSED_TRUTH_ERROR_RELATIVE,
)

pytestmark = pytest.mark.render


@pytest.fixture(scope="module")
def planes(tmp_path_factory):
    out = tmp_path_factory.mktemp("planes") / "planes"
    result = run_experiment("planes", out, scale="tiny", progress=False)
    return out, {(row["method"], row["depth_m"]): row for row in result.rows}


def test_files_and_figures(planes):
    out, rows = planes
    for name in ("table.csv", "table.md", "meta.json", "planes_disparity.png", "planes_errors.png"):
        assert (out / name).is_file(), name
    assert len(rows) == 15
    assert all(row["boards"] >= 10 for row in rows.values())  # the rig calibrated on most boards


def test_proposed_is_as_good_as_the_ideal_images(planes):
    _, rows = planes
    for depth in (0.3, 0.45, 0.6):
        proposed, ideal = rows[("proposed", depth)], rows[("ideal", depth)]
        assert proposed["plane_rmse_mm"] <= PLANES_PROPOSED_OVER_IDEAL_RMSE * ideal["plane_rmse_mm"], depth
        assert proposed["truth_error_mm"] <= PLANES_PROPOSED_TRUTH_ERROR_RELATIVE * depth * 1e3, depth
        assert proposed["completeness"] > 0.5


def test_approximation_degrades_away_from_its_calibration_depth(planes):
    """The paper's main claim: calibrated near, the approximation is good near and wrong far."""
    _, rows = planes
    near, far = rows[("approx near", 0.3)], rows[("approx near", 0.6)]
    assert far["truth_error_mm"] >= PLANES_APPROX_GROWTH_MIN * near["truth_error_mm"]
    assert far["truth_error_mm"] >= PLANES_APPROX_GROWTH_MIN * rows[("proposed", 0.6)]["truth_error_mm"]
    assert all(math.isfinite(row["plane_rmse_mm"]) for row in rows.values())
