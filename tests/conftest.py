"""Shared fixtures and markers."""

from __future__ import annotations

import pytest


LONGEST_FIRST = ("tests/scaleout/", "tests/test_docs.py", "tests/test_kill_anywhere.py",
                 "tests/pairs/test_pairset.py")
"""The files that take longest (``pytest --durations``), run first: with ``make test``'s two
processes (pytest-xdist, one file to a process at a time) a long file does not start last. Not
measured against the plain order."""


def _rank(item: pytest.Item) -> int:
    path = item.nodeid.split("::")[0]
    return next((i for i, p in enumerate(LONGEST_FIRST) if path.startswith(p)),
                len(LONGEST_FIRST))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the longest files first; skip ``@pytest.mark.sc2`` tests where the StarCraft II binary
    is absent."""
    from sc2data.game.env import sc2_available

    items.sort(key=_rank)  # stable: the order within and among the other files is kept

    if sc2_available():
        return
    skip = pytest.mark.skip(reason="StarCraft II binary or BuildMarines map not found (set SC2PATH)")
    for item in items:
        if "sc2" in item.keywords:
            item.add_marker(skip)
