"""Data safety of the core's commands on real files (issue 12): no command writes over its own
inputs, every command refuses an existing output unless --overwrite is given, and --overwrite
replaces only an output of the same kind."""

from __future__ import annotations

import errno
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lfrefract.cli import main
from lfrefract.formats.exr import read_exr, write_exr
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.formats.outputs import MANIFEST_NAME
from tests.lfrefract.test_cli import commands, make_capture, refused


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def capture(tmp_path) -> Path:
    return make_capture(tmp_path / "R")


@pytest.mark.parametrize(
    ("command", "out", "named"),
    [
        ("naive", "raw.exr", "raw.exr"),  # the capture itself
        ("synth", "raw.exr", "raw.exr"),
        ("synth", "meta.exr", "meta.json"),  # its sidecar OUT.json would be the capture's meta.json
        ("calibrate-mla", "meta.json", "meta.json"),
        ("calibrate-approx", "raw.exr", "raw.exr"),
    ],
)
def test_no_command_writes_over_its_input(capture, capsys, command, out, named):
    """``naive R/raw.exr --out R/raw.exr`` replaced the capture; ``synth R/raw.exr --out
    R/meta.exr`` replaced its meta.json (the sidecar is OUT with .json)."""
    folder = capture.parent
    before = snapshot(folder)
    argv = commands(capture, folder)[command]
    argv[argv.index("--out") + 1] = str(folder / out)
    for extra in ([], ["--overwrite"]):
        err = refused(capsys, [*argv, *extra])
        assert "the command's own input" in err, err
        assert named in err
    assert snapshot(folder) == before


def test_a_capture_given_as_its_folder_is_still_an_input(capture, capsys):
    """With the capture given as its folder R, the commands counted R and R's parent's meta.json as their
    inputs, not R/raw.exr and R/meta.json: only the kind check kept them (the message said "exists")."""
    folder = capture.parent
    before = snapshot(folder)
    for command, out, named in (("naive", "raw.exr", "raw.exr"), ("synth", "meta.exr", "meta.json")):
        for extra in ([], ["--overwrite"]):
            err = refused(capsys, [command, str(folder), "--out", str(folder / out), *extra])
            assert "the command's own input" in err, err
            assert named in err
    assert snapshot(folder) == before


def test_views_never_replaces_the_capture_folder(capture, capsys):
    folder = capture.parent
    before = snapshot(folder)
    argv = commands(capture, folder)["views"]
    argv[argv.index("--out") + 1] = str(folder)
    refused(capsys, [*argv, "--overwrite"])
    assert snapshot(folder) == before


def test_views_overwrite_keeps_a_folder_with_a_copied_views_json(tmp_path, capture, capsys):
    """The audit's repro: a folder with a copied views.json (even with the manifest copied too)."""
    argv = commands(capture, tmp_path / "out")["views"]
    assert main(argv) == 0
    capsys.readouterr()
    home = tmp_path / "V"
    (home / "Documents").mkdir(parents=True)
    (home / "Documents" / "thesis.tex").write_text("t")
    shutil.copy(tmp_path / "out" / "v" / "views.json", home)
    before = snapshot(home)
    target = [*argv[: argv.index("--out") + 1], str(home), *argv[argv.index("--out") + 2 :], "--overwrite"]
    assert "is not an lfrefract output" in refused(capsys, target)
    shutil.copy(tmp_path / "out" / "v" / ".lfrefract-output.json", home)
    assert "'Documents' (a folder it did not make)" in refused(capsys, target)
    assert (home / "Documents" / "thesis.tex").read_text() == "t"
    assert {k: v for k, v in snapshot(home).items() if k != ".lfrefract-output.json"} == before


@pytest.mark.parametrize("command", ["synth", "naive"])  # calibrate mla: tests/simulator/test_data_safety.py
def test_an_existing_output_needs_overwrite_and_of_the_same_kind(tmp_path, capture, capsys, command):
    out = tmp_path / "out"
    argv = commands(capture, out)[command]
    assert main(argv) == 0
    capsys.readouterr()
    written = snapshot(out)
    assert "exists (pass --overwrite" in refused(capsys, argv)
    assert snapshot(out) == written
    assert main([*argv, "--overwrite"]) == 0  # its own earlier output
    capsys.readouterr()
    target = Path(argv[argv.index("--out") + 1])
    if target.suffix == ".exr":
        write_exr(target, np.zeros((4, 4), np.float32), role="raw")  # someone's image under that name
    else:
        write_json(target, {"kind": "notes of mine"})
    foreign = target.read_bytes()
    assert "refusing to replace it" in refused(capsys, [*argv, "--overwrite"])
    assert target.read_bytes() == foreign


def test_synth_companions_are_replaced_only_as_listed_by_its_sidecar(tmp_path, capture, capsys):
    out = tmp_path / "out"
    argv = commands(capture, out)["synth"]
    assert main(argv) == 0
    sidecar = read_json(out / "s.json")
    expected = {"image": "s.exr", "coverage": "s.coverage.exr", "filled": "s.filled.exr", "figure": "s.png"}
    assert sidecar["files"] == expected
    (out / "s.json").unlink()  # the figure is no longer listed anywhere: it may be the user's
    for name in ("s.exr", "s.coverage.exr", "s.filled.exr"):
        (out / name).unlink()
    figure = (out / "s.png").read_bytes()
    assert "is not a file listed in" in refused(capsys, [*argv, "--overwrite"])
    assert (out / "s.png").read_bytes() == figure


