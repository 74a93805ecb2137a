"""``lfsim experiment``: the command line of the experiment harness."""

from __future__ import annotations

from lfrefract.formats.jsonio import read_json
from simulator import cli as sim_cli
from simulator.experiments import load_experiments


def test_experiments_are_registered():
    assert {"planes", "averaging", "fov"} <= set(load_experiments())


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
