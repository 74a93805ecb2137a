"""Data safety (lfrefract.formats.outputs): atomic files, staged output directories with a manifest of their
own files, what --overwrite may replace, stale staging of killed writers, the user's umask."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest

from lfrefract.formats.exr import write_exr
from lfrefract.formats.jsonio import read_json, write_json
from lfrefract.formats.outputs import (
    MANIFEST_NAME,
    ExpectedKind,
    atomic_file,
    output_manifest,
    prepare_output_files,
    refuse_own_inputs,
    remove_stale_staging,
    scratch_directory,
    staged_directory,
)

KIND = "test.output"


def entries(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def own_output(out: Path, kind: str = KIND) -> Path:
    """An output of ``kind`` at ``out``: a file and a nested one, written through staged_directory."""
    with staged_directory(out, kind=kind) as stage:
        (stage / "a.txt").write_text("a")
        (stage / "sub").mkdir()
        (stage / "sub" / "b.txt").write_text("bb")
    return out


def write_then_fail(out: Path, exc: BaseException, **kwargs) -> None:
    """Write a file into a staged ``out`` and raise ``exc`` before the block ends."""
    with staged_directory(out, kind=KIND, **kwargs) as stage:
        (stage / "new.txt").write_text("new")
        raise exc


# =============================================================================== staging
def test_staged_directory_appears_complete_with_its_manifest(tmp_path):
    out = tmp_path / "run"
    with staged_directory(out, kind=KIND) as stage:
        assert stage.parent == tmp_path
        assert not out.exists()  # nothing visible until the block finishes
        (stage / "a.txt").write_text("a")
        (stage / "sub").mkdir()
        (stage / "sub" / "b.txt").write_text("bb")
    assert entries(out) == [MANIFEST_NAME, "a.txt", "sub"]
    assert entries(tmp_path) == ["run"]
    assert output_manifest(out) == {"kind": KIND, "files": {"a.txt": 1, "sub/b.txt": 2}, "directories": ["sub"]}


def test_staged_directory_leaves_nothing_when_the_block_raises(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(RuntimeError, match="boom"):
        write_then_fail(out, RuntimeError("boom"))
    assert entries(tmp_path) == []
    with pytest.raises(KeyboardInterrupt):  # also for exceptions that are not Exceptions (Ctrl-C)
        write_then_fail(out, KeyboardInterrupt())
    assert entries(tmp_path) == []


def test_staged_directory_refuses_a_non_empty_directory_without_overwrite(tmp_path):
    out = own_output(tmp_path / "run")
    with (
        pytest.raises(
            FileExistsError, match=re.escape(f"output directory {str(out)!r} is not empty (pass --overwrite")
        ),
        staged_directory(out, kind=KIND),
    ):
        pytest.fail("the block must not run")
    assert (out / "a.txt").read_text() == "a"


def test_overwrite_replaces_an_own_output_of_the_same_kind(tmp_path):
    out = own_output(tmp_path / "run")
    with staged_directory(out, kind=KIND, overwrite=True) as stage:
        (stage / "new.txt").write_text("new")
        assert (out / "a.txt").exists()  # the old output stays until the new one is complete
    assert entries(out) == [MANIFEST_NAME, "new.txt"]
    assert entries(tmp_path) == ["run"]


def test_overwrite_keeps_the_old_output_when_the_block_fails(tmp_path):
    out = own_output(tmp_path / "run")
    with pytest.raises(KeyError):
        write_then_fail(out, KeyError("x"), overwrite=True)
    assert entries(out) == [MANIFEST_NAME, "a.txt", "sub"]
    assert entries(tmp_path) == ["run"]


def test_empty_directory_is_used_and_a_file_is_refused(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    with staged_directory(empty, kind=KIND) as stage:
        (stage / "x").write_text("x")
    assert entries(empty) == [MANIFEST_NAME, "x"]
    file_out = tmp_path / "file"
    file_out.write_text("not a dir")
    with pytest.raises(FileExistsError, match="exists and is not a directory"), staged_directory(file_out, kind=KIND):
        pytest.fail("the block must not run")
    assert file_out.read_text() == "not a dir"


def test_the_earlier_output_is_back_when_the_final_rename_fails(tmp_path, monkeypatch):
    out = tmp_path / "run"
    with staged_directory(out, kind=KIND) as stage:
        write_json(stage / "meta.json", {"n": 1})
    real_replace = os.replace

    def failing_replace(src, dst):
        if Path(src).name.endswith(".partial") and not Path(src).name.endswith(".old.partial"):
            raise OSError("disk full")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OSError, match="disk full"), staged_directory(out, kind=KIND, overwrite=True) as stage:
        write_json(stage / "meta.json", {"n": 2})
    monkeypatch.setattr(os, "replace", real_replace)
    assert read_json(out / "meta.json")["n"] == 1
    assert entries(tmp_path) == ["run"]  # nothing staged or set aside is left
    with staged_directory(out, kind=KIND, overwrite=True) as stage:
        write_json(stage / "meta.json", {"n": 3})
    assert read_json(out / "meta.json")["n"] == 3
    assert entries(tmp_path) == ["run"]


# =============================================================================== what overwrite may replace
def test_overwrite_refuses_a_folder_with_a_copied_sidecar(tmp_path):
    """The audit's repro: a home folder with a thesis and a copied meta.json (and even a copied
    manifest) is not an output: nothing in it may be deleted."""
    donor = own_output(tmp_path / "donor")
    home = tmp_path / "H"
    (home / "Documents").mkdir(parents=True)
    (home / "Documents" / "thesis.tex").write_text("t")
    write_json(home / "meta.json", {"kind": KIND})
    with (
        pytest.raises(FileExistsError, match="is not an lfrefract output"),
        staged_directory(home, kind=KIND, overwrite=True),
    ):
        pytest.fail("the block must not run")
    (home / MANIFEST_NAME).write_bytes((donor / MANIFEST_NAME).read_bytes())
    with (
        pytest.raises(FileExistsError, match=r"holds what it did not write: 'Documents' \(a folder"),
        staged_directory(home, kind=KIND, overwrite=True),
    ):
        pytest.fail("the block must not run")
    assert (home / "Documents" / "thesis.tex").read_text() == "t"
    assert entries(tmp_path) == ["H", "donor"]


def test_overwrite_refuses_an_output_of_another_kind(tmp_path):
    out = own_output(tmp_path / "rig", kind="lfsim.rig")
    refusal = pytest.raises(FileExistsError, match=re.escape("holds an output of kind 'lfsim.rig', not 'lfsim.render'"))
    with refusal, staged_directory(out, kind="lfsim.render", overwrite=True):
        pytest.fail("the block must not run")
    assert entries(out) == [MANIFEST_NAME, "a.txt", "sub"]


@pytest.mark.parametrize(
    ("change", "named"),
    [
        (lambda out: (out / "notes.txt").write_text("mine"), r"'notes.txt' \(not written by it\)"),
        (lambda out: (out / "sub" / "b.txt").write_text("edited by hand"), r"'sub/b.txt' \(changed: 14 bytes"),
        (lambda out: (out / "mine").mkdir(), r"'mine' \(a folder it did not make\)"),
        (lambda out: ((out / "a.txt").unlink(), (out / "a.txt").symlink_to("/etc/hostname")), r"'a.txt' \(no longer"),
    ],
    ids=["added-file", "edited-file", "added-folder", "file-became-link"],
)
def test_overwrite_refuses_an_own_output_holding_anything_else(tmp_path, change, named):
    out = own_output(tmp_path / "run")
    change(out)
    before = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    with pytest.raises(FileExistsError, match=named), staged_directory(out, kind=KIND, overwrite=True):
        pytest.fail("the block must not run")
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == before


def test_a_deleted_file_does_not_stop_overwrite(tmp_path):
    out = own_output(tmp_path / "run")
    (out / "a.txt").unlink()
    with staged_directory(out, kind=KIND, overwrite=True) as stage:
        (stage / "x").write_text("x")
    assert entries(out) == [MANIFEST_NAME, "x"]


def test_the_current_directory_and_its_parents_are_refused(tmp_path, monkeypatch):
    """``--out .`` crashed with EBUSY after a full render and left two hidden folders."""
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    for given in (".", "..", str(work)):
        refusal = pytest.raises(FileExistsError, match="is the current directory or one of its parents")
        with refusal, staged_directory(given, kind=KIND, overwrite=True):
            pytest.fail("the block must not run")
    assert entries(tmp_path) == ["work"]
    assert entries(work) == []


def test_an_output_directory_holding_an_input_is_refused(tmp_path):
    out = own_output(tmp_path / "run")
    refusal = pytest.raises(FileExistsError, match=r"holds the command's own input")
    with refusal, staged_directory(out, kind=KIND, overwrite=True, inputs=[out / "a.txt"]):
        pytest.fail("the block must not run")
    with pytest.raises(FileExistsError, match=r"is the command's own input"):
        refuse_own_inputs([out / "a.txt"], [out / "sub" / ".." / "a.txt"])


# =============================================================================== killed writers
KILL_INSIDE_BLOCK = """
import os, sys
from lfrefract.formats.outputs import staged_directory
with staged_directory(sys.argv[1], kind="test.output", overwrite=True) as stage:
    (stage / "half.txt").write_text("half")
    print("staged", flush=True)
    os._exit(9)  # as SIGKILL would: no cleanup runs
