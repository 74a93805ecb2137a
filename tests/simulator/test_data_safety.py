"""Data safety of the simulator's commands, on real folders through the real CLIs (issue 12):
--overwrite replaces only an earlier output of the same kind holding nothing but its own files,
``--out .`` is refused, and failed writes end in one line with the earlier output kept."""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lfrefract import cli as core_cli
from lfrefract.formats.capture import RAW_NAME
from lfrefract.formats.outputs import MANIFEST_NAME
from simulator import cli
from tests.lfrefract.test_cli_outputs import run_with_file_size_limit

pytestmark = pytest.mark.render

QUICK = ["--spp", "1", "--quiet", "--no-previews"]


def tree(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` with its content (hidden ones too)."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """A real render (the white scene) and a real rig output, rendered once at 1 spp."""
    base = tmp_path_factory.mktemp("outputs")
    assert cli.main(["render", "white", "--out", str(base / "render"), *QUICK]) == 0
    assert cli.main(["rig", "--out", str(base / "rig"), *QUICK]) == 0
    return base


def thesis_folder(root: Path) -> Path:
    home = root / "H"
    (home / "Documents").mkdir(parents=True)
    (home / "Documents" / "thesis.tex").write_text("t")
    return home


def refused(capsys, argv: list[str], *, main=cli.main) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    return err


def test_render_overwrite_keeps_a_home_folder_with_a_copied_meta_json(tmp_path, outputs, capsys):
    home = thesis_folder(tmp_path)
    shutil.copy(outputs / "render" / "meta.json", home / "meta.json")
    before = tree(home)
    err = refused(capsys, ["render", "white", "--out", str(home), "--overwrite", *QUICK])
    assert "is not an lfrefract output" in err
    # Even with the manifest copied as well, the thesis is a file the render did not write.
    shutil.copy(outputs / "render" / MANIFEST_NAME, home / MANIFEST_NAME)
    err = refused(capsys, ["render", "white", "--out", str(home), "--overwrite", *QUICK])
    assert "'Documents' (a folder it did not make)" in err
    assert (home / "Documents" / "thesis.tex").read_text() == "t"
    assert {k: v for k, v in tree(home).items() if k != MANIFEST_NAME} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["H"]


def test_a_calibration_written_as_meta_json_does_not_make_a_folder_replaceable(tmp_path, outputs, capsys):
    home = thesis_folder(tmp_path)
    white = outputs / "render" / "raw.exr"
    mla = ["calibrate", "mla", str(white), "--out", str(home / "meta.json")]
    assert core_cli.main(mla) == 0
    capsys.readouterr()
    before = tree(home)
    refused(capsys, ["render", "white", "--out", str(home), "--overwrite", *QUICK])
    assert tree(home) == before
    # The calibration itself: refused without --overwrite, replaced with it, never over a foreign JSON.
    assert "exists (pass --overwrite" in refused(capsys, mla, main=core_cli.main)
    assert core_cli.main([*mla, "--overwrite"]) == 0
    capsys.readouterr()
    shutil.copy(outputs / "render" / "meta.json", home / "meta.json")  # a render's sidecar under that name
    err = refused(capsys, [*mla, "--overwrite"], main=core_cli.main)
    assert "is not a JSON sidecar of kind 'lfrefract.calibrate.mla'" in err
    assert (home / "meta.json").read_bytes() == (outputs / "render" / "meta.json").read_bytes()


def test_outputs_of_other_kinds_are_never_replaced(tmp_path, outputs, capsys):
    render, rig = tmp_path / "render", tmp_path / "rig"
    shutil.copytree(outputs / "render", render)
    shutil.copytree(outputs / "rig", rig)
    before = {"render": tree(render), "rig": tree(rig)}
    err = refused(capsys, ["render", "white", "--out", str(rig), "--overwrite", *QUICK])
    assert "holds an output of kind 'lfsim.rig', not 'lfsim.render'" in err
    err = refused(capsys, ["rig", "--out", str(render), "--overwrite", *QUICK])
    assert "holds an output of kind 'lfsim.render', not 'lfsim.rig'" in err
    err = refused(capsys, ["experiment", "fov", "--out", str(render), "--overwrite", "--quiet"])
    assert "not 'lfsim.experiment.fov'" in err
    err = refused(capsys, ["demo", "--out", str(rig), "--overwrite", "--quiet"])
    assert "not 'lfsim.demo'" in err
    assert {"render": tree(render), "rig": tree(rig)} == before


def test_the_demo_refuses_an_existing_output_unless_told(tmp_path, capsys):
    out = tmp_path / "demo"
    out.mkdir()
    (out / "report.md").write_text("my notes")
    err = refused(capsys, ["demo", "--out", str(out), "--quiet"])
    assert "is not empty (pass --overwrite" in err
    refused(capsys, ["demo", "--out", str(out), "--quiet", "--overwrite"])
    assert (out / "report.md").read_text() == "my notes"


def test_render_overwrite_replaces_its_own_earlier_output(tmp_path, outputs, capsys):
    out = tmp_path / "render"
    shutil.copytree(outputs / "render", out)
    refused(capsys, ["render", "white", "--out", str(out), *QUICK])
    assert cli.main(["render", "white", "--out", str(out), "--overwrite", "--seed", "7", *QUICK]) == 0
    assert '"seed": 7' in (out / "meta.json").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["render"]


def test_out_dot_is_refused_before_rendering(tmp_path, monkeypatch, capsys):
    """``--out .`` used to render in full, then crash with EBUSY leaving two hidden folders."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "scene-notes.txt").write_text("mine")
    for out in (".", "./", str(tmp_path)):
        err = refused(capsys, ["render", "white", "--out", out, "--overwrite", *QUICK])
        assert "is the current directory or one of its parents" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene-notes.txt"]


def test_write_failures_are_one_line_and_keep_the_earlier_output(tmp_path, outputs, monkeypatch, capsys):
    out = tmp_path / "render"
    shutil.copytree(outputs / "render", out)
    before = tree(out)
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    err = refused(capsys, ["render", "white", "--out", str(blocker / "sub"), *QUICK])
    assert "a-file" in err
    real_replace = os.replace

    def disk_full(src, dst):
        if Path(dst) == out and not Path(src).name.endswith(".old.partial"):  # the new output's rename
            raise OSError(errno.ENOSPC, "No space left on device", str(dst))
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", disk_full)
    err = refused(capsys, ["render", "white", "--out", str(out), "--overwrite", *QUICK])
    assert "No space left on device" in err
    assert str(out) in err
    monkeypatch.setattr(os, "replace", real_replace)
    assert tree(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file", "render"]


def test_a_full_disk_during_a_render_is_one_line_naming_the_file(tmp_path):
    """OpenEXR's failed write (RuntimeError) came out of ``lfsim render`` as a traceback with exit 1.
    A real failing write (files limited to 20 kB: the raw image is 115 kB) ends in one line naming the
    file, exit 2, and neither the output nor its staging folder is left."""
    out = tmp_path / "render"
    done = run_with_file_size_limit(["render", "white", "--out", str(out), *QUICK], 20_000, cli="simulator")
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("lfsim: error: "), lines[0]
    assert str(out / RAW_NAME) in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == []


def _terminate_lfsim(args: list[str], ready, *, env: dict | None = None, signum: int = signal.SIGTERM) -> str:
    """Run ``lfsim ARGS``, send it ``signum`` (SIGTERM) once ``ready()`` holds (within 60 s), check that it
    ended by the signal (status 128 + signum) with one line and no traceback; return the line."""
    code = "import sys; from simulator.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.Popen(
        [sys.executable, "-c", code, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env
    )
    deadline = time.monotonic() + 60
    while not ready():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.02)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signum, err.decode()
    lines = err.decode().strip().splitlines()
    assert len(lines) == 1, err.decode()
    return lines[0]


def test_sigterm_during_a_render_leaves_nothing_behind(tmp_path):
    """SIGTERM used to end the process without cleanup, leaving a hidden ``.NAME.*.partial``."""
    out = tmp_path / "render"
    _terminate_lfsim(
        ["render", "--out", str(out), "--spp", "64", "--quiet", "--no-previews"],
        lambda: any(p.name.endswith(".partial") for p in tmp_path.iterdir()),
    )
    assert list(tmp_path.iterdir()) == []


def test_ctrl_c_during_a_render_is_one_line_and_leaves_nothing_behind(tmp_path):
    """Ctrl-C raised KeyboardInterrupt wherever the main thread was: once inside Dr.Jit's import, which
    ended in a traceback of an ImportError and a NameError, exit 1. Now: one line, exit 130, no staging."""
    out = tmp_path / "render"
    for delay_s in (0.0, 0.5):  # while loading the renderer, and while rendering
        started = time.monotonic()
        line = _terminate_lfsim(
            ["render", "--out", str(out), "--spp", "64", "--quiet", "--no-previews"],
            lambda started=started, delay_s=delay_s: (
                any(p.name.endswith(".partial") for p in tmp_path.iterdir()) and time.monotonic() - started > delay_s
            ),
            signum=signal.SIGINT,
        )
        assert line == "lfsim: interrupted; unfinished outputs removed"
        assert list(tmp_path.iterdir()) == []


def test_ctrl_c_during_an_experiment_with_kept_renders_says_it_resumes(tmp_path):
    scratch, out, renders = tmp_path / "tmp", tmp_path / "out", tmp_path / "renders"
    scratch.mkdir()
    line = _terminate_lfsim(
        ["experiment", "planes", "--scale", "tiny", "--out", str(out), "--renders", str(renders), "--quiet"],
        lambda: renders.is_dir() and any(p.name.endswith(".partial") for p in renders.rglob("*")),
        env={**os.environ, "TMPDIR": str(scratch)},
        signum=signal.SIGINT,
    )
    assert line == "lfsim: interrupted; unfinished outputs removed; run again to resume"
    assert list(scratch.iterdir()) == []
    assert not [p for p in renders.rglob("*") if p.name.endswith((".partial", ".tmp"))]


def test_sigterm_during_an_experiment_removes_its_temporary_folder(tmp_path):
    """The experiments' scratch folders (``tempfile.TemporaryDirectory``) were unknown to the SIGTERM
    handler: a terminated ``lfsim experiment pipeline --scale illum`` left 6 GB in /tmp every time."""
    scratch, out = tmp_path / "tmp", tmp_path / "out"
    scratch.mkdir()
    _terminate_lfsim(
        ["experiment", "planes", "--scale", "tiny", "--out", str(out), "--quiet"],
        lambda: any(p.name.startswith("lfsim-planes-") for p in scratch.iterdir()),
        env={**os.environ, "TMPDIR": str(scratch)},
    )
    assert list(scratch.iterdir()) == []
    assert not out.exists() or list(out.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) in (["tmp"], ["out", "tmp"])
