"""``lfrefract synth --method depth-aware``: what it writes, that it keeps the warp map's exact pixels,
and what it refuses (depth options without the method, bad values, ``--colour cfa``, files in the way)."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from lfrefract.cli import SYNTH_DEPTH_ROLE, build_parser, main, synth_outputs
from lfrefract.formats.exr import read_exr, write_exr
from lfrefract.formats.jsonio import write_json
from lfrefract.optics.port import FlatPort
from lfrefract.synthesis.depth_aware import FILLED_EXACT_GIVEN_DEPTH, DepthAwareOptions, trace_scene_rays
from lfrefract.synthesis.warp_map import FILLED_APPROXIMATED, FILLED_EMPTY, FILLED_EXACT
from tests.lfrefract.test_cli import PORT, TINY, commands, make_capture, refused
from tests.lfrefract.test_cli_outputs import snapshot
from tests.lfrefract.test_depth_aware import crossing, raw_of, texture

DEPTH_AWARE = ["--method", "depth-aware"]
CLASSES = {
    "empty": FILLED_EMPTY,
    "approximated": FILLED_APPROXIMATED,
    "exact": FILLED_EXACT,
    "exact_given_depth": FILLED_EXACT_GIVEN_DEPTH,
}


def plane_capture_raw() -> np.ndarray:
    """RGB raw of the tiny camera behind PORT looking at a textured plane at 0.5 m (each usable ray
    holds the texture where it crosses the plane; a scene with a depth to find, unlike noise)."""
    rays = trace_scene_rays(TINY, PORT)
    x = crossing(rays, 0.5)
    grey = raw_of(rays, texture(x[:, 0], x[:, 1]))
    return np.stack([grey, 0.8 * grey, 0.6 * grey + 0.1], axis=2).astype(np.float32)


def run(argv: list[str]) -> str:
    """Run the command line, assert it succeeds, return what it printed."""
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(argv) == 0
    return printed.getvalue()


@pytest.fixture(scope="module")
def synthesized(tmp_path_factory) -> dict:
    """One capture of the tiny camera behind the 20 deg port, synthesized by both methods (one map
    cache: the depth-aware run loads the proposed run's map)."""
    root = tmp_path_factory.mktemp("depth-aware")
    raw = make_capture(root / "R", plane_capture_raw())
    cache = ["--map-cache", str(root / "maps")]
    proposed = run([*commands(raw, root / "p")["synth"], *cache])
    depth_aware = run([*commands(raw, root / "d")["synth"], *cache, *DEPTH_AWARE])
    return {"raw": raw, "p": root / "p", "d": root / "d", "printed": {"p": proposed, "d": depth_aware}}


def sidecar(folder: Path) -> dict:
    return json.loads((folder / "s.json").read_text())


def test_depth_aware_writes_every_listed_file(synthesized):
    folder = synthesized["d"]
    expected = synth_outputs(folder / "s.exr", "depth-aware")
    assert sorted(p.name for p in folder.iterdir()) == sorted(p.name for p in expected)
    meta = sidecar(folder)
    assert meta["kind"] == "lfrefract.synth"
    assert meta["method"] == "depth-aware"
    assert meta["files"] == {
        "image": "s.exr",
        "coverage": "s.coverage.exr",
        "filled": "s.filled.exr",
        "depth": "s.depth.exr",
        "confidence": "s.confidence.exr",
        "figure": "s.png",
    }
    shape = (meta["height_px"], meta["width_px"])
    image = read_exr(folder / "s.exr", role="refraction_free")
    depth = read_exr(folder / "s.depth.exr", role=SYNTH_DEPTH_ROLE)
    confidence = read_exr(folder / "s.confidence.exr", role="confidence")
    coverage = read_exr(folder / "s.coverage.exr", role="coverage")
    classes = read_exr(folder / "s.filled.exr", role="filled")
    assert image.shape == (*shape, 3)
    for single in (depth, confidence, coverage, classes):
        assert single.shape == shape
    for array in (image, depth, confidence, coverage, classes):
        assert array.dtype == np.float32
    assert (folder / "s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The four classes, as the sidecar documents them, and each present on this capture.
    assert meta["filled_classes"] == CLASSES
    assert set(np.unique(classes)) == set(CLASSES.values())
    assert meta["depth_options"] == DepthAwareOptions().to_dict()
    assert set(meta["seconds"]) == {"map", "rays", "compile", "apply"}
    stats = meta["coverage"]
    assert stats["exact_fraction"] == np.mean(classes == FILLED_EXACT)
    assert stats["exact_given_depth_fraction"] == np.mean(classes == FILLED_EXACT_GIVEN_DEPTH)
    assert stats["approximated_fraction"] == np.mean(classes == FILLED_APPROXIMATED)
    assert stats["filled_fraction"] == np.mean(classes != FILLED_EMPTY)
    assert stats["mean_coverage"] == pytest.approx(float(coverage.mean()))
    assert stats["nonzeros_per_pixel"] > 0
    # NaN exactly where no value.
    assert np.array_equal(np.isnan(image).any(axis=2), classes == FILLED_EMPTY)
    assert np.array_equal(np.isnan(image).all(axis=2), classes == FILLED_EMPTY)
    printed = synthesized["printed"]["d"]
    assert f"exact given depth {stats['exact_given_depth_fraction']:.1%}" in printed, printed
    assert "depth-aware synthesis in" in printed
    assert "loaded" in printed  # the proposed run's cached map


def test_depth_is_in_the_searched_range_and_confidence_in_0_1(synthesized):
    folder = synthesized["d"]
    depth = read_exr(folder / "s.depth.exr", role=SYNTH_DEPTH_ROLE)
    confidence = read_exr(folder / "s.confidence.exr", role="confidence")
    classes = read_exr(folder / "s.filled.exr", role="filled")
    options = DepthAwareOptions()
    given = classes == FILLED_EXACT_GIVEN_DEPTH
    assert np.isfinite(depth[given]).all()
    found = np.isfinite(depth)
    assert (depth[found] >= np.float32(options.depth_min_m)).all()
    assert (depth[found] <= np.float32(options.depth_max_m)).all()
    assert np.array_equal(np.isfinite(confidence), found)
    assert ((confidence[found] >= 0) & (confidence[found] <= 1)).all()


def test_depth_aware_keeps_the_warp_maps_exact_pixels(synthesized):
    """Inside the exact coverage the composition keeps the warp map's values: bit for bit the proposed image."""
    proposed, depth_aware = synthesized["p"], synthesized["d"]
    exact = read_exr(proposed / "s.filled.exr", role="filled") == FILLED_EXACT
    classes = read_exr(depth_aware / "s.filled.exr", role="filled")
    assert exact.any()
    assert np.array_equal(classes == FILLED_EXACT, exact)
    assert np.array_equal(read_exr(depth_aware / "s.exr")[exact], read_exr(proposed / "s.exr")[exact])
    assert sidecar(depth_aware)["coverage"]["exact_fraction"] == sidecar(proposed)["coverage"]["exact_fraction"]
    assert (proposed / "s.coverage.exr").read_bytes() == (depth_aware / "s.coverage.exr").read_bytes()


def test_the_proposed_method_is_the_default_and_writes_no_depth(synthesized):
    folder = synthesized["p"]
    meta = sidecar(folder)
    assert meta["method"] == "proposed"
    assert "depth_options" not in meta
    assert set(meta["coverage"]) == {"exact_fraction", "filled_fraction", "mean_coverage", "nonzeros_per_pixel"}
    assert sorted(p.name for p in folder.iterdir()) == sorted(p.name for p in synth_outputs(folder / "s.exr"))
    assert not any(p.name.endswith((".depth.exr", ".confidence.exr")) for p in synth_outputs(folder / "s.exr"))
    assert "exact given depth" not in synthesized["printed"]["p"]


def test_depth_options_reach_the_synthesis(tmp_path, synthesized):
    argv = [*commands(synthesized["raw"], tmp_path)["synth"], *DEPTH_AWARE]
    argv += ["--depth-range", "0.2", "1.5", "--depth-steps", "16", "--aggregation-radius", "2", "--occlusion-aware"]
    run(argv)
    expected = DepthAwareOptions(
        depth_min_m=0.2, depth_max_m=1.5, depth_steps=16, aggregation_radius_px=2, occlusion_aware=True
    )
    assert sidecar(tmp_path)["depth_options"] == expected.to_dict()
    depth = read_exr(tmp_path / "s.depth.exr", role=SYNTH_DEPTH_ROLE)
    found = np.isfinite(depth)
    assert found.any()
    assert ((depth[found] >= np.float32(0.2)) & (depth[found] <= np.float32(1.5))).all()


def test_the_parser_takes_its_defaults_from_the_options(capsys):
    args = build_parser().parse_args(["synth", "raw.exr", "--out", "o.exr"])
    assert args.method == "proposed"
    # None: not given (so refused with another method); the defaults are the dataclass's.
    assert (args.depth_range, args.depth_steps, args.aggregation_radius, args.occlusion_aware) == (
        None,
        None,
        None,
        False,
    )
    with pytest.raises(SystemExit):
        main(["synth", "--help"])
    shown = " ".join(capsys.readouterr().out.split())
    defaults = DepthAwareOptions()
    assert f"(default: {defaults.depth_min_m} {defaults.depth_max_m})" in shown
    assert f"uniform in 1/z, at least 3 (default: {defaults.depth_steps})" in shown
    assert f"0 for none (default: {defaults.aggregation_radius_px})" in shown
    assert "(default: None)" not in shown


# =============================================================================== refusals
@pytest.mark.parametrize(
    "option",
    [["--depth-range", "0.2", "2"], ["--depth-steps", "12"], ["--aggregation-radius", "3"], ["--occlusion-aware"]],
    ids=lambda option: option[0],
)
def test_depth_options_without_the_depth_aware_method_are_refused(tmp_path, capsys, option):
    raw = make_capture(tmp_path / "R")
    argv = [*commands(raw, tmp_path / "out")["synth"], *option]
    for method in ([], ["--method", "proposed"]):
        err = refused(capsys, [*argv, *method])
        assert f"{option[0]} applies to --method depth-aware only" in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("option", "says"),
    [
        (["--depth-range", "1.0", "1.0"], "depth_max_m must exceed depth_min_m"),
        (["--depth-range", "2.0", "0.5"], "depth_max_m must exceed depth_min_m"),
        (["--depth-range", "-0.1", "2"], "depth_min_m must be positive"),
        (["--depth-range", "0.1", "inf"], "depth_max_m must be finite"),
        (["--depth-steps", "2"], "depth_steps must be at least 3"),
        (["--aggregation-radius", "-1"], "aggregation_radius_px must be non-negative"),
    ],
    ids=["range-equal", "range-reversed", "range-negative", "range-infinite", "steps", "radius"],
)
def test_bad_depth_options_are_refused_naming_the_option(tmp_path, capsys, option, says):
    raw = make_capture(tmp_path / "R")
    err = refused(capsys, [*commands(raw, tmp_path / "out")["synth"], *DEPTH_AWARE, *option])
    assert err.startswith(f"lfrefract: error: {option[0]}: "), err
    assert says in err, err
    assert not (tmp_path / "out").exists()


def test_depth_aware_refuses_colour_by_cfa_on_a_lytro_capture_and_takes_the_demosaiced_image(tmp_path, capsys):
    from lfrefract.formats.lytro import write_lfr
    from tests.lfrefract.test_lytro import full_scale_mosaic

    lfr = write_lfr(tmp_path / "c.lfr", full_scale_mosaic((360, 480), 10, 64, "GRBG", seed=7), TINY)
    port = write_json(tmp_path / "port.json", {"port": PORT.to_dict()})
    argv = ["synth", str(lfr), "--port", str(port), "--out", str(tmp_path / "out" / "s.exr"), "--quiet", *DEPTH_AWARE]
    err = refused(capsys, [*argv, "--colour", "cfa"])
    assert "--colour cfa does not apply to --method depth-aware" in err, err
    assert "use --colour demosaic" in err
    assert not (tmp_path / "out").exists()
    # The demosaiced image (the default): its saturated pixels are unrecorded, and used by neither
    # the depth search nor the render (their NaN would be refused).
    run([*argv, "--colour", "demosaic"])
    meta = sidecar(tmp_path / "out")
    assert (meta["method"], meta["colour"]) == ("depth-aware", "demosaic")
    assert meta["unrecorded_raw"]["pixels"] > 0
    classes = read_exr(tmp_path / "out" / "s.filled.exr", role="filled")
    image = read_exr(tmp_path / "out" / "s.exr")
    assert np.array_equal(np.isnan(image).any(axis=2), classes == FILLED_EMPTY)


def test_depth_aware_gives_masked_raw_pixels_no_weight(tmp_path, capsys):
    holed = plane_capture_raw()
    holes = np.random.default_rng(1).random(holed.shape[:2]) < 0.03
    holed[holes, 0] = np.nan
    n_nan = int(holes.sum())
    raw = make_capture(tmp_path / "R", raw=holed)
    argv = [*commands(raw, tmp_path / "out")["synth"], *DEPTH_AWARE]
    assert "pass --nonfinite mask" in refused(capsys, argv)
    printed = run([*argv, "--nonfinite", "mask"])
    assert f"masked {n_nan} NaN pixel values" in printed, printed
    meta = sidecar(tmp_path / "out")
    assert meta["unrecorded_raw"]["nan"] == n_nan
    assert meta["coverage"]["exact_given_depth_fraction"] > 0
    image = read_exr(tmp_path / "out" / "s.exr")
    classes = read_exr(tmp_path / "out" / "s.filled.exr", role="filled")
    assert np.array_equal(np.isnan(image).any(axis=2), classes == FILLED_EMPTY)


def test_depth_aware_takes_a_camera_calibrations_ray_model(tmp_path):
    """A camera calibration's ray model (here a radial one that scales the pupil by 1.1) is the model of
    both the warp map and the depth-aware rays (it was refused before, the rays being the thin lens's)."""
    from lfrefract.optics.ray_correction import RayCorrection

    raw = make_capture(tmp_path / "R")
    correction = RayCorrection(pupil_scale=1.1)
    calibration = write_json(
        tmp_path / "camera.json",
        {"kind": "lfrefract.calibrate.camera", "camera": TINY.to_dict(), "correction": correction.to_dict()},
    )
    run([*commands(raw, tmp_path / "out")["synth"], "--camera", str(calibration), *DEPTH_AWARE, "--quiet"])
    meta = sidecar(tmp_path / "out")
    assert meta["method"] == "depth-aware"
    assert meta["options"]["ray_correction"] == correction.to_dict()


def test_depth_aware_rays_are_the_calibrated_models():
    """trace_scene_rays with a ray model: each pixel's ray is its thin-lens ray corrected, the same
    pixels kept (their thin-lens aperture point decides); warp_correction reads a map's model back."""
    from lfrefract.optics.camera_model import CameraModel
    from lfrefract.optics.ray_correction import RayCorrection
    from lfrefract.synthesis.depth_aware import trace_scene_rays, warp_correction
    from lfrefract.synthesis.warp_map import SynthesisOptions, build_warp_map

    correction = RayCorrection(pupil_scale=1.1, k1=0.2)
    thin = trace_scene_rays(TINY, None)
    model = trace_scene_rays(CameraModel(camera=TINY, correction=correction), None)
    assert np.array_equal(thin.raw_index, model.raw_index)
    expected = correction.corrected(TINY.captured_rays()).origins_cam[thin.raw_index]
    np.testing.assert_allclose(model.origins_cam, expected.astype(np.float32), rtol=0, atol=1e-9)
    assert not np.allclose(model.origins_cam, thin.origins_cam, rtol=0, atol=1e-6)
    port = FlatPort(distance_m=0.02, thickness_m=0.003, tilt_x_rad=0.2)
    warp = build_warp_map(TINY, port, options=SynthesisOptions(ray_correction=correction))
    assert warp_correction(warp) == correction
    assert warp_correction(build_warp_map(TINY, port)) is None


def test_overwrite_replaces_only_depth_aware_outputs(tmp_path, synthesized, capsys):
    """A depth map of someone else's under OUT.depth.exr (a render's ground truth, role "depth") is
    never replaced; a proposed run does not claim it at all."""
    out = tmp_path / "out"
    argv = [*commands(synthesized["raw"], out)["synth"], "--quiet"]
    truth = write_exr(out / "s.depth.exr", np.ones((4, 4), np.float32), role="depth")
    before = snapshot(out)
    for extra in ([], ["--overwrite"]):
        err = refused(capsys, [*argv, *DEPTH_AWARE, *extra])
        assert str(truth) in err, err
    assert "refusing to replace it" in err
    assert snapshot(out) == before
    run(argv)  # the proposed method writes no depth: the file is not in its way
    assert truth.read_bytes() == before["s.depth.exr"]
    assert "s.depth.exr" not in sidecar(out)["files"].values()
    # A depth-aware output of its own is replaced; the confidence map in the way of another is not.
    truth.unlink()
    run([*argv, *DEPTH_AWARE, "--overwrite"])
    run([*argv, *DEPTH_AWARE, "--overwrite"])
    write_exr(out / "s.confidence.exr", np.zeros((4, 4), np.float32), role="raw")
    foreign = (out / "s.confidence.exr").read_bytes()
    assert "refusing to replace it" in refused(capsys, [*argv, *DEPTH_AWARE, "--overwrite"])
    assert (out / "s.confidence.exr").read_bytes() == foreign


def test_a_depth_range_in_front_of_the_water_is_refused_and_writes_nothing(tmp_path, capsys):
    """``--depth-range 1e-9 1e-8`` gave an all-NaN depth with exit status 0; it is refused, naming the option."""
    raw = make_capture(tmp_path / "R", plane_capture_raw())
    err = refused(capsys, [*commands(raw, tmp_path / "out")["synth"], *DEPTH_AWARE, "--depth-range", "1e-9", "1e-8"])
    assert "depth_min_m=1e-09, depth_max_m=1e-08 (--depth-range) lies in front of the water" in err, err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


# SIGTERM must end a depth-aware synth within this many seconds once the sweep runs: the sweep is split into
# calls of one plane per thread (20 ms a plane on tiny here); the rest is the cleanup and the exit, on a loaded
# 2-core machine. The sweep of this test takes about 20 s whole (1000 planes), which one call held to its end.
SIGTERM_WITHIN_S = 3.0


def test_sigterm_ends_a_depth_aware_synth_during_its_sweep(tmp_path):
    """The depth sweep was one numba call over every plane, so SIGTERM waited for all of it (39 s an Illum
    frame). The subprocess announces the sweep's first call on stderr (the real kernel runs); SIGTERM then ends
    it within SIGTERM_WITHIN_S, exit 143, its outputs removed."""
    import signal
    import subprocess
    import sys
    import time

    raw = make_capture(tmp_path / "R", plane_capture_raw())
    out = tmp_path / "out"
    argv = [*commands(raw, out)["synth"], *DEPTH_AWARE, "--depth-steps", "1000"]
    code = (
        "import sys\n"
        "import lfrefract.synthesis.depth_aware as d\n"
        "kernel = d.sweep_cost\n"
        "def announced(*args):\n"
        "    if not getattr(announced, 'said', False):\n"
        "        announced.said = True\n"
        "        sys.stderr.write('sweeping\\n')\n"
        "        sys.stderr.flush()\n"
        "    return kernel(*args)\n"
        "d.sweep_cost = announced\n"
        "from lfrefract.cli import main\n"
        "sys.exit(main(sys.argv[1:]))\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code, *argv], stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    line = proc.stderr.readline()  # blocks until the sweep starts (or the process ends)
    assert line == "sweeping\n", line + proc.communicate()[1]
    time.sleep(0.5)  # well inside the sweep
    assert proc.poll() is None
    start = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    took = time.monotonic() - start
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert took < SIGTERM_WITHIN_S, f"SIGTERM took {took:.1f} s"
    assert "terminated (signal 15); unfinished outputs removed" in err, err
    assert not out.exists() or list(out.iterdir()) == [], sorted(p.name for p in out.iterdir())
