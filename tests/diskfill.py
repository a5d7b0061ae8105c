"""Run ``sc2data`` in a process whose disk fills up the moment it opens a named file to write.

``python -m tests.diskfill NAME N BALLAST -- ARGS…`` runs ``sc2data ARGS`` with an audit hook
(:func:`sys.addaudithook`, Python's own ``open`` event: nothing of sc2data is patched) that, at
the ``N``-th opening for writing of a file whose name starts with ``NAME``, fills the filesystem
of ``BALLAST`` with that file (``posix_fallocate`` of every free block) and lets the open go on:
the write that follows meets a real full disk (``ENOSPC`` from the kernel). So a full disk can be
made to strike at any one write of a command — a checkpoint's model, its curve, its state, the
logger's ``progress.csv``, ``eval.json`` — however small the file.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_TRUNC


def fill(ballast: Path) -> None:
    """Take every free block of ``ballast``'s filesystem."""
    st = os.statvfs(ballast.parent)
    with open(ballast, "ab") as f:
        if st.f_bavail:
            os.posix_fallocate(f.fileno(), f.tell(), st.f_bavail * st.f_frsize)


def _writes(mode: Any, flags: Any) -> bool:
    if isinstance(mode, str):
        return any(c in mode for c in "wax+")
    return isinstance(flags, int) and bool(flags & WRITE_FLAGS)


def install(name: str, nth: int, ballast: Path) -> None:
    """Fill ``ballast``'s filesystem at the ``nth`` opening for writing of a file named
    ``name…``."""
    seen = 0

    def hook(event: str, args: tuple[Any, ...]) -> None:
        nonlocal seen
        if event != "open" or seen >= nth or not isinstance(args[0], (str, bytes, os.PathLike)):
            return
        if not os.path.basename(os.fsdecode(args[0])).startswith(name):
            return
        if _writes(args[1], args[2]):
            seen += 1
            if seen == nth:
                fill(ballast)

    sys.addaudithook(hook)


def main() -> None:
    name, nth, ballast, sep, *args = sys.argv[1:]
    assert sep == "--", "usage: python -m tests.diskfill NAME N BALLAST -- ARGS…"
    install(name, int(nth), Path(ballast))
    from sc2data.cli import main as sc2data

    sys.argv = ["sc2data", *args]  # as the console script runs it
    sc2data()


if __name__ == "__main__":
    main()
