"""Experiments as one's own regression tests, written as a user of the package would write them.

docs/experiments.md ("Experiments as regression tests") walks through this file. Two patterns:

1. Pin a measured figure. Run the experiment once through the public API
   (:func:`simulator.experiments.run_experiment`), keep the numbers you trust as a baseline, and
   assert that later runs stay within a tolerance you choose and can justify.
2. Hold your own method to a built-in one. Register it (``register_method``), run a stereo
   experiment with just the methods you compare, and assert on the ratio of their errors.
"""

from __future__ import annotations

import math

import pytest

from lfrefract.methods import build_projector
from lfrefract.synthesis.warp_map import SynthesisOptions, build_warp_map
from simulator.experiments import run_experiment
from simulator.experiments.methods import CentralImages, MethodRig, register_method, unregister_method

# ----------------------------------------------------------------------------------------------
# 1. The perfect field of view of the tiny camera behind its 12 mm port, pinned.

#: (tilt_deg, f_number) -> (exact share, perfect FOV horizontal, vertical in degrees), measured
#: once with ``lfsim experiment fov --scale tiny --tilts-deg 0,15,30 --f-numbers 2.2,4``.
FOV_BASELINE = {
    (0.0, 2.2): (0.48582, 31.638, 23.994),
    (0.0, 4.0): (0.14587, 16.126, 16.594),
    (15.0, 2.2): (0.32073, 31.145, 17.268),
    (15.0, 4.0): (0.08727, 16.591, 8.708),
    (30.0, 2.2): (0.02583, 17.323, 2.680),
    (30.0, 4.0): (0.0, 0.0, 0.0),
}
#: The tolerances: the share may move by 0.5 % of the image (32 of its 6348 pixels), a field of
#: view by one pixel at the principal point (0.48 deg for this 120 px focal length). A geometry change
#: that moves the exact region by more than a pixel fails.
SHARE_TOLERANCE = 0.005
FOV_TOLERANCE_DEG = 0.48


@pytest.fixture(scope="module")
def fov_rows(tmp_path_factory):
    result = run_experiment(
        "fov",
        out=tmp_path_factory.mktemp("regression") / "fov",
        scale="tiny",
        tilts_deg=(0.0, 15.0, 30.0),
        f_numbers=(2.2, 4.0),
        progress=False,
    )
    return {(r["tilt_deg"], r["f_number"]): r for r in result.rows if r["series"] == "tilt"}


@pytest.mark.parametrize("condition", sorted(FOV_BASELINE))
def test_perfect_field_of_view_has_not_moved(fov_rows, condition):
    share, fov_h, fov_v = FOV_BASELINE[condition]
    row = fov_rows[condition]
    assert row["exact_share"] == pytest.approx(share, abs=SHARE_TOLERANCE)
    assert row["perfect_fov_h_deg"] == pytest.approx(fov_h, abs=FOV_TOLERANCE_DEG)
    assert row["perfect_fov_v_deg"] == pytest.approx(fov_v, abs=FOV_TOLERANCE_DEG)


# ----------------------------------------------------------------------------------------------
# 2. My method (the synthesis with one ray per sub-pixel sample, no averaging) against ``proposed``.


def single_ray_synthesis(rig: MethodRig) -> CentralImages:
    """The refraction-free synthesis with k = 1: each sub-pixel sample takes its nearest captured ray."""
    one_ray = SynthesisOptions(k=1)
    projectors = {
        c.name: build_projector("proposed", c.camera, warp=build_warp_map(c.camera, c.port, options=one_ray))
        for c in rig.cameras
    }
    return CentralImages(
        outputs={name: p.output for name, p in projectors.items()},
        project=lambda name, shot: projectors[name].apply(shot.raw(name)),
    )


#: What I accept from my method: an error against the true plane at most 1.5 times the built-in
#: synthesis's at every depth (k = 1 keeps more render noise; more than that would be a regression).
MY_METHOD_OVER_PROPOSED_MAX = 1.5


@pytest.mark.render
def test_my_method_is_close_to_proposed(tmp_path):
    register_method("single ray", single_ray_synthesis)
    try:
        result = run_experiment("planes", out=tmp_path / "planes", methods=("proposed", "single ray"), progress=False)
    finally:
        unregister_method("single ray")
    rows = {(r["matcher"], r["method"], r["depth_m"]): r for r in result.rows}
    mine = [r for r in result.rows if r["method"] == "single ray"]
    assert mine
    # Both methods must have run: a failed row has NaN measures, which no tolerance below would name.
    for name in ("single ray", "proposed"):
        failed = [r["error"] for r in result.rows if r["method"] == name and r["status"] != "ok"]
        assert failed == [], (name, failed)
    for row in mine:
        proposed = rows[(row["matcher"], "proposed", row["depth_m"])]
        assert math.isfinite(row["truth_error_mm"])
        assert row["truth_error_mm"] <= MY_METHOD_OVER_PROPOSED_MAX * proposed["truth_error_mm"], row
