"""Fixtures for simulator tests: Mitsuba loaded once per session, small scenes."""

from __future__ import annotations

import pytest

from lfrefract import camera_preset
from simulator.backend import load_mitsuba


@pytest.fixture(scope="session")
def mi():
    """Mitsuba with the project's plugins registered (LLVM variant: what CI has)."""
    return load_mitsuba("llvm_ad_rgb")


@pytest.fixture(scope="session")
def tiny():
    """The tiny preset camera."""
    return camera_preset("tiny")
