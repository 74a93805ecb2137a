"""Renders kept for reuse (``lfsim experiment --renders DIR``): a kept render is reused only while its
files are as they were rendered (simulator.experiments.kept)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from lfrefract.formats.capture import RAW_NAME
from lfrefract.formats.exr import read_exr
from lfrefract.formats.jsonio import read_json, write_json
from simulator.experiments.kept import differs, record_path
from simulator.experiments.rigstereo import RigSetup, chessboards, experiment_rig, render_capture, with_objects

pytestmark = pytest.mark.render

SETUP = RigSetup(rig="default", calibration_depths_m=(0.3,), px_per_square=10.0, spp=1)


def _mtimes(folder):
    return {p.relative_to(folder).as_posix(): p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def kept(tmp_path_factory):
    """Two kept captures of the tiny default rig, ``a`` and ``b``, each of another board."""
    root = tmp_path_factory.mktemp("renders")
    base = experiment_rig(SETUP)
    boards = chessboards(base, SETUP, 0.3)
    rig = with_objects(base, boards[:1])
    render_capture(rig, root / "a")
    render_capture(with_objects(base, boards[1:2]), root / "b")
    return rig, root


def test_a_kept_render_is_reused_while_its_files_are_unchanged(kept, capsys):
    rig, root = kept
    assert differs(root / "a", {"rig": "another"}) == "rendered for another scene"
    before = _mtimes(root / "a")
    render_capture(rig, root / "a")
    assert _mtimes(root / "a") == before
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("damage", ["another capture's raw", "same size", "added file", "old record"])
def test_a_kept_render_whose_files_changed_is_rendered_again(kept, tmp_path, capsys, damage):
    """The audit's case: a kept capture's raw images replaced by another's (another plane's) was reused,
    because only the scene's signature was compared: its depth row went from 2.08 to 292.5 mm off with
    status ok. Every file's size and SHA-256 is now compared: a changed one is rendered again (said so),
    or refused where the render may not replace the folder."""
    rig, root = kept
    folder = tmp_path / "a"

    shutil.copytree(root / "a", folder)
    shutil.copy(record_path(root / "a"), record_path(folder))
    camera = rig.cameras[0].name
    original = read_exr(folder / camera / RAW_NAME)
    assert differs(folder, read_json(record_path(folder))["signature"]) is None
    if damage in ("another capture's raw", "added file"):
        # Not reused; the render replaces only a folder holding just what it wrote, each file of its size
        # (the project's rule for --overwrite): refused, naming why, with the folder left as it is.
        if damage == "added file":
            (folder / camera / "notes.txt").write_text("mine")
            said = f"'{camera}/notes.txt' was not written by the render"
        else:
            shutil.copy(root / "b" / camera / RAW_NAME, folder / camera / RAW_NAME)
            said = f"'{camera}/{RAW_NAME}' changed ("
        before = {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}
        with pytest.raises(FileExistsError) as refusal:
            render_capture(rig, folder)
        assert f"kept render {str(folder)!r} cannot be reused (" in str(refusal.value)
        assert said in str(refusal.value)
        assert "refusing to replace it" in str(refusal.value)
        assert {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()} == before
        return
    if damage == "same size":
        raw = folder / camera / RAW_NAME
        data = bytearray(raw.read_bytes())
        data[-1] ^= 0xFF
        raw.write_bytes(bytes(data))
        said = f"'{camera}/{RAW_NAME}' changed (same size, another SHA-256)"
    else:  # kept by the version that recorded the signature only
        record = read_json(record_path(folder))
        write_json(record_path(folder), {"signature": record["signature"]})
        said = "kept by an earlier version without file hashes"
    render_capture(rig, folder)
    err = capsys.readouterr().err
    assert f"lfsim: rendered {str(folder)!r} again: " in err, err
    assert said in err, err
    np.testing.assert_array_equal(read_exr(folder / camera / RAW_NAME), original)  # the same scene's render
    assert differs(folder, read_json(record_path(folder))["signature"]) is None