"""


def test_stale_staging_of_a_killed_writer_is_removed_by_the_next_run(tmp_path):
    out = tmp_path / "run"
    subprocess.run([sys.executable, "-c", KILL_INSIDE_BLOCK, str(out)], check=False, capture_output=True)
    leftovers = [p.name for p in tmp_path.iterdir()]
    assert len(leftovers) == 1
    assert re.fullmatch(r"\.run\..*\.partial", leftovers[0])
    own_output(out)
    assert entries(tmp_path) == ["run"]


def test_live_staging_and_foreign_hidden_folders_are_kept(tmp_path):
    foreign = tmp_path / ".mine.abc.partial"  # a user's own folder that merely looks like staging
    foreign.mkdir()
    (foreign / "x").write_text("x")
    started, release = threading.Event(), threading.Event()

    def writer():
        with staged_directory(tmp_path / "slow", kind=KIND) as stage:
            (stage / "x").write_text("x")
            started.set()
            release.wait(10)

    thread = threading.Thread(target=writer)
    thread.start()
    started.wait(10)
    try:
        assert remove_stale_staging(tmp_path) == []  # held under a lock by a live writer
        live = [p for p in tmp_path.iterdir() if p.name.startswith(".slow.")]
        assert len(live) == 1
    finally:
        release.set()
        thread.join()
    assert entries(tmp_path) == [".mine.abc.partial", "slow"]


def test_an_earlier_output_moved_aside_by_a_killed_writer_is_put_back(tmp_path):
    out = own_output(tmp_path / "run")
    aside = tmp_path / ".run.lfrefract-k3x9q2ab.old.partial"
    os.replace(out, aside)  # where a writer killed between its two renames leaves it
    assert remove_stale_staging(tmp_path) == [aside]
    assert entries(tmp_path) == ["run"]
    assert (out / "a.txt").read_text() == "a"


# =============================================================================== files
def test_atomic_file_names_are_unique_and_cleaned_up(tmp_path):
    target = tmp_path / "map.npz"
    with atomic_file(target) as first, atomic_file(target) as second:
        assert first != second
        assert first.parent == second.parent == tmp_path
        first.write_text("1")
        second.write_text("2")
    assert target.read_text() == "1"  # the outer block finishes last and wins

    def half_write() -> None:
        with atomic_file(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError, match="interrupted"):
        half_write()
    assert entries(tmp_path) == ["map.npz"]
    assert target.read_text() == "1"


def test_scratch_directory_is_removed_on_exit_and_on_an_exception(tmp_path, monkeypatch):
    """The experiments' working folders: in TMPDIR, known to the SIGTERM handler while in use, gone after."""
    from lfrefract.formats import outputs

    monkeypatch.setattr(tempfile, "tempdir", None)  # tempfile caches the directory it chose
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    with scratch_directory(prefix="lfsim-test-") as work:
        assert work.parent == tmp_path
        assert work.name.startswith("lfsim-test-")
        assert outputs._PENDING[work] is True  # terminate_cleanly removes it
        (work / "sub").mkdir()
        (work / "sub" / "render.exr").write_text("x")
    assert entries(tmp_path) == []
    assert work not in outputs._PENDING

    def fail() -> None:
        with scratch_directory(prefix="lfsim-test-") as work:
            (work / "half.exr").write_text("x")
            raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError, match="interrupted"):
        fail()
    assert entries(tmp_path) == []
    with scratch_directory(prefix="lfsim-test-") as work:
        work.rmdir()  # already gone: not an error
    assert entries(tmp_path) == []
    assert work not in outputs._PENDING


