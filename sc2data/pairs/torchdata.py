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
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.errors import MissingDependencyError, Sc2DataError
from sc2data.pairs.layout import packed_path
from sc2data.pairs.loader import SPLITS, PairSet
from sc2data.pairs.packed import BLOCK

try:
    import torch
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
        pairset = PairSet(path)
        self.path, self.split = Path(path), split
        self.schema = pairset.schema
        self.keys: tuple[str, ...] = tuple(keys) if keys is not None else self.schema.keys()
        unknown = [k for k in self.keys if k not in self.schema.keys()]
        if unknown:
            raise Sc2DataError(f"{unknown[0]!r} is not stored in {path}; stored: "
                               f"{', '.join(self.schema.keys())}")
        self.commands: list[str] = [str(c["id"]) for c in pairset.commands]
        """Command ids in pair-set order: ``command_index`` indexes this list."""
        pairs = pairset.pairs(split)
        with pairset.packed(split):  # checks the packed file against the pair set once, here
            pass
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

    def _open(self) -> Any:
        if self._pid != os.getpid():  # first use in this process (a DataLoader worker)
            import h5py
            import hdf5plugin  # noqa: F401  (registers the packed files' LZ4 filter)

            self._file = h5py.File(packed_path(self.path, self.split), "r",
                                   rdcc_nbytes=_CHUNK_CACHE, rdcc_nslots=101)
            self._pid = os.getpid()
        return self._file

    def __getitem__(self, i: int) -> dict[str, Any]:
        f = self._open()
        row = int(self.state[i])
        return {
            "state": {k: f[k][row] for k in self.keys},
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
