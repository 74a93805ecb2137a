"""The core's command line: ``lfrefract describe``, and every command on hostile captures (issue 12)."""

from __future__ import annotations

import inspect
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest

from lfrefract import FlatPort, Pose, camera_preset, virtual_camera_for
from lfrefract.cli import main
from lfrefract.formats.exr import read_exr, write_exr
from lfrefract.formats.jsonio import write_json


def test_describe_preset_prints_derived_optics(capsys):
    assert main(["describe", "illum", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    cam = camera_preset("illum")
    assert info["micro_image_pitch_px"] == pytest.approx(20e-6 * (1 + 36e-6 / 9.993e-3) / 1.4e-6)
    assert info["refraction_free_image"]["K"][0][0] == pytest.approx(cam.lens_to_mla_m / 10e-6)
    assert info["lens_count"] > 230_000


def test_describe_meta_json_includes_the_port(tmp_path, capsys):
    port = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.005, tilt_x_deg=20.0)
    meta = tmp_path / "meta.json"
    write_json(meta, {"camera": camera_preset("tiny").to_dict(), "port": port.to_dict()})
    assert main(["describe", str(meta)]) == 0
    out = capsys.readouterr().out
    assert "port:" in out
    assert f"total_tilt_deg: {math.degrees(port.total_tilt_rad):.6g} deg" in out


def test_describe_takes_a_camera_file(tmp_path, capsys):
    """A TOML camera file, as --camera takes it, describes the same camera as its preset."""
    from lfrefract.formats.paramfile import write_camera_file

    write_camera_file(tmp_path / "camera.toml", camera_preset("f01"))
    assert main(["describe", str(tmp_path / "camera.toml"), "--json"]) == 0
    from_file = json.loads(capsys.readouterr().out)
    (tmp_path / "camera.toml").rename(tmp_path / "CAMERA.TOML")  # as --camera takes it: any case
    assert main(["describe", str(tmp_path / "CAMERA.TOML"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == from_file
    assert main(["describe", "f01", "--json"]) == 0
    assert from_file == json.loads(capsys.readouterr().out)
    (tmp_path / "bad.toml").write_text("[camera]\nname = 'x'\n")
    assert main(["describe", str(tmp_path / "bad.toml")]) == 2
    assert "bad.toml" in capsys.readouterr().err


def test_describe_bad_file_is_a_clear_error(tmp_path, capsys):
    assert main(["describe", str(tmp_path / "nope.json")]) == 2
    assert "no such file" in capsys.readouterr().err


# =============================================================================== hostile inputs (issue 12)
# Every test below runs the real command line on real files; a refusal is exit status 2 with a one-line
# message on stderr (an exception escaping main() is a traceback for the user, and fails the test).

TINY = camera_preset("tiny")
PORT = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.005, tilt_x_deg=20.0)
MISSING = object()


def textured_raw(camera=TINY, *, seed=0) -> np.ndarray:
    """A positive RGB raw image of the camera's size, 0.4-0.6."""
    rng = np.random.default_rng(seed)
    return (0.4 + 0.2 * rng.random((camera.sensor.height_px, camera.sensor.width_px, 3))).astype(np.float32)


def make_capture(folder: Path, raw: np.ndarray | None = None, **keys) -> Path:
    """A capture folder as lfsim render writes one: raw.exr and a meta.json with camera, port, ideal
    and pose. ``keys`` replace entries of meta.json; ``MISSING`` drops one. Returns the raw path."""
    meta = {
        "kind": "lfsim.render",
        "camera": TINY.to_dict(),
        "port": PORT.to_dict(),
        "ideal": virtual_camera_for(TINY).to_dict(),
        "pose": Pose().to_dict(),
    }
    for key, value in keys.items():
        if value is MISSING:
            del meta[key]
        else:
            meta[key] = value
    write_exr(folder / "raw.exr", textured_raw() if raw is None else raw, role="raw")
    write_json(folder / "meta.json", meta)
    return folder / "raw.exr"


def refused(capsys, argv: list[str]) -> str:
    """Run the command line, assert it refuses (status 2, nothing on stdout), return its message."""
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith("lfrefract: error: "), captured.err
    assert "Traceback" not in captured.err
    return captured.err


def assert_says(err: str, *parts: str) -> None:
    """Every one of ``parts`` is in the message."""
    for part in parts:
        assert part in err, err


def commands(raw: Path, out: Path) -> dict[str, list[str]]:
    """Every lfrefract command that reads a capture, on ``raw``."""
    board = ["--squares", "5", "4", "--square-size-m", "0.01", "--out", str(out / "c.json")]
    return {
        "synth": ["synth", str(raw), "--out", str(out / "s.exr"), "--quiet"],
        "naive": ["naive", str(raw), "--out", str(out / "n.exr")],
        "views": ["views", str(raw), "--out", str(out / "v"), "--grid", "3"],
        "describe": ["describe", str(raw.parent / "meta.json")],
        "calibrate-mla": ["calibrate", "mla", str(raw), "--out", str(out / "mla.json")],
        "calibrate-port": ["calibrate", "port", str(raw), *board],
        "calibrate-approx": ["calibrate", "approx", str(raw), *board],
    }


COMMANDS = ["synth", "naive", "views", "describe", "calibrate-mla", "calibrate-port", "calibrate-approx"]

# (key, value, what the message must also say): values of the wrong type, and wrong values inside.
BAD_VALUES = [
    ("camera", "tiny", "must be a table"),
    ("camera", 5, "must be a table"),
    ("camera", None, "must be a table"),
    ("camera", {**TINY.to_dict(), "mla": "hex"}, "camera.mla must be a table"),
    ("camera", {**TINY.to_dict(), "sensor": {**TINY.to_dict()["sensor"], "width_px": "480"}}, "sensor.width_px"),
    ("camera", {**TINY.to_dict(), "mla": {**TINY.to_dict()["mla"], "offset_m": 5}}, "mla.offset_m"),
    ("camera", {**TINY.to_dict(), "name": ["tiny"]}, "name must be a string"),
    ("port", "flat", "must be a table"),
    ("port", [0.03], "must be a table"),
    ("port", {**PORT.to_dict(), "distance_m": "far"}, "port.distance_m"),
    ("ideal", "92x69", "must be a table"),
    ("ideal", {**virtual_camera_for(TINY).to_dict(), "K": "eye"}, "K must be a 3 x 3 matrix"),
    ("ideal", {**virtual_camera_for(TINY).to_dict(), "width_px": 92.5}, "width_px"),
    ("ideal", {**virtual_camera_for(TINY).to_dict(), "zoom": 2}, "unknown key"),
    ("pose", "identity", "must be a table"),
    ("pose", {"rotation": 5}, "pose.rotation"),
    ("pose", {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "position_m": 5}, "pose.position_m"),
    ("pose", {"rotation_xyz_deg": "up"}, "rotation_xyz_deg"),
]


@pytest.mark.parametrize(
    ("key", "value", "says"), BAD_VALUES, ids=[f"{k}-{i}" for i, (k, _, _) in enumerate(BAD_VALUES)]
)
def test_a_meta_json_key_of_the_wrong_type_names_the_file_and_key(tmp_path, capsys, key, value, says):
    # Issue 12: '"camera": "tiny"' in meta.json gave a ValueError traceback. synth reads all four keys.
    raw = make_capture(tmp_path / "cap", **{key: value})
    err = refused(capsys, commands(raw, tmp_path / "out")["synth"])
    assert_says(err, repr(str(raw.parent / "meta.json")), f"key {key!r}")
    assert says in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_checks_the_camera_of_the_meta_json(tmp_path, capsys, command):
    raw = make_capture(tmp_path / "cap", camera="tiny")
    err = refused(capsys, commands(raw, tmp_path / "out")[command])
    assert_says(err, repr(str(raw.parent / "meta.json")), "key 'camera' must be a table")


@pytest.mark.parametrize("command", COMMANDS)
def test_a_meta_json_without_camera_names_the_file_and_key(tmp_path, capsys, command):
    # Issue 12: it printed "lfrefract: error: 'camera'" (a KeyError caught at the CLI).
    raw = make_capture(tmp_path / "cap", camera=MISSING)
    if command == "calibrate-mla":  # the camera is optional there: the lattice alone is written
        white = TINY.captured_rays().in_aperture.reshape(TINY.sensor.height_px, TINY.sensor.width_px)
        write_exr(raw, white.astype(np.float32), role="raw")
        assert main(commands(raw, tmp_path / "out")[command]) == 0
        assert "camera" not in json.loads((tmp_path / "out" / "mla.json").read_text())
        return
    err = refused(capsys, commands(raw, tmp_path / "out")[command])
    assert_says(err, repr(str(raw.parent / "meta.json")), "no key 'camera'")


def test_a_meta_json_without_port_names_the_file_and_key_for_synth(tmp_path, capsys):
    raw = make_capture(tmp_path / "cap", port=MISSING)
    err = refused(capsys, commands(raw, tmp_path / "out")["synth"])
    assert_says(err, repr(str(raw.parent / "meta.json")), "has no port", "--port")
    raw = make_capture(tmp_path / "null", port=None)  # what lfsim render writes for a scene without a port
    assert "has no port" in refused(capsys, commands(raw, tmp_path / "out")["synth"])


def test_calibrate_port_without_a_port_in_meta_json_names_the_options(tmp_path, capsys):
    raw = make_capture(tmp_path / "cap", port=MISSING)
    err = refused(capsys, commands(raw, tmp_path / "out")["calibrate-port"])
    assert "--thickness-m and --n-glass and --n-water needed" in err, err


@pytest.mark.parametrize("key", ["ideal", "pose"])
def test_ideal_and_pose_are_optional(tmp_path, capsys, key):
    raw = make_capture(tmp_path / "cap", **{key: MISSING})
    out = tmp_path / "out"
    assert main(commands(raw, out)["synth"]) == 0
    sidecar = json.loads((out / "s.json").read_text())
    if key == "ideal":  # the default refraction-free image geometry
        assert sidecar["K"] == virtual_camera_for(TINY).K.tolist()
    else:
        assert sidecar["pose"] is None
    assert main(commands(raw, out)["views"]) == 0
    assert json.loads((out / "v" / "views.json").read_text())["metadata"]["pose"] == (
        None if key == "pose" else Pose().to_dict()
    )


def test_a_raw_image_of_another_size_than_the_camera_is_refused(tmp_path, capsys):
    raw = make_capture(tmp_path / "cap", raw=textured_raw(camera_preset("tiny-2x")))
    err = refused(capsys, commands(raw, tmp_path / "out")["naive"])
    assert_says(err, repr(str(raw)), "960 x 720 px, but the camera", "480 x 360 px sensor")


# ------------------------------------------------------------------------------- encodings
@pytest.mark.parametrize("command", ["synth", "describe"])
def test_a_utf16_meta_json_is_a_clear_error(tmp_path, capsys, command):
    # Issue 12: UnicodeDecodeError traceback.
    raw = make_capture(tmp_path / "cap")
    meta = raw.parent / "meta.json"
    meta.write_bytes(meta.read_text().encode("utf-16"))
    err = refused(capsys, commands(raw, tmp_path / "out")[command])
    assert_says(err, repr(str(meta)), "is not UTF-8 text")


@pytest.mark.parametrize("option", ["--port", "--mla"])
def test_calibration_files_given_as_options_are_checked(tmp_path, capsys, option):
    # A UTF-16 file (UnicodeDecodeError traceback before) and one without the key ("error: 'port'").
    raw = make_capture(tmp_path / "cap")
    given = tmp_path / "given.json"
    write_json(given, {"kind": "something else"})
    err = refused(capsys, [*commands(raw, tmp_path / "out")["synth"], option, str(given)])
    key = option.lstrip("-")
    assert_says(err, repr(str(given)), f"has no key {key!r}")
    given.write_bytes(given.read_text().encode("utf-16"))
    err = refused(capsys, [*commands(raw, tmp_path / "out")["synth"], option, str(given)])
    assert_says(err, repr(str(given)), "is not UTF-8 text")
    write_json(given, {key: "x"} if key == "port" else {"kind": "lfrefract.calibrate.mla", key: "x"})
    err = refused(capsys, [*commands(raw, tmp_path / "out")["synth"], option, str(given)])
    assert_says(err, repr(str(given)), f"key {key!r} must be a table")


# ------------------------------------------------------------------------------- bare raw images
def test_a_bare_raw_image_runs_given_a_camera_and_a_port_file(tmp_path, capsys):
    raw = tmp_path / "bare" / "raw.exr"
    write_exr(raw, textured_raw(), role="raw")
    port_file = tmp_path / "port.json"
    write_json(port_file, {"kind": "lfrefract.calibrate.port", "port": PORT.to_dict()})
    out = tmp_path / "out"
    err = refused(capsys, commands(raw, out)["synth"])
    assert_says(err, "has no meta.json beside it", "--camera")
    assert main([*commands(raw, out)["synth"], "--camera", "tiny"]) == 2
    assert "has no meta.json, and no --port was given" in capsys.readouterr().err
    assert main([*commands(raw, out)["synth"], "--camera", "tiny", "--port", str(port_file)]) == 0
    sidecar = json.loads((out / "s.json").read_text())
    assert sidecar["camera"] == TINY.to_dict()
    assert sidecar["port"] == PORT.to_dict()
    # A camera file: what `lfrefract describe PRESET --json` prints.
    capsys.readouterr()
    assert main(["describe", "tiny", "--json"]) == 0
    camera_file = tmp_path / "camera.json"
    camera_file.write_text(capsys.readouterr().out)
    assert main([*commands(raw, out)["naive"], "--camera", str(camera_file)]) == 0
    assert main([*commands(raw, out)["views"], "--camera", str(camera_file)]) == 0
    assert json.loads((out / "v" / "views.json").read_text())["metadata"]["pose"] is None
    err = refused(capsys, [*commands(raw, out)["naive"], "--camera", "tiny-3x"])
    assert_says(err, "--camera must be a preset", "'tiny-3x'")


def test_a_given_camera_replaces_the_meta_json_camera(tmp_path, capsys):
    raw = make_capture(tmp_path / "cap", camera=MISSING)
    assert main([*commands(raw, tmp_path / "out")["naive"], "--camera", "tiny"]) == 0
    raw = make_capture(tmp_path / "cap2", camera=camera_preset("tiny-2x").to_dict())
    assert main([*commands(raw, tmp_path / "out2")["naive"], "--camera", "tiny"]) == 0


# ------------------------------------------------------------------------------- NaN, inf, negative raw values
def holed_raw(fraction: float, *, seed: int = 1, value: float | None = None) -> tuple[np.ndarray, int]:
    """A raw image with NaN in channel 0 of ``fraction`` of its pixels (and ``value``, if given, in
    the other channels too); returns it and the number of NaN values."""
    raw = textured_raw() if value is None else np.full((TINY.sensor.height_px, TINY.sensor.width_px, 3), value, "f4")
    holes = np.random.default_rng(seed).random(raw.shape[:2]) < fraction
    raw[holes, 0] = np.nan
    return raw, int(holes.sum())


def test_a_raw_image_with_nan_inf_or_negative_values_is_refused_with_the_count(tmp_path, capsys):
    # Issue 12: 3 % NaN raw pixels became 38 % NaN output, silently.
    raw, n_nan = holed_raw(0.03)
    raw[0, :5, 1] = np.inf
    raw[1, :17, 2] = -0.25
    raw[2, :2, 2] = -np.inf
    path = make_capture(tmp_path / "cap", raw=raw)
    for command in ("synth", "naive", "views", "calibrate-mla", "calibrate-approx"):
        err = refused(capsys, commands(path, tmp_path / "out")[command])
        assert f"{str(path)!r} has {n_nan} NaN, 5 +inf, 2 -inf and 17 negative pixel values" in err, err
        if command in ("synth", "naive", "views"):
            assert "pass --nonfinite mask" in err
    assert not (tmp_path / "out").exists()


def test_masked_synthesis_gives_unrecorded_pixels_no_weight_and_says_how_many(tmp_path, capsys):
    from tests.tolerances import FLOAT32_WEIGHT_SUM

    # A uniform scene: every output pixel of the clean capture is its gain. With 3 % of the raw pixels
    # NaN and masked, each output pixel must still be exactly the mean of the recorded rays it selected
    # (the weights renormalised), so the same value, and never NaN.
    clean = make_capture(tmp_path / "clean", raw=np.full((360, 480, 3), 0.5, "f4"))
    holed, n_nan = holed_raw(0.03, value=0.5)
    path = make_capture(tmp_path / "holed", raw=holed)
    assert main(commands(clean, tmp_path / "a")["synth"]) == 0
    capsys.readouterr()
    assert main([*commands(path, tmp_path / "b")["synth"], "--nonfinite", "mask"]) == 0
    printed = capsys.readouterr().out
    assert f"masked {n_nan} NaN pixel values (in {n_nan} pixels) as unrecorded" in printed, printed
    reference, image = read_exr(tmp_path / "a" / "s.exr"), read_exr(tmp_path / "b" / "s.exr")
    # NaN exactly where the pixel has no value (class 0 of s.filled.exr), never elsewhere.
    empty = read_exr(tmp_path / "b" / "s.filled.exr", role="filled") == 0
    assert np.array_equal(np.isnan(image).any(axis=2), empty)
    assert np.array_equal(np.isnan(image).all(axis=2), empty)
    filled = np.isfinite(image[..., 0]) & (image[..., 0] > 0)
    reference_filled = np.isfinite(reference[..., 0]) & (reference[..., 0] > 0)
    # A pixel loses all its rays (k per sub-pixel ray, 8 by default) to 3 % holes rarely.
    assert filled.sum() >= 0.999 * reference_filled.sum()
    assert not (filled & ~reference_filled).any()
    np.testing.assert_allclose(image[filled], reference[filled], rtol=FLOAT32_WEIGHT_SUM)
    sidecar = json.loads((tmp_path / "b" / "s.json").read_text())
    assert sidecar["unrecorded_raw"]["nan"] == n_nan
    assert sidecar["unrecorded_raw"]["pixels"] == n_nan
    assert sidecar["unrecorded_raw"]["values"] == n_nan
    assert sidecar["coverage"]["filled_fraction"] == pytest.approx(filled.mean())
    assert json.loads((tmp_path / "a" / "s.json").read_text())["unrecorded_raw"] is None


def test_an_all_nan_raw_image_is_refused_masked_or_not(tmp_path, capsys):
    # Issue 12: an all-NaN raw reported "filled 55 %". Issue 36: masked, it wrote an image of NaN, exit 0.
    raw = np.full((360, 480, 3), np.nan, "f4")
    path = make_capture(tmp_path / "cap", raw=raw)
    assert f"has {raw.size} NaN pixel values (in {360 * 480} pixels)" in refused(
        capsys, commands(path, tmp_path / "out")["synth"]
    )
    for name in ("synth", "naive", "views"):
        err = refused(capsys, [*commands(path, tmp_path / "out")[name], "--nonfinite", "mask"])
        assert_says(err, "has no value anywhere: every ray it needs lies on", "masked as unrecorded", "--nonfinite")
        assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir()), name


def test_an_output_geometry_that_sees_nothing_is_refused_by_every_command(tmp_path, capsys):
    """An ``ideal`` whose principal point lies 10 000 px off (a K typed wrong): synth, naive and views wrote
    images of NaN everywhere with exit status 0. Each refuses, naming the output geometry, and writes nothing."""
    ideal = virtual_camera_for(TINY).to_dict()
    K = np.array(ideal["K"])
    K[0, 2] += 1e4
    path = make_capture(tmp_path / "cap", ideal={**ideal, "K": K.tolist()})
    for name, why in (
        ("synth", "totally internally reflected"),
        ("naive", "lies among the lenses"),
        ("views", "lies among the lenses"),
    ):
        err = refused(capsys, commands(path, tmp_path / "out")[name])
        assert_says(err, "has no value anywhere", "92 x 69 px output", "cx 1.005e+04", why)
        assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir()), name


def test_a_port_that_passes_no_line_of_sight_is_refused_by_synth(tmp_path, capsys):
    """A 70 deg port reflects the light of every line of sight of the image totally: no pixel has a value."""
    port = FlatPort.from_degrees(distance_m=0.03, thickness_m=0.005, tilt_x_deg=70.0)
    path = make_capture(tmp_path / "cap", port=port.to_dict())
    for method in ([], ["--method", "depth-aware"]):
        err = refused(capsys, [*commands(path, tmp_path / "out")["synth"], *method])
        assert_says(err, "the refraction-free image has no value anywhere", "totally internally reflected", "tilt 70")
        assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_masked_views_and_naive_views_skip_unrecorded_pixels(tmp_path, capsys):
    from tests.tolerances import FLOAT32_WEIGHT_SUM, MASKED_VIEW_EXTRA_NAN_FRACTION

    clean = make_capture(tmp_path / "clean", raw=np.full((360, 480, 3), 0.5, "f4"))
    holed, n_nan = holed_raw(0.03, value=0.5)
    path = make_capture(tmp_path / "holed", raw=holed)
    for index, (command, extra, name) in enumerate(
        (
            ("naive", [], "n.exr"),
            ("naive", ["--kind", "full"], "n.exr"),
            ("views", ["--format", "exr"], "v/input_Cam000.exr"),
        )
    ):
        reference_dir, masked_dir = tmp_path / f"a{index}", tmp_path / f"b{index}"
        assert main([*commands(clean, reference_dir)[command], *extra]) == 0
        assert main([*commands(path, masked_dir)[command], *extra, "--nonfinite", "mask"]) == 0
        assert f"masked {n_nan} NaN pixel values" in capsys.readouterr().out
        reference, image = read_exr(reference_dir / name), read_exr(masked_dir / name)
        # NaN only where no recorded pixel contributes: a few, not the 30 % that spreading NaN gave.
        extra_nan = np.isnan(image).any(axis=2) & ~np.isnan(reference).any(axis=2)
        assert extra_nan.mean() <= MASKED_VIEW_EXTRA_NAN_FRACTION, extra_nan.mean()
        both = ~np.isnan(image) & ~np.isnan(reference)
        np.testing.assert_allclose(image[both], 0.5, rtol=FLOAT32_WEIGHT_SUM)
    metadata = json.loads((tmp_path / "b2" / "v" / "views.json").read_text())["metadata"]
    assert metadata["unrecorded_raw"]["nan"] == n_nan


# ------------------------------------------------------------------------------- sizes beyond memory
def _fast_refusal(capsys, argv: list[str]) -> str:
    from tests.tolerances import OVERSIZE_REFUSAL_SECONDS

    start = time.perf_counter()
    err = refused(capsys, argv)
    assert time.perf_counter() - start < OVERSIZE_REFUSAL_SECONDS
    return err


def test_an_ideal_image_beyond_the_size_limit_is_refused_at_once(tmp_path, capsys):
    # Issue 12: a meta.json whose ideal is 200000 x 200000 ran for minutes.
    ideal = {"K": [[1e5, 0, 1e5], [0, 1e5, 1e5], [0, 0, 1]], "width_px": 200_000, "height_px": 200_000}
    raw = make_capture(tmp_path / "cap", ideal=ideal)
    for command in ("synth", "naive", "views"):
        err = _fast_refusal(capsys, commands(raw, tmp_path / "out")[command])
        assert_says(err, "key 'ideal'", "width_px must be at most 65536 px, got 200000")


def test_an_ideal_image_beyond_the_memory_is_refused_with_the_estimate(tmp_path, capsys):
    # Within the size limit, but 3.6e9 pixels: terabytes for synth (at the paper's k = 32; at the default
    # k = 8 its map needs 0.95 TiB) and views, 624 GiB for naive (its resampling and image, 186 B per pixel).
    ideal = {"K": [[3e4, 0, 3e4], [0, 3e4, 3e4], [0, 0, 1]], "width_px": 60_000, "height_px": 60_000}
    raw = make_capture(tmp_path / "cap", ideal=ideal)
    for command, size in (("synth", "TiB"), ("naive", "624 GiB"), ("views", "TiB")):
        extra = ["--k", "32"] if command == "synth" else []
        err = _fast_refusal(capsys, [*commands(raw, tmp_path / "out")[command], *extra])
        assert_says(err, "60000 x 60000 px", "needs about", f"{size} of memory")
        assert "available" in err
    assert not (tmp_path / "out").exists()


def test_a_view_grid_beyond_the_memory_is_refused_with_the_estimate(tmp_path, capsys, monkeypatch):
    # Issue 12: `lfrefract views --grid 1001` tried to allocate 71 GiB. The estimate (views, their
    # export) is 88.9 GiB; with 16 GiB available it is refused. (A machine with more must not
    # attempt it in a test: the available memory is fixed here.)
    import lfrefract._memory

    monkeypatch.setattr(lfrefract._memory, "available_memory", lambda: (16 * 2**30, "MemAvailable (test)"))
    raw = make_capture(tmp_path / "cap")
    argv = commands(raw, tmp_path / "out")["views"][:-1]
    err = _fast_refusal(capsys, [*argv, "1001"])
    assert "a 1001 x 1001 stack of 92 x 69 px views with 3 channel(s)" in err, err
    assert_says(err, "needs about 88.9 GiB of memory", "more than the 16 GiB available")
    monkeypatch.undo()
    err = _fast_refusal(capsys, [*argv, "100001"])  # beyond any machine
    assert_says(err, "a 100001 x 100001 stack", "866 TiB of memory")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("option", [["--thickness-m", "-1"], ["--n-glass", "1e300"], ["--n-water", "nan"]])
def test_calibrate_port_checks_the_port_options_before_detecting_corners(tmp_path, capsys, option):
    # They were checked only after the corners of every capture were found (minutes on the Illum).
    raw = make_capture(tmp_path / "cap")
    err = refused(capsys, [*commands(raw, tmp_path / "out")["calibrate-port"], *option])
    assert_says(err, "--thickness-m / --n-glass / --n-water: port.")


def _camera_calibration(path: Path, *, covariance: bool = True) -> Path:
    """A camera calibration file of the tiny camera (a small correction), with or without the
    covariance that ``--refine-camera`` needs (files of earlier versions have none)."""
    from lfrefract.optics.ray_correction import PARAMETERS, CorrectionEstimate, RayCorrection

    estimate = CorrectionEstimate(correction=RayCorrection(pupil_scale=0.99), covariance=np.eye(len(PARAMETERS)) * 1e-6)
    data = {
        "kind": "lfrefract.calibrate.camera",
        "camera": TINY.to_dict(),
        "correction": estimate.correction.to_dict(),
    }
    if covariance:
        data["correction_covariance"] = estimate.covariance_to_dict()
    write_json(path, data)
    return path


@pytest.mark.parametrize(
    ("camera", "refined", "says"),
    [
        (None, "r.json", "--refine-camera needs --camera"),
        ("tiny", "r.json", "is not a camera calibration"),
        ("old.json", "r.json", "has no correction_covariance"),
        ("camera.json", "r.txt", "--refine-camera must name a .json file"),
        ("camera.json", "camera.json", "is the command's own input"),
    ],
)
def test_refine_camera_is_refused_before_detecting_corners(tmp_path, capsys, camera, refined, says):
    raw = make_capture(tmp_path / "cap")
    _camera_calibration(tmp_path / "camera.json")
    _camera_calibration(tmp_path / "old.json", covariance=False)
    argv = [*commands(raw, tmp_path / "out")["calibrate-port"], "--refine-camera", str(tmp_path / refined)]
    if camera is not None:
        argv += ["--camera", camera if camera == "tiny" else str(tmp_path / camera)]
    assert_says(refused(capsys, argv), says)
    assert not (tmp_path / "out").exists()


def test_synth_refuses_a_port_calibrated_on_another_ray_model(tmp_path, capsys):
    raw = make_capture(tmp_path / "cap")
    camera = _camera_calibration(tmp_path / "camera.json")
    port = {"kind": "lfrefract.calibrate.port", "port": FlatPort(distance_m=0.02).to_dict()}
    write_json(tmp_path / "thin-port.json", {**port, "ray_model": {"camera": "tiny", "correction": None}})
    synth = commands(raw, tmp_path / "out")["synth"]
    err = refused(capsys, [*synth, "--camera", str(camera), "--port", str(tmp_path / "thin-port.json")])
    assert_says(err, "was calibrated on the ray model of 'tiny' (the thin lens)", "not on that of --camera")
    other = {"camera": "c.json", "correction": {"pupil_scale": 0.98, "slope_scale": 1.0, "k1": 0.0, "k2": 0.0}}
    write_json(tmp_path / "other-port.json", {**port, "ray_model": other})
    err = refused(capsys, [*synth, "--camera", str(camera), "--port", str(tmp_path / "other-port.json")])
    assert_says(err, "'c.json' (a calibrated correction)", "(another correction)")
    assert not (tmp_path / "out").exists()
    # The ray model it was calibrated on, and a port file that records none, pass.
    same = {"camera": str(camera), "correction": {"pupil_scale": 0.99, "slope_scale": 1.0, "k1": 0.0, "k2": 0.0}}
    write_json(tmp_path / "port.json", {**port, "ray_model": same})
    assert main([*synth, "--camera", str(camera), "--port", str(tmp_path / "port.json")]) == 0
    write_json(tmp_path / "plain.json", port)
    assert main([*synth, "--camera", str(camera), "--port", str(tmp_path / "plain.json"), "--overwrite"]) == 0
    bad = {**port, "ray_model": {"camera": "c.json"}}
    write_json(tmp_path / "bad.json", bad)
    err = refused(capsys, [*synth, "--camera", str(camera), "--port", str(tmp_path / "bad.json"), "--overwrite"])
    assert_says(err, "ray_model must be a table with a correction")


def test_a_masked_synthesis_caches_the_full_map(tmp_path, capsys):
    from lfrefract.synthesis.warp_map import WarpMap

    holed, _ = holed_raw(0.03)
    path = make_capture(tmp_path / "holed", raw=holed)
    cache = tmp_path / "maps"
    assert main([*commands(path, tmp_path / "a")["synth"], "--nonfinite", "mask", "--map-cache", str(cache)]) == 0
    (cached,) = cache.glob("*.npz")
    assert "unrecorded_raw_pixels" not in WarpMap.load(cached).meta
    clean = make_capture(tmp_path / "clean")
    assert main([*commands(clean, tmp_path / "b")["synth"], "--map-cache", str(cache)]) == 0
    assert "loaded" in capsys.readouterr().out
    image, classes = read_exr(tmp_path / "b" / "s.exr"), read_exr(tmp_path / "b" / "s.filled.exr", role="filled")
    assert np.array_equal(np.isfinite(image).all(axis=2), classes > 0)
    assert json.loads((tmp_path / "b" / "s.json").read_text())["coverage"]["filled_fraction"] == np.mean(classes > 0)


# =============================================================================== the parser (issue 13)


def test_version_is_the_package_version(capsys):
    from importlib.metadata import version

    import lfrefract

    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out == f"lfrefract {lfrefract.__version__}\n"
    assert version("lfrefract") == lfrefract.__version__  # pyproject.toml takes it from lfrefract.__version__


def test_python_dash_m_runs_the_same_command_line(tmp_path):
    import subprocess
    import sys

    import lfrefract

    done = subprocess.run(
        [sys.executable, "-m", "lfrefract", "--version"], capture_output=True, text=True, check=False, timeout=120
    )
    assert (done.returncode, done.stdout) == (0, f"lfrefract {lfrefract.__version__}\n"), done.stderr
    done = subprocess.run(
        [sys.executable, "-m", "lfrefract", "describe", "tiny", "--json"],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["camera"] == camera_preset("tiny").to_dict()


def test_synth_defaults_are_the_synthesis_options_defaults(tmp_path, capsys):

    from lfrefract.cli import build_parser
    from lfrefract.synthesis.warp_map import SEARCH_METHODS, SynthesisOptions

    args = build_parser().parse_args(["synth", "raw.exr", "--out", "o.exr"])
    defaults = SynthesisOptions()
    assert (args.k, args.supersample, args.lam, args.search) == (
        defaults.k,
        defaults.supersample,
        defaults.lambda_m_per_rad,
        defaults.search,
    )
    for method in SEARCH_METHODS:
        assert build_parser().parse_args(["synth", "raw.exr", "--out", "o.exr", "--search", method]).search == method
    with pytest.raises(SystemExit):
        build_parser().parse_args(["synth", "raw.exr", "--out", "o.exr", "--search", "nearest"])
    assert "(choose from " + ", ".join(map(repr, SEARCH_METHODS)) + ")" in capsys.readouterr().err
    # ... and a synth run with no options records exactly the default options.
    raw = make_capture(tmp_path / "cap")
    assert main(commands(raw, tmp_path / "out")["synth"]) == 0
    recorded = json.loads((tmp_path / "out" / "s.json").read_text())["options"]
    assert recorded == defaults.to_dict()


def test_help_shows_the_defaults(capsys):
    from lfrefract.synthesis.views import naive_view, subaperture_stack
    from lfrefract.synthesis.warp_map import SynthesisOptions

    def help_of(*argv: str) -> str:
        with pytest.raises(SystemExit) as exit_info:
            main([*argv, "--help"])
        assert exit_info.value.code == 0
        return " ".join(capsys.readouterr().out.split())  # unwrapped

    synth_help = help_of("synth")
    defaults = SynthesisOptions()
    for option, value in (
        ("--k K", defaults.k),
        ("--supersample SUPERSAMPLE", defaults.supersample),
        ("--lambda LAM", defaults.lambda_m_per_rad),
        ("--search {auto,analytic,kdtree}", defaults.search),
    ):
        shown = synth_help.split(option, 2)[-1].split(" --", 1)[0]  # the option's own help text
        assert f"(default: {value})" in shown, (option, shown)
    assert "the paper used 32" in synth_help
    naive_help = help_of("naive")
    assert f"(default: {inspect.signature(naive_view).parameters['kind'].default})" in naive_help
    views_help = help_of("views")
    assert f"odd >= 3 (default: {inspect.signature(subaperture_stack).parameters['grid'].default})" in views_help
    assert "(default: png)" in views_help
    assert "(default: None)" not in synth_help + naive_help + views_help
    assert "(default: False)" not in synth_help


def test_every_command_in_the_tables_is_dispatched(capsys, tmp_path):
    from lfrefract.cli import CALIBRATE_COMMANDS, COMMANDS, build_parser

    parser = build_parser()
    for name, command in COMMANDS.items():
        argv = [name, "tiny"] if name == "describe" else [name, "raw.exr", "--out", "o"]
        assert parser.parse_args(argv).handler is command.handler
    for name, command in CALIBRATE_COMMANDS.items():
        argv = ["calibrate", name, "w.exr", "--out", "o"]
        if name != "mla":
            argv += ["--squares", "5", "4", "--square-size-m", "0.01"]
        assert parser.parse_args(argv).handler is command.handler
    # A handler's refusal is still one line and exit status 2 through the table.
    raw = make_capture(tmp_path / "cap")
    for name in ("naive", "views", "calibrate-mla"):
        err = refused(capsys, [*commands(raw, tmp_path / "out")[name], "--camera", "nope"])
        assert_says(err, "nope")


def test_a_k_beyond_the_search_names_what_the_command_line_can_change(tmp_path, capsys):
    """``synth --k 1000000000`` advised lens_rings and window, which the command line does not set: the
    message gives the largest --k, and the Python options as such."""
    raw = make_capture(tmp_path / "cap")
    err = refused(capsys, [*commands(raw, tmp_path / "out")["synth"], "--k", "1000000000"])
    assert_says(
        err, "k=1000000000 exceeds the 175 candidates searched", "choose k at most 175 (--k on the command line)"
    )
    assert "(SynthesisOptions, in Python)" in err


@pytest.mark.parametrize(
    ("option", "value", "field"),
    [
        ("--k", "0", "k must be positive"),
        ("--k", "-1", "k must be positive"),
        ("--supersample", "0", "supersample must be positive"),
        ("--lambda", "-1", "lambda_m_per_rad must be non-negative"),
        ("--lambda", "nan", "lambda_m_per_rad must be finite"),
        ("--lambda", "inf", "lambda_m_per_rad must be finite"),
    ],
)
def test_an_invalid_synthesis_option_is_refused_naming_its_flag_before_reading(tmp_path, capsys, option, value, field):
    """A bad --k, --supersample or --lambda is named by its flag (the audit found 'k must be positive' alone,
    which names a Python field the command line does not have), before the capture is read: the raw
    here does not exist."""
    err = refused(capsys, ["synth", str(tmp_path / "none.exr"), "--out", str(tmp_path / "s.exr"), option, value])
    assert_says(err, f"{option}: ", field)
    assert not (tmp_path / "s.exr").exists()


def test_a_warp_map_beyond_the_memory_names_the_options_that_shrink_it(tmp_path, capsys):
    raw = make_capture(tmp_path)
    err = refused(capsys, ["synth", str(raw), "--out", str(tmp_path / "s.exr"), "--supersample", "100000"])
    assert_says(err, "needs about", "choose a smaller --supersample or --k")


# The first apply of a fresh process may take this many times the second's, plus APPLY_REPEAT_SLACK_S, on a
# loaded 2-core machine (measured 12.2 and 12.2 ms on tiny); numba's compilation of the gather (2.8 s on a fresh
# cache here) inside the first would exceed it a hundredfold.
APPLY_REPEAT_FACTOR = 5.0
APPLY_REPEAT_SLACK_S = 0.1


def test_synth_reports_the_gathers_compilation_apart_from_the_apply(tmp_path, capsys):
    """The first synth of a process said 'applied in 6807 ms' (numba compiling the gather), later ones 33-41 ms.
    In a fresh process with an empty numba cache, the compilation is reported apart and the first apply times
    as the second (the warp map loaded from --map-cache, so the gather is the only kernel compiled there)."""
    import os
    import re
    import subprocess
    import sys

    raw = make_capture(tmp_path / "cap")
    cache = tmp_path / "maps"
    assert main([*commands(raw, tmp_path / "warm")["synth"], "--map-cache", str(cache)]) == 0  # builds the map
    capsys.readouterr()
    code = (
        "import sys\nfrom lfrefract.cli import main\n"
        "for out in sys.argv[2:]:\n"
        "    assert main(['synth', sys.argv[1], '--out', out, '--quiet', '--map-cache', "
        + repr(str(cache))
        + "]) == 0\n"
    )
    outs = [str(tmp_path / name / "s.exr") for name in ("first", "second")]
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    done = subprocess.run(
        [sys.executable, "-c", code, str(raw), *outs], capture_output=True, text=True, env=env, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr
    pattern = (
        r"loaded .* warp map \(.*\), compiled in (\d+) ms \(first run only: numba caches it\), applied in ([\d.]+) ms"
    )
    found = [re.search(pattern, line) for line in done.stdout.splitlines()]
    (compile1, apply1), (compile2, apply2) = [(float(m[1]) / 1e3, float(m[2]) / 1e3) for m in found if m]
    assert compile1 > apply1  # a compilation: seconds; a gather of tiny's image: milliseconds
    assert compile2 < compile1  # compiled once
    assert apply1 <= APPLY_REPEAT_FACTOR * apply2 + APPLY_REPEAT_SLACK_S, done.stdout


@pytest.mark.parametrize("grid", ["0", "4", "-3"])
def test_views_names_a_bad_grid_by_its_option_before_reading(tmp_path, capsys, grid):
    # "grid must be an odd integer >= 3" named the Python parameter, after the capture was read.
    err = refused(capsys, ["views", str(tmp_path / "none.exr"), "--out", str(tmp_path / "v"), "--grid", grid])
    assert_says(err, "--grid must be an odd integer >= 3", f"got {grid}")


def test_a_white_given_for_a_linear_raw_image_names_the_option(tmp_path, capsys):
    raw = make_capture(tmp_path / "cap")
    err = refused(capsys, ["naive", str(raw), "--out", str(tmp_path / "n.exr"), "--white", str(tmp_path)])
    assert_says(err, "(--white)", "is a linear raw image already", "leave the white image out")