def test_atomic_file_refuses_a_directory_and_leaves_nothing(tmp_path):
    (tmp_path / "cache").mkdir()
    with pytest.raises(IsADirectoryError, match="is an existing directory"), atomic_file(tmp_path / "cache"):
        pytest.fail("the block must not run")
    assert entries(tmp_path) == ["cache"]
    assert entries(tmp_path / "cache") == []


@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_outputs_respect_the_umask(tmp_path, mask):
    """mkstemp / mkdtemp make 0600 / 0700; outputs get what open() and mkdir() would give."""
    old = os.umask(mask)
    try:
        write_json(tmp_path / "x.json", {"a": 1})
        with staged_directory(tmp_path / "out", kind=KIND) as stage:
            write_json(stage / "meta.json", {"a": 1})
    finally:
        os.umask(old)
    assert (tmp_path / "x.json").stat().st_mode & 0o777 == 0o666 & ~mask
    assert (tmp_path / "out").stat().st_mode & 0o777 == 0o777 & ~mask
    assert (tmp_path / "out" / "meta.json").stat().st_mode & 0o777 == 0o666 & ~mask
    assert (tmp_path / "out" / MANIFEST_NAME).stat().st_mode & 0o777 == 0o666 & ~mask


def test_prepare_output_files_replaces_only_the_same_kind_and_never_an_input(tmp_path):
    image, sidecar, figure = tmp_path / "a.exr", tmp_path / "a.json", tmp_path / "a.png"
    outputs = {
        image: ExpectedKind(exr_role="refraction_free"),
        sidecar: ExpectedKind(json_kind="lfrefract.synth"),
        figure: ExpectedKind(listed_in=sidecar, listed_kind="lfrefract.synth"),
    }
    prepare_output_files(outputs)  # nothing there yet
    write_exr(image, np.zeros((2, 2), np.float32), role="refraction_free")
    write_json(sidecar, {"kind": "lfrefract.synth", "files": {"figure": "a.png"}})
    figure.write_bytes(b"png")
    with pytest.raises(FileExistsError, match=r"'.*a\.exr' exists \(pass --overwrite"):
        prepare_output_files(outputs)
    prepare_output_files(outputs, overwrite=True)  # all three are this command's own
    write_exr(image, np.zeros((2, 2), np.float32), role="raw")
    with pytest.raises(FileExistsError, match="is not an EXR image of role 'refraction_free'"):
        prepare_output_files(outputs, overwrite=True)
    with pytest.raises(FileExistsError, match="is the command's own input"):
        prepare_output_files({tmp_path / "." / "a.exr": ExpectedKind(exr_role="raw")}, inputs=[image], overwrite=True)
    write_json(sidecar, {"kind": "lfsim.render"})
    with pytest.raises(FileExistsError, match=re.escape("is not a JSON sidecar of kind 'lfrefract.synth'")):
        prepare_output_files({sidecar: outputs[sidecar]}, overwrite=True)
    with pytest.raises(FileExistsError, match="is not a file listed in"):
        prepare_output_files({figure: outputs[figure]}, overwrite=True)
    with pytest.raises(FileExistsError, match="is an existing directory"):
        prepare_output_files({tmp_path: ExpectedKind(json_kind="x")}, overwrite=True)
    assert json.loads(sidecar.read_text())["kind"] == "lfsim.render"  # nothing was written by the checks


