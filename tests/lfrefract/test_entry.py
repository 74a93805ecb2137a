"""The command lines' entry (lfrefract._entry): Ctrl-C or SIGTERM while a command is still importing its
modules ends in one line (a KeyboardInterrupt traceback before), and both scripts run through it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

SLOW_MODULE = """
import pathlib, time
pathlib.Path({marker!r}).write_text("loading")
time.sleep(60)
def main():
    return 0
"""


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_while_the_command_loads_ends_in_one_line(tmp_path, signum):
    marker = tmp_path / "loading"
    (tmp_path / "slow_command.py").write_text(SLOW_MODULE.format(marker=str(marker)))
    code = "import sys; from lfrefract._entry import run_command; sys.exit(run_command('lfx', 'slow_command'))"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not marker.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert marker.exists(), "the module never started loading"
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signum
    assert "Traceback" not in err
    assert err.strip().splitlines() == [f"lfx: interrupted while starting (signal {int(signum)}); nothing was written"]


@pytest.mark.parametrize(("module", "prog"), [("lfrefract", "lfrefract"), ("simulator", "lfsim")])
def test_both_command_lines_run_through_the_entry(module, prog):
    result = subprocess.run([sys.executable, "-m", module, "--version"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"{prog} ")
