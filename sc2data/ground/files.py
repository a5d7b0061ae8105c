"""Safe files: written whole or not at all, hashed by content, and folders locked while written.

Every writer in sc2data goes through this module:

* a file is written under a temporary ``….partial`` name, fsynced, renamed into place and its
  folder fsynced (:func:`atomic_file`, :func:`write_atomic`, :func:`publish`), so a crash or
  Ctrl-C leaves the old file or none, never a half-written one under the final name; readers and
  resumed runs treat any ``*.partial`` as debris;
* content is identified by sha256 (:func:`sha256_file`, :func:`sha256_files`);
* one :class:`FolderLock` per output folder (``.lock``) keeps two commands from writing it at once,
  and the refusal names the command that holds it; the lock never follows a link or writes into
  a file it did not make, and :func:`writer` tells a reader (``verify``) that a folder is being
  written now.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import os
import stat
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

from sc2data.ground.errors import Sc2DataError, reason

PARTIAL = ".partial"
"""Suffix of a file or folder still being written; never a complete result."""

LOCK = ".lock"
"""The lock file in every folder an sc2data command writes."""

LOCK_WAIT_S = 10.0
"""How long a command waits for another's lock on its folder before refusing."""


def fsync_path(path: Path) -> None:
    """Flush a file (or a folder's entries) to disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def publish(tmp: Path, final: Path) -> None:
    """Give a complete, fsynced ``tmp`` (file or folder) its final name, durably."""
    if tmp.is_file():
        fsync_path(tmp)
    os.replace(tmp, final)
    fsync_path(final.parent)


@contextlib.contextmanager
def atomic_file(path: Path) -> Iterator[Path]:
    """Yield a temporary path to write ``path``'s content to; on success it becomes ``path``
    (fsynced), on any exception it is removed. The temporary name carries the process id, so
    concurrent attempts (a retried Ray task) never write one file."""
    tmp = path.with_name(f"{path.name}.{os.getpid()}{PARTIAL}")
    try:
        yield tmp
        publish(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS)
"""The errors of a write that the disk refused: full, over quota or read-only."""


def one_line(e: BaseException) -> str:
    """An exception as the one line a failed worker or task reports: a user error as it is, a
    write the disk refused as its errno's text and what to do (HDF5's own message runs over
    several lines), anything else by type and first line."""
    if isinstance(e, Sc2DataError):
        return str(e)
    if isinstance(e, OSError) and e.errno in FULL:
        return f"{reason(e)}; free some space, then rerun the same command to resume"
    first = (str(e).strip().splitlines() or [""])[0]
    return f"{type(e).__name__}: {first}" if first else type(e).__name__


@contextlib.contextmanager
def writing(what: str, remedy: str) -> Iterator[None]:
    """Turn a write the disk refuses (:data:`FULL`) inside the block into one line about
    ``what``; other errors pass as they are."""
    try:
        yield
    except OSError as e:
        if e.errno not in FULL:
            raise
        raise Sc2DataError(f"cannot write {what}: {reason(e)}; {remedy}") from None


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``path`` so that it is either absent, old, or complete."""
    with atomic_file(path) as tmp:
        tmp.write_bytes(data)


