"""The experiments' method registry (simulator/experiments/methods.py) and outside methods in ``planes``.

The outside methods here are written as a user would write them, against the public API only:
``naive view`` makes central images (the conventional image, no refraction handling: the harness
calibrates the rig on them and runs stereo), ``depth oracle`` returns depth maps (the rendered
ground truth, so that the harness's depth path is held to an exact answer), and ``broken`` raises.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from lfrefract import ParameterError
from lfrefract.methods import build_projector
from simulator.experiments import run_experiment
from simulator.experiments.methods import (
    BUILTIN_METHODS,
    ENTRY_POINT_GROUP,
    CentralImages,
    DepthMaps,
    MethodRig,
    file_stem,
    method_factories,
    method_names,
    register_method,
    unregister_method,
)
from simulator.experiments.planes import PLANE_DEPTHS_M
from simulator.experiments.rigstereo import MATCHERS

#: The depth oracle's error against the true plane may not exceed this, mm: its depth is the
#: renderer's own float32 depth of the same plane (relative error about 1e-7, 0.1 um at 0.6 m), so
#: anything above is the harness mis-placing a pixel's ray.
ORACLE_TRUTH_ERROR_MAX_MM = 0.01


# ------------------------------------------------------------------------------- outside methods
def naive_view(rig: MethodRig) -> CentralImages:
    """Each camera's conventional image (the central sub-aperture view), refraction ignored."""
    projectors = {c.name: build_projector("naive", c.camera) for c in rig.cameras}
    return CentralImages(
        outputs={name: p.output for name, p in projectors.items()},
        project=lambda name, shot: projectors[name].apply(shot.raw(name)),
    )


def depth_oracle(rig: MethodRig) -> DepthMaps:
    """The first camera's rendered ground-truth depth (a method that returns depth, not images)."""
    first = rig.cameras[0]
    return DepthMaps(output=first.warp.output, depth=lambda shot: shot.depth(first.name))


def broken(rig: MethodRig) -> CentralImages:
    raise RuntimeError("this method is broken on purpose")


def broken_on_captures(rig: MethodRig) -> DepthMaps:
    """Sets up, then fails on every capture (a wrong depth-map shape)."""
    return DepthMaps(output=rig.cameras[0].warp.output, depth=lambda shot: np.zeros((3, 3)))


OUTSIDE = {
    "naive view": naive_view,
    "depth oracle": depth_oracle,
    "broken": broken,
    "broken on captures": broken_on_captures,
}


@pytest.fixture
def registered():
    """The outside methods registered for one test, and removed after it."""
    for name, factory in OUTSIDE.items():
        register_method(name, factory)
    yield
    for name in OUTSIDE:
        unregister_method(name)


# ------------------------------------------------------------------------------- the registry
def test_registry_is_read_at_call_time(registered):
    names = method_names()
    assert names[: len(BUILTIN_METHODS)] == tuple(BUILTIN_METHODS)
    assert names[len(BUILTIN_METHODS) :] == tuple(OUTSIDE)
    assert method_factories()["naive view"] is naive_view
    unregister_method("broken")
    assert "broken" not in method_names()
    register_method("broken", broken)  # back, for the fixture's teardown


def test_register_refuses_bad_names_and_taken_ones(registered):
    with pytest.raises(ParameterError, match="built in"):
        register_method("proposed", naive_view)
    with pytest.raises(ParameterError, match="already registered"):
        register_method("naive view", naive_view)
    register_method("naive view", naive_view, replace=True)
    for bad in ("", "a,b", " padded"):
        with pytest.raises(ParameterError, match="method name"):
            register_method(bad, naive_view)
    with pytest.raises(ParameterError, match="callable"):
        register_method("not callable", 42)
    with pytest.raises(ParameterError, match="no method 'never'"):
        unregister_method("never")


def test_entry_point_methods(tmp_path, monkeypatch):
    """A method of an installed package, through its ``lfrefract.methods`` entry point; one that
    cannot be loaded is kept as a failing method."""
    package = tmp_path / "outside_methods_pkg"
    package.mkdir()
    (package / "__init__.py").write_text(
        textwrap.dedent(
            """
            from simulator.experiments.methods import DepthMaps

            def flat(rig):
                first = rig.cameras[0]
                return DepthMaps(output=first.warp.output, depth=lambda shot: None)
            """
        )
    )
    info = tmp_path / "outside_methods_pkg-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: outside-methods-pkg\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\nflat plane = outside_methods_pkg:flat\nmissing = outside_methods_pkg:nowhere\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    factories = method_factories()
    assert list(factories)[-2:] == ["flat plane", "missing"]
    assert factories["flat plane"].__module__ == "outside_methods_pkg"
    with pytest.raises(RuntimeError, match=r"entry point 'missing'.*could not be loaded"):
        factories["missing"](None)


def test_unknown_method_is_refused_before_any_work(tmp_path):
    with pytest.raises(ParameterError, match="method must be one of"):
        run_experiment("planes", out=tmp_path / "planes", methods=("proposed", "telepathy"), progress=False)
    assert not (tmp_path / "planes").exists()


