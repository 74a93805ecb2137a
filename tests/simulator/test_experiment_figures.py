"""The figures of the experiments and of the demo follow the project's figure rule (tests/figure_rules.py):
each image has a colour bar naming its quantity and unit, the axes are labelled, the set-up (camera,
wall or port, depth) is in the title, and pixels with no value are drawn grey (NaN was white) with a
legend entry saying what grey means. Built on small synthetic inputs: no render."""

from __future__ import annotations

import matplotlib.image
import numpy as np
import pytest

from lfrefract import virtual_camera_for
from lfrefract.figures import NO_VALUE_RGB, save_figure
from simulator.experiments import averaging, fov, pipeline
from simulator.experiments.objects import BACKDROP_RGB, objects_error_figure
from simulator.experiments.planes import disparity_figure, errors_figure, plane_figures, setup_for
from simulator.experiments.rigstereo import MATCHERS, experiment_rig, rig_setup
from tests.figure_rules import assert_follows_the_figure_rules, image_pixels_in_png

#: A PNG stores 8-bit colours: a saved grey is within one step of NO_VALUE_RGB.
PNG_STEP = 1.5 / 255

DEPTHS = (0.3, 0.45, 0.6)
METHODS = ["approx near", "proposed", "ideal"]


def _legend_texts(fig) -> list[str]:
    return [t.get_text() for legend in fig.legends for t in legend.get_texts()]


def _colour_bar_labels(fig) -> list[str]:
    return [ax.get_ylabel() for ax in fig.axes if hasattr(ax, "_colorbar")]


@pytest.fixture(scope="module")
def rig_title() -> str:
    return rig_setup(experiment_rig(setup_for("tiny")))


def _disparities() -> dict:
    """Disparity maps (px) of every matcher, method and depth, NaN (no match) in the top eighth."""
    rng = np.random.default_rng(0)
    maps = {}
    for matcher in MATCHERS:
        for method in METHODS:
            for depth in DEPTHS:
                disparity = rng.uniform(10.0, 20.0, (30, 40)) / depth
                disparity[:4] = np.nan
                maps[(matcher, method, depth)] = disparity
    return maps


def _rows(failed: str | None = None) -> list[dict]:
    rows = []
    for matcher in MATCHERS:
        for method in METHODS:
            for depth in DEPTHS:
                if method == failed:
                    rows.append({"matcher": matcher, "method": method, "depth_m": depth, "status": "failed"})
                    continue
                measures = {"plane_rmse_mm": 1.0 + depth, "truth_error_mm": 2.0, "exact_truth_error_mm": 1.5}
                rows.append({"matcher": matcher, "method": method, "depth_m": depth, "status": "ok", **measures})
    return rows


def test_the_rig_set_up_names_the_cameras_their_baseline_and_the_wall(rig_title):
    assert rig_title.startswith("experiment-default: two tiny-2x cameras 60 mm apart")
    assert "wall tilted 20 deg (4 mm glass, 15 mm from the rig's origin, water n = 1.333)" in rig_title


@pytest.mark.parametrize("matcher", MATCHERS)
def test_the_disparity_figures_follow_the_figure_rules(matcher, rig_title):
    fig = disparity_figure(_disparities(), matcher, DEPTHS, METHODS, rows=_rows(), setup=rig_title)
    assert_follows_the_figure_rules(fig)
    labels = _colour_bar_labels(fig)
    assert labels == [f"disparity at {d:g} m (px)" for d in DEPTHS]  # one per depth: each has its range
    assert "no disparity (no match)" in _legend_texts(fig)
    assert rig_title in fig.get_suptitle()
    assert matcher.upper() in fig.get_suptitle()


