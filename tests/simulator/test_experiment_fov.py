"""Experiment ``fov`` (paper section 6): exact share and perfect field of view, tiny scale."""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import math

import numpy as np
import pytest

from lfrefract import FlatPort, ParameterError, camera_preset, virtual_camera_for
from lfrefract.formats.outputs import MANIFEST_NAME
from lfrefract.synthesis.warp_map import SynthesisOptions, build_warp_map
from simulator.experiments import run_experiment
from simulator.experiments.fov import (
    REFERENCE_AXIAL_DISTANCE_M,
    REFERENCE_NORMAL,
    _rows_for,
    exact_mask,
    fov_measures,
    original_fov,
    reference_port,
    required_aperture_radius,
    setup_for,
)
from tests.tolerances import (
    FLOAT64_ANGLE_DEG,
    FOV_CENTRED_CONE_PX,
    FOV_EQUIV_CONE_PX,
    FOV_MASK_MISMATCH_MAX_PX,
    FOV_RUN_PX,
    FOV_SEEN_SHARE_RENDERED,
    FOV_SEEN_SHARE_SAMPLING,
    FOV_SHARE_RISE_MAX,
)

FIGURES = ("fov_exact_share.png", "fov_perfect_fov.png", "fov_masks.png")


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("experiment") / "fov"
    result = run_experiment("fov", out=out, scale="tiny", progress=False)
    with open(out / "table.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    return out, result, rows


def _series(rows, series):
    return [r for r in rows if r["series"] == series]


def test_files_and_table(tiny_run):
    out, result, rows = tiny_run
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [MANIFEST_NAME, "meta.json", "table.csv", "table.md", *FIGURES]
    )
    assert [p.name for p in result.figures] == list(FIGURES)
    for name in FIGURES:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    meta = json.loads((out / "meta.json").read_text())
    assert meta["kind"] == "lfsim.experiment"
    assert (meta["experiment"], meta["scale"]) == ("fov", "tiny")
    assert meta["parameters"]["camera"]["name"] == "tiny"
    assert len(rows) == len(result.rows)
    tilts = {float(r["tilt_deg"]) for r in _series(rows, "tilt")}
    f_numbers = {float(r["f_number"]) for r in _series(rows, "tilt")}
    assert min(tilts) == 0.0
    assert max(tilts) >= 30.0
    assert min(f_numbers) == camera_preset("tiny").f_number
    assert len(f_numbers) >= 3
    assert len(_series(rows, "tilt")) == len(tilts) * len(f_numbers)
    assert "exact" in result.summary


def test_exact_share_against_tilt(tiny_run):
    """The exact region is the cone of lines of sight about the port normal: tilt moves it out of the
    image. Its pixel share may rise a little while it is still inside (a cone off axis covers more
    pixels of a pinhole image), never by more than FOV_SHARE_RISE_MAX, and at the preset f-number,
    whose region fills the image's water field, it falls at every step until it is gone."""
    _, _, rows = tiny_run
    tilt_rows = _series(rows, "tilt")
    for n in sorted({float(r["f_number"]) for r in tilt_rows}):
        share = [float(r["exact_share"]) for r in tilt_rows if float(r["f_number"]) == n]
        for i in range(len(share) - 1):
            assert max(share[i + 1 :]) <= share[i] + FOV_SHARE_RISE_MAX
        assert share[0] > 0.0
        assert share[-1] == 0.0  # 40 deg: the cone has left the image
    preset = [float(r["exact_share"]) for r in tilt_rows if float(r["f_number"]) == camera_preset("tiny").f_number]
    positive = [s for s in preset if s > 0]
    assert all(b < a for a, b in itertools.pairwise(positive))
    assert len(positive) >= 10


def test_exact_share_against_f_number(tiny_run):
    """A larger f-number is a smaller usable aperture: the pixels exact at it are a subset of those
    exact at a smaller one (same necessary rays, smaller disc), so share and perfect FOV never grow."""
    _, _, rows = tiny_run
    tilt_rows = _series(rows, "tilt")
    for tilt in sorted({float(r["tilt_deg"]) for r in tilt_rows}):
        sel = sorted((r for r in tilt_rows if float(r["tilt_deg"]) == tilt), key=lambda r: float(r["f_number"]))
        for key in ("exact_share", "perfect_fov_h_deg", "perfect_fov_v_deg", "perfect_fov_equiv_deg"):
            values = [float(r[key]) for r in sel]
            assert all(b <= a for a, b in itertools.pairwise(values)), (tilt, key, values)
        radii = [float(r["usable_aperture_radius_mm"]) for r in sel]
        assert all(b < a for a, b in itertools.pairwise(radii))
    untilted = sorted((r for r in tilt_rows if float(r["tilt_deg"]) == 0.0), key=lambda r: float(r["f_number"]))
    untilted = [float(r["exact_share"]) for r in untilted]
    assert all(b < a for a, b in itertools.pairwise(untilted))


