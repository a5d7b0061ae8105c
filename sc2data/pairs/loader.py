"""Read a pair-set folder (``sc2data pair`` output) and feed its pairs to the trainer in batches.

The folder (``docs/pairset.md``): ``pairs.parquet``, ``pairset.json``, ``packed/<split>.h5``.
:class:`PairSet` validates it and gives each split's pairs as columns; :class:`PairLoader` turns
one split into batches without random HDF5 reads: it visits the packed file's blocks in random
order, decodes a window of consecutive-in-that-order blocks at once, shuffles the pairs whose
states lie in the window, and cuts batches from memory. A background thread decodes the next
window, and applies the model's input packing, while the model trains on the current one.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.formats import PAIRSET, loads
from sc2data.pairs.layout import META_FILE, PAIRS_FILE, check_content, packed_path
from sc2data.pairs.packed import BLOCK, PackedSplit
from sc2data.schema import Schema, SchemaError

SPLITS = ("train", "val", "test")
COLUMNS = ("split", "state", "episode", "step", "command_id", "command", "target", "kind", "label")


@dataclass(frozen=True)
class SplitPairs:
    """One split's pairs as numpy columns (strings as numpy unicode arrays)."""

    state: np.ndarray
    command_id: np.ndarray
    command: np.ndarray
    target: np.ndarray
    kind: np.ndarray
    label: np.ndarray

    def __len__(self) -> int:
        return len(self.state)

    def __repr__(self) -> str:
        return f"SplitPairs(n={len(self)})"


class PairSet:
    """A validated pair-set folder: metadata, schema, commands, and per-split pairs and stacks."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            why = "it is a file" if self.path.exists() else "it does not exist"
            raise Sc2DataError(f"{self.path} is not a pair-set folder ({why}); build one with "
                               f"sc2data build RECIPE --out DIR")
        meta_path = self.path / META_FILE
        try:
            self.meta: dict[str, Any] = loads(meta_path.read_text())
        except FileNotFoundError:
            raise Sc2DataError(f"{self.path} has no pairset.json; is it a pair-set folder "
                               f"(sc2data pair output)?") from None
        except ValueError as e:  # invalid JSON, or no record (formats.loads)
            raise Sc2DataError(f"{meta_path} is not valid JSON or not a readable record ({e}); "
                               f"rebuild the pair set") from None
        PAIRSET.check(self.meta, meta_path)
        try:
            self.schema = Schema.from_dict(self.meta["schema"])
            self.commands: list[dict[str, Any]] = list(self.meta["commands"])
            self.pairset_fingerprint = str(self.meta["fingerprint"])
        except SchemaError as e:
            raise Sc2DataError(f"{meta_path}: {e}") from None
        except (KeyError, TypeError) as e:
            raise Sc2DataError(f"{meta_path} lacks the field {e}; rebuild the pair set") from None
        check_content(self.path, self.pairset_fingerprint)
        self.recipe_name = str(self.meta.get("recipe_name", "pairs"))
        self._table = self._read_pairs()

    def _read_pairs(self) -> dict[str, SplitPairs]:
        path = self.path / PAIRS_FILE
        try:
            table = pq.read_table(path)
        except FileNotFoundError:
            raise Sc2DataError(f"{self.path} has no pairs.parquet; rerun sc2data pair") from None
        except Exception as e:  # pyarrow raises ArrowInvalid & co. for a damaged file
            raise Sc2DataError(f"{path} is not a readable Parquet file ({type(e).__name__}); "
                               f"rerun sc2data pair") from None
        missing = [c for c in COLUMNS if c not in table.column_names]
        if missing:
            raise Sc2DataError(f"{path} lacks the column(s) {', '.join(missing)}")
        cols = {c: table.column(c).to_numpy(zero_copy_only=False) for c in COLUMNS}
        split = cols["split"].astype(str)
        out = {}
        for s in SPLITS:
            m = split == s
            out[s] = SplitPairs(cols["state"][m].astype(np.int64),
                                cols["command_id"][m].astype(str), cols["command"][m].astype(str),
                                cols["target"][m].astype(np.float32), cols["kind"][m].astype(str),
                                cols["label"][m].astype(str))
        return out

    def pairs(self, split: str) -> SplitPairs:
        return self._table[split]

    def packed(self, split: str) -> PackedSplit:
        """Open ``packed/<split>.h5``, checking it matches the pair set's schema and rows."""
        path = packed_path(self.path, split)
        if not path.is_file():
            raise Sc2DataError(f"{self.path} lacks packed/{split}.h5; rerun sc2data pair")
        p = PackedSplit(path)
        if p.schema != self.schema:
            raise Sc2DataError(f"{path} has another schema than pairset.json; rerun sc2data pair")
        rows = self.pairs(split).state
        if len(rows) and (rows.min() < 0 or rows.max() >= len(p)):
            raise Sc2DataError(f"pairs.parquet refers to {split} state {rows.max()}, but "
                               f"{path} holds {len(p)} stacks; rerun sc2data pair")
        return p

    def texts(self) -> dict[str, str]:
        """Command id → canonical text."""
        return {str(c["id"]): str(c["text"]) for c in self.commands}

    def paraphrases(self) -> dict[str, list[str]]:
        """Command id → held-out paraphrases (evaluation only)."""
        return {str(c["id"]): [str(p) for p in c.get("paraphrases", [])] for c in self.commands}

    def train_paraphrases(self) -> dict[str, list[str]]:
        """Command id → training phrasings (drawn for train-split pairs beside the canonical
        text); empty lists for a pair set built without them."""
        return {str(c["id"]): [str(p) for p in c.get("train_paraphrases", [])]
                for c in self.commands}


