"""``lfsim experiment``: the command line of the experiment harness, its options and ``lfsim --version``."""

from __future__ import annotations

import csv
import importlib.metadata

import pytest

import lfrefract
from lfrefract.formats.jsonio import read_json
from simulator import cli as sim_cli
from simulator.experiments import OPTION_FLAGS, ExperimentOptions, experiment_names, load_experiments


def test_experiments_are_registered():
    assert {"planes", "averaging", "fov", "objects"} <= set(load_experiments())
    assert experiment_names() == tuple(sorted(load_experiments()))
    for experiment in load_experiments().values():
        assert set(experiment.options) <= set(OPTION_FLAGS)
        assert experiment.description


def test_experiment_command_writes_its_table(tmp_path, capsys):
    out = tmp_path / "fov"
    assert sim_cli.main(["experiment", "fov", "--scale", "tiny", "--out", str(out), "--quiet"]) == 0
    assert "wrote" in capsys.readouterr().out
    meta = read_json(out / "meta.json")
    assert (meta["kind"], meta["experiment"], meta["scale"]) == ("lfsim.experiment", "fov", "tiny")
    assert (out / "table.csv").read_text().splitlines()[0].startswith("series,")
    assert all((out / name).is_file() for name in meta["figures"])
    # A second run refuses to write over it unless asked.
    assert sim_cli.main(["experiment", "fov", "--out", str(out), "--quiet"]) == 2
    assert "not empty" in capsys.readouterr().err
    assert sim_cli.main(["experiment", "fov", "--out", str(out), "--quiet", "--overwrite"]) == 0


