"""Layering: the core never imports the renderer (README, "Layout")."""

from __future__ import annotations

import subprocess
import sys


def test_core_imports_no_renderer():
    code = (
        "import sys, lfrefract, lfrefract.cli, lfrefract.formats.capture\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('mitsuba', 'drjit', 'simulator'))\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == ""


def test_simulator_imports_mitsuba_only_when_asked():
    code = (
        "import sys, simulator.config, simulator.scene, simulator.job, simulator.cli\n"
        "print(','.join(sorted(m for m in sys.modules if m.split('.')[0] in ('mitsuba', 'drjit'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == ""
