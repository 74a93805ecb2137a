"""The README stays true: CI runs exactly the documented test command, and "Python in 15 lines" runs as
written (15 lines at most) and prints what the README says it printed, to the rounding of the render."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import pytest

from lfrefract import camera_preset, virtual_camera_for

ROOT = Path(__file__).resolve().parents[1]


def test_ci_runs_the_readme_test_command():
    ci_lines = [line for line in (ROOT / ".ci" / "run").read_text().splitlines() if line.startswith("python3 -m venv")]
    assert len(ci_lines) == 1
    assert ci_lines[0] in (ROOT / "README.md").read_text()


def test_readme_main_job_command_runs_the_demo():
    readme = (ROOT / "README.md").read_text()
    assert "python3 -m venv .venv && .venv/bin/pip install -q -e '.[sim]' && .venv/bin/lfsim demo\n" in readme


def python_block() -> str:
    """The code block of the README's "Python in 15 lines" section."""
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## Python in 15 lines") :]
    section = section[: section.index("\n## ", 1)]
    blocks = re.findall(r"^```python\n(.*?)^```$", section, re.MULTILINE | re.DOTALL)
    assert len(blocks) == 1
    return blocks[0]


def test_the_python_section_is_at_most_15_lines():
    lines = [line for line in python_block().splitlines() if line.strip()]
    assert len(lines) <= 15


@pytest.mark.render
def test_the_python_section_runs_as_written_and_prints_what_the_readme_says(tmp_path):
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    done = subprocess.run(
        [sys.executable, "-c", python_block()], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr
    printed = re.fullmatch(r"PSNR (\d+\.\d) dB, corners (\d\.\d\d) px off\n", done.stdout)
    assert printed, done.stdout
    said = re.search(r"it printed `PSNR (\d+\.\d) dB, corners\s+(\d\.\d\d) px off`", (ROOT / "README.md").read_text())
    assert said
    # The render is seeded; Mitsuba's CPU and GPU variants may differ in the last digits.
    assert float(printed[1]) == pytest.approx(float(said[1]), abs=0.3)
    assert float(printed[2]) == pytest.approx(float(said[2]), abs=0.1)
    figure = matplotlib.image.imread(tmp_path / "out" / "python.png")
    output = virtual_camera_for(camera_preset("tiny"))
    assert figure.shape[:2] == (output.height_px, 2 * output.width_px)  # refraction-free | ideal
    assert (tmp_path / "out" / "python" / "raw.exr").is_file()


def readme_outputs(readme: str) -> list[str]:
    """Every path the README's commands write to: each ``--out`` and ``--refine-camera`` of a command in
    a code block or an inline code span (with ``synth``'s companions OUT.json and OUT.png), the
    demo's default ``demo/``, and the files the Python section writes."""
    commands = re.findall(r"^```bash\n(.*?)^```$", readme, re.MULTILINE | re.DOTALL)
    commands += re.findall(r"`((?:\.venv/bin/)?(?:lfsim|lfrefract) [^`]+)`", readme)
    paths = []
    for block in commands:
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line.split("#")[0])
            for i, word in enumerate(words[:-1]):
                if word in ("--out", "--refine-camera"):
                    paths.append(words[i + 1])
                    if "synth" in words and word == "--out" and words[i + 1].endswith(".exr"):
                        paths += [words[i + 1][: -len(".exr")] + suffix for suffix in (".json", ".png")]
            if re.search(r"lfsim demo\b(?!.*--out)", line):
                paths.append("demo/")
    for call in re.findall(r"(?:render_job\([^,]+|imsave|savefig)\(?,?\s*\"([^\"]+)\"", python_block()):
        paths.append(call)
    return [p for p in paths if not p.isupper()]  # not the placeholders of a synopsis (--out DIR)


def test_the_readmes_commands_write_only_where_git_ignores():
    """Run in the checkout, the README's commands left untracked files (rig/, white/, mla.json,
    python.png ...): every path they write is ignored by .gitignore."""
    paths = readme_outputs((ROOT / "README.md").read_text())
    assert "out/python" in paths  # the parser finds the Python section's render ...
    assert "demo/" in paths  # ... the demo's default folder ...
    assert "out/rf.json" in paths  # ... and synth's companions
    files = [f"{p.rstrip('/')}/any-file" if p.endswith("/") or not Path(p).suffix else p for p in paths]
    done = subprocess.run(
        ["git", "check-ignore", "--no-index", "--verbose", "--non-matching", *files],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    tracked = [line.split("\t")[-1] for line in done.stdout.splitlines() if line.startswith("::")]
    assert not tracked, f"the README's commands write outside the ignored folders: {tracked}"