@pytest.mark.parametrize(
    ("tilt_x_deg", "tilt_y_deg", "f_number"),
    [(0.0, 0.0, None), (15.0, 0.0, None), (30.0, 0.0, None), (15.0, 0.0, 4.0), (10.0, -20.0, 2.8)],
)
def test_mask_agrees_with_warp_map(tilt_x_deg, tilt_y_deg, f_number):
    camera = camera_preset("tiny")
    if f_number is not None:
        camera = dataclasses.replace(camera, f_number=f_number)
    port = FlatPort.from_degrees(distance_m=0.012, thickness_m=0.004, tilt_x_deg=tilt_x_deg, tilt_y_deg=tilt_y_deg)
    expected = build_warp_map(camera, port).exact
    mask = exact_mask(camera, port)
    assert mask.shape == expected.shape
    assert 0 < expected.sum() < expected.size  # a boundary to agree on
    assert np.count_nonzero(mask != expected) <= FOV_MASK_MISMATCH_MAX_PX


def test_measures_of_a_known_cone():
    """Masks of the pixels whose line of sight lies within a cone of known apex angle."""
    output = virtual_camera_for(camera_preset("tiny"))
    px_deg = math.degrees(1.0 / output.focal_px)  # one pixel at the principal point
    vv, uu = np.mgrid[0 : output.height_px, 0 : output.width_px]
    rays = np.stack(
        [(uu - output.cx_px) / output.focal_px, (vv - output.cy_px) / output.focal_px, np.ones(uu.shape)], -1
    )
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    for half_deg, off_axis_deg in [(5.0, 0.0), (8.0, 0.0), (12.0, 0.0), (6.0, 8.0)]:
        axis = np.array([math.tan(math.radians(off_axis_deg)), 0.0, 1.0])
        mask = np.degrees(np.arccos(np.clip(rays @ (axis / np.linalg.norm(axis)), -1, 1))) <= half_deg
        m = fov_measures(mask, output)
        full = 2 * half_deg
        assert m["perfect_fov_h_deg"] == pytest.approx(full, abs=FOV_RUN_PX * px_deg)
        assert m["perfect_fov_v_deg"] == pytest.approx(full, abs=FOV_RUN_PX * px_deg)
        assert m["perfect_fov_equiv_deg"] == pytest.approx(full, abs=FOV_EQUIV_CONE_PX * px_deg)
        if off_axis_deg == 0.0:
            assert full - FOV_CENTRED_CONE_PX * px_deg <= m["perfect_cone_centred_deg"] <= full
        else:
            assert m["perfect_cone_centred_deg"] == 0.0  # the principal point is outside the cone
    assert fov_measures(np.zeros(mask.shape, bool), output)["perfect_fov_h_deg"] == 0.0


def test_original_fov():
    """In air the image's edges; in the water, through an untilted port, Snell's law (parallel faces:
    the glass does not change the final angle)."""
    output = virtual_camera_for(camera_preset("tiny"))
    fov = original_fov(output, FlatPort.from_degrees(distance_m=0.01, thickness_m=0.003, n_water=1.333))
    half_h = math.atan(output.width_px / 2 / output.focal_px)
    half_v = math.atan(output.height_px / 2 / output.focal_px)
    assert fov["original_fov_h_deg"] == pytest.approx(2 * math.degrees(half_h), abs=FLOAT64_ANGLE_DEG)
    assert fov["original_fov_v_deg"] == pytest.approx(2 * math.degrees(half_v), abs=FLOAT64_ANGLE_DEG)
    for key, half in (("original_fov_water_h_deg", half_h), ("original_fov_water_v_deg", half_v)):
        assert fov[key] == pytest.approx(2 * math.degrees(math.asin(math.sin(half) / 1.333)), abs=FLOAT64_ANGLE_DEG)
    assert fov["original_fov_equiv_deg"] < fov["original_fov_h_deg"]


def test_unknown_scale(tmp_path):
    with pytest.raises(ParameterError, match="scale"):
        run_experiment("fov", out=tmp_path / "fov", scale="huge", progress=False)
    assert not (tmp_path / "fov").exists()


# The paper's reference port and its perfect field of view (docs/experiments.md, fov).
#: Perpendicular distance of the reference port, metres: 59.2 mm along the axis times the unit
#: normal's z, 1 / |(-0.0085, -0.5004, 1)| = 0.894258.
REFERENCE_PERPENDICULAR_M = 0.0592 / math.sqrt(0.0085**2 + 0.5004**2 + 1.0)
#: The perfect horizontal field (degrees) of an untilted port at the reference distance, no glass,
#: Illum at f/2, and the band the numbers must stay in: one Illum output pixel is 0.056 deg at the
#: centre, and a change of model (rim margin, sub-pixel sampling) moves the figure by several.
ILLUM_PERFECT_FOV_DEG = {"usable": 14.15, "doubled": 26.36}
ILLUM_PERFECT_FOV_BAND_DEG = 0.3


