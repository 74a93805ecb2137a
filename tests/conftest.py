"""Settings for the whole test suite."""

from __future__ import annotations

import pytest
from hypothesis import settings

# Hypothesis fails an example that takes longer than its deadline (200 ms by default) and reports
# it as flaky when the rerun is fast. On a loaded machine that is timing, not correctness: on the
# 2-core CI VM beside another job, test_slab_lateral_shift_matches_textbook once took 276 ms for an
# example that reran in 0.75 ms and failed the run. The property tests check results; speed is
# measured by the benchmarks (benchmarks/), so no example has a deadline.
settings.register_profile("lfrefract", deadline=None)
settings.load_profile("lfrefract")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Files marked ``minutes`` first, in place (the sort is stable, so each file stays whole and in
    its order). With ``-n logical`` (README; ``pyproject.toml`` hands each file whole to a worker, in
    this order) a worker then starts such a file at once while the others share the rest, instead of
    meeting it last and running it alone."""
    items.sort(key=lambda item: item.get_closest_marker("minutes") is None)