def test_an_output_file_that_is_a_directory_or_not_exr_is_refused(tmp_path, capture, capsys):
    argv = commands(capture, tmp_path)["naive"]
    (tmp_path / "n.exr").mkdir()
    assert "is an existing directory" in refused(capsys, [*argv, "--overwrite"])
    argv[argv.index("--out") + 1] = str(tmp_path / "n.json")
    assert "--out must name an .exr file" in refused(capsys, argv)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["R", "n.exr"]


def test_write_failures_are_one_line_and_keep_the_earlier_output(tmp_path, capture, capsys, monkeypatch):
    out = tmp_path / "out"
    argv = commands(capture, out)["naive"]
    assert main(argv) == 0
    earlier = read_exr(out / "n.exr")
    real_replace = os.replace

    def disk_full(src, dst):
        raise OSError(errno.ENOSPC, "No space left on device", str(dst))

    monkeypatch.setattr(os, "replace", disk_full)
    err = refused(capsys, [*argv, "--overwrite"])
    monkeypatch.setattr(os, "replace", real_replace)
    assert "No space left on device" in err
    assert str(out / "n.exr") in err
    assert len(err.strip().splitlines()) == 1
    np.testing.assert_array_equal(read_exr(out / "n.exr"), earlier)
    assert sorted(p.name for p in out.iterdir()) == ["n.exr"]  # no temporary file left
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    argv[argv.index("--out") + 1] = str(blocker / "n.exr")
    err = refused(capsys, argv)
    assert "a-file" in err


def run_with_file_size_limit(argv: list[str], limit_bytes: int, *, cli: str) -> subprocess.CompletedProcess:
    """Run ``cli`` (``"lfrefract"`` or ``"simulator"``) with ``argv`` in a subprocess whose files may not
    grow past ``limit_bytes`` (RLIMIT_FSIZE, SIGXFSZ ignored): every write beyond it really fails,
    as on a full disk (EFBIG instead of ENOSPC), inside OpenEXR, numpy or Python alike."""

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    code = f"import sys; from {cli}.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run(
        [sys.executable, "-c", code, *argv], capture_output=True, text=True, preexec_fn=limit, timeout=600
    )


def test_a_write_that_fails_inside_openexr_is_one_line_naming_the_file(tmp_path, capture):
    """A full disk while OpenEXR wrote gave a traceback and exit 1 (OpenEXR raises RuntimeError); the
    failure is now an OSError naming the output, one line, exit 2, with nothing half-written left."""
    out = tmp_path / "out"
    for command in ("naive", "synth"):
        argv = commands(capture, out)[command]
        target = argv[argv.index("--out") + 1]
        done = run_with_file_size_limit(argv, 4096, cli="lfrefract")
        assert done.returncode == 2, done.stderr
        assert "Traceback" not in done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1, done.stderr
        assert lines[0].startswith("lfrefract: error: "), lines[0]
        assert target in lines[0], lines[0]
        assert os.strerror(errno.EFBIG) in lines[0]
        assert not out.exists() or list(out.iterdir()) == [], sorted(p.name for p in out.iterdir())


def test_ctrl_c_ends_a_command_in_one_line_with_status_130(tmp_path, capture):
    """Ctrl-C used to print a KeyboardInterrupt traceback; now one line, exit 130, the staged output removed."""
    out = tmp_path / "out"
    argv = commands(capture, out)["views"]
    argv[argv.index("--grid") + 1] = "9"  # writing 81 views keeps the output staged for about a second
    code = "import sys; from lfrefract.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.Popen([sys.executable, "-c", code, *argv], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (out.is_dir() and any(p.name.endswith(".partial") for p in out.iterdir())):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["lfrefract: interrupted; unfinished outputs removed"], err
    left = sorted(p.name for p in out.iterdir())
    # Nothing, or (when the signal came as the last rename was done) the complete output.
    assert left == [] or (left == ["v"] and (out / "v" / MANIFEST_NAME).is_file()), left


def test_synth_takes_the_flat_port_txt_that_calibrate_port_writes(tmp_path, capsys):
    """``--port port.txt`` (the calibmar / Refractive COLMAP layout the project writes) was "not valid JSON"."""
    from lfrefract.formats.flatport import write_flat_port
    from tests.lfrefract.test_cli import PORT

    raw = make_capture(tmp_path / "R", port=None)
    port_txt = write_flat_port(tmp_path / "port.txt", PORT)
    argv = commands(raw, tmp_path / "out")["synth"]
    assert main([*argv, "--port", str(port_txt)]) == 0
    assert read_json(tmp_path / "out" / "s.json")["port"]["distance_m"] == pytest.approx(PORT.distance_m)
    capsys.readouterr()
    bad = {
        "utf16.txt": ("# Nx Ny Nz\n0 0 1 0.02 0 1 1.5 1.33\n".encode("utf-16"), "is not UTF-8 text"),
        "range.txt": (b"0 0 1 0.02 0 1 1e300 1.33\n", "is not a valid port"),
        "big.txt": (b"#" * 70000, "not a flat port (at most"),
    }
    for name, (content, message) in bad.items():
        (tmp_path / name).write_bytes(content)
        assert message in refused(capsys, [*argv, "--overwrite", "--port", str(tmp_path / name)])