def test_reference_port_is_the_authors():
    """59.2 mm along the optical axis with normal (-0.0085, -0.5004, 1): 52.94 mm perpendicular,
    normal turned up (-y), a single interface."""
    port = reference_port()
    normal = np.array(REFERENCE_NORMAL) / np.linalg.norm(REFERENCE_NORMAL)
    np.testing.assert_allclose(port.normal, normal, atol=1e-12)
    assert port.normal[1] < 0  # up: OpenCV's +y is down
    assert port.distance_m == pytest.approx(REFERENCE_PERPENDICULAR_M, rel=1e-12)
    assert port.distance_m == pytest.approx(0.0529, abs=5e-5)  # the 52.9 mm of the authors' code
    assert port.distance_m / port.normal[2] == pytest.approx(REFERENCE_AXIAL_DISTANCE_M, rel=1e-12)
    assert port.thickness_m == 0.0
    assert math.degrees(port.total_tilt_rad) == pytest.approx(26.58, abs=0.01)
    assert setup_for("illum").reference_port == port


def test_illum_scale_sweeps_about_the_reference_port():
    """The illum grid: an untilted port at the reference port's perpendicular distance, no glass,
    and the reference port itself turned up (until this was fixed: 59.2 mm perpendicular, 5 mm of
    glass and the normal turned down)."""
    setup = setup_for("illum")
    normal = np.array([-0.0085, -0.5004, 1.0]) / np.linalg.norm([-0.0085, -0.5004, 1.0])
    assert setup.distance_m == pytest.approx(REFERENCE_PERPENDICULAR_M, rel=1e-12)
    assert setup.thickness_m == 0.0
    assert setup.n_water == 1.33
    np.testing.assert_allclose(setup.reference_port.normal, normal, atol=1e-12)
    assert setup.reference_port.distance_m == pytest.approx(REFERENCE_PERPENDICULAR_M, rel=1e-12)
    assert setup.reference_port.thickness_m == 0.0
    assert setup.distance_m in setup.distances_m


def test_illum_perfect_fov_with_the_aperture_and_twice_it():
    """About 14 deg with the Illum's f/2 aperture, about 26 deg with the radius doubled as the
    authors' code has it: the two rows of the distance series at the reference distance."""
    setup = setup_for("illum")
    camera, port = setup.camera, setup.port(0.0)
    output = virtual_camera_for(camera)
    radius = required_aperture_radius(camera, port, output)
    rows, _ = _rows_for("distance", setup, port, radius, output, (2.0,), SynthesisOptions(), "usable")
    doubled, _ = _rows_for("distance", setup, port, radius, output, (2.0,), SynthesisOptions(), "doubled")
    for aperture, row in (("usable", rows[0]), ("doubled", doubled[0])):
        expected = ILLUM_PERFECT_FOV_DEG[aperture]
        assert row["perfect_fov_h_deg"] == pytest.approx(expected, abs=ILLUM_PERFECT_FOV_BAND_DEG), aperture
        assert row["perfect_fov_v_deg"] == pytest.approx(expected, abs=ILLUM_PERFECT_FOV_BAND_DEG), aperture
    assert doubled[0]["usable_aperture_radius_mm"] == pytest.approx(2 * rows[0]["usable_aperture_radius_mm"])


def test_doubled_aperture_rows(tiny_run):
    """Every distance has a row per aperture; twice the radius never sees fewer exact pixels."""
    _, _, rows = tiny_run
    distance = _series(rows, "distance")
    by = {(float(r["distance_mm"]), r["aperture"]): r for r in distance}
    assert {a for _, a in by} == {"usable", "doubled"}
    assert len(by) == len(distance)
    for (mm, aperture), row in by.items():
        if aperture == "doubled":
            usable = by[(mm, "usable")]
            assert float(row["exact_share"]) >= float(usable["exact_share"])
            assert float(row["perfect_fov_h_deg"]) >= float(usable["perfect_fov_h_deg"])
    assert {r["aperture"] for r in _series(rows, "tilt")} == {"usable"}


def test_options_change_the_grid(tmp_path):
    result = run_experiment(
        "fov",
        out=tmp_path / "fov",
        camera="tiny",
        port_distance_m=0.02,
        thickness_m=0.0,
        tilts_deg=(12.0, 0.0),
        f_numbers=(4.0, 2.2),
        progress=False,
    )
    tilt = [r for r in result.rows if r["series"] == "tilt"]
    assert [(r["tilt_deg"], r["f_number"]) for r in tilt] == [(0.0, 2.2), (0.0, 4.0), (12.0, 2.2), (12.0, 4.0)]
    assert {r["distance_mm"] for r in tilt} == {20.0}
    assert 20.0 in {r["distance_mm"] for r in result.rows if r["series"] == "distance"}
    assert "tiny camera, port 20 mm away (perpendicular), no glass" in result.summary