def test_unknown_experiment_is_refused_before_any_work(tmp_path, capsys):
    assert sim_cli.main(["experiment", "bubbles", "--out", str(tmp_path / "x")]) == 2
    assert "experiment must be one of" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_options_reach_the_experiment_and_parents_are_created(tmp_path, capsys):
    out = tmp_path / "runs" / "2026" / "fov-options"  # none of these folders exists yet
    argv = ["experiment", "fov", "--out", str(out), "--quiet", "--camera", "tiny", "--port-distance-m", "0.02"]
    argv += ["--thickness-m", "0", "--tilts-deg", "0,10", "--f-numbers", "2.8,2.2"]
    assert sim_cli.main(argv) == 0, capsys.readouterr().err
    with open(out / "table.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    tilt = [r for r in rows if r["series"] == "tilt"]
    assert sorted({float(r["tilt_deg"]) for r in tilt}) == [0.0, 10.0]
    assert sorted({float(r["f_number"]) for r in tilt}) == [2.2, 2.8]
    assert {float(r["distance_mm"]) for r in tilt} == {20.0}
    meta = read_json(out / "meta.json")
    assert meta["options"]["tilts_deg"] == [0.0, 10.0]
    assert meta["options"]["camera"]["name"] == "tiny"
    assert meta["parameters"]["port"] == {"distance_m": 0.02, "thickness_m": 0.0, "n_water": 1.333}


def test_camera_file(tmp_path, capsys):
    """--camera takes a camera file (here ``lfrefract describe --json`` output) as well as a preset."""
    from lfrefract import cli as core_cli

    path = tmp_path / "camera.json"
    assert core_cli.main(["describe", "tiny", "--json"]) == 0
    path.write_text(capsys.readouterr().out)
    out = tmp_path / "fov"
    argv = ["experiment", "fov", "--out", str(out), "--quiet", "--camera", str(path), "--tilts-deg", "0"]
    assert sim_cli.main(argv) == 0, capsys.readouterr().err
    assert read_json(out / "meta.json")["parameters"]["camera"]["name"] == "tiny"


@pytest.mark.parametrize(
    ("experiment", "option", "value"),
    [
        ("fov", "--methods", "proposed"),
        ("planes", "--tilts-deg", "0,10"),
        ("objects", "--f-numbers", "2.8"),
        ("averaging", "--methods", "proposed"),
        ("averaging", "--tilts-deg", "5"),
        ("fov", "--lens", "double-gauss"),
    ],
)
def test_an_option_that_does_not_apply_is_refused(tmp_path, capsys, experiment, option, value):
    out = tmp_path / "x"
    assert sim_cli.main(["experiment", experiment, "--out", str(out), option, value]) == 2
    err = capsys.readouterr().err
    assert f"option {option}" in err
    assert f"does not apply to experiment {experiment!r}" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--port-distance-m", "-1"], "--port-distance-m: port_distance_m must be positive, got -1"),
        (
            ["--port-distance-m=0.0001"],
            "--port-distance-m: port.distance_m=0.0001 at tilt 5 deg cuts the main-lens aperture",
        ),
        (["--thickness-m", "2"], "--thickness-m: thickness_m must lie in [0, 1] m"),
        (["--thickness-m=nan"], "--thickness-m: thickness_m must be finite, got nan"),
        (["--tilts-deg", "0,95"], "--tilts-deg: tilts_deg[1] must lie in (-90, 90) deg, got 95"),
        (["--tilts-deg=nan"], "--tilts-deg: tilts_deg[0] must be finite, got nan"),
        (["--tilts-deg", "0,0"], "--tilts-deg: tilts_deg must not repeat"),
        (["--camera", "pinhole"], "--camera must be a preset"),
        (["--f-numbers=0"], "--f-numbers: f_numbers[0] must be positive, got 0"),
        (["--f-numbers", "0.1"], "--f-numbers: f_number must lie in [0.5, 128]"),
        (["--f-numbers", "1"], "--f-numbers: f_number=1.0 gives an image-side f-number"),
    ],
)
def test_invalid_option_values_name_the_option(tmp_path, capsys, argv, message):
    out = tmp_path / "x"
    assert sim_cli.main(["experiment", "fov", "--out", str(out), "--quiet", *argv]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--methods", "nonesuch"], "--methods: method must be one of"),
        (["--thickness-m", "0"], "--thickness-m: wall.thickness_m must be positive, got 0"),
    ],
)
def test_invalid_option_values_of_a_stereo_experiment_name_the_option(tmp_path, capsys, argv, message):
    out = tmp_path / "x"
    assert sim_cli.main(["experiment", "planes", "--out", str(out), "--quiet", *argv]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_lens_reaches_every_rig_camera_and_a_bad_one_is_named():
    from lfrefract.errors import ParameterError
    from simulator.experiments.planes import setup_for
    from simulator.experiments.rigstereo import experiment_rig

    rig = experiment_rig(setup_for("tiny"), ExperimentOptions(lens="double-gauss"))
    assert [c.scene.lens.name for c in rig.cameras] == ["double-gauss", "double-gauss"]
    assert all(c.scene.lens is None for c in experiment_rig(setup_for("tiny"), ExperimentOptions()).cameras)
    assert all(c.scene.lens is None for c in experiment_rig(setup_for("tiny"), ExperimentOptions(lens="thin")).cameras)
    with pytest.raises(ParameterError, match="lens"):
        ExperimentOptions(lens="tessar")
    with pytest.raises(ParameterError, match="does not clear the main lens 'wide-angle'"):
        experiment_rig(setup_for("tiny"), ExperimentOptions(lens="wide-angle"))


def test_options_are_one_frozen_dataclass():
    options = ExperimentOptions(scale="illum", methods=["proposed"], camera="tiny", tilts_deg=[0, 5])
    assert options.methods == ("proposed",)
    assert options.tilts_deg == (0.0, 5.0)
    assert options.camera.name == "tiny"
    assert options.given() == ("methods", "camera", "tilts_deg")
    with pytest.raises(AttributeError):
        options.scale = "tiny"  # frozen


def test_help_lists_the_experiments_and_shows_defaults(capsys):
    with pytest.raises(SystemExit) as exit_info:
        sim_cli.main(["experiment", "--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    for name in experiment_names():
        assert f"  {name}: " in text
    assert "(default: tiny)" in text
    with pytest.raises(SystemExit):
        sim_cli.main(["render", "--help"])
    assert "(default: 8000000)" in capsys.readouterr().out


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_info:
        sim_cli.main(["--version"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out.strip()
    assert out.startswith(f"lfsim {lfrefract.__version__}")
    assert lfrefract.__version__ == importlib.metadata.version("lfrefract") or "installed distribution" in out


def test_options_or_separate_values_not_both(tmp_path):
    from lfrefract import ParameterError
    from simulator.experiments import run_experiment

    options = ExperimentOptions(tilts_deg=(0.0,))
    for separate in ({"scale": "tiny"}, {"tilts_deg": (5.0,)}):
        with pytest.raises(ParameterError, match="give either options or"):
            run_experiment("fov", out=tmp_path / "x", options=options, progress=False, **separate)
    with pytest.raises(ParameterError, match="options must be an ExperimentOptions"):
        run_experiment("fov", out=tmp_path / "x", options={"scale": "tiny"}, progress=False)
    assert not (tmp_path / "x").exists()


def test_the_experiments_that_render_keep_their_renders_on_request():
    experiments = load_experiments()
    assert {name for name, e in experiments.items() if e.keeps_renders} == {"pipeline", "planes"}


@pytest.fixture
def renders_probe(monkeypatch):
    """A registered experiment that records the ``renders_dir`` it was given and counts its renders
    there: the harness's part of ``--renders``, without rendering."""
    from simulator.experiments import EXPERIMENTS, Experiment, ExperimentResult

    def run(out_dir, options, *, progress, renders_dir=None):
        made = 0
        if renders_dir is not None:
            renders_dir.mkdir(parents=True, exist_ok=True)
            if not (renders_dir / "render.txt").exists():  # what a later run finds is not made again
                (renders_dir / "render.txt").write_text("a render")
                made = 1
        return ExperimentResult(name="probe", scale=options.scale, rows=({"made": made},))

    monkeypatch.setitem(EXPERIMENTS, "probe", Experiment("probe", run, (), "records renders_dir", keeps_renders=True))
    return run


def test_renders_reach_the_experiment_and_a_later_run_reuses_them(tmp_path, capsys, renders_probe):
    renders = tmp_path / "renders"
    for k, made in enumerate((1, 0)):
        out = tmp_path / f"out-{k}"
        assert sim_cli.main(["experiment", "probe", "--out", str(out), "--renders", str(renders), "--quiet"]) == 0
        assert (out / "table.csv").read_text().splitlines() == ["made", str(made)]
        assert read_json(out / "meta.json")["renders_dir"] == str(renders)
        assert not (out / "render.txt").exists()
    assert (renders / "render.txt").read_text() == "a render"  # kept after both runs
    out = tmp_path / "out-2"
    assert sim_cli.main(["experiment", "probe", "--out", str(out), "--quiet"]) == 0
    assert read_json(out / "meta.json")["renders_dir"] is None


@pytest.mark.parametrize("where", ["inside", "same", "around"])
def test_renders_overlapping_the_output_are_refused_before_any_work(tmp_path, capsys, renders_probe, where):
    out = tmp_path / "out"
    renders = {"inside": out / "renders", "same": out, "around": tmp_path}[where]
    assert sim_cli.main(["experiment", "probe", "--out", str(out), "--renders", str(renders), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "must not hold one another" in err
    assert f"--renders ({str(renders)!r}) and --out ({str(out)!r})" in err
    assert not out.exists()
    assert not (tmp_path / "renders").exists()


def test_renders_for_an_experiment_that_keeps_none_are_refused(tmp_path, capsys):
    out, renders = tmp_path / "out", tmp_path / "renders"
    assert sim_cli.main(["experiment", "fov", "--out", str(out), "--renders", str(renders), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"--renders ({str(renders)!r}) does not apply to experiment 'fov'" in err
    assert "pipeline, planes" in err
    assert not out.exists()
    assert not renders.exists()
