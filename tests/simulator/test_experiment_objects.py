"""``lfsim experiment objects`` at the tiny scale: a textured bowl and figurine, every method."""

from __future__ import annotations

import pytest

from lfrefract.formats.ply import read_ply
from simulator.experiments import run_experiment
from simulator.experiments.methods import file_stem
from tests.tolerances import OBJECTS_APPROX_FAR_OVER_PROPOSED_MIN, OBJECTS_COMPLETENESS_MIN

pytestmark = pytest.mark.render


def test_objects_by_method(tmp_path):
    out = tmp_path / "objects"
    result = run_experiment("objects", out=out, scale="tiny", progress=False)
    rows = {row["method"]: row for row in result.rows if row["matcher"] == "zncc"}
    assert (out / "objects_depth_error.png").is_file()
    for row in result.rows:
        method, suffix = row["method"], "" if row["matcher"] == "zncc" else f"_{row['matcher']}"
        assert row["completeness"] > OBJECTS_COMPLETENESS_MIN[row["matcher"]], (row["matcher"], method)
        assert 0 <= row["bad_2px"] <= row["bad_1px"] <= row["bad_0.5px"] <= 1
        points, _ = read_ply(out / f"cloud_{file_stem(method)}{suffix}.ply")
        assert len(points) > 1000, (row["matcher"], method)
    # The approximation calibrated at 0.6 m, twice as far as the objects, misses them most.
    far, proposed = rows["approx far"]["median_abs_mm"], rows["proposed"]["median_abs_mm"]
    assert far > OBJECTS_APPROX_FAR_OVER_PROPOSED_MIN * proposed
    # The same on the pixels both cameras see exactly, which are part of the objects' only.
    assert 0 < rows["proposed"]["exact_share"] < 1
    far, proposed = rows["approx far"]["exact_median_abs_mm"], rows["proposed"]["exact_median_abs_mm"]
    assert far > OBJECTS_APPROX_FAR_OVER_PROPOSED_MIN * proposed
