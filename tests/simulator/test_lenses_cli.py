"""``lfsim lenses``: one line per main-lens preset, name first, then focal length, f-number, surfaces, source."""

from __future__ import annotations

import re

import pytest

from lfrefract.optics.lens import LENS_PRESETS
from simulator import cli as sim_cli


def test_lenses_lists_every_preset_with_its_first_order_data(capsys):
    assert sim_cli.main(["lenses"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split("\t")[0] for line in lines] == list(LENS_PRESETS)
    for line in lines:
        name, focal, f_number, surfaces, source = line.split("\t")
        lens = LENS_PRESETS[name].build()
        first = lens.first_order()
        focal_mm = float(re.fullmatch(r"f = ([0-9.]+) mm", focal).group(1))
        assert focal_mm == pytest.approx(first.efl_m * 1e3, abs=0.005)
        assert float(f_number.removeprefix("f/")) == pytest.approx(first.f_number, abs=0.005)
        assert surfaces == f"{len(lens.surfaces)} surfaces"
        assert source == lens.source


def test_lenses_help_names_the_columns(capsys):
    with pytest.raises(SystemExit):
        sim_cli.main(["lenses", "--help"])
    assert "surface count" in " ".join(capsys.readouterr().out.split())
