"""Named numpy arrays in one shared-memory file that several processes map.

The learner creates the file (in ``/dev/shm``, else the temporary folder), its worker processes
map it by path, and once all have, the learner unlinks it: from then on the memory belongs to
the mappings alone and is released when the last process holding one ends, however it ends
(``kill -9`` included). A file can only outlive its processes if they are killed in the second
or so between its creation and its unlinking; its name carries the creator's pid, and every new
arena first removes the files of creators that no longer run (:func:`sweep`).
"""

from __future__ import annotations

import errno
import mmap
import os
import secrets
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sc2data.ground.errors import Sc2DataError

PREFIX = "sc2data-rl-"
_ALIGN = 64


@dataclass(frozen=True)
class Field:
    """One array of an arena: its name, shape and dtype."""

    name: str
    shape: tuple[int, ...]
    dtype: np.dtype

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64)) * np.dtype(self.dtype).itemsize


def folder() -> Path:
    """Where arenas are made: ``/dev/shm`` (memory) where it exists, else the temporary folder."""
    shm = Path("/dev/shm")
    return shm if shm.is_dir() and os.access(shm, os.W_OK) else Path(tempfile.gettempdir())


def _offsets(fields: list[Field]) -> tuple[list[int], int]:
    offsets, end = [], 0
    for f in fields:
        end = -(-end // _ALIGN) * _ALIGN
        offsets.append(end)
        end += f.nbytes
    return offsets, max(end, 1)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def sweep(where: Path | None = None) -> list[Path]:
    """Remove the arena files whose creating process no longer runs; the paths removed."""
    removed = []
    for path in (where or folder()).glob(f"{PREFIX}*"):
        try:
            pid = int(path.name[len(PREFIX):].split("-", 1)[0])
        except ValueError:
            continue
        if not _alive(pid):
            try:
                path.unlink()
                removed.append(path)
            except FileNotFoundError:
                pass
    return removed


def _reserve(fd: int, size: int, where: Path) -> None:
    """Give the file ``size`` bytes of real memory now: a sparse file on a full ``/dev/shm``
    maps, and then kills every process that writes to it (SIGBUS)."""
    try:
        os.posix_fallocate(fd, 0, size)
    except OSError as e:
        if e.errno in (errno.EOPNOTSUPP, errno.EINVAL):  # no fallocate there (or size 0)
            os.ftruncate(fd, size)
        elif e.errno in (errno.ENOSPC, errno.EDQUOT):
            raise Sc2DataError(f"cannot make the games' shared memory ({size:,} bytes) in "
                               f"{where}: {os.strerror(e.errno)}; free space there, or run with "
                               f"--processes 0 (the games in this process)") from None
        else:
            raise


class Arena:
    """The arrays of ``fields`` over one mapping (:meth:`create`, :meth:`attach`, or
    :meth:`private` for one process)."""

    def __init__(self, fields: list[Field], buf: mmap.mmap | bytearray, path: str | None) -> None:
        self.path = path
        self._buf = buf
        offsets, _ = _offsets(fields)
        self.arrays: dict[str, np.ndarray] = {
            f.name: np.frombuffer(buf, f.dtype, int(np.prod(f.shape, dtype=np.int64)),
                                  off).reshape(f.shape)
            for f, off in zip(fields, offsets)}

    @classmethod
    def create(cls, fields: list[Field]) -> Arena:
        """A new shared file (zeroed), after :func:`sweep`; :meth:`unlink` it once mapped."""
        where = folder()
        sweep(where)
        _, size = _offsets(fields)
        path = where / f"{PREFIX}{os.getpid()}-{secrets.token_hex(4)}"
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
        try:
            _reserve(fd, size, where)
            buf = mmap.mmap(fd, size)
        except BaseException:
            os.close(fd)
            path.unlink(missing_ok=True)
            raise
        os.close(fd)
        return cls(fields, buf, str(path))

    @classmethod
    def attach(cls, path: str, fields: list[Field]) -> Arena:
        """Map the file another process made with the same ``fields``."""
        _, size = _offsets(fields)
        fd = os.open(path, os.O_RDWR | os.O_NOFOLLOW)
        try:
            buf = mmap.mmap(fd, size)
        finally:
            os.close(fd)
        return cls(fields, buf, path)

    @classmethod
    def private(cls, fields: list[Field]) -> Arena:
        """Arrays in this process's own memory (no file)."""
        _, size = _offsets(fields)
        return cls(fields, bytearray(size), None)

    def unlink(self) -> None:
        """Remove the file's name; the memory stays while a process maps it."""
        if self.path is not None:
            Path(self.path).unlink(missing_ok=True)
