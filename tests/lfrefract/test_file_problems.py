"""A path that is no readable file is named for what it is: missing, a folder, a symbolic link loop or a
link to nothing (the audit found a loop given as an output a traceback, and as an input "no such
file"), by every reader and by both command lines."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from lfrefract import cli
from lfrefract.errors import FileFormatError
from lfrefract.formats.exr import read_exr
from lfrefract.formats.flatport import read_flat_port
from lfrefract.formats.jsonio import read_json
from lfrefract.formats.pfm import read_pfm
from lfrefract.formats.viewstack import read_view_stack
from lfrefract.validate import file_problem
from tests.lfrefract.test_cli import make_capture

READERS = {
    "read_exr": read_exr,
    "read_json": read_json,
    "read_flat_port": read_flat_port,
    "read_pfm": read_pfm,
    "read_view_stack": read_view_stack,
}


def _paths(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    """Each kind of unreadable path, and what its message must say."""
    loop = tmp_path / "loop.exr"
    loop.symlink_to(loop)
    dangling = tmp_path / "dangling.exr"
    dangling.symlink_to(tmp_path / "gone.exr")
    folder = tmp_path / "folder.exr"
    folder.mkdir()
    return {
        "missing": (tmp_path / "none.exr", "no such file"),
        "loop": (loop, "symbolic link loop"),
        "dangling": (dangling, "symbolic link to nothing"),
        "folder": (folder, "is a directory, not a regular file"),
    }


def test_file_problem_names_each_kind_and_passes_a_file(tmp_path):
    for path, says in _paths(tmp_path).values():
        problem = file_problem(path)
        assert problem is not None
        assert says in problem
        assert str(path) in problem
    (tmp_path / "f.exr").write_bytes(b"x")
    assert file_problem(tmp_path / "f.exr") is None


@pytest.mark.parametrize("reader", sorted(READERS))
def test_every_reader_names_what_the_path_is(tmp_path, reader):
    for name, (path, says) in _paths(tmp_path).items():
        if reader == "read_view_stack" and name == "folder":
            continue  # a folder is a view stack's own form: it names the stack.npz inside it
        with pytest.raises(FileFormatError, match=says):
            READERS[reader](path)


def test_a_raw_image_that_is_a_link_loop_is_named_so(tmp_path, capsys):
    loop = tmp_path / "raw.exr"
    loop.symlink_to(loop)
    assert cli.main(["naive", str(loop), "--out", str(tmp_path / "o.exr")]) == 2
    err = capsys.readouterr().err
    assert "symbolic link loop" in err
    assert "no such file" not in err


@pytest.mark.parametrize("command", ["lfrefract", "lfsim"])
def test_an_output_that_is_a_link_loop_is_one_line_naming_it(tmp_path, command):
    """``Path.resolve`` raised RuntimeError on the loop: a traceback with exit 1."""
    out = tmp_path / ("o.exr" if command == "lfrefract" else "r")
    out.symlink_to(out)
    if command == "lfrefract":
        raw = make_capture(tmp_path)
        argv = [sys.executable, "-m", "lfrefract", "naive", str(raw), "--out", str(out), "--overwrite"]
    else:
        argv = [sys.executable, "-m", "simulator.cli", "render", "--out", str(out), "--spp", "1", "--quiet"]
    result = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    assert "symbolic link loop" in result.stderr
    assert str(out) in result.stderr
    assert out.is_symlink()
