"""The demo's report (no rendering): it leads with the error against the true plane, and says why
the proposed method's plane RMSE can fall below the ideal images'."""

from __future__ import annotations

import itertools

from simulator.demo import RMSE_BELOW_IDEAL, _report
from simulator.experiments.planes import PLANE_DEPTHS_M
from simulator.experiments.rigstereo import MATCHERS, METHOD_NAMES


def _rows() -> list[dict]:
    """Rows of every matcher, method and depth; the proposed RMSE below the ideal's (as on the
    tiny rig), its error against the truth above."""
    depths = PLANE_DEPTHS_M["tiny"]
    rows = []
    for matcher, method, (i, depth) in itertools.product(MATCHERS, METHOD_NAMES, enumerate(depths)):
        rmse = {"proposed": 0.8, "ideal": 1.0}.get(method, 2.0) * (1 + i)
        error = {"proposed": 1.5, "ideal": 1.2}.get(method, 3.0) * (1 + i)
        rows.append({"matcher": matcher, "method": method, "depth_m": depth, "plane_rmse_mm": rmse,
                     "truth_error_mm": error})  # fmt: skip
    return rows


def test_the_report_leads_with_the_error_against_the_true_plane():
    report = _report(_rows(), 12.0, ["cloud_proposed.ply"])
    lines = report.splitlines()
    first_claim = next(line for line in lines if line.startswith("- "))
    assert first_claim.startswith("- Proposed error against the true plane: 1.50, 3.00, 4.50 mm")
    assert "(ideal images: 1.20, 2.40, 3.60 mm" in first_claim
    assert "Mean error against the true plane / plane-fit RMSE" in report
    assert report.index("error against the true plane") < report.index("plane RMSE over the ideal")
    assert "| proposed | 1.50 / 0.80 | 3.00 / 1.60 | 4.50 / 2.40 |" in report
    assert "0.80, 0.80, 0.80" in report  # the ratio under 1 ...
    assert RMSE_BELOW_IDEAL in report  # ... and why
    assert "averages many captured rays" in RMSE_BELOW_IDEAL
