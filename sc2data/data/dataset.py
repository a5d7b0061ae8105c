"""A dataset folder, and reading 2-frame stacks from it without h5py fancy indexing.

A folder holds ``dataset.json`` (settings, schema, codec, versions), the shards
``shard-NNNNN.h5`` (:mod:`sc2data.data.shards`) and ``index.parquet``: one row per episode with its
shard, frame and step offsets, and the shard's sha256 and size. The index is written last,
atomically, so its presence means the rollout finished.

Reads go chunk by chunk: a batch of (episode, step) requests is sorted into the chunks it
touches, each chunk of each storage block holding a wanted key is fetched and decoded once (or
taken from an LRU cache of decoded chunks), and the stacks are gathered in numpy.

A shard is checked when it is opened to be read: its size as the index records it, and its
header (format, settings, schema) and episode table as the dataset's record and index say
(:func:`shard_fault`), so a shard copied from another dataset is an error, not other stacks read
as this dataset's. Every chunk read is checked by its checksum; ``sc2data verify`` and ``label``
check every shard's sha256.
"""

from __future__ import annotations

import ctypes
import json
import os
from collections import OrderedDict
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from sc2data.data.chunks import ChunkDecoder, Codec
from sc2data.data.shards import Shard, unpack_available
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import write_atomic
from sc2data.ground.formats import DATASET, loads
from sc2data.schema import Block, Index, Schema, SchemaError, StackBatch, positions

DATASET_RECORD = "dataset.json"
"""A dataset folder's record: format, settings, schema, versions, … (its shape:
:data:`sc2data.ground.formats.DATASET`)."""
INDEX = "index.parquet"
INDEX_SCHEMA = pa.schema([
    ("shard", pa.string()), ("episode", pa.int64()), ("n_steps", pa.int64()),
    ("frame_start", pa.int64()), ("step_start", pa.int64()), ("env_seed", pa.int64()),
    ("agent_seed", pa.int64()), ("reward", pa.float64()), ("shard_sha256", pa.string()),
    ("shard_bytes", pa.int64()),
])
"""One row per episode. ``frame_start``/``step_start`` locate it inside its shard."""


def shard_name(i: int) -> str:
    return f"shard-{i:05d}.h5"


def shard_settings(settings: dict[str, Any], version: int = DATASET.version) -> dict[str, Any]:
    """What each shard of a dataset of format ``version`` records of its settings: all of them
    but, from format 3 on, the episode count (a shard does not depend on how many follow it)."""
    return {k: v for k, v in settings.items() if version < 3 or k != "episodes"}


def write_dataset_record(folder: Path, record: dict[str, Any]) -> None:
    """Write ``record`` as the folder's ``dataset.json``, atomically."""
    text = json.dumps(record, indent=2, sort_keys=True) + "\n"
    write_atomic(folder / DATASET_RECORD, text.encode())


def write_index(folder: Path, rows: Sequence[dict[str, Any]]) -> None:
    table = pa.Table.from_pylist(sorted(rows, key=lambda r: r["episode"]), schema=INDEX_SCHEMA)
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    write_atomic(folder / INDEX, sink.getvalue().to_pybytes())


def read_dataset_record(folder: Path) -> dict[str, Any]:
    """``dataset.json``; a folder without one is not an sc2data dataset."""
    path = Path(folder) / DATASET_RECORD
    if not Path(folder).is_dir():
        raise Sc2DataError(f"{folder} is not a folder")
    if not path.is_file():
        raise Sc2DataError(f"{folder} is not an sc2data dataset (no {DATASET_RECORD}); make one "
                           f"with `sc2data rollout --out {folder}`")
    try:
        record = loads(path.read_text())
    except (OSError, ValueError) as e:
        raise Sc2DataError(f"{path} is unreadable ({e}); delete the folder and roll out "
                           f"again") from e
    DATASET.check(record, path)
    return record


