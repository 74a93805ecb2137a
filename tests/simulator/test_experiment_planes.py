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
    PLANES_EXACT_OVER_ALL_ERROR_MAX,
    PLANES_EXACT_SHARE_RANGE,
    PLANES_PROPOSED_OVER_IDEAL_RMSE,
    PLANES_PROPOSED_TRUTH_ERROR_RELATIVE,
)

pytestmark = pytest.mark.render


@pytest.fixture(scope="module")
def planes(tmp_path_factory):
    out = tmp_path_factory.mktemp("planes") / "planes"
    result = run_experiment("planes", out=out, scale="tiny", progress=False)
    rows = {(row["matcher"], row["method"], row["depth_m"]): row for row in result.rows}
    return out, {key[1:]: row for key, row in rows.items() if key[0] == "zncc"}, rows


def test_files_and_figures(planes):
    out, rows, every = planes
    names = ("table.csv", "table.md", "meta.json", "planes_disparity_zncc.png", "planes_disparity_sgbm.png")
    for name in (*names, "planes_errors.png"):
        assert (out / name).is_file(), name
    assert len(rows) == 18  # six methods, three depths
    assert len(every) == 36  # and as many with SGBM
    assert all(row["boards"] >= 10 for row in rows.values())  # the rig calibrated on most boards


def test_exact_coverage_measures(planes):
    """Part of each plane lies in both cameras' exact coverage, and there the proposed method is
    at least as close to the true plane as over all its points (outside it the synthesis approximates)."""
    _, _, every = planes
    for (matcher, method, depth), row in every.items():
        low, high = PLANES_EXACT_SHARE_RANGE
        assert low < row["exact_share"] < high, (matcher, method, depth)
        if method == "proposed":
            assert row["exact_truth_error_mm"] <= PLANES_EXACT_OVER_ALL_ERROR_MAX * row["truth_error_mm"], (
                matcher,
                depth,
            )


@pytest.mark.parametrize("matcher", ["zncc", "sgbm"])
def test_proposed_is_as_good_as_the_ideal_images(planes, matcher):
    _, _, every = planes
    rows = {key[1:]: row for key, row in every.items() if key[0] == matcher}
    for depth in (0.3, 0.45, 0.6):
        proposed, ideal = rows[("proposed", depth)], rows[("ideal", depth)]
        assert proposed["plane_rmse_mm"] <= PLANES_PROPOSED_OVER_IDEAL_RMSE * ideal["plane_rmse_mm"], depth
        assert proposed["truth_error_mm"] <= PLANES_PROPOSED_TRUTH_ERROR_RELATIVE * depth * 1e3, depth
        assert proposed["completeness"] > 0.5


@pytest.mark.parametrize("matcher", ["zncc", "sgbm"])
def test_approximation_degrades_away_from_its_calibration_depth(planes, matcher):
    """The paper's main claim: calibrated near, the approximation is good near and wrong far."""
    _, _, every = planes
    rows = {key[1:]: row for key, row in every.items() if key[0] == matcher}
    near, far = rows[("approx near", 0.3)], rows[("approx near", 0.6)]
    assert far["truth_error_mm"] >= PLANES_APPROX_GROWTH_MIN * near["truth_error_mm"]
    assert far["truth_error_mm"] >= PLANES_APPROX_GROWTH_MIN * rows[("proposed", 0.6)]["truth_error_mm"]
    assert all(math.isfinite(row["plane_rmse_mm"]) for row in rows.values())
