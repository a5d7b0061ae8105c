"""A rolled-out dataset as a PyTorch ``torch.utils.data.Dataset``: one stack per item.

For a researcher's own loop over the raw stacks (offline RL, behaviour cloning, a state
encoder), where :mod:`sc2data.pairs.torchdata` serves the pairs of a pair set::

    from torch.utils.data import DataLoader
    from sc2data.data.torchdata import StackDataset

    stacks = StackDataset("demo-out/data/rollout")
    for batch in DataLoader(stacks, batch_size=64, shuffle=True, num_workers=2):
        batch["state"]["screen/unit_type"]     # (64, 2, 64, 64) uint16: previous, current frame
        batch["function"], batch["args"]       # the pysc2 call that led from one to the other
        batch["reward"]                        # (64,) float32: what the game returned for it
        batch["available"]                     # (64, 573) bool: the calls it could have made

Item ``i`` is the stack at global position ``i`` (episode, step order): ``state`` (schema key →
the ``(2, …)`` array, frames ``step`` and ``step + 1``), ``episode``, ``step``, the action taken
in it — ``function`` (pysc2 function id) and ``args`` (its arguments flattened, ``-1`` padded to
:data:`~sc2data.data.shards.ARG_WIDTH`; :func:`~sc2data.data.shards.function_call` rebuilds the
call) — the ``reward`` it returned and, where the dataset keeps action masks (format 4 on),
``available`` and ``next_available``: pysc2's ``available_actions`` of the two frames as boolean
masks over ``actions.FUNCTIONS``. A ``DataLoader`` with automatic batching fetches a whole
batch with one read (``__getitems__``), so each chunk it touches is decoded once. The dataset
folder is opened lazily, once per process, so the object pickles into ``DataLoader`` workers.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.data.dataset import Dataset as Rollout
from sc2data.ground.errors import MissingDependencyError, Sc2DataError

try:
    from torch.utils.data import Dataset
except ImportError:
    raise MissingDependencyError("torch", "train", "sc2data.data.torchdata") from None


class StackDataset(Dataset):
    """The stacks of a rollout folder, one per item (see the module docstring)."""

    def __init__(self, path: str | os.PathLike[str], keys: Sequence[str] | None = None,
                 cache_bytes: int = 128 << 20) -> None:
        self.path = Path(path)
        self.cache_bytes = cache_bytes
        rollout = Rollout(self.path, cache_bytes=cache_bytes)
        self.schema = rollout.schema
        stored = self.schema.keys()
        self.keys: tuple[str, ...] = tuple(keys) if keys is not None else tuple(stored)
        unknown = [k for k in self.keys if k not in stored]
        if unknown:
            raise Sc2DataError(f"{unknown[0]!r} is not stored in {path}; stored: "
                               f"{', '.join(stored)}")
        self._len = len(rollout)
        self._rollout: Rollout | None = rollout
        self._pid: int | None = os.getpid()

    def __len__(self) -> int:
        return self._len

    def __repr__(self) -> str:
        return f"StackDataset({str(self.path)!r}, stacks={len(self)}, keys={len(self.keys)})"

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_rollout": None, "_pid": None}  # open shards do not pickle

    def _open(self) -> Rollout:
        if self._rollout is None or self._pid != os.getpid():  # a DataLoader worker's first use
            self._rollout = Rollout(self.path, cache_bytes=self.cache_bytes)
            self._pid = os.getpid()
        return self._rollout

    def _items(self, positions: np.ndarray) -> list[dict[str, Any]]:
        """The stacks at ``positions`` (read together), one item each."""
        rollout = self._open()
        episodes, steps = rollout.locate_positions(positions)
        state = rollout.read(episodes, steps, self.keys).arrays
        acts = rollout.actions(episodes, steps)
        args = acts["args"].astype(np.int64)
        rewards = acts["reward"].astype(np.float32)
        masks = {k: acts[k] for k in ("available", "next_available") if k in acts}
        return [{"state": {k: v[j] for k, v in state.items()}, "episode": int(episodes[j]),
                 "step": int(steps[j]), "function": int(acts["function"][j]), "args": args[j],
                 "reward": rewards[j], **{k: v[j] for k, v in masks.items()}}
                for j in range(len(positions))]

    def _positions(self, indices: Sequence[int]) -> np.ndarray:
        positions = np.asarray(indices, np.int64).reshape(-1)
        if len(positions) and (positions.min() < -len(self) or positions.max() >= len(self)):
            raise IndexError(f"stack positions must lie in [-{len(self)}, {len(self)})")
        return positions % max(len(self), 1)

    def __getitem__(self, i: int) -> dict[str, Any]:
        return self._items(self._positions([i]))[0]

    def __getitems__(self, indices: Sequence[int]) -> list[dict[str, Any]]:
        """A whole batch in one read (what ``DataLoader`` calls with automatic batching), one
        item per index; its default ``collate_fn`` stacks them into tensors."""
        return self._items(self._positions(indices))


__all__ = ["StackDataset"]
