"""Shared fixtures and markers."""

from __future__ import annotations

import pytest


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Skip ``@pytest.mark.sc2`` tests where the StarCraft II binary is absent."""
    from sc2data.game.env import sc2_available

    if sc2_available():
        return
    skip = pytest.mark.skip(reason="StarCraft II binary or BuildMarines map not found (set SC2PATH)")
    for item in items:
        if "sc2" in item.keywords:
            item.add_marker(skip)
