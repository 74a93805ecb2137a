"""``lfrefract calibrate`` on rendered captures: MLA from a white image, approximation baseline and
port from chessboard captures, and ``synth`` with the estimates."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfrefract import FlatPort, virtual_camera_for
from lfrefract import cli as core_cli
from lfrefract.formats.exr import read_exr
from lfrefract.formats.flatport import read_flat_port
from lfrefract.formats.jsonio import read_json, write_json
from simulator import cli as sim_cli
from simulator.boards import (
    SQUARES,
    board_scene,
    calibration_boards,
    empty_scene,
    in_air_board_scene,
    in_air_boards,
)
from simulator.job import render_job

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
    image, classes = read_exr(out, role="refraction_free"), read_exr(out.with_suffix(".filled.exr"), role="filled")
    assert np.array_equal(np.isfinite(image).all(axis=2), classes > 0)  # NaN: no value, and only there
    assert read_json(out.with_suffix(".json"))["coverage"]["filled_fraction"] == np.mean(classes > 0)


TILT = (25.0, 10.0)


@pytest.fixture(scope="module")
def port_captures(tmp_path_factory) -> list[str]:
    """Six board captures behind the port of :data:`TILT` at 0.2 m (``calibration_boards``)."""
    root = tmp_path_factory.mktemp("port-boards")
    captures = []
    for i, table in enumerate(calibration_boards(TILT, 0.2, virtual_camera_for(empty_scene(TILT).camera))):
        render_job(board_scene(TILT, table, spp=16, seed=i), root / f"board{i}", progress=False, write_previews=False)
        captures.append(str(root / f"board{i}" / "raw.exr"))
    return captures


def _port_square_size_m() -> str:
    return str(calibration_boards(TILT, 0.2, virtual_camera_for(empty_scene(TILT).camera))[0]["square_size_m"])


def test_calibrate_approx_and_port_from_board_captures(port_captures, tmp_path, capsys):
    tilt = TILT
    captures = port_captures
    board_args = ["--squares", *map(str, SQUARES), "--square-size-m", _port_square_size_m()]
    assert core_cli.main(["calibrate", "approx", *captures, *board_args, "--out", str(tmp_path / "approx.json")]) == 0
    approx = read_json(tmp_path / "approx.json")
    assert approx["rms_px"] < 1.0
    # Corners located in the light field determine the port from these six captures at one depth
    # (0.13 deg, 0.06 mm off measured); both files are written.
    out = tmp_path / "port.json"
    assert core_cli.main(["calibrate", "port", *captures, *board_args, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "port normal" in printed
    # Six boards at one depth: the command says what they leave poorly determined and which views to add.
    advice = read_json(out)["advice"]
    stds = {
        "normal": (advice["normal_std_deg"], advice["target_normal_std_deg"]),
        "distance": (advice["distance_std_m"], advice["target_distance_std_m"]),
    }
    assert advice["poorly_determined"] == [name for name, (std, target) in stds.items() if std > target]
    assert all(f"add {k}: a board" in printed for k in range(1, len(advice["views"]) + 1))
    estimated = FlatPort.from_dict(read_json(out)["port"])
    truth = empty_scene(tilt).port
    assert math.degrees(math.acos(min(1.0, float(estimated.normal @ truth.normal)))) < 0.5
    assert abs(estimated.distance_m - truth.distance_m) < 1e-3
    layout = read_flat_port(out.with_suffix(".txt"))
    np.testing.assert_allclose(layout.normal, estimated.normal, atol=1e-12)
    assert layout.distance_m == pytest.approx(estimated.distance_m, rel=1e-12)
    # OpenCV's corners in the central views (0.3-0.4 px off) do not determine it: the calibration
    # says so instead of answering, and writes nothing.
    for extra in (["--corners", "views"], ["--corners", "views", "--subaperture-offset-px", "2"]):
        out = tmp_path / "views.json"
        code = core_cli.main(["calibrate", "port", *captures, *board_args, "--out", str(out), *extra])
        assert code == 2
        assert "do not determine the" in capsys.readouterr().err
        assert not out.exists()
    code = core_cli.main(
        ["calibrate", "port", *captures, *board_args, "--out", str(out), "--subaperture-offset-px", "2"]
    )
    assert code == 2
    assert "needs --corners views" in capsys.readouterr().err
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
    assert "--squares must be at least 4 x 4" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["port", "approx"])
def test_squares_fewer_than_the_boards_are_refused_naming_its_squares(port_captures, tmp_path, capsys, command):
    # --squares 6 4 on these 7 x 5 boards: OpenCV found the 5 x 3 inner corners in a scrambled order
    # and the port fit ended at the end of its distance range, advising to widen it.
    out = tmp_path / "o.json"
    args = ["calibrate", command, *port_captures, "--squares", "6", "4", "--square-size-m", _port_square_size_m()]
    assert core_cli.main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "the chessboard has 7 x 5 squares (6 x 4 inner corners)" in err
    assert "(--squares 7 5)" in err
    assert not out.exists()


def test_boards_captured_in_air_are_refused_by_calibrate_port(tmp_path, capsys):
    # In-air boards with the port's glass given: the fit ran to an end of its distance range (or over
    # its std limits) and advised widening the range; straight lines fit them 7 times better.
    view = virtual_camera_for(empty_scene(TILT).camera)
    tables = in_air_boards(view)[:3]
    captures = []
    for i, table in enumerate(tables):
        render_job(in_air_board_scene(table, seed=i), tmp_path / f"air{i}", progress=False, write_previews=False)
        captures.append(str(tmp_path / f"air{i}" / "raw.exr"))
    sizes = [str(table["square_size_m"]) for table in tables]
    glass = ["--thickness-m", "0.004", "--n-glass", "1.5", "--n-water", "1.333"]
    out = tmp_path / "port.json"
    args = ["calibrate", "port", *captures, "--squares", *map(str, SQUARES), "--square-size-m", *sizes, *glass]
    assert core_cli.main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "the boards show no refraction" in err
    assert "in-air captures (for the camera's calibration: lfrefract calibrate camera)" in err
    assert not out.exists()
    assert not out.with_suffix(".txt").exists()


def test_a_capture_without_a_located_board_is_left_out_and_named(tmp_path, capsys):
    # Five board captures and a sixth of a board with too few squares: the calibration goes on with
    # the five, names the sixth on stderr and lists it in the output; with too few left it stops.
    tilt = (25.0, 10.0)
    view = virtual_camera_for(empty_scene(tilt).camera)
    boards = calibration_boards(tilt, 0.2, view)[:5]
    captures = []
    for i, table in enumerate([*boards, {**boards[0], "squares": [4, 3]}]):
        out = tmp_path / f"board{i}"
        render_job(board_scene(tilt, table, spp=16, seed=i), out, progress=False, write_previews=False)
        captures.append(str(out / "raw.exr"))
    small = captures.pop()
    board_args = ["--squares", *map(str, SQUARES), "--square-size-m", str(boards[0]["square_size_m"])]
    out = tmp_path / "port.json"
    assert core_cli.main(["calibrate", "port", captures[0], small, *captures[1:], *board_args, "--out", str(out)]) == 0
    assert f"{small}: left out: no chessboard of 6 x 4 inner corners, nor a part of one" in capsys.readouterr().err
    written = read_json(out)
    assert written["sources"] == captures  # in the order of the views' poses and residuals
    assert [item["source"] for item in written["left_out"]] == [small]
    assert len(written["view_rms_px"]) == len(captures)
    truth = empty_scene(tilt).port
    assert abs(FlatPort.from_dict(written["port"]).distance_m - truth.distance_m) < 1e-3
    # One board left: under the two a port calibration needs.
    out = tmp_path / "one.json"
    assert core_cli.main(["calibrate", "port", small, captures[0], *board_args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "the board was located in 1 of 2 captures, under the 2 needed" in err
    assert repr(small) in err
    assert not out.exists()
    assert core_cli.main(["calibrate", "port", captures[0], *board_args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "the board was located in 1 of 1 captures, under the 2 needed" in err
    assert "left out" not in err
