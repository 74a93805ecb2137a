"""``lfrefract calibrate``'s board options and inputs, refused at once (before any corner is looked
for) with a message naming the option or the files: no render needed."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from lfrefract.cli import build_parser
from tests.lfrefract.test_cli import assert_says, make_capture, refused, textured_raw


def _board(raw, out, *, squares=("5", "4"), size=("0.01",), target="approx"):
    return ["calibrate", target, *map(str, raw), "--squares", *squares, "--square-size-m", *size, "--out", str(out)]


@pytest.mark.parametrize("squares", [("2", "2"), ("3", "3")])
@pytest.mark.parametrize("target", ["approx", "port", "camera"])
def test_a_board_too_small_for_the_detector_names_squares(tmp_path, capsys, target, squares):
    # 2 x 2 squares passed the check and failed later naming "pattern", a Python parameter; 3 x 3
    # squares (2 x 2 inner corners) passed and failed in OpenCV's detector, which needs 3 a side.
    raw = make_capture(tmp_path / "cap")
    err = refused(capsys, _board([raw] * 3, tmp_path / "c.json", squares=squares, target=target))
    assert_says(err, "--squares must be at least 4 x 4", f"got [{squares[0]}, {squares[1]}]")
    assert "pattern" not in err


@pytest.mark.parametrize("size", ["1e9", "1e-5", "nan", "-0.01"])
@pytest.mark.parametrize("target", ["approx", "port", "camera"])
def test_an_implausible_square_size_is_refused_at_once(tmp_path, capsys, target, size):
    # 1e9 was refused after minutes of corner detection as "use more views".
    raw = make_capture(tmp_path / "cap")
    err = refused(capsys, _board([raw], tmp_path / "c.json", size=(size,), target=target))
    assert_says(err, "--square-size-m", "between 0.0001 and 1 m")


@pytest.mark.parametrize("target", ["approx", "port", "camera"])
@pytest.mark.parametrize("how", ["same path", "copy", "link"])
def test_one_capture_given_twice_is_refused_naming_both(tmp_path, capsys, target, how):
    # calibrate camera A0 A0 A0 wrote k1 -0.54, k2 0.82 (truth 0); approx W0 W0 W0 fx 2009 px (truth 240).
    first = make_capture(tmp_path / "a")
    other = make_capture(tmp_path / "b", raw=textured_raw(seed=1))
    if how == "same path":
        again = first
    elif how == "copy":
        shutil.copytree(first.parent, tmp_path / "c")
        again = tmp_path / "c" / "raw.exr"
    else:
        (tmp_path / "c").mkdir()
        os.symlink(first, tmp_path / "c" / "raw.exr")
        shutil.copy(first.parent / "meta.json", tmp_path / "c" / "meta.json")
        again = tmp_path / "c" / "raw.exr"
    err = refused(capsys, _board([first, other, again], tmp_path / "c.json", target=target))
    assert_says(err, f"{str(first)!r} and {str(again)!r} are the same capture", "give each capture once")
    assert not (tmp_path / "c.json").exists()


def test_calibrate_mla_on_a_white_with_nan_says_what_to_do(tmp_path, capsys):
    # It advised --nonfinite, which calibrate mla does not have.
    white = textured_raw()
    white[3, 4] = np.nan
    raw = make_capture(tmp_path / "cap", raw=white)
    err = refused(capsys, ["calibrate", "mla", str(raw), "--out", str(tmp_path / "mla.json")])
    assert_says(err, repr(str(raw)), "3 NaN pixel values (in 1 pixels)", "a white image must record every pixel")
    assert "--nonfinite" not in err


@pytest.mark.parametrize("target", ["approx", "port", "camera"])
def test_board_commands_take_the_nonfinite_option_they_advise(tmp_path, capsys, target):
    board = textured_raw()
    board[3, 4] = np.nan
    raw = make_capture(tmp_path / "cap", raw=board)
    err = refused(capsys, _board([raw] * 1, tmp_path / "c.json", target=target))
    assert_says(err, "pass --nonfinite mask")
    args = build_parser().parse_args([*_board([raw], tmp_path / "c.json", target=target), "--nonfinite", "mask"])
    assert args.nonfinite == "mask"


def test_calibrate_port_takes_the_distance_range_it_advises(tmp_path):
    raw = make_capture(tmp_path / "cap")
    argv = [*_board([raw], tmp_path / "c.json", target="port"), "--distance-range-m", "0.001", "0.5"]
    assert build_parser().parse_args(argv).distance_range_m == [0.001, 0.5]


@pytest.mark.parametrize("target", ["approx", "port", "camera"])
def test_more_squares_than_the_central_view_holds_are_refused_at_once(tmp_path, capsys, target):
    # 1000 x 1000 squares were searched for in every capture and left each out as "not found".
    raw = make_capture(tmp_path / "cap")
    err = refused(capsys, _board([raw], tmp_path / "c.json", squares=("1000", "1000"), target=target))
    assert_says(err, "--squares 1000 1000", "cannot be located in the 92 x 69 px central view", "at least 3 px")


@pytest.mark.parametrize("value", [0.0, 0.5])
def test_calibrate_mla_on_a_white_with_no_contrast_names_the_file(tmp_path, capsys, value):
    # "white has no contrast: every pixel is 0.0" named no file.
    raw = make_capture(tmp_path / "cap", raw=np.full_like(textured_raw(), value))
    err = refused(capsys, ["calibrate", "mla", str(raw), "--out", str(tmp_path / "mla.json")])
    assert_says(err, repr(str(raw)), "no contrast")
