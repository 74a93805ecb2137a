"""``lfsim demo``, the README's main job: files, report and the issue's claims on this run."""

from __future__ import annotations

import pytest

from lfrefract.formats.jsonio import read_json
from lfrefract.formats.ply import read_ply
from simulator import cli as sim_cli

pytestmark = pytest.mark.render


def test_demo_writes_a_report_with_every_method(tmp_path, capsys):
    out = tmp_path / "demo"
    assert sim_cli.main(["demo", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "holds the 2 x bound" in printed
    assert "holds the paper's claim" in printed
    report = (out / "report.md").read_text()
    for name in ("approx far", "approx near", "proposed", "proposed+distortion", "depth-aware", "ideal"):
        assert f"| {name} |" in report
    for figure in ("planes_disparity_zncc.png", "planes_disparity_sgbm.png", "planes_errors.png"):
        assert f"]({figure})" in report
        assert (out / figure).is_file()
    points, colours = read_ply(out / "cloud_proposed.ply")
    assert len(points) > 1000
    assert colours is not None
    assert 0.3 < float(points[:, 2].mean()) < 0.6  # the medium plane (0.45 m) in the left camera frame
    assert read_json(out / "meta.json")["kind"] == "lfsim.demo"