def test_a_negative_tilt_keeps_its_sign(tmp_path):
    """A port turned down by 10 deg is the mirror image of one turned up by 10 deg (the tiny camera
    is symmetric about its horizontal axis): the rows keep the sweep's sign and mirror each other."""
    result = run_experiment("fov", out=tmp_path / "fov", tilts_deg=(-10.0, 10.0), f_numbers=(2.2,), progress=False)
    by_tilt = {r["tilt_deg"]: r for r in result.rows if r["series"] == "tilt"}
    assert sorted(by_tilt) == [-10.0, 10.0]
    down, up = by_tilt[-10.0], by_tilt[10.0]
    assert 0 < down["exact_share"] < 1
    for key in ("exact_share", "perfect_fov_h_deg", "perfect_fov_v_deg", "perfect_fov_equiv_deg"):
        assert down[key] == pytest.approx(up[key], abs=1e-9), key


@pytest.mark.parametrize("tilt_x_deg", [0.0, 10.0, 20.0])
def test_a_real_lens_records_no_necessary_ray_the_thin_lens_misses(tilt_x_deg):
    """The double Gauss has the thin lens's focal length and entrance pupil diameter; its other
    apertures only vignette, so its exact region lies inside the thin lens's full-aperture one, is
    mirror-symmetric for a port tilted about x, and moves up with the tilt as the thin lens's does."""
    from lfrefract.optics.real_lens import RealLensCamera
    from simulator.experiments.fov import real_lens_exact_mask

    setup = setup_for("tiny")
    camera, port = setup.camera, setup.port(tilt_x_deg)
    output = virtual_camera_for(camera)
    thin = required_aperture_radius(camera, port, output) <= camera.aperture_radius_m
    real = real_lens_exact_mask(RealLensCamera.from_preset(camera, "double-gauss"), port, output)
    assert real.shape == thin.shape
    assert not np.any(real & ~thin)
    assert 0.5 * thin.mean() < real.mean() < thin.mean()
    assert np.array_equal(real, real[:, ::-1])
    rows, rows_thin = np.nonzero(real)[0], np.nonzero(thin)[0]
    assert abs(rows.mean() - rows_thin.mean()) < 3.0  # pixels


def test_given_depth_share_holds_the_exact_pixels(tiny_run):
    _, _, rows = tiny_run
    usable = [r for r in rows if r["aperture"] == "usable"]
    assert usable
    for row in usable:
        # Exact pixels are recorded at every depth; every share is of the same image.
        assert float(row["exact_share"]) <= float(row["given_depth_share"]) + FOV_SEEN_SHARE_SAMPLING
    tilted = [r for r in usable if r["series"] == "tilt" and float(r["tilt_deg"]) >= 30]
    # Where the exact cone has left the image, the recorded field has not.
    assert all(float(r["exact_share"]) < 0.03 < 0.3 < float(r["given_depth_share"]) for r in tilted)
    doubled = [r for r in rows if r["aperture"] == "doubled"]
    assert all(math.isnan(float(r["given_depth_share"])) for r in doubled)


@pytest.mark.parametrize("tilt_x_deg", [0.0, 30.0])
def test_given_depth_share_is_what_the_depth_aware_synthesis_renders(tilt_x_deg):
    """On a closed-form plane at GIVEN_DEPTH_M the depth-aware synthesis fills the pixels counted as recorded."""
    from lfrefract.synthesis.depth_aware import FILLED_EXACT_GIVEN_DEPTH, DepthAwareOptions, DepthAwareSynthesis
    from simulator.experiments.fov import GIVEN_DEPTH_M, seen_share
    from tests.lfrefract.test_depth_aware import crossing, raw_of

    setup = setup_for("tiny")
    port = setup.port(tilt_x_deg)
    # Every pixel its rays render, whatever the depth's confidence: the geometric question.
    synthesis = DepthAwareSynthesis.build(setup.camera, port, options=DepthAwareOptions(min_confidence=0.0))
    x = crossing(synthesis.rays, GIVEN_DEPTH_M)
    texture = 0.5 + 0.4 * np.sin(2 * np.pi * x[:, 0] / 0.05) * np.cos(2 * np.pi * x[:, 1] / 0.07)
    result = synthesis.apply(raw_of(synthesis.rays, texture))
    rendered = float(np.mean(np.isin(result.classes, (FILLED_EXACT_GIVEN_DEPTH, 2))))
    share = seen_share(setup.camera, port, synthesis.output)
    assert share == pytest.approx(rendered, abs=FOV_SEEN_SHARE_RENDERED)
