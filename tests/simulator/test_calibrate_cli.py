"""``lfrefract calibrate`` on rendered captures: MLA from a white image, approximation baseline and
port from chessboard captures, and ``synth`` with the estimates."""

from __future__ import annotations

import numpy as np
import pytest

from lfrefract import cli as core_cli
from lfrefract import virtual_camera_for
from lfrefract.io import read_exr, read_json, write_json
from simulator import cli as sim_cli
from simulator.job import render_job
from tests.simulator.chessboards import SQUARES, board_scene, calibration_boards, empty_scene

pytestmark = pytest.mark.render


def test_calibrate_mla_then_synthesize_with_it_and_a_port_file(tmp_path, capsys):
    white, scene = tmp_path / "white", tmp_path / "scene"
    for name, out in (("white", white), ("default", scene)):
        assert sim_cli.main(["render", name, "--out", str(out), "--spp", "4", "--quiet", "--no-previews"]) == 0
    assert core_cli.main(["calibrate", "mla", str(white / "raw.exr"), "--out", str(tmp_path / "mla.json")]) == 0
    assert "hex lattice" in capsys.readouterr().out
    mla = read_json(tmp_path / "mla.json")
    truth = read_json(white / "meta.json")["camera"]
    assert mla["mla"]["grid"] == "hex"
    assert mla["camera"]["mla"]["pitch_m"] == pytest.approx(truth["mla"]["pitch_m"], rel=1e-4)
    # A port file as `calibrate port` writes it (here the truth), and the estimated MLA.
    write_json(tmp_path / "port.json", {"port": read_json(scene / "meta.json")["port"]})
    out = tmp_path / "synth.exr"
    args = ["synth", str(scene / "raw.exr"), "--out", str(out), "--quiet"]
    assert core_cli.main([*args, "--port", str(tmp_path / "port.json"), "--mla", str(tmp_path / "mla.json")]) == 0
    assert read_json(out.with_suffix(".json"))["camera"]["mla"] == mla["camera"]["mla"]
    assert np.isfinite(read_exr(out, role="refraction_free")).all()


def test_calibrate_approx_and_port_from_board_captures(tmp_path, capsys):
    tilt = (25.0, 10.0)
    view = virtual_camera_for(empty_scene(tilt).camera)
    captures = []
    for i, table in enumerate(calibration_boards(tilt, 0.2, view)):
        out = tmp_path / f"board{i}"
        render_job(board_scene(tilt, table, spp=16, seed=i), out, progress=False, write_previews=False)
        captures.append(str(out / "raw.exr"))
    board_args = [
        "--squares",
        *map(str, SQUARES),
        "--square-size-m",
        str(calibration_boards(tilt, 0.2, view)[0]["square_size_m"]),
    ]
    assert core_cli.main(["calibrate", "approx", *captures, *board_args, "--out", str(tmp_path / "approx.json")]) == 0
    approx = read_json(tmp_path / "approx.json")
    assert approx["rms_px"] < 1.0
    # The central views of this small camera locate corners to ~0.35 px, which does not determine
    # the port (docs/calibration.md): the calibration says so instead of answering.
    for extra in ([], ["--subaperture-offset-px", "2"]):  # central views, and five views per board
        out = ["--out", str(tmp_path / "port.json")]
        code = core_cli.main(["calibrate", "port", *captures, *board_args, *out, *extra])
        assert code == 2
        assert "do not determine the" in capsys.readouterr().err
        assert not (tmp_path / "port.json").exists()
    assert (
        core_cli.main(
            [
                "calibrate",
                "port",
                *captures[:2],
                "--squares",
                "1",
                "5",
                "--square-size-m",
                "0.01",
                "--out",
                str(tmp_path / "x.json"),
            ]
        )
        == 2
    )
    assert "--squares must be at least 2 x 2" in capsys.readouterr().err
