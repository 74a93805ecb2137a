"""The test suite's own settings (tests/conftest.py)."""

from __future__ import annotations

from hypothesis import settings


def test_property_examples_have_no_deadline():
    # A deadline fails examples on a loaded machine (the CI VM beside another job), not wrong results.
    assert settings.default.deadline is None