def read_index(folder: Path) -> pa.Table:
    path = Path(folder) / INDEX
    if not path.is_file():
        raise Sc2DataError(f"{folder} is an unfinished rollout (no {INDEX}); rerun the same "
                           f"`sc2data rollout` command to finish it")
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as e:
        raise Sc2DataError(f"{path} is unreadable ({e}); rerun the rollout to rewrite it") from e
    missing = set(INDEX_SCHEMA.names) - set(table.column_names)
    if missing:
        raise Sc2DataError(f"{path} lacks columns {sorted(missing)}; rerun the rollout")
    return table


IDENTITY = ("episode", "n_steps", "frame_start", "step_start", "env_seed", "agent_seed")
"""The episode-table columns a shard and the index must agree on."""


def shard_fault(shard: Shard, rows: dict[str, np.ndarray], record: dict[str, Any]
                ) -> str | None:
    """Why ``shard`` is not the one the dataset record ``record`` and the index ``rows`` (its
    episodes, sorted) describe — its format version, settings, schema or episode table — or None."""
    version = record.get("format_version")
    if shard.attrs.get("format_version") != version:
        return f"shard format {shard.attrs.get('format_version')} in a dataset of format {version}"
    if shard.attrs.get("settings") != shard_settings(record["settings"], version):
        return f"its settings differ from {DATASET_RECORD}'s"
    if shard.attrs.get("schema") != record["schema"]:
        return f"its schema differs from {DATASET_RECORD}'s"
    for col in IDENTITY:
        if not np.array_equal(np.asarray(shard.episodes[col]), rows[col]):
            return f"its episode table ({col}) differs from {INDEX}"
    return None


def record_schema(record: dict[str, Any], where: Path) -> Schema:
    """The schema a dataset record holds; a one-line error naming ``where`` if it is invalid."""
    try:
        return Schema.from_dict(record["schema"])
    except (SchemaError, KeyError, ValueError) as e:
        raise Sc2DataError(f"{where}: {e}") from None


def record_codec(record: dict[str, Any], where: Path) -> Codec:
    """The codec in a dataset record's settings; a one-line error naming ``where`` if invalid."""
    try:
        codec = Codec.from_dict(record["settings"]["codec"])
    except (KeyError, TypeError, ValueError) as e:
        raise Sc2DataError(f"{where}: no valid codec in its settings ({e!r}); regenerate the "
                           f"dataset with this sc2data") from None
    if codec.chunk_frames < 1:
        raise Sc2DataError(f"{where}: chunk_frames {codec.chunk_frames} must be at least 1")
    return codec


_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_malloc_tuned = False


def keep_freed_memory() -> None:
    """Ask glibc to keep freed batch-sized blocks instead of returning them to the OS.

    By default glibc hands blocks above 128 KB back on ``free`` and page-faults them in again on
    the next batch; on this project's VMs a fault costs ~2.5 µs per 4 KB, which halves read
    speed (BENCHMARKS.md). This is what ``MALLOC_MMAP_THRESHOLD_``/``MALLOC_TRIM_THRESHOLD_``
    do; it is process-wide, done once, and a no-op where glibc is absent.
    """
    global _malloc_tuned
    if _malloc_tuned:
        return
    _malloc_tuned = True
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt(_M_MMAP_THRESHOLD, 32 << 20)  # glibc's largest allowed value
        libc.mallopt(_M_TRIM_THRESHOLD, 512 << 20)
    except (OSError, AttributeError):
        pass


class _ChunkCache:
    """The chunks the last read decoded (read-only arrays), up to ``max_bytes``.

    Entries are views into the arrays that read decoded its chunks into, so caching copies
    nothing; keeping only the last read's bounds the memory they hold alive to about one read.
    That is what a cache is for here: a sequential batch finds the chunk it shares with the one
    before; random stacks of a large dataset seldom meet a chunk twice.
    """

    def __init__(self, max_bytes: int) -> None:
        self.max_bytes = max_bytes
        self._items: dict[tuple[int, str, int], np.ndarray] = {}

    def get(self, key: tuple[int, str, int]) -> np.ndarray | None:
        return self._items.get(key)

    def replace(self, items: Iterable[tuple[tuple[int, str, int], np.ndarray]]) -> None:
        """Forget what was cached; keep ``items`` (in order, while they fit)."""
        self._items = {}
        room = self.max_bytes
        for key, value in items:
            if value.nbytes > room:
                break
            self._items[key] = value
            room -= value.nbytes


