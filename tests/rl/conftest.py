"""Fixtures shared by the RL tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.mem_helpers import tiny_pairset, train_tiny


@pytest.fixture(scope="module")
def mem_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny trained MEM run (one epoch on a tiny pair set), one per test module."""
    root = tmp_path_factory.mktemp("mem")
    return train_tiny(tiny_pairset(root / "pairs"), root / "run", epochs=1)