# =============================================================================== the warp-map cache
SAVE_LOOP = """
import sys
from lfrefract.synthesis.warp_map import WarpMap
warp = WarpMap.load(sys.argv[1])
for _ in range(15):
    warp.save(sys.argv[2])
"""


@pytest.fixture(scope="module")
def small_map(tmp_path_factory):
    from lfrefract import FlatPort, camera_preset
    from lfrefract.synthesis.warp_map import build_warp_map

    warp = build_warp_map(camera_preset("tiny"), FlatPort.from_degrees(distance_m=0.02, tilt_x_deg=20.0))
    return warp.save(tmp_path_factory.mktemp("map") / "source.npz")


def test_warp_maps_saved_at_once_into_one_cache_never_collide(tmp_path, small_map):
    """Two ``synth --map-cache C`` runs at once crashed (a fixed temporary name, 2 of 6 trials)."""
    from lfrefract.synthesis.warp_map import WarpMap

    target = tmp_path / "cache" / "key.npz"
    runs = [
        subprocess.Popen([sys.executable, "-c", SAVE_LOOP, str(small_map), str(target)], stderr=subprocess.PIPE)
        for _ in range(3)
    ]
    errors = [run.communicate()[1].decode() for run in runs]
    assert [run.returncode for run in runs] == [0, 0, 0], errors
    assert entries(target.parent) == ["key.npz"]  # no temporary file left
    assert WarpMap.load(target).key == WarpMap.load(small_map).key


