"""The tiers of the test suite. A test marked `slow` (a long C build, a cluster, a long simulation)
runs only with DCTS_SLOW=1; the README's test command skips it and says so. What each one checks
is also checked more cheaply in the default tier (its docstring or mark says where), or is a
second instance of a check that tier runs."""

from __future__ import annotations

import os

import pytest

SLOW = pytest.mark.skip(reason="a slow test (a long C build, a cluster, a long simulation): set DCTS_SLOW=1 to run it")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get("DCTS_SLOW"):
        return
    for item in items:
        if item.get_closest_marker("slow") is not None:
            item.add_marker(SLOW)
