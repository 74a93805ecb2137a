"""``lfsim``'s refusals name what the user gave: the scene or rig file and its key as the file spells
it, or the option as it was typed, with the value; and they come before any render starts."""

from __future__ import annotations

import pytest

from simulator import cli as sim_cli

#: A small scene: the tiny camera behind a tilted port, one point light, one textured plane.
SCENE = (
    '[camera]\npreset = "tiny"\n[port]\ndistance_m = 0.02\nthickness_m = 0.004\ntilt_x_deg = 10.0\n'
    '[render]\nspp = 1\n[[light]]\ntype = "point"\nposition_m = [0.0, -0.2, 0.1]\nintensity_w_sr = 0.3\n'
    '[[object]]\ntype = "textured_plane"\nposition_m = [0.0, 0.0, 0.6]\nsize_m = [0.8, 0.6]\ntexture_px = 64\n'
)


def _refusal(capsys, argv: list[str]) -> str:
    """The one line ``lfsim argv`` printed, after checking that it refused (exit 2)."""
    assert sim_cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lfsim: error: "), err
    assert "\n" not in err, err
    return err


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("tilt_x_deg = 10.0", "tilt_x_deg = 90.0", ["tilt_x_deg", "90"]),
        ("tilt_x_deg = 10.0", "tilt_x_deg = -95.0", ["tilt_x_deg", "-95"]),
        ("tilt_x_deg = 10.0", "tilt_x_deg = nan", ["tilt_x_deg", "nan"]),
        ("distance_m = 0.02", "distance_m = -0.02", ["distance_m", "-0.02"]),
        ("spp = 1", "spp = 0", ["spp", "0"]),
        ("size_m = [0.8, 0.6]", "size_m = [0.0, 0.6]", ["object[0] (textured_plane)", "size_m"]),
        ("intensity_w_sr = 0.3", "intensity_w_sr = nan", ["light[0] (point)", "intensity_w_sr", "nan"]),
        ("texture_px = 64", "texture_px = 10000000", ["texture_px", "10000000"]),
        ("spp = 1", "spp = 1\nsamples = 4", ["samples"]),
        ('preset = "tiny"', 'preset = "hasselblad"', ["hasselblad"]),
        ("[render]", "[water]\nphase_g = 2.0\n[render]", ["water.phase_g", "2.0"]),
        ("[render]", '[sensor]\npreset = "tiny"\nframes = 0\n[render]', ["sensor.frames", "0"]),
        # Refused by the geometry check, after the file is read: an object on the camera side of the port.
        ("position_m = [0.0, 0.0, 0.6]", "position_m = [0.0, 0.0, 0.01]", ["object[0] (textured_plane)"]),
    ],
)
def test_a_bad_scene_file_is_named_with_its_key(tmp_path, capsys, old, new, words):
    scene, out = tmp_path / "scene.toml", tmp_path / "r"
    scene.write_text(SCENE.replace(old, new))
    err = _refusal(capsys, ["render", str(scene), "--out", str(out), "--quiet", "--no-previews"])
    assert err.startswith(f"lfsim: error: scene file {str(scene)!r}: "), err
    for word in words:
        assert word in err
    assert "_rad" not in err  # the file gives degrees
    assert not out.exists()


def test_options_that_change_a_scene_are_named_with_it(tmp_path, capsys):
    # --lens double-gauss puts a real lens behind this port, whose glass its front reaches.
    scene, out = tmp_path / "scene.toml", tmp_path / "r"
    scene.write_text(SCENE.replace("distance_m = 0.02", "distance_m = 0.0005"))
    err = _refusal(capsys, ["render", str(scene), "--out", str(out), "--lens", "double-gauss", "--quiet"])
    assert f"scene file {str(scene)!r} with --lens" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--spp", "0"], ["--spp", "0"]),
        (["--spp", "-1"], ["--spp", "-1"]),
        (["--spp", "100000"], ["--spp", "100000"]),
        (["--seed", "-1"], ["--seed", "-1"]),
        (["--ideal-spp", "0"], ["--ideal-spp", "0"]),
        (["--band-pixels", "0"], ["--band-pixels", "0"]),
        (["--frames", "0", "--sensor", "tiny"], ["--frames", "0"]),
        (["--frames", "100000", "--sensor", "tiny"], ["--frames", "100000"]),
    ],
)
def test_render_options_are_named_by_their_flag(tmp_path, capsys, argv, words):
    out = tmp_path / "r"
    err = _refusal(capsys, ["render", "--out", str(out), "--quiet", *argv])
    assert err.startswith(f"lfsim: error: {words[0]}"), err
    assert all(word in err for word in words)
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--spp", "0"], ["--spp", "0"]),
        (["--seed", "-1"], ["--seed", "-1"]),
        (["--seed", "3000000000"], ["--seed", "3000000000"]),
    ],
)
def test_rig_options_are_named_by_their_flag(tmp_path, capsys, argv, words):
    out = tmp_path / "r"
    err = _refusal(capsys, ["rig", "--out", str(out), "--quiet", *argv])
    assert err.startswith(f"lfsim: error: {words[0]}"), err
    assert all(word in err for word in words)
    assert not out.exists()


