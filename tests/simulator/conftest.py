"""Fixtures for simulator tests: Mitsuba loaded once per session, small scenes, shared renders."""

from __future__ import annotations

import functools

import pytest

from lfrefract import camera_preset
from simulator import boards
from simulator.backend import load_mitsuba


@pytest.fixture(scope="session")
def mi():
    """Mitsuba with the project's plugins registered (LLVM variant: what CI has)."""
    return load_mitsuba("llvm_ad_rgb")


@pytest.fixture(scope="session")
def tiny():
    """The tiny preset camera."""
    return camera_preset("tiny")


@pytest.fixture(scope="session")
def port_from_renders(mi):
    """:func:`simulator.boards.port_from_renders` with this session's Mitsuba, rendered and calibrated
    once per tilt (test_port_calibration_render and test_estimated_pipeline share the renders)."""
    return functools.cache(functools.partial(boards.port_from_renders, mi=mi))