def test_a_warp_map_saved_over_a_directory_leaves_nothing(tmp_path, small_map):
    from lfrefract.synthesis.warp_map import WarpMap

    (tmp_path / "key.npz").mkdir()
    with pytest.raises(IsADirectoryError, match="is an existing directory"):
        WarpMap.load(small_map).save(tmp_path / "key.npz")
    assert entries(tmp_path) == ["key.npz"]
    assert entries(tmp_path / "key.npz") == []


def test_an_empty_output_folder_keeps_its_identity_and_nested_staging_works(tmp_path):
    """A folder the user made (or the stage of an enclosing output) is filled, not replaced."""
    out = tmp_path / "made-by-me"
    out.mkdir()
    inode = out.stat().st_ino
    with staged_directory(tmp_path / "outer", kind="outer") as outer:
        own_output(outer, kind="inner")  # staged into the (empty) stage of another output
        (outer / "extra.txt").write_text("x")
    assert output_manifest(tmp_path / "outer")["kind"] == "outer"
    assert entries(tmp_path / "outer") == [MANIFEST_NAME, "a.txt", "extra.txt", "sub"]
    own_output(out)
    assert out.stat().st_ino == inode
    assert entries(out) == [MANIFEST_NAME, "a.txt", "sub"]
    assert entries(tmp_path) == ["made-by-me", "outer"]


# =============================================================================== failed writes
_WRITE_UNDER_A_SIZE_LIMIT = """
import resource, signal, sys
from pathlib import Path
from lfrefract.formats.outputs import atomic_file, staged_directory
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (1024, 1024))
target, how = Path(sys.argv[1]), sys.argv[2]
try:
    if how == "file":
        with atomic_file(target) as tmp:
            tmp.write_bytes(b"x" * 4096)
    else:
        with staged_directory(target, kind="test.output") as stage:
            (stage / "big.bin").write_bytes(b"x" * 4096)
except OSError as exc:
    print(type(exc).__name__, exc.errno, exc.filename, "|", exc)
"""


@pytest.mark.parametrize("how", ["file", "directory"])
def test_a_failed_low_level_write_names_the_output(tmp_path, how):
    """A write refused by the system (a full disk; here a real EFBIG under RLIMIT_FSIZE) raised
    ``[Errno 28] No space left on device`` with no path: Python's file writes leave ``filename`` unset.
    The error now names the output (the file, or the output directory for a file written into its stage)."""
    target = tmp_path / ("out.bin" if how == "file" else "out")
    done = subprocess.run(
        [sys.executable, "-c", _WRITE_UNDER_A_SIZE_LIMIT, str(target), how], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    name, code, filename, message = done.stdout.replace(" | ", " ", 1).split(" ", 3)
    assert name == "OSError", done.stdout
    assert int(code) == 27, done.stdout  # EFBIG
    assert filename == str(target), done.stdout
    assert str(target) in message, done.stdout
    assert entries(tmp_path) == []