@pytest.mark.parametrize("experiment", ["planes", "objects"])
def test_methods_whose_files_would_collide_are_refused_before_any_work(tmp_path, experiment):
    """'approx-far' and 'approx far' both wrote cloud_approx_far.ply (one cloud silently replaced the other),
    and upper case and digits were dropped ('MyMethod' wrote cloud__y_ethod.ply)."""
    register_method("approx-far", naive_view)
    try:
        with pytest.raises(ParameterError, match=r"'approx far' and 'approx-far' would write the same files"):
            run_experiment(experiment, out=tmp_path / "out", methods=("approx far", "approx-far"), progress=False)
    finally:
        unregister_method("approx-far")
    assert not (tmp_path / "out").exists()
    assert [file_stem(n) for n in ("proposed+distortion", "MyMethod v2", "approx near")] == [
        "proposed_distortion",
        "MyMethod_v2",
        "approx_near",
    ]


# ------------------------------------------------------------------------------- in planes
@pytest.fixture(scope="module")
def planes_run(tmp_path_factory):
    """``planes`` at the tiny scale with the outside methods and ``proposed``, rendered once."""
    for name, factory in OUTSIDE.items():
        register_method(name, factory)
    try:
        out = tmp_path_factory.mktemp("outside") / "planes"
        result = run_experiment("planes", out=out, scale="tiny", methods=("proposed", *OUTSIDE), progress=False)
    finally:
        for name in OUTSIDE:
            unregister_method(name)
    return out, result


@pytest.mark.render
def test_outside_methods_run_in_planes(planes_run):
    """Done when an outside method runs in ``planes`` through the public API."""
    out, result = planes_run
    rows = {(r["matcher"], r["method"], r["depth_m"]): r for r in result.rows}
    depths = PLANE_DEPTHS_M["tiny"]
    for matcher in MATCHERS:
        for depth in depths:
            naive = rows[(matcher, "naive view", depth)]
            assert naive["status"] == "ok"
            assert naive["error"] == ""
            assert naive["boards"] >= 10  # the rig was calibrated on the method's own images
            assert naive["completeness"] > 0.3
            assert math.isfinite(naive["truth_error_mm"])
    # Refraction ignored: the naive images miss the plane by more than the synthesis does, far away.
    far = depths[-1]
    assert rows[("zncc", "naive view", far)]["truth_error_mm"] > rows[("zncc", "proposed", far)]["truth_error_mm"]
    assert (out / "table.csv").read_text().splitlines()[0].split(",")[-2:] == ["status", "error"]


@pytest.mark.render
def test_a_depth_method_skips_stereo(planes_run):
    """The depth maps are compared with the true plane directly: one row per depth, no matcher."""
    _, result = planes_run
    oracle = [r for r in result.rows if r["method"] == "depth oracle"]
    assert [r["matcher"] for r in oracle] == ["none"] * len(PLANE_DEPTHS_M["tiny"])
    for row in oracle:
        assert row["status"] == "ok"
        assert row["truth_error_mm"] < ORACLE_TRUTH_ERROR_MAX_MM, row
        assert row["outlier_share"] == 0.0
        assert row["completeness"] > 0.9
        assert math.isnan(row["stereo_rms_px"])


@pytest.mark.render
def test_a_failing_method_is_a_row(planes_run):
    out, result = planes_run
    failed = [r for r in result.rows if r["method"] == "broken"]
    assert len(failed) == len(MATCHERS) * len(PLANE_DEPTHS_M["tiny"])
    for row in failed:
        assert row["status"] == "failed"
        assert "RuntimeError: this method is broken on purpose" in row["error"]
        assert math.isnan(row["plane_rmse_mm"])
    on_captures = [r for r in result.rows if r["method"] == "broken on captures"]
    assert len(on_captures) == len(PLANE_DEPTHS_M["tiny"])
    assert all(r["status"] == "failed" and "depth map must have shape" in r["error"] for r in on_captures)
    # The other methods ran, and the table says which failed.
    assert all(r["status"] == "ok" for r in result.rows if r["method"] == "proposed")
    assert "broken: RuntimeError" in result.summary
    assert "broken on purpose" in (out / "table.md").read_text()


@pytest.mark.render
def test_a_depth_method_in_objects(tmp_path):
    """``objects`` scores a depth method's maps against the ground truth directly: the rendered depth
    itself scores (close to) zero on every object pixel."""
    register_method("depth oracle", depth_oracle)
    try:
        result = run_experiment("objects", out=tmp_path / "objects", methods=("depth oracle",), progress=False)
    finally:
        unregister_method("depth oracle")
    (row,) = result.rows
    assert (row["matcher"], row["method"], row["status"]) == ("none", "depth oracle", "ok")
    assert row["median_abs_mm"] < ORACLE_TRUTH_ERROR_MAX_MM
    assert row["exact_median_abs_mm"] < ORACLE_TRUTH_ERROR_MAX_MM
    assert row["completeness"] > 0.99
    assert row["bad_0.5px"] < 0.01
