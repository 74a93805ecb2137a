"""A render through a real main lens, given to the core: the thin lens it is scaled to does not
stand for it. Every command that uses the camera's rays refuses it without a calibrated ray model
(``lfrefract synth`` on a ``--lens double-gauss`` render used the thin lens, and the board could not
be found in its result), and names what to do; with a camera calibration it runs, and with the
render's ``meta.json`` as its camera the recorded lens is traced (the true rays)."""

from __future__ import annotations

import shutil

import pytest

from lfrefract.cli import main as core_main
from lfrefract.formats.capture import read_sidecar, recorded_main_lens
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.optics.ray_correction import RayCorrection
from simulator import cli as sim_cli

BOARD = ["--squares", "5", "4", "--square-size-m", "0.01"]


@pytest.fixture(scope="module")
def double_gauss(tmp_path_factory):
    """The default scene (tiny camera, tilted port) rendered through the double Gauss, 1 spp."""
    out = tmp_path_factory.mktemp("dg") / "render"
    argv = ["render", "--out", str(out), "--spp", "1", "--ideal-spp", "1", "--lens", "double-gauss"]
    assert sim_cli.main([*argv, "--quiet", "--no-previews"]) == 0
    return out


def _refused(capsys, argv: list[str]) -> str:
    assert core_main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("lfrefract: error: "), err
    assert err.count("\n") == 1, err  # one line
    return err


@pytest.mark.render
def test_the_commands_refuse_a_real_lens_render_on_the_thin_lens(double_gauss, tmp_path, capsys):
    assert recorded_main_lens(read_sidecar(double_gauss / "meta.json").data) == "double-gauss"
    out = tmp_path / "out"
    commands = {
        "synth": ["synth", str(double_gauss), "--out", str(out / "s.exr"), "--quiet"],
        "naive": ["naive", str(double_gauss), "--out", str(out / "n.exr")],
        "views": ["views", str(double_gauss), "--out", str(out / "v"), "--grid", "3"],
        "calibrate port": ["calibrate", "port", str(double_gauss), *BOARD, "--out", str(out / "p.json")],
        "calibrate approx": ["calibrate", "approx", str(double_gauss), *BOARD, "--out", str(out / "a.json")],
    }
    for name, argv in commands.items():
        err = _refused(capsys, argv)
        for part in (
            f"{str(double_gauss / 'meta.json')!r} says the capture",
            "through the real main lens 'double-gauss'",
            "no calibrated ray model",
            "lfrefract calibrate camera",
            "--camera camera.json",
        ):
            assert part in err, (name, err)
        # A preset camera is a thin lens too.
        assert "--camera 'tiny', a thin lens" in _refused(capsys, [*argv, "--camera", "tiny"]), name
    assert not out.exists()


@pytest.mark.render
def test_a_real_lens_renders_meta_json_as_camera_traces_its_lens(double_gauss, tmp_path, capsys):
    # Asked for (--camera the render's meta.json), the core traces the recorded prescription: the
    # render's true rays, the oracle of a calibration from its data; on a bare raw image too.
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(double_gauss / "raw.exr", bare / "raw.exr")  # no meta.json beside it
    meta = str(double_gauss / "meta.json")
    out = tmp_path / "s.exr"
    argv = ["synth", str(bare / "raw.exr"), "--camera", meta, "--port", meta, "--out", str(out), "--quiet"]
    assert core_main(argv) == 0, capsys.readouterr().err
    written = read_json(out.with_suffix(".json"))
    assert written["options"]["ray_correction"]["family"] == "traced"
    assert written["options"]["ray_correction"]["lens"]["name"] == "double-gauss"
    # the views take no traced model (its rays of one view share no centre): refused, by name
    views = ["views", str(bare / "raw.exr"), "--camera", meta, "--out", str(tmp_path / "v"), "--grid", "3"]
    assert "no sub-aperture views" in _refused(capsys, views)
    assert not (tmp_path / "v").exists()


@pytest.mark.render
def test_with_a_camera_calibration_a_real_lens_render_is_synthesized(double_gauss, tmp_path, capsys):
    # What the refusal asks for: a calibrated ray model (here a correction written as calibrate
    # camera writes it; its values are not what is tested, the command's acceptance is).
    calibration = tmp_path / "camera.json"
    camera = read_json(double_gauss / "meta.json")["camera"]
    write_json(
        calibration,
        {"kind": "lfrefract.calibrate.camera", "camera": camera, "correction": RayCorrection(k1=0.01).to_dict()},
    )
    argv = ["synth", str(double_gauss), "--camera", str(calibration), "--out", str(tmp_path / "s.exr"), "--quiet"]
    assert core_main(argv) == 0, capsys.readouterr().err
    assert (tmp_path / "s.exr").is_file()