def default_max_open() -> int:
    """How many shards a reader keeps open: 1,024, or fewer where the process may open fewer files
    (a shard holds two descriptors). Random reads touch most shards of a large dataset in every
    batch, and reopening one costs ~10 ms, against ~0.2 ms for a whole stack once open."""
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    except (ImportError, OSError, ValueError):
        return 64
    return 1024 if soft == resource.RLIM_INFINITY else max(8, min(1024, soft // 4))


class Dataset:
    """Stacks of a finished rollout folder, by (episode, step); see :func:`open_dataset`."""

    def __init__(self, folder: Path, cache_bytes: int = 128 << 20,
                 max_open: int | None = None) -> None:
        keep_freed_memory()
        self.folder = Path(folder)
        self.record: dict[str, Any] = read_dataset_record(self.folder)
        """The dataset record (``dataset.json``): format, settings, schema, versions, …"""
        self.schema = record_schema(self.record, self.folder / DATASET_RECORD)
        self.index = read_index(self.folder)
        cols = {c: self.index.column(c).to_numpy() for c in
                ("episode", "n_steps", "frame_start", "step_start")}
        order = np.argsort(cols["episode"], kind="stable")
        self.episode_ids: np.ndarray = cols["episode"][order]
        """Episode ids, ascending."""
        self.n_steps: np.ndarray = cols["n_steps"][order]
        """Steps (= stacks) of each episode, aligned with :attr:`episode_ids`."""
        self._frame_start = cols["frame_start"][order]
        self._step_start = cols["step_start"][order]
        names = np.asarray(self.index.column("shard").to_pylist(), dtype=object)[order]
        self.shard_names: list[str] = sorted(set(names))
        self._shard_rows = names
        self._identity = {c: self.index.column(c).to_numpy()[order]
                          for c in (*IDENTITY, "shard_bytes")}
        self._shard_of = np.searchsorted(np.asarray(self.shard_names, dtype=object), names)
        self._stack_offsets = np.concatenate([[0], np.cumsum(self.n_steps)])
        self._cache = _ChunkCache(cache_bytes)
        self._decoder = ChunkDecoder()
        self._blocks = self.schema.blocks()
        self._chunk_frames = record_codec(self.record, self.folder / DATASET_RECORD).chunk_frames
        self._frame_layout: dict[str, tuple[tuple[int, ...], np.dtype]] = {
            l.key: ((self.schema.size(l.group),) * 2, l.dtype) for l in self.schema.layers}
        self._frame_layout.update({v.name: ((v.size,), v.dtype) for v in self.schema.vectors})
        self._max_open = max_open if max_open is not None else default_max_open()
        self._open: OrderedDict[int, Shard] = OrderedDict()
        self._steps: dict[int, dict[str, np.ndarray]] = {}
        self._masks: dict[int, np.ndarray | None] = {}

    # -- bookkeeping --------------------------------------------------------------------------
    def __len__(self) -> int:
        """Number of stacks (agent steps) in the dataset."""
        return int(self._stack_offsets[-1])

    def __repr__(self) -> str:
        """Counts and the shape of one stack, never arrays."""
        per_stack = []
        for group in ("screen", "minimap"):
            ls = self.schema.group(group)
            if ls:
                side = self.schema.size(group)
                dtypes = "/".join(sorted({l.dtype.name for l in ls}))
                per_stack.append(f"{group} {len(ls)} x (2, {side}, {side}) {dtypes}")
        per_stack += [f"{v.name} (2, {v.size}) {v.dtype.name}" for v in self.schema.vectors]
        return (f"Dataset({str(self.folder)!r}, episodes={len(self.episode_ids)}, "
                f"stacks={len(self)}; per stack: {', '.join(per_stack)})")

    def __getitem__(self, index: Index | tuple[int, Index]) -> StackBatch:
        """Stacks as a :class:`StackBatch`: ``ds[i]`` by global position (the order of
        :meth:`iter_batches`; an int gives a batch of one), ``ds[i:j]``, ``ds[positions]`` or a
        boolean mask, and ``ds[episode, step]`` (``step`` also a slice or positions within that
        episode)."""
        if isinstance(index, tuple):
            if len(index) != 2 or not isinstance(index[0], (int, np.integer)):
                raise IndexError("index a dataset as ds[position] or ds[episode, step]")
            episode = int(index[0])
            row = int(self._rows(np.array([episode]), np.array([0]))[0])
            steps = _as_array(positions(index[1], int(self.n_steps[row])))
            return self.read(np.full(len(steps), episode), steps)
        return self.read(*self.locate_positions(_as_array(positions(index, len(self)))))

    def __iter__(self) -> Iterator[StackBatch]:
        """Every stack in global order, each a batch of one (read 1,024 at a time; for speed
        iterate :meth:`iter_batches` instead)."""
        for _, _, batch in self.iter_batches():
            yield from batch

    def __enter__(self) -> Dataset:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        for shard in self._open.values():
            shard.close()
        self._open.clear()

    @property
    def settings(self) -> dict[str, Any]:
        return dict(self.record["settings"])

    @property
    def has_masks(self) -> bool:
        """Whether the dataset keeps each frame's ``available_actions`` (format 4 on): then
        :meth:`actions` gives ``available`` and ``next_available``."""
        return int(self.record["format_version"]) >= 4

    def _shard(self, i: int) -> Shard:
        shard = self._open.get(i)
        if shard is None:
            shard = self._checked(self.shard_names[i])
            self._open[i] = shard
            if len(self._open) > self._max_open:
                self._open.popitem(last=False)[1].close()
        else:
            self._open.move_to_end(i)
        return shard

    def _checked(self, name: str) -> Shard:
        """Open shard ``name``; a one-line error unless it is the shard the index lists."""
        path = self.folder / name
        mine = self._shard_rows == name  # the index's rows in episode order: sorted
        rows = {c: v[mine] for c, v in self._identity.items()}
        recorded = set(rows["shard_bytes"].tolist())
        try:
            size = path.stat().st_size
        except OSError:
            size = None
        fault = None if size is None or recorded == {size} else \
            f"{size:,} bytes, the index says {min(recorded):,}"
        shard = None
        if fault is None:
            shard = Shard(path)
            fault = shard_fault(shard, rows, self.record)
        if fault is not None:
            if shard is not None:
                shard.close()
            raise Sc2DataError(f"{path} is not this dataset's shard ({fault}): damaged, replaced "
                               f"or copied from another dataset; run sc2data verify "
                               f"{self.folder}, and roll the shard out again")
        assert shard is not None
        return shard

    def _rows(self, episodes: np.ndarray, steps: np.ndarray) -> np.ndarray:
        rows = np.searchsorted(self.episode_ids, episodes)
        rows = np.minimum(rows, len(self.episode_ids) - 1)
        bad = self.episode_ids[rows] != episodes
        if bad.any():
            raise KeyError(f"episode {int(episodes[bad][0])} is not in {self.folder}")
        out = (steps < 0) | (steps >= self.n_steps[rows])
        if out.any():
            i = int(np.flatnonzero(out)[0])
            raise IndexError(f"step {int(steps[i])} is outside episode {int(episodes[i])} "
                             f"(0..{int(self.n_steps[rows[i]]) - 1})")
        return rows

    def _keys(self, keys: Iterable[str] | None) -> list[str]:
        known = self.schema.keys()
        if keys is None:
            return list(known)
        keys = list(keys)
        for k in keys:
            if k not in known:
                raise KeyError(f"{k!r} is not stored in {self.folder}; stored: {', '.join(known)}")
        return keys

    # -- reading ------------------------------------------------------------------------------
    def _decode(self, blocks: Sequence[Block], shard_of: np.ndarray, frames: np.ndarray
                ) -> tuple[list[np.ndarray], np.ndarray]:
        """Decode what ``blocks`` hold of frames ``frames[i]`` of shards ``shard_of[i]``.

        Returns one array per block holding every chunk needed, chunk after chunk (from the
        cache or decoded straight into place), and the row of that array where each requested
        frame lies. The checksums of every chunk decoded, of all shards and blocks, are verified
        together in one vectorised pass.
        """
        c = self._chunk_frames
        chunk = shard_of.astype(np.int64) << 40 | frames // c  # (shard, chunk) as one sortable key
        uniq, inverse = np.unique(chunk, return_inverse=True)
        rows = inverse.reshape(-1) * c + frames % c
        u_shard, u_chunk = uniq >> 40, uniq & ((1 << 40) - 1)
        starts = np.flatnonzero(np.diff(u_shard, prepend=-1))
        spans = list(zip(starts.tolist(), [*starts[1:].tolist(), len(uniq)]))
        cache = self._cache
        raws: list[bytes] = []
        masks: list[int] = []
        dests: list[np.ndarray] = []
        wheres: list[str] = []
        fresh: list[tuple[int, int, int, int]] = []  # (block, shard, row of its array, chunk)
        bufs = [np.empty((len(uniq), c, *b.frame_shape), b.dtype) for b in blocks]
        for lo, hi in spans:  # shard by shard, so that each is opened once per read
            si = int(u_shard[lo])
            shard = self._shard(si)
            for b, (block, buf) in enumerate(zip(blocks, bufs, strict=True)):
                src = shard.frames(block.name)
                if src.chunk_frames != c or src.frame_shape != block.frame_shape:
                    raise Sc2DataError(f"{src.where} is chunked or shaped unlike {DATASET_RECORD} "
                                       f"says; run `sc2data verify` on {self.folder}")
                missing: list[int] = []
                for j, i in enumerate(u_chunk[lo:hi].tolist(), lo):
                    hit = cache.get((si, block.name, i))
                    if hit is None:
                        missing.append(j)
                    else:
                        buf[j] = hit
                ids = u_chunk[missing]
                if missing and src.fast:
                    r, m = src.raw_chunks(ids)
                    raws += r
                    masks += m
                    dests += [buf[j] for j in missing]
                    wheres += [src.where] * len(r)
                elif missing:
                    for j, data in zip(missing, src.read_chunks(ids), strict=True):
                        buf[j] = np.frombuffer(data, block.dtype).reshape(buf.shape[1:])
                fresh += [(b, si, j, i) for j, i in zip(missing, ids.tolist())]
        if raws:
            self._decoder.decode_into(raws, masks, dests, wheres)
        for buf in bufs:
            buf.flags.writeable = False
        cache.replace(((si, blocks[b].name, i), bufs[b][j]) for b, si, j, i in fresh)
        return [b.reshape(-1, *b.shape[2:]) for b in bufs], rows

    def read(self, episodes: Sequence[int] | np.ndarray, steps: Sequence[int] | np.ndarray,
             keys: Iterable[str] | None = None) -> StackBatch:
        """Stacks ``(episodes[i], steps[i])`` for all i, as one :class:`StackBatch`."""
        episodes = np.asarray(episodes, np.int64).reshape(-1)
        steps = np.asarray(steps, np.int64).reshape(-1)
        if episodes.shape != steps.shape:
            raise ValueError("episodes and steps must have the same length")
        keys = self._keys(keys)
        rows = self._rows(episodes, steps)
        first = self._frame_start[rows] + steps
        frames = np.stack([first, first + 1], axis=1).reshape(-1)  # (previous, current) pairs
        wanted = set(keys)
        blocks = [b for b in self._blocks if wanted.intersection(b.keys)]
        bufs, at = self._decode(blocks, np.repeat(self._shard_of[rows], 2), frames)
        out: dict[str, np.ndarray] = {}
        for block, buf in zip(blocks, bufs, strict=True):
            for k, part in zip(block.keys, block.parts, strict=True):
                if k in wanted:  # numpy's gather copies whole frames at a time
                    out[k] = buf[at, part].reshape(len(rows), 2, *self._frame_layout[k][0])
        return StackBatch({k: out[k] for k in keys}, self.schema)

    def stack(self, episode: int, step: int, keys: Iterable[str] | None = None) -> StackBatch:
        """One stack (a batch of size 1): frames ``step`` and ``step + 1`` of ``episode``."""
        return self.read([episode], [step], keys)

    def locate(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """(episodes, steps) of the stacks at global positions ``[start, stop)``, in order."""
        return self.locate_positions(np.arange(start, stop, dtype=np.int64))

    def locate_positions(self, positions: Sequence[int] | np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """(episodes, steps) of stacks by global position ``0 <= p < len(self)`` (the order of
        :meth:`iter_batches`): e.g. ``read(*locate_positions(rng.integers(0, len(ds), 256)))``."""
        pos = np.asarray(positions, np.int64).reshape(-1)
        if len(pos) and (pos.min() < 0 or pos.max() >= len(self)):
            raise IndexError(f"stack positions must lie in [0, {len(self)})")
        rows = np.searchsorted(self._stack_offsets, pos, side="right") - 1
        return self.episode_ids[rows], pos - self._stack_offsets[rows]

    def iter_batches(self, batch_size: int = 1024, keys: Iterable[str] | None = None
                     ) -> Iterator[tuple[np.ndarray, np.ndarray, StackBatch]]:
        """Every stack in (episode, step) order: ``(episodes, steps, StackBatch)`` per batch."""
        if batch_size < 1:
            raise ValueError("batch_size must be at least 1")
        keys = self._keys(keys)
        for start in range(0, len(self), batch_size):
            episodes, steps = self.locate(start, min(start + batch_size, len(self)))
            yield episodes, steps, self.read(episodes, steps, keys)

    def actions(self, episodes: Sequence[int] | np.ndarray, steps: Sequence[int] | np.ndarray
                ) -> dict[str, np.ndarray]:
        """The action taken in each stack (pysc2 ``function`` id, flattened ``args``) and the
        ``reward`` it returned; :func:`sc2data.data.shards.function_call` rebuilds the call.

        Where the dataset keeps action masks (:attr:`has_masks`), also ``available`` and
        ``next_available``: ``(N, len(actions.FUNCTIONS))`` booleans, pysc2's
        ``available_actions`` of the stack's previous frame (the one the action was chosen in)
        and of its current frame."""
        episodes = np.asarray(episodes, np.int64).reshape(-1)
        steps = np.asarray(steps, np.int64).reshape(-1)
        rows = self._rows(episodes, steps)
        at = self._step_start[rows] + steps
        frame = self._frame_start[rows] + steps
        shard_of = self._shard_of[rows]
        out: dict[str, np.ndarray] = {}
        for si in np.unique(shard_of).tolist():
            if si not in self._steps:
                shard = self._shard(si)
                self._steps[si] = shard.steps()
                self._masks[si] = shard.masks() if self.has_masks else None
            sel = np.flatnonzero(shard_of == si)
            table = dict(self._steps[si])
            masks = self._masks[si]
            if self.has_masks:
                if masks is None or len(masks) < int(frame[sel].max()) + 2:
                    raise Sc2DataError(f"{self.folder / self.shard_names[si]} lacks action masks "
                                       f"of its frames; run sc2data verify {self.folder}")
                table["available"] = masks[frame[sel]]
                table["next_available"] = masks[frame[sel] + 1]
            for k, v in table.items():
                if k not in out:
                    out[k] = np.empty((len(rows), *v.shape[1:]), v.dtype)
                out[k][sel] = v if k.endswith("available") else v[at[sel]]
        for k in ("available", "next_available"):
            if k in out:
                out[k] = unpack_available(out[k])
        return out


def _as_array(rows: np.ndarray | slice) -> np.ndarray:
    return np.arange(rows.start, rows.stop, rows.step, dtype=np.int64) \
        if isinstance(rows, slice) else rows


def open_dataset(folder: str | os.PathLike[str], cache_bytes: int = 128 << 20) -> Dataset:
    """Open a finished rollout folder for reading (no PyTorch needed)."""
    return Dataset(Path(folder), cache_bytes=cache_bytes)