@dataclass
class Batch:
    """A batch of pairs: stacks by schema key ``(b, 2, …)`` (or as the loader's ``transform``
    and ``collate`` made them), text index, target, pair index."""

    arrays: Any
    text: np.ndarray
    target: np.ndarray
    index: np.ndarray

    def __len__(self) -> int:
        return len(self.target)


class PairLoader:
    """Batches of one split's pairs; random block order and in-window shuffles when ``shuffle``.

    ``transform`` maps a decoded window's arrays (rows = stacks) to other arrays with rows first
    — the model's input packing, done once per stack however many pairs use it; ``collate`` maps
    a batch's rows (e.g. to tensors). Both run in the loader's thread.
    """

    def __init__(self, packed: PackedSplit, state: np.ndarray, text: np.ndarray,
                 target: np.ndarray, *, batch_size: int, keys: Sequence[str], shuffle: bool,
                 seed: int = 0, window: int = 4, prefetch: int = 16,
                 transform: Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]] | None = None,
                 collate: Callable[[dict[str, np.ndarray]], Any] | None = None) -> None:
        self.packed, self.keys = packed, list(keys)
        self.transform, self.collate = transform, collate
        self.state, self.text, self.target = state, text, target
        self.batch_size, self.shuffle, self.seed = batch_size, shuffle, seed
        self.window, self.prefetch = window, prefetch
        order = np.argsort(state, kind="stable")
        block_of = state[order] // BLOCK
        n_blocks = -(-len(packed) // BLOCK)
        bounds = np.searchsorted(block_of, np.arange(n_blocks + 1))
        self._pairs_of_block = [order[bounds[b]:bounds[b + 1]] for b in range(n_blocks)]

    def __len__(self) -> int:
        """Batches per epoch (an upper bound: a window's last batch may be short)."""
        return -(-len(self.state) // self.batch_size) + (-(-len(self._pairs_of_block)
                                                          // self.window))

    def epoch(self, epoch: int = 0) -> Iterator[Batch]:
        """All pairs once, in batches; seeded by (seed, epoch)."""
        it = self._batches(np.random.default_rng([self.seed, epoch]))
        return _prefetch(it, self.prefetch) if self.prefetch else it

    def _batches(self, rng: np.random.Generator) -> Iterator[Batch]:
        blocks = [b for b, p in enumerate(self._pairs_of_block) if len(p)]
        if self.shuffle:
            blocks = [blocks[i] for i in rng.permutation(len(blocks))]
        for w in range(0, len(blocks), self.window):
            chosen = blocks[w:w + self.window]
            parts = [self.packed.read(b * BLOCK, min((b + 1) * BLOCK, len(self.packed)),
                                      self.keys) for b in chosen]
            arrays = {k: np.concatenate([p.arrays[k] for p in parts]) for k in self.keys}
            if self.transform:  # once per stack, not once per pair
                arrays = self.transform(arrays)
            offset = {b: sum(len(p) for p in parts[:i]) for i, (b, p) in
                      enumerate(zip(chosen, parts))}
            pairs = np.concatenate([self._pairs_of_block[b] for b in chosen])
            rows = np.concatenate([self.state[self._pairs_of_block[b]] - b * BLOCK + offset[b]
                                   for b in chosen])
            if self.shuffle:
                perm = rng.permutation(len(pairs))
                pairs, rows = pairs[perm], rows[perm]
            for s in range(0, len(pairs), self.batch_size):
                p, r = pairs[s:s + self.batch_size], rows[s:s + self.batch_size]
                stacks = {k: a[r] for k, a in arrays.items()}
                yield Batch(self.collate(stacks) if self.collate else stacks, self.text[p],
                            self.target[p], p)


def _prefetch(it: Iterator[Batch], depth: int) -> Iterator[Batch]:
    """Run ``it`` in a background thread, at most ``depth`` batches ahead."""
    q: queue.Queue[Any] = queue.Queue(maxsize=depth)
    stop = threading.Event()
    done = object()

    def put(item: Any) -> bool:
        while not stop.is_set():
            try:
                q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        try:
            for item in it:
                if not put(item):
                    return
            put(done)
        except BaseException as e:  # re-raised in the consumer
            put(e)

    t = threading.Thread(target=work, daemon=True, name="sc2data-loader")
    t.start()
    try:
        while True:
            item = q.get()
            if item is done:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        t.join(timeout=5)
