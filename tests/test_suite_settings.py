"""The test suite's own settings (tests/conftest.py)."""

from __future__ import annotations

from hypothesis import settings


def test_property_examples_have_no_deadline():
    # A deadline fails examples on a loaded machine (the CI VM beside another job), not wrong results.
    assert settings.default.deadline is None


def test_files_that_take_minutes_are_collected_first(request):
    # tests/conftest.py puts them first, so that a parallel run (README) starts them at once.
    takes_minutes = [item.get_closest_marker("minutes") is not None for item in request.session.items]
    assert takes_minutes == sorted(takes_minutes, reverse=True)


def test_a_parallel_run_keeps_each_file_whole_and_in_the_collected_order(request):
    # pyproject.toml's addopts: module fixtures render once per file, and the files marked `minutes`
    # start first (xdist otherwise reorders files by their number of tests).
    # (read from the settings: a worker's own options say "no distribution")
    addopts = request.config.getini("addopts")
    assert "--dist=loadfile" in addopts
    assert "--no-loadscope-reorder" in addopts