def sha256_files(paths: Iterable[Path]) -> str:
    """sha256 over the given files' bytes, in order."""
    h = hashlib.sha256()
    for p in paths:
        with open(p, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def sha256_file(path: Path) -> str:
    """sha256 of one file's bytes."""
    return sha256_files([path])


class FolderLock:
    """``flock`` on ``folder/.lock`` for one command (``rollout``, ``label``, …).

    Taken exclusively, it records the command in the lock file, so another command that finds
    the folder locked can say which one holds it. A rollout takes it exclusively while it
    prepares the folder, then :meth:`share`\\ s it with its worker processes, which take shared
    locks: a second run then waits for every process of the first (orphaned workers of a killed
    run included). A command waits up to ``wait_s`` seconds, then refuses in one line.
    """

    def __init__(self, folder: Path, command: str, *, exclusive: bool = True,
                 wait_s: float | None = None, name: str = LOCK, what: Path | None = None,
                 remove: bool = False) -> None:
        """``name``: the lock file in ``folder``; ``what``: the path named in the refusal (a
        folder that is written whole and renamed into place is locked from beside it);
        ``remove``: delete the lock file when the command ends, still holding it (an exclusive
        lock never shared: a build folder keeps no ``.lock``). A command that waited on a lock
        file removed meanwhile takes the one now at its path."""
        self.folder, self.command, self.what = folder, command, what or folder
        self._path = folder / name
        self._remove = remove and exclusive
        self._fd = _open_lock(self._path)
        try:
            self._take(fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH,
                       LOCK_WAIT_S if wait_s is None else wait_s)
            if exclusive:
                os.ftruncate(self._fd, 0)
                os.pwrite(self._fd, f"sc2data {command} (pid {os.getpid()})\n".encode(), 0)
        except BaseException:
            if self._fd >= 0:
                os.close(self._fd)
            raise

    def _holder(self) -> str:
        return (_record(self._fd) or "sc2data command").split(" (pid")[0]

    def _current(self) -> bool:
        """Whether the locked file is still the one at the lock's path (its holder may have
        removed it when it ended)."""
        try:
            here, mine = os.lstat(self._path), os.fstat(self._fd)
        except FileNotFoundError:
            return False
        return (here.st_dev, here.st_ino) == (mine.st_dev, mine.st_ino)

    def _take(self, mode: int, wait_s: float) -> None:
        deadline = time.monotonic() + wait_s
        while True:
            try:
                fcntl.flock(self._fd, mode | fcntl.LOCK_NB)
                if self._current():
                    return
                os.close(self._fd)  # removed by the command that held it: take the new one
                self._fd = -1
                self._fd = _open_lock(self._path)
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    raise Sc2DataError(f"another {self._holder()} is writing to {self.what}; "
                                       f"wait for it to finish or stop it") from None
                time.sleep(0.05)

    def share(self) -> None:
        """Downgrade to a shared lock, so that this run's workers can take theirs."""
        fcntl.flock(self._fd, fcntl.LOCK_SH)
        self._remove = False

    def __enter__(self) -> FolderLock:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._remove and self._current():
            with contextlib.suppress(OSError):
                self._path.unlink()
        os.close(self._fd)


_MINE = b"sc2data "
"""How the record in every lock file sc2data writes begins (``sc2data label (pid 12)``)."""


def _record(fd: int) -> str | None:
    """The record in an open lock file (``sc2data train (pid 12)``), None if it holds none."""
    with contextlib.suppress(OSError, UnicodeDecodeError):
        text = os.pread(fd, 200, 0).decode().strip()
        if text.startswith(_MINE.decode()):
            return text
    return None


def _not_a_lock(path: Path, why: str) -> Sc2DataError:
    return Sc2DataError(f"{path} {why}, so it is not a lock file sc2data made (sc2data never "
                        f"writes through it); move it away or delete it, then rerun the command")


_KINDS = {stat.S_IFLNK: "a symbolic link", stat.S_IFDIR: "a folder", stat.S_IFIFO: "a named pipe",
          stat.S_IFSOCK: "a socket", stat.S_IFCHR: "a device", stat.S_IFBLK: "a device"}


def _open_lock(path: Path) -> int:
    """Open (or create) the lock file at ``path`` for reading and writing, never through a link:
    a one-line error unless it is a regular file with one name whose content is empty or
    sc2data's own record, so that the lock never writes into a file it did not make."""
    for _ in range(10):
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            try:  # made here, by us: O_EXCL fails if anything appeared there meanwhile
                return os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                               | os.O_CLOEXEC, 0o644)
            except FileExistsError:
                continue
        if not stat.S_ISREG(st.st_mode):
            raise _not_a_lock(path, f"is {_KINDS.get(stat.S_IFMT(st.st_mode), 'not a file')}")
        try:
            fd = os.open(path, os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
        except FileNotFoundError:  # removed meanwhile: make it
            continue
        except OSError as e:
            if e.errno == errno.ELOOP:  # became a link meanwhile
                raise _not_a_lock(path, "is a symbolic link") from None
            raise
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                raise _not_a_lock(path, f"is {_KINDS.get(stat.S_IFMT(st.st_mode), 'not a file')}")
            if st.st_nlink != 1:
                raise _not_a_lock(path, f"has {st.st_nlink} names (hard links to one file)")
            if st.st_size and _record(fd) is None:
                raise _not_a_lock(path, "holds something other than sc2data's lock record")
        except BaseException:
            os.close(fd)
            raise
        return fd
    raise Sc2DataError(f"{path} keeps changing while sc2data opens it as its lock file; stop "
                       f"whatever is replacing it, then rerun the command")


def writer(folder: Path, name: str = LOCK) -> str | None:
    """The command writing ``folder`` now, as its lock records it (``sc2data train (pid 12)``),
    or None when no other process holds the lock (this one's own lock is no other writer). Reads
    only: it never creates the lock file, and a lock path that is not a regular file counts as
    no lock."""
    try:
        fd = os.open(folder / name, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        try:  # flock ignores the open mode: a held lock, shared or not, refuses this one
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            record = _record(fd) or "an sc2data command"
            return None if record.endswith(f"(pid {os.getpid()})") else record
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def check_out(path: Path, flag: str = "--out") -> None:
    """One line unless ``path`` can be created where it is: no folder above it is a file."""
    for above in Path(path).parents:
        if above.exists():
            if not above.is_dir():
                raise Sc2DataError(f"cannot write {path}: {above} is a file, not a folder; "
                                   f"choose another {flag}")
            return
