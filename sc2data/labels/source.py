"""What a labelling run reads: *units* of stacks (one per dataset shard) and where they come from.

:func:`dataset_source` is the door from a rolled-out dataset; tests build a :class:`Source` by hand.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import sha256_file
from sc2data.schema import Schema, StackBatch

READ_STACKS = 4096
"""Stacks read from a dataset at once; ``--batch-size`` stacks at a time go through the rules."""

Batches = Iterable[tuple[np.ndarray, np.ndarray, StackBatch]]
"""``(episode ids, steps, StackBatch)`` triples, as ``Dataset.iter_batches`` yields them."""


@dataclass(frozen=True)
class WorkUnit:
    """One resumable piece of labelling work, typically one shard."""

    key: str
    """Stable and unique within the dataset; changes when the unit's content changes."""
    stacks: int
    """How many stacks it yields (for the progress bar)."""
    batches: Callable[[int, Sequence[str]], Batches]
    """``batches(batch_size, keys)``: its stacks, reading only ``keys``."""


@dataclass(frozen=True)
class Source:
    """What is labelled: the units, the schema they share, and a description for provenance."""

    units: Sequence[WorkUnit]
    schema: Schema
    info: dict[str, Any] = field(default_factory=dict)
    """JSON-able description of the dataset (path, its dataset fingerprint as ``fingerprint``,
    …), stored with the labels."""


def dataset_source(path: Path | str) -> Source:
    """A :class:`Source` over the rolled-out dataset at ``path``: one unit per shard, keyed by the
    shard's name and sha256 (a re-rolled shard is relabelled), reading only the keys asked for."""
    from sc2data.data.dataset import open_dataset

    ds = open_dataset(path)
    index = ds.index.to_pydict()
    shards: dict[str, dict[str, Any]] = {}
    for shard, sha, episode, n in zip(index["shard"], index["shard_sha256"], index["episode"],
                                      index["n_steps"]):
        entry = shards.setdefault(shard, {"sha256": sha, "episodes": []})
        entry["episodes"].append((int(episode), int(n)))

    def reader(name: str, sha256: str, episodes: list[tuple[int, int]]
               ) -> Callable[[int, Sequence[str]], Batches]:
        ep = np.concatenate([np.full(n, e, np.int64) for e, n in episodes]) if episodes else \
            np.zeros(0, np.int64)
        st = np.concatenate([np.arange(n, dtype=np.int64) for _, n in episodes]) if episodes \
            else np.zeros(0, np.int64)

        def batches(batch_size: int, keys: Sequence[str]) -> Batches:
            # The whole shard is the one the index recorded, even the blocks the rules skip.
            if sha256_file(Path(path) / name) != sha256:
                raise Sc2DataError(f"{Path(path) / name} does not match the sha256 the index "
                                   f"recorded (damaged or replaced); run sc2data verify "
                                   f"{path}, and roll the shard out again")
            # Read big (chunk decoding amortises), label small (the rules' temporaries stay in
            # cache): sub-batches are views of one read.
            step = max(batch_size, READ_STACKS)
            for i in range(0, len(ep), step):
                e, s = ep[i:i + step], st[i:i + step]
                try:
                    big = ds.read(e, s, keys)
                except OSError as err:
                    raise Sc2DataError(f"{Path(path) / name} is unreadable ({err}); run sc2data "
                                       f"verify {path}") from None
                for j in range(0, len(e), batch_size):
                    part = {k: a[j:j + batch_size] for k, a in big.arrays.items()}
                    yield e[j:j + batch_size], s[j:j + batch_size], StackBatch(part, big.schema)
        return batches

    units = [WorkUnit(key=f"{name}:{info['sha256']}", stacks=sum(n for _, n in info["episodes"]),
                  batches=reader(name, info["sha256"], sorted(info["episodes"])))
             for name, info in sorted(shards.items())]
    dataset_fingerprint = hashlib.sha256(json.dumps(
        [ds.schema.to_dict(), sorted((u.key for u in units))]).encode()).hexdigest()
    info = {"path": str(Path(path).resolve()), "fingerprint": dataset_fingerprint,
            "episodes": int(len(ds.episode_ids)), "stacks": len(ds),
            "settings": ds.settings, "schema": ds.schema.to_dict()}
    return Source(units, ds.schema, info)
