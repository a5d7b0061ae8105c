"""A pair set as a PyTorch ``torch.utils.data.Dataset``, for your own training loop.

``sc2data train`` has its own loader (:mod:`sc2data.pairs.loader`); this module is for a
researcher who wants the pairs in a standard ``DataLoader``::

    from torch.utils.data import DataLoader
    from sc2data.pairs.torchdata import PairDataset

    pairs = PairDataset("demo-out/data/pairs", split="train")
    for batch in DataLoader(pairs, batch_size=32, shuffle=True, num_workers=2):
        batch["state"]["screen/unit_type"]   # (32, 2, 64, 64) uint16 tensor
        batch["command"], batch["target"]    # 32 texts, (32,) float32 tensor

Each item is one pair: ``state`` (schema key → the stack's ``(2, …)`` array, previous frame
first), ``command`` (its text), ``command_id`` (the rule id), ``command_index`` (position in
``pairs.commands``), ``target`` (0.0 a match, 1.0 a mismatch), ``kind`` (matched, mismatched,
null) and ``pair`` (row within the split). The packed split is opened lazily, once per process,
so the object pickles into ``DataLoader`` workers and each opens its own file. Packed files are
compressed in blocks of 256 stacks: :func:`block_order` gives a shuffled order that reads each
block once per epoch, where ``shuffle=True`` decodes a block for every pair.

The pair set is checked by content when the object is made (its pair-set fingerprint, and the packed
split against its pairs), and again before an item is read whenever ``pairs.parquet`` or the
split's packed file changed since (another inode, size or modification time): the same bytes
read on, other bytes (a folder rebuilt or replaced) are a one-line error, never new states
paired with the commands read before.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import MissingDependencyError, Sc2DataError
from sc2data.pairs.layout import PAIRS_FILE, packed_path, pairset_fingerprint
from sc2data.pairs.loader import SPLITS, PairSet
from sc2data.pairs.packed import BLOCK

try:
    import torch  # noqa: F401  (present: the loader's tensors)
    from torch.utils.data import Dataset, Sampler
except ImportError:
    raise MissingDependencyError("torch", "train", "sc2data.pairs.torchdata") from None

_CHUNK_CACHE = 5 << 20
"""HDF5 chunk cache per dataset: one block of the largest key, (256, 2, 64, 64) uint16 = 4 MiB."""


class PairDataset(Dataset):
    """The pairs of one split of a pair-set folder, one pair per item."""

    def __init__(self, path: str | os.PathLike[str], split: str = "train",
                 keys: Sequence[str] | None = None) -> None:
        if split not in SPLITS:
            raise Sc2DataError(f"unknown split {split!r}; choose one of: {', '.join(SPLITS)}")
        self.path, self.split = Path(path), split
        before = self._stat()
        pairset = PairSet(path)
        self.schema = pairset.schema
        self.keys: tuple[str, ...] = tuple(keys) if keys is not None else self.schema.keys()
        unknown = [k for k in self.keys if k not in self.schema.keys()]
        if unknown:
            raise Sc2DataError(f"{unknown[0]!r} is not stored in {path}; stored: "
                               f"{', '.join(self.schema.keys())}")
        self.commands: list[str] = [str(c["id"]) for c in pairset.commands]
        """Command ids in pair-set order: ``command_index`` indexes this list."""
        pairs = pairset.pairs(split)
        with pairset.packed(split):  # the packed file against the pair set's schema and rows
            pass
        self.pairset_fingerprint = pairset.pairset_fingerprint
        """The pair set's content as checked here: what every later read must still be."""
        self._signature = self._stat()
        if self._signature != before:
            raise Sc2DataError(f"{self.path} changed while it was being opened; open it again "
                               f"when whatever writes it has finished")
        self.state, self.command = pairs.state, pairs.command
        self.command_id, self.target, self.kind = pairs.command_id, pairs.target, pairs.kind
        index = {c: i for i, c in enumerate(self.commands)}
        self.command_index = np.array([index[c] for c in pairs.command_id], np.int64)
        self._file: Any = None
        self._pid: int | None = None

    def __len__(self) -> int:
        return len(self.state)

    def __repr__(self) -> str:
        return (f"PairDataset({str(self.path)!r}, split={self.split!r}, pairs={len(self)}, "
                f"keys={len(self.keys)})")

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_file": None, "_pid": None}  # h5py handles do not pickle

    def _stat(self) -> tuple[tuple[int, int, int, int], ...] | None:
        """What tells a changed file: (device, inode, size, mtime) of ``pairs.parquet`` and the
        split's packed file; None if one is gone."""
        try:
            return tuple((st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns) for st in (
                os.stat(self.path / PAIRS_FILE), os.stat(packed_path(self.path, self.split))))
        except OSError:
            return None

    def _recheck(self) -> None:
        """The files changed since they were checked: the same bytes read on (reopened), other
        bytes are an error."""
        now = self._stat()
        try:
            same = now is not None and \
                pairset_fingerprint(self.path) == self.pairset_fingerprint
        except OSError:
            same = False
        if not same:
            raise Sc2DataError(f"{self.path}: pairs.parquet or packed/{self.split}.h5 changed or "
                               f"is gone since this PairDataset checked it (its sha256 differs); "
                               f"make a new PairDataset to read the pair set as it is now")
        self._signature = now
        self._close()

    def _close(self) -> None:
        if self._file is not None and self._pid == os.getpid():
            self._file.close()
        self._file, self._pid = None, None

    def _open(self) -> Any:
        if self._stat() != self._signature:
            self._recheck()
        if self._pid != os.getpid():  # first use in this process (a DataLoader worker)
            import h5py
            import hdf5plugin  # noqa: F401  (registers the packed files' LZ4 filter)

            self._file = h5py.File(packed_path(self.path, self.split), "r",
                                   rdcc_nbytes=_CHUNK_CACHE, rdcc_nslots=101)
            self._pid = os.getpid()
            if self._stat() != self._signature:  # replaced between the check and the open
                self._recheck()
                return self._open()
        return self._file

    def __getitem__(self, i: int) -> dict[str, Any]:
        f = self._open()
        row = int(self.state[i])
        try:
            state = {k: f[k][row] for k in self.keys}
        except OSError as e:  # a chunk that fails its checksum
            raise Sc2DataError(f"{packed_path(self.path, self.split)} is unreadable at stack "
                               f"{row} ({(str(e).strip().splitlines() or [''])[0]}); rerun "
                               f"sc2data pair") from None
        return {
            "state": state,
            "command": str(self.command[i]),
            "command_id": str(self.command_id[i]),
            "command_index": int(self.command_index[i]),
            "target": np.float32(self.target[i]),
            "kind": str(self.kind[i]),
            "pair": int(i),
        }


class BlockOrder(Sampler[int]):
    """Pair indices in random order, block by block: the blocks of the packed file in a random
    order, the pairs within each shuffled. Pass as ``DataLoader(…, sampler=BlockOrder(ds))``;
    call :meth:`set_epoch` for a new order each epoch (seeded by ``seed`` and the epoch)."""

    def __init__(self, dataset: PairDataset, seed: int = 0) -> None:
        self.seed, self.epoch = seed, 0
        block = dataset.state // BLOCK
        order = np.argsort(block, kind="stable")
        cuts = np.flatnonzero(np.diff(block[order])) + 1
        self._blocks = np.split(order, cuts) if len(order) else []
        self._n = len(order)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return self._n

    def __iter__(self) -> Iterator[int]:
        rng = np.random.default_rng([self.seed, self.epoch])
        for b in rng.permutation(len(self._blocks)):
            yield from rng.permutation(self._blocks[b]).tolist()


def block_order(dataset: PairDataset, seed: int = 0) -> BlockOrder:
    """A :class:`BlockOrder` sampler over ``dataset``."""
    return BlockOrder(dataset, seed)


__all__ = ["BlockOrder", "PairDataset", "block_order"]
