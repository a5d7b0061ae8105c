"""Shared fixtures (a small filesystem to fill) and markers."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

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
    skip = pytest.mark.skip(
        reason="StarCraft II binary or BuildMarines map not found (set SC2PATH)")
    for item in items:
        if "sc2" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def fs(tmp_path: Path) -> Iterator[Path]:
    """A 64 MB tmpfs of its own (a disk to fill: root only, skipped elsewhere), unmounted
    afterwards."""
    where = tmp_path / "fs"
    where.mkdir()
    p = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64m", "tmpfs", str(where)],
                       capture_output=True, text=True, check=False)
    if p.returncode:
        pytest.skip(f"cannot mount a small tmpfs to fill (needs root): {p.stderr.strip()}")
    yield where
    subprocess.run(["umount", "-l", str(where)], check=False)


def leave_free(fs: Path, free: int) -> Path:
    """Fill ``fs`` with a ballast file so that about ``free`` bytes stay free."""
    st = os.statvfs(fs)
    ballast = fs / "ballast"
    with open(ballast, "wb") as f:
        os.posix_fallocate(f.fileno(), 0, st.f_bavail * st.f_frsize - free)
    return ballast