def test_a_bad_rig_file_is_named(tmp_path, capsys):
    from simulator.rig import embedded_rigs

    rig, out = tmp_path / "rig.toml", tmp_path / "r"
    text = embedded_rigs()["default"].read_text()
    assert "spp = " in text
    rig.write_text(text.replace("spp = ", "spp = 0 #", 1))
    err = _refusal(capsys, ["rig", str(rig), "--out", str(out), "--quiet"])
    assert err.startswith(f"lfsim: error: rig file {str(rig)!r}: "), err
    assert "spp" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--frames", "0"], ["--frames", "0"]),
        (["--spp", "0"], ["--spp", "0"]),
        (["--seed", "-1"], ["--seed", "-1"]),
        (["--seed", "2147483647"], ["--seed", "2147483647"]),
        (["--focus-m", "-1"], ["--focus-m", "-1"]),
        (["--focus-m", "0.001"], ["--focus-m", "0.001"]),
        (["--focal-lengths-mm", "0"], ["--focal-lengths-mm", "0 mm"]),
        (["--focal-lengths-mm", "nan"], ["--focal-lengths-mm", "nan mm"]),
        (["--focal-lengths-mm", "0.001"], ["--focal-lengths-mm", "0.001 mm"]),
        (["--focal-lengths-mm", "20000"], ["--focal-lengths-mm", "20000 mm"]),
        (["--focal-lengths-mm", "10", "--focus-m", "0.015"], ["--focus-m", "0.015", "--focal-lengths-mm 10"]),
    ],
)
def test_whites_options_are_named_by_their_flag(tmp_path, capsys, argv, words):
    out = tmp_path / "w"
    err = _refusal(capsys, ["whites", "--camera", "tiny", "--out", str(out), "--quiet", *argv])
    assert err.startswith(f"lfsim: error: {words[0]}"), err
    assert all(word in err for word in words)
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--workers", "0"], ["--workers", "0"]),
        (["--threads", "0"], ["--threads", "0"]),
        (["--retries", "-1"], ["--retries", "-1"]),
        # 100000 local worker processes were started (one Mitsuba each) until memory ran out.
        (["--workers", "100000"], ["--workers", "100000", "CPU(s)", "give at most"]),
    ],
)
def test_dataset_run_options_are_named_by_their_flag(tmp_path, capsys, argv, words):
    out = tmp_path / "ds"
    err = _refusal(capsys, ["dataset", "run", "tilt", "--out", str(out), "--quiet", *argv])
    assert err.startswith(f"lfsim: error: {words[0]}"), err
    assert all(word in err for word in words)
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        ("spp = 0\n", ["sweep.spp", "0"]),
        ('[grid]\n"port.tilt_x_deg" = [0.0, 95.0]\n', ["sample s000001", "port.tilt_x_deg", "95.0"]),
    ],
)
def test_a_bad_sweep_spec_is_named_with_its_key(tmp_path, capsys, extra, words):
    spec, out = tmp_path / "spec.toml", tmp_path / "ds"
    spec.write_text('[sweep]\nname = "t"\nseed = 5\nscene = "default"\n' + extra)
    err = _refusal(capsys, ["dataset", "run", str(spec), "--out", str(out), "--quiet"])
    assert err.startswith(f"lfsim: error: sweep spec file {str(spec)!r}: "), err
    assert all(word in err for word in words)
    assert "_rad" not in err
    assert not out.exists()