def test_the_disparity_figures_draw_pixels_with_no_match_grey(tmp_path, rig_title):
    disparities = _disparities()
    paths = plane_figures(tmp_path, _rows(), disparities, DEPTHS, METHODS, setup=rig_title)
    assert [p.name for p in paths] == ["planes_disparity_zncc.png", "planes_disparity_sgbm.png", "planes_errors.png"]
    png = matplotlib.image.imread(paths[0])
    fig = disparity_figure(disparities, "zncc", DEPTHS, METHODS, rows=_rows(), setup=rig_title)
    panels = [(fig.axes[4 * i], ("zncc", METHODS[i], d)) for i, d in enumerate(DEPTHS)]  # the diagonal
    for ax, key in panels:
        disparity = disparities[key]
        shown = image_pixels_in_png(fig, ax, png, disparity.shape)
        none = ~np.isfinite(disparity).ravel()
        assert np.abs(shown[none] - NO_VALUE_RGB).max() <= PNG_STEP, key
        assert np.abs(shown[~none] - NO_VALUE_RGB).max(axis=1).min() > PNG_STEP, key  # the rest in colour


def test_a_failed_method_is_said_in_the_disparity_figure(rig_title):
    disparities = {k: v for k, v in _disparities().items() if not (k[1] == "proposed" and k[2] == 0.45)}
    rows = [r for r in _rows() if not (r["method"] == "proposed" and r["depth_m"] == 0.45)]
    rows += [{"matcher": m, "method": "proposed", "depth_m": 0.45, "status": "failed"} for m in MATCHERS]
    fig = disparity_figure(disparities, "zncc", DEPTHS, METHODS, rows=rows, setup=rig_title)
    assert_follows_the_figure_rules(fig)
    panel = fig.axes[3 + 1]  # second row (0.45 m), second column (proposed)
    assert [t.get_text() for t in panel.texts] == ["proposed, 0.45 m:\nfailed"]
    assert not panel.images


def test_the_errors_figure_follows_the_figure_rules_and_names_a_method_with_no_value(rig_title):
    fig = errors_figure(_rows(failed="approx near"), DEPTHS, METHODS, setup=rig_title)
    assert_follows_the_figure_rules(fig)
    assert rig_title in fig.get_suptitle()
    texts = _legend_texts(fig)
    assert "approx near (no value at 0.3, 0.45, 0.6 m)" in texts
    assert {"proposed", "ideal"} <= set(texts)
    plots = [ax for ax in fig.axes if not hasattr(ax, "_colorbar")]
    assert all(ax.get_ylabel() == "error (mm)" and ax.get_xlabel() == "plane depth (m)" for ax in plots)


# ----------------------------------------------------------------------------------------- objects
def _object_errors() -> tuple[dict, np.ndarray]:
    """Depth error maps (m) of every matcher and method, and the objects' pixels (the rest is backdrop):
    the objects fill the middle columns; the top five of their rows have no estimate."""
    mask = np.zeros((30, 40), dtype=bool)
    mask[:, 10:30] = True
    rng = np.random.default_rng(1)
    errors = {}
    for matcher in MATCHERS:
        for method in METHODS:
            error = np.where(mask, rng.uniform(0.0, 0.01, mask.shape), np.nan)
            error[:5] = np.nan
            errors[(matcher, method)] = error
    return errors, mask


def test_the_objects_error_figure_follows_the_figure_rules(rig_title):
    errors, mask = _object_errors()
    fig = objects_error_figure(errors, METHODS, mask=mask, setup=rig_title)
    assert_follows_the_figure_rules(fig)
    assert _colour_bar_labels(fig) == ["|depth error| (mm)"]
    assert {"no estimate", "backdrop (not scored)"} <= set(_legend_texts(fig))
    assert rig_title in fig.get_suptitle()


def test_the_objects_error_figure_draws_pixels_with_no_estimate_grey(tmp_path, rig_title):
    errors, mask = _object_errors()
    fig = objects_error_figure(errors, METHODS, mask=mask, setup=rig_title)
    save_figure(fig, tmp_path / "objects.png")
    png = matplotlib.image.imread(tmp_path / "objects.png")
    error = errors[("zncc", METHODS[0])]
    shown = image_pixels_in_png(fig, fig.axes[0], png, error.shape)
    none = (mask & ~np.isfinite(error)).ravel()
    backdrop = ~mask.ravel()
    assert np.abs(shown[none] - NO_VALUE_RGB).max() <= PNG_STEP
    assert np.abs(shown[backdrop] - BACKDROP_RGB).max() <= PNG_STEP  # not the grey of no estimate
    assert np.abs(shown[~none & ~backdrop] - NO_VALUE_RGB).max(axis=1).min() > PNG_STEP


