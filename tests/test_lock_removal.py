"""A folder lock that removes its file when its command ends (``sc2data build``'s) leaves no
``.lock`` behind, and a command that waited on it still excludes every later one."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import LOCK, FolderLock, writer


def test_the_lock_file_goes_with_the_command(tmp_path: Path) -> None:
    with FolderLock(tmp_path, "build", remove=True):
        assert (tmp_path / LOCK).is_file()
        assert writer(tmp_path) is None  # this process's own lock
    assert not (tmp_path / LOCK).exists()
    with FolderLock(tmp_path, "label"):  # without remove: kept, as before
        pass
    assert (tmp_path / LOCK).is_file()


def test_a_waiter_takes_the_new_lock_and_still_excludes_others(tmp_path: Path) -> None:
    first = FolderLock(tmp_path, "build", remove=True)
    got: list[FolderLock] = []
    waiter = threading.Thread(target=lambda: got.append(FolderLock(tmp_path, "second",
                                                                   wait_s=10)))
    waiter.start()
    time.sleep(0.3)  # the waiter is blocked on the first lock's file
    assert not got
    first.__exit__(None, None, None)  # removes the file it locked
    waiter.join(10)
    assert got, "the waiting command never got the lock"
    try:
        assert (tmp_path / LOCK).is_file()  # the waiter's: made anew at the lock's path
        with pytest.raises(Sc2DataError, match="another sc2data second is writing"):
            FolderLock(tmp_path, "third", wait_s=0.2)
    finally:
        got[0].__exit__(None, None, None)
