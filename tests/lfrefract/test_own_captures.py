"""docs/own-captures.md runs as written: every block, in order, in one folder, on a raw image and a white image
of the tiny camera drawn with numpy (no renderer); and what the blocks write agrees with itself."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lfrefract import camera_preset, virtual_camera_for
from lfrefract.formats.capture import read_capture
from lfrefract.formats.exr import read_exr, write_exr
from lfrefract.formats.jsonio import read_json
from lfrefract.formats.paramfile import read_camera_file, read_port_file
from tests.lfrefract.test_calibration_mla import synthetic_white

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "own-captures.md"
TINY = camera_preset("tiny")
BLOCK = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```$", re.MULTILINE | re.DOTALL)
MAX_BLOCK_LINES = 20


def blocks() -> list[tuple[str, str, str]]:
    """(language, what follows it on the fence line, body) of every fenced block of the page, in order."""
    return [(m.group(1), m.group(2).strip(), m.group(3)) for m in BLOCK.finditer(DOC.read_text(encoding="utf-8"))]


def test_the_page_has_only_blocks_the_test_runs_and_each_is_short():
    found = blocks()
    assert DOC.read_text(encoding="utf-8").count("```") == 2 * len(found)  # no fence the pattern missed
    assert {language for language, _, _ in found} == {"toml", "bash", "python"}
    for language, name, body in found:
        assert (language == "toml") == bool(name), f"a toml block names its file, no other block does: {body[:60]!r}"
        code = [line for line in body.splitlines() if line.strip() and not line.lstrip().startswith("#")]
        assert len(code) < MAX_BLOCK_LINES, f"a block of {len(code)} lines: {body[:60]!r}"


def run_block(language: str, body: str, folder: Path) -> str:
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
        "MPLBACKEND": "Agg",
    }
    command = ["bash", "-euo", "pipefail", "-c", body] if language == "bash" else [sys.executable, "-c", body]
    done = subprocess.run(command, cwd=folder, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, f"{language} block failed ({done.returncode}):\n{body}\n{done.stdout}\n{done.stderr}"
    return done.stdout


@pytest.fixture(scope="module")
def ran(tmp_path_factory) -> tuple[Path, list[str]]:
    """The folder after every block of the page has run in it, and what each block printed."""
    folder = tmp_path_factory.mktemp("own")
    (folder / "my").mkdir()
    white = synthetic_white(TINY)  # the micro-image discs of the tiny camera
    texture = 0.3 + 0.6 * np.random.default_rng(5).random(white.shape)
    write_exr(folder / "my" / "white.exr", np.repeat(white[..., None], 3, axis=2).astype(np.float32), role="raw")
    write_exr(folder / "my" / "raw.exr", (white * texture)[..., None].repeat(3, axis=2).astype(np.float32), role="raw")
    printed = []
    for language, name, body in blocks():
        if language == "toml":
            (folder / name).write_text(body, encoding="utf-8")
        else:
            printed.append(run_block(language, body, folder))
    return folder, printed


def test_the_files_of_the_page_are_the_camera_and_port_they_say(ran):
    folder, _ = ran
    assert read_camera_file(folder / "camera.toml") == dataclasses.replace(TINY, name="mine")
    assert read_port_file(folder / "port.toml") == read_port_file(ROOT / "docs" / "examples" / "port-tilted.toml")
    assert read_port_file(folder / "port.toml") == read_port_file(folder / "port.toml")
    normal = read_port_file(ROOT / "docs" / "examples" / "port-normal.toml")
    np.testing.assert_allclose(normal.normal, read_port_file(folder / "port.toml").normal, atol=1e-15)


def test_the_command_line_and_python_give_one_refraction_free_image(ran):
    folder, printed = ran
    output = virtual_camera_for(TINY)
    image = read_exr(folder / "my" / "rf.exr", role="refraction_free")
    assert image.shape == (output.height_px, output.width_px, 3)
    assert read_exr(folder / "my" / "rf.coverage.exr", role="coverage").shape == image.shape[:2]
    assert read_json(folder / "my" / "rf.json")["K"] == output.K.tolist()  # as the page says
    assert (folder / "my" / "rf.png").is_file()
    assert any((folder / "my" / "maps").iterdir())  # the map kept for the next capture
    np.testing.assert_array_equal(read_exr(folder / "my" / "rf2.exr", role="refraction_free"), image)
    np.testing.assert_array_equal(read_exr(folder / "my" / "rf-python.exr", role="refraction_free"), image)
    assert read_exr(folder / "my" / "naive.exr").shape[:2] == image.shape[:2]
    assert f"{output.width_px} x {output.height_px} px, exact where" in "".join(printed)
    assert "exact coverage" in printed[0]
    classes = read_exr(folder / "my" / "rf.filled.exr", role="filled")
    assert np.array_equal(np.isfinite(image).all(axis=2), classes > 0)  # NaN only where no value
    assert np.nanmax(image) > 0


def test_the_white_image_gives_the_camera_its_lattice_and_the_capture_folder_keeps_it(ran):
    folder, printed = ran
    calibrated = read_camera_file(folder / "camera-calibrated.toml")
    assert calibrated.sensor == TINY.sensor
    assert calibrated.mla.grid == "hex"
    assert calibrated.mla.pitch_m == pytest.approx(TINY.mla.pitch_m, rel=1e-3)
    assert "hex lattice, pitch 10.33" in "".join(printed)  # the tiny camera's micro-image pitch, 10.333 px
    capture = read_capture(folder / "my" / "capture" / "raw.exr")
    assert capture.camera == calibrated
    assert capture.port == read_port_file(folder / "port.toml")
    from_folder = read_exr(folder / "my" / "rf-capture.exr", role="refraction_free")
    with_mla = read_exr(folder / "my" / "rf-mla.exr", role="refraction_free")
    assert from_folder.shape == with_mla.shape
    # The same calibration by two routes: --mla (the lattice through MLA.json, in pixels) and the camera
    # file written from it (in metres); the two cameras differ in the last digits, the images by 1e-5.
    via_json = read_camera_file(folder / "my" / "mla.json")  # calibrate mla writes the camera too
    assert via_json.mla.pitch_m == pytest.approx(calibrated.mla.pitch_m, rel=1e-9)
    np.testing.assert_allclose(from_folder, with_mla, rtol=1e-4, atol=1e-6)