def test_a_failed_method_is_said_in_the_objects_error_figure(rig_title):
    errors, mask = _object_errors()
    errors = {k: v for k, v in errors.items() if k[1] != "proposed"}
    fig = objects_error_figure(errors, METHODS, mask=mask, setup=rig_title)
    assert_follows_the_figure_rules(fig)
    panels = [ax for ax in fig.axes if not hasattr(ax, "_colorbar") and not ax.images]
    assert len(panels) == len(MATCHERS)
    said = [[t.get_text() for t in ax.texts] for ax in panels]
    assert said == [[f"proposed, {m.upper()}:\nno depth map (failed)"] for m in MATCHERS]


# --------------------------------------------------------------------------------------------- fov
def _fov_inputs(scale: str = "tiny"):
    """A set-up, rows of every series (invented measures of the right shape), the masks of the drawn
    tilts (and of the reference port at ``illum``) and the output camera: what the fov figures draw."""
    setup = fov.setup_for(scale)
    output = virtual_camera_for(setup.camera)
    rows = []
    original = {"original_fov_h_deg": 56.0, "original_fov_v_deg": 41.0, "original_fov_water_h_deg": 42.0}
    for tilt in setup.tilts_deg:
        for i, n in enumerate(setup.f_numbers):
            share = max(0.9 - tilt / 50.0, 0.0) * (1.0 - 0.1 * i)
            fov_deg = {"perfect_fov_h_deg": 40.0 * share, "perfect_fov_v_deg": 30.0 * share}
            rows.append({"series": "tilt", "tilt_deg": tilt, "f_number": n, "aperture": "usable"} | original)
            rows[-1] |= {"exact_share": share, "given_depth_share": min(1.0, share + 0.1), **fov_deg}
    for aperture in fov.APERTURES:
        for d in setup.distances_m:
            fov_deg = {"perfect_fov_h_deg": 30.0 - 200.0 * d, "perfect_fov_v_deg": 25.0 - 200.0 * d}
            rows.append({"series": "distance", "tilt_deg": 0.0, "distance_mm": d * 1e3, "aperture": aperture})
            rows[-1] |= {"f_number": setup.f_numbers[0], "usable_aperture_radius_mm": 1.2, **fov_deg, **original}
    if setup.reference_port is not None:
        fov_deg = {"perfect_fov_h_deg": 26.0, "perfect_fov_v_deg": 20.0}
        rows += [{"series": "reference", "tilt_deg": 26.6, "f_number": n, **fov_deg} for n in setup.f_numbers]
    v, u = np.mgrid[0 : output.height_px, 0 : output.width_px]
    radius = np.hypot(u - output.cx_px, v - output.cy_px) / output.width_px
    masks = {
        t: {n: radius < 0.5 / (1 + i + t / 10) for i, n in enumerate(setup.f_numbers)} for t in setup.mask_tilts_deg
    }
    reference = None if setup.reference_port is None else masks[setup.mask_tilts_deg[-1]]
    return setup, rows, masks, reference, output


@pytest.mark.parametrize("scale", ["tiny", "illum"])
def test_the_fov_figures_follow_the_figure_rules(scale):
    setup, rows, masks, reference, output = _fov_inputs(scale)
    water = f"water n = {setup.n_water:.4g}"
    for fig in (
        fov.exact_share_figure(setup, rows),
        fov.perfect_fov_figure(setup, rows),
        fov.masks_figure(setup, masks, reference, output),
    ):
        assert_follows_the_figure_rules(fig)
        title = fig.get_suptitle()
        assert setup.camera.name in title, title
        assert water in title, title
    bar = _colour_bar_labels(fov.masks_figure(setup, masks, reference, output))
    assert bar == ["largest main-lens f-number at which the pixel is exact"]


# --------------------------------------------------------------------------------------- averaging
AVERAGING_SETUP = "default scene, tiny camera behind a port tilted 20 deg, 16 spp (ideal 2048 spp)"


def _averaging_inputs():
    """Each shown k's image and filled mask, the ideal image, the exact coverage, the rows and the
    data range: a 40 x 60 px output, exact in its middle, with no captured ray in its left fifth."""
    rng = np.random.default_rng(2)
    ideal = rng.uniform(0.2, 1.0, (40, 60, 3))
    exact = np.zeros((40, 60), dtype=bool)
    exact[8:32, 10:50] = True
    filled = np.ones((40, 60), dtype=bool)
    filled[:, :12] = False
    images = {
        k: np.where(filled[..., None], ideal + rng.normal(0.0, 0.05 / k, ideal.shape), np.nan) for k in (1, 8, 64)
    }
    keys = ("psnr_db", "ssim", "sharpness_ratio", "noise_rel", "psnr_noise_free_db")
    rows = [
        {"k": k, **dict(zip(keys, (30.0 + k / 8, 0.9, 1.0 - k / 100, 0.05 / k, 35.0), strict=True))}
        for k in averaging.K_VALUES
    ]
    return {k: (image, filled) for k, image in images.items()}, ideal, exact, rows, float(np.percentile(ideal, 99.5))


def test_the_averaging_crops_follow_the_figure_rules(tmp_path):
    images, ideal, exact, rows, peak = _averaging_inputs()
    fig, crop = averaging.crops_figure(images, ideal, exact, rows, peak, setup=AVERAGING_SETUP)
    assert_follows_the_figure_rules(fig)
    assert AVERAGING_SETUP in fig.get_suptitle()
    assert _colour_bar_labels(fig) == ["radiance per channel (the render's units)"]
    assert {"no captured ray", "edge of the exact coverage"} <= set(_legend_texts(fig))
    save_figure(fig, tmp_path / "crops.png")
    png = matplotlib.image.imread(tmp_path / "crops.png")
    filled = images[1][1][crop]
    box = fig.axes[0].get_window_extent(fig.canvas.get_renderer())  # laid out as saved
    (x0, x1), (y1, y0) = fig.axes[0].get_xlim(), fig.axes[0].get_ylim()  # the output image's pixels
    v, u = np.mgrid[crop]
    cols = (box.x0 + (u - x0) / (x1 - x0) * box.width).astype(int)
    rows = (png.shape[0] - (box.y1 - (v - y0) / (y1 - y0) * box.height)).astype(int)
    shown = png[rows, cols, :3]
    assert (~filled).sum() > 0
    assert np.abs(shown[~filled] - NO_VALUE_RGB).max() <= PNG_STEP  # grey where no ray was captured
    assert np.abs(shown[filled] - NO_VALUE_RGB).max(axis=1).min() > 0  # the rest is the image


def test_the_averaging_curves_follow_the_figure_rules():
    _, _, _, rows, _ = _averaging_inputs()
    fig = averaging.curves_figure(rows, setup=AVERAGING_SETUP)
    assert_follows_the_figure_rules(fig)
    assert AVERAGING_SETUP in fig.get_suptitle()
    plots = [ax for ax in fig.axes if ax.lines]
    assert all(ax.get_legend() is not None for ax in plots)  # every line is named


# ---------------------------------------------------------------------------------------- pipeline
def test_the_pipeline_summary_follows_the_figure_rules_and_marks_a_missing_value():
    measures = ("corner_rms_px", "plane_rmse_mm", "truth_error_mm", "port_normal_err_deg")
    measures += ("port_distance_err_mm", "ray_rms_mm")
    rows = [{"method": m, **dict.fromkeys(measures, 1.0)} for m in pipeline.METHODS]
    rows[-1] = {"method": pipeline.METHODS[-1], **dict.fromkeys(measures, float("nan"))}  # failed
    setup = "pipeline (tiny), double-gauss lens, tiny sensor: " + "experiment-default: two tiny-2x cameras"
    fig = pipeline.summary_figure(rows, setup=setup)
    assert_follows_the_figure_rules(fig)
    assert setup in fig.get_suptitle()
    panels = [ax for ax in fig.axes if ax.patches]
    assert len(panels) == len(measures)
    for ax in panels:
        assert ax.get_ylabel().endswith(")"), ax.get_ylabel()  # the unit
        assert [t.get_text() for t in ax.texts] == ["no value"]  # the failed method's bar
        assert ax.texts[0].get_position()[0] == len(rows) - 1
