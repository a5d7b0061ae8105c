"""One shard file: consecutive episodes of frames, actions and rewards, in HDF5.

Layout, all derived from a :class:`~sc2data.schema.Schema`::

    /frames/<block>    (F, …)  one dataset per storage block (``Schema.blocks()``): the layers of
                               one group and dtype stacked, ``screen_uint8`` (F, L, 64, 64), …,
                               and the vectors end to end, ``vectors_int32`` (F, 25); its ``keys``
                               attribute names what it holds, in order. Episodes back to back,
                               T+1 frames for T steps, each frame once
    /steps/function    (S,)    pysc2 function id of the action taken between frames t and t+1
    /steps/args        (S, 5)  its arguments, flattened in pysc2's order, -1 padded
    /steps/reward      (S,)    the reward the step returned
    /available_actions (F, 72) each frame's pysc2 ``available_actions`` as a bit set over
                               ``actions.FUNCTIONS`` (``np.packbits``, little bit order; schema's
                               ``AVAILABLE``): row ``t`` masks the choice of step ``t``. Shard
                               format 4 on; older shards have none
    /episodes/<column> (E,)    episode, env_seed, agent_seed, frame_start, step_start, n_steps,
                               reward
    /chunk_index       (K, C, 3) file offset, stored size and filter mask of chunk c of frame
                               dataset k (blocks in schema order): what HDF5's chunk index says,
                               kept so that a reader need not walk it (~9 ms per dataset)

Stack ``t`` of an episode is frames ``frame_start + t`` and ``frame_start + t + 1`` with step
``step_start + t``. Every dataset is chunked, Zstd-compressed and fletcher32-checksummed
(:mod:`sc2data.data.chunks`); the root's attributes describe the shard (schema, versions,
settings…).
Nothing written depends on the time or on the worker that wrote it, so a shard's bytes depend on
its settings and seeds alone.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

import h5py
import numpy as np

from sc2data._pysc2 import actions
from sc2data.data.chunks import (
    ChecksumError,
    ChunkDecoder,
    ChunkEncoder,
    Codec,
    fast_path_ok,
)
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import fsync_path
from sc2data.ground.formats import SHARD, loads
from sc2data.schema import AVAILABLE, Schema, SchemaError

ARG_WIDTH = max(sum(len(a.sizes) for a in f.args) for f in actions.FUNCTIONS)
"""Widest flattened argument list of any pysc2 function (select_rect: add, x0, y0, x1, y1)."""
EPISODE_COLUMNS: tuple[str, ...] = ("episode", "env_seed", "agent_seed", "frame_start",
                                    "step_start", "n_steps", "reward")
_GROW = 256
"""Chunks added at a time when a frame dataset must grow."""
_SEAL_EVERY = 64
"""Flushes whose compressed chunks are checksummed and written together (a few hundred KB)."""
CHUNK_INDEX = "chunk_index"
MASKS = "available_actions"
"""The dataset of per-frame action masks (shard format 4 on)."""
MASK_BYTES = -(-AVAILABLE.size // 8)
"""Bytes of one packed mask row."""


def pack_available(available: Sequence[int] | np.ndarray) -> np.ndarray:
    """pysc2's ``available_actions`` (function ids) as one packed ``MASK_BYTES`` uint8 row."""
    ids = np.asarray(available, np.int64).reshape(-1)
    if len(ids) and (ids.min() < 0 or ids.max() >= AVAILABLE.size):
        raise ValueError(f"available_actions holds ids outside pysc2's {AVAILABLE.size} functions")
    mask = np.zeros(AVAILABLE.size, bool)
    mask[ids] = True
    return np.packbits(mask, bitorder="little")


def unpack_available(rows: np.ndarray) -> np.ndarray:
    """Packed mask rows ``(…, MASK_BYTES)`` as boolean masks ``(…, len(actions.FUNCTIONS))``."""
    return np.unpackbits(rows, axis=-1, count=AVAILABLE.size, bitorder="little").astype(bool)


def chunk_table(ds: h5py.Dataset) -> np.ndarray:
    """``(chunks, 3)``: file offset, stored size and filter mask of every chunk of a dataset
    chunked along axis 0 only, by chunk number, from HDF5's own chunk index (offset -1: none).
    """
    c = int(ds.chunks[0])
    table = np.full((-(-int(ds.shape[0]) // c), 3), -1, np.int64)

    def visit(info: Any) -> None:
        j = info.chunk_offset[0] // c
        if j < len(table):
            table[j] = (info.byte_offset, info.size, info.filter_mask)

    ds.id.chunk_iter(visit)
    return table


def flatten_args(function: int, args: Sequence[Sequence[int]]) -> np.ndarray:
    """A pysc2 FunctionCall's arguments as one ``ARG_WIDTH`` int16 row, -1 padded."""
    flat = [int(v) for a in args for v in a]
    if len(flat) > ARG_WIDTH:
        raise ValueError(f"function {function} has {len(flat)} argument values > {ARG_WIDTH}")
    return np.array(flat + [-1] * (ARG_WIDTH - len(flat)), np.int16)


def function_call(function: int, flat: np.ndarray) -> actions.FunctionCall:
    """Rebuild the pysc2 ``FunctionCall`` that :func:`flatten_args` stored."""
    args, i = [], 0
    for arg in actions.FUNCTIONS[int(function)].args:
        args.append([int(v) for v in flat[i:i + len(arg.sizes)]])
        i += len(arg.sizes)
    return actions.FunctionCall(int(function), args)


class ObservationError(Sc2DataError, ValueError):
    """An observation the schema cannot store losslessly (a value its layer's dtype cannot hold)."""


class ShardWriter:
    """Streams the episodes of one shard into ``path``; memory use is one chunk of frames and
    the compressed chunks of up to ``_SEAL_EVERY`` flushes.

    Call :meth:`begin_episode`, then :meth:`add_frame` T+1 times and :meth:`add_step` T times,
    then :meth:`end_episode`; :meth:`close` writes the tables and fsyncs the file.
    """

    def __init__(self, path: Path, schema: Schema, codec: Codec, attrs: Mapping[str, Any]) -> None:
        self.path = Path(path)
        self.schema = schema
        self.codec = codec
        self._file = h5py.File(self.path, "w", libver="latest")
        header = {**SHARD.header(), "schema": schema.to_dict(),
                  "schema_version": schema.version, "codec": codec.to_dict()}
        for k, v in {**header, **attrs}.items():
            # Integers stay integers for any HDF5 tool; everything else is JSON, unambiguously.
            self._file.attrs[k] = v if type(v) is int else json.dumps(v)
        c = codec.chunk_frames
        self._blocks = schema.blocks()
        self._frames: dict[str, h5py.Dataset] = {}
        for b in self._blocks:
            ds = self._file.create_dataset(
                f"frames/{b.name}", shape=(0, *b.frame_shape), maxshape=(None, *b.frame_shape),
                dtype=b.dtype, chunks=(c, *b.frame_shape), **codec.dataset_kwargs())
            ds.attrs["keys"] = json.dumps(list(b.keys))
            self._frames[b.name] = ds
        self._buffers = {b.name: np.zeros((c, *b.frame_shape), b.dtype) for b in self._blocks}
        self._ids = [(self._frames[b.name].id, (0,) * len(b.frame_shape), self._buffers[b.name])
                     for b in self._blocks]
        layer_of = {l.key: l for l in schema.layers}
        # Per spatial block: the observation key, the pysc2 indices of its layers (a slice when
        # they are consecutive: a view, no gather), the dtype's limit and the layers themselves.
        self._spatial: list[tuple[str, np.ndarray | slice, int, np.ndarray, list[Any]]] = []
        self._vectors: list[tuple[str, np.ndarray]] = []
        for b in self._blocks:
            buf = self._buffers[b.name]
            if b.name.startswith("vectors_"):
                self._vectors += [(k, buf[:, part]) for k, part in zip(b.keys, b.parts)]
                continue
            ls = [layer_of[k] for k in b.keys]
            idx = np.array([l.index for l in ls])
            sel: np.ndarray | slice = idx
            if len(idx) and np.array_equal(idx, np.arange(idx[0], idx[0] + len(idx))):
                sel = slice(int(idx[0]), int(idx[0]) + len(idx))
            self._spatial.append((f"feature_{ls[0].group}", sel, ls[0].limit, buf, ls))
        self._encoder = ChunkEncoder(codec)
        self._pending: list[tuple[int, list[bytes]]] = []
        self._n_frames = 0
        self._capacity = 0
        self._functions: list[int] = []
        self._args: list[np.ndarray] = []
        self._rewards: list[float] = []
        self._masks: list[np.ndarray] = []
        self._episodes: list[tuple[int, ...] | tuple[Any, ...]] = []
        self._current: dict[str, Any] | None = None

    # -- episodes ---------------------------------------------------------------------------
    def begin_episode(self, episode: int, env_seed: int, agent_seed: int) -> None:
        if self._current is not None:
            raise RuntimeError("begin_episode before end_episode")
        self._current = {"episode": episode, "env_seed": env_seed, "agent_seed": agent_seed,
                         "frame_start": self._n_frames, "step_start": len(self._functions),
                         "reward": 0.0}

    def add_frame(self, arrays: Mapping[str, np.ndarray],
                  available: Sequence[int] | np.ndarray = ()) -> None:
        """Append one frame: ``arrays`` holds every schema key (``Schema.extract``'s output),
        ``available`` the frame's ``available_actions`` (pysc2 function ids)."""
        self._masks.append(pack_available(available))
        slot = self._n_frames % self.codec.chunk_frames
        for b in self._blocks:
            frame = self._buffers[b.name][slot]
            for k, part in zip(b.keys, b.parts):
                frame[part] = np.asarray(arrays[k]).reshape(frame[part].shape)
        self._next_frame()

    def add_observation(self, obs: Mapping[str, Any]) -> None:
        """Append one pysc2 observation: what ``add_frame(schema.extract(obs))`` does, with the
        same lossless range check, but one vectorised check per block and no intermediate copy.
        """
        self._masks.append(pack_available(obs["available_actions"]))
        slot = self._n_frames % self.codec.chunk_frames
        for obs_key, sel, limit, buf, layers in self._spatial:
            planes = np.asarray(obs[obs_key])[sel]
            if planes.dtype == np.int32:  # one pass: negatives read as unsigned exceed any limit
                bad = planes.view(np.uint32).max() >= limit
            else:
                bad = planes.max() >= limit or planes.min() < 0
            if bad:
                self._out_of_range(planes, limit, layers)
            buf[slot] = planes
        for name, buf in self._vectors:
            buf[slot] = np.asarray(obs[name]).reshape(buf.shape[1:])
        self._next_frame()

    def _out_of_range(self, planes: np.ndarray, limit: int, layers: list[Any]) -> NoReturn:
        """Raise the error naming the first layer of ``planes`` outside ``[0, limit)``."""
        flat = planes.reshape(len(planes), -1)
        j = int(np.flatnonzero((flat.max(axis=1) >= limit) | (flat.min(axis=1) < 0))[0])
        l, plane = layers[j], planes[j]
        cur = self._current or {}
        raise ObservationError(
            f"frame {self._n_frames - cur.get('frame_start', 0)} of episode "
            f"{cur.get('episode')}: {l.key} holds values outside [0, {l.limit}) (min "
            f"{plane.min()}, max {plane.max()}), which its {l.dtype} cannot store losslessly")

    def _next_frame(self) -> None:
        self._n_frames += 1
        if self._n_frames % self.codec.chunk_frames == 0:
            self._flush()

    def add_step(self, function: int, args: Sequence[Sequence[int]], reward: float) -> None:
        """Record the action taken between the last two frames and the reward it returned."""
        assert self._current is not None
        self._functions.append(int(function))
        self._args.append(flatten_args(function, args))
        self._rewards.append(float(reward))
        self._current["reward"] += float(reward)

    def end_episode(self) -> int:
        """Close the episode; returns its number of steps."""
        cur = self._current
        assert cur is not None
        n_steps = len(self._functions) - cur["step_start"]
        if self._n_frames - cur["frame_start"] != n_steps + 1:
            raise RuntimeError("an episode needs exactly one frame more than it has steps")
        self._episodes.append(tuple(cur[c] if c != "n_steps" else n_steps
                                    for c in EPISODE_COLUMNS))
        self._current = None
        return n_steps

    # -- chunks -----------------------------------------------------------------------------
    def _flush(self) -> None:
        """Compress the buffered chunk of every key and write it where it belongs."""
        c = self.codec.chunk_frames
        start = ((self._n_frames - 1) // c) * c
        if start + c > self._capacity:
            self._capacity += _GROW * c
            for ds in self._frames.values():
                ds.resize(self._capacity, axis=0)
        self._pending.append((start, self._encoder.compress([buf for _, _, buf in self._ids])))
        if len(self._pending) == _SEAL_EVERY:
            self._write_pending()

    def _write_pending(self) -> None:
        """Checksum the compressed chunks of the last flushes together and write them."""
        sealed = iter(self._encoder.seal([p for _, ps in self._pending for p in ps]))
        for start, _ in self._pending:
            for dsid, zeros, _ in self._ids:
                dsid.write_direct_chunk((start, *zeros), next(sealed))
        self._pending.clear()

    def close(self) -> None:
        """Write the last chunk, the step and episode tables; trim; fsync."""
        if self._current is not None:
            raise RuntimeError("close() inside an episode")
        filled = self._n_frames % self.codec.chunk_frames
        if filled:  # the last, partial chunk: zero the stale frames after it, as HDF5 would
            for buf in self._buffers.values():
                buf[filled:] = 0
            self._flush()
        self._write_pending()
        for ds in self._frames.values():
            ds.resize(self._n_frames, axis=0)
        kw = self.codec.dataset_kwargs()
        n = len(self._functions)
        step_chunk = (max(1, min(n, 4096)),)
        self._file.create_dataset("steps/function", data=np.array(self._functions, np.uint16),
                                  chunks=step_chunk, **kw)
        self._file.create_dataset("steps/args", data=np.array(self._args, np.int16).reshape(
            n, ARG_WIDTH), chunks=(step_chunk[0], ARG_WIDTH), **kw)
        self._file.create_dataset("steps/reward", data=np.array(self._rewards, np.float32),
                                  chunks=step_chunk, **kw)
        table = np.array(self._episodes, dtype=object).reshape(-1, len(EPISODE_COLUMNS))
        for j, col in enumerate(EPISODE_COLUMNS):
            dtype = np.float64 if col == "reward" else np.int64
            self._file.create_dataset(f"episodes/{col}", data=table[:, j].astype(dtype),
                                      chunks=(max(1, len(table)),), **kw)
        masks = np.array(self._masks, np.uint8).reshape(-1, MASK_BYTES)
        self._file.create_dataset(MASKS, data=masks, chunks=(max(1, min(len(masks), 4096)),
                                                             MASK_BYTES), **kw)
        self._file.attrs["n_frames"] = self._n_frames
        self._file.attrs["n_steps"] = n
        index = np.stack([chunk_table(self._frames[b.name]) for b in self._blocks])
        if index.size:
            self._file.create_dataset(CHUNK_INDEX, data=index, chunks=index.shape, **kw)
        self._file.close()
        fsync_path(self.path)

    def abort(self) -> None:
        """Close without finishing; the caller deletes the file."""
        try:
            self._file.close()
        except Exception:  # noqa: BLE001 - the file is being thrown away
            pass


def _damaged(path: Path, what: object) -> Sc2DataError:
    return Sc2DataError(f"{path} is damaged ({what}); delete it and rerun the rollout to "
                        f"regenerate it, or run `sc2data verify` on its folder")


class FrameSource:
    """Decoded whole chunks of one frame dataset, as bytes.

    Fast path (our Zstd + fletcher32 pipeline): the chunk table comes from the shard's stored
    chunk index (or one ``chunk_iter`` walk), chunks are read from the file with ``os.pread``,
    their checksums verified in one vectorised pass, then decompressed. (``pread`` rather than a
    memory map: a map faults in each page on first touch, which halved random reads of a large
    dataset already in the page cache, BENCHMARKS.md.) Any other pipeline is read through h5py,
    chunk by chunk.
    """

    def __init__(self, ds: h5py.Dataset, fd: int | None, where: str,
                 table: np.ndarray | None = None) -> None:
        self.ds = ds
        self.where = where
        self.chunk_frames = int(ds.chunks[0])
        self.n_frames = int(ds.shape[0])
        self.frame_shape: tuple[int, ...] = tuple(ds.shape[1:])
        self.dtype = ds.dtype
        self.chunk_bytes = self.chunk_frames * int(np.prod(self.frame_shape)) * ds.dtype.itemsize
        self._fd = fd if fd is not None and fast_path_ok(ds) else None
        self._decoder = ChunkDecoder()
        self._stored = table
        self._table: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def _chunk_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """File offset, stored size and filter mask of every chunk, by chunk number: the
        shard's stored chunk index, else (older shards) HDF5's, walked once."""
        if self._table is None:
            n = -(-self.n_frames // self.chunk_frames)
            t = self._stored if self._stored is not None else chunk_table(self.ds)
            if t.shape != (n, 3):
                raise ChecksumError(f"{self.where}: the chunk index does not fit the dataset")
            if (t[:, 0] < 0).any() or (t[:, 1] < 5).any():
                raise ChecksumError(f"{self.where}: {int((t[:, 0] < 0).sum())} chunk(s) missing")
            self._table = (t[:, 0], t[:, 1], t[:, 2])
        return self._table

    @property
    def fast(self) -> bool:
        """True when chunks come raw from the file (then use :meth:`raw_chunks`)."""
        return self._fd is not None

    def raw_chunks(self, ids: np.ndarray) -> tuple[list[bytes], list[int]]:
        """Fast path: the stored bytes (payload + checksum) and filter masks of chunks ``ids``,
        for a :class:`~sc2data.data.chunks.ChunkDecoder` to verify and decode."""
        assert self._fd is not None
        offset, size, mask = self._chunk_table()
        fd = self._fd
        raws = [os.pread(fd, n, o) for o, n in zip(offset[ids].tolist(), size[ids].tolist())]
        return raws, mask[ids].tolist()

    def read_chunks(self, ids: np.ndarray) -> list[bytes]:
        """The decoded bytes of chunks ``ids`` (``chunk_bytes`` each, the last zero padded)."""
        if self._fd is not None:
            raws, masks = self.raw_chunks(ids)
            return self._decoder.decode(raws, masks, [self.chunk_bytes] * len(raws),
                                        [self.where] * len(raws))
        c, out = self.chunk_frames, []
        for i in np.asarray(ids).tolist():
            block = np.zeros((c, *self.frame_shape), self.dtype)
            part = self.ds[i * c:min((i + 1) * c, self.n_frames)]
            block[:len(part)] = part
            out.append(block.tobytes())
        return out


class Shard:
    """One shard opened read-only: attributes, schema, episode table, frames and steps."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        try:
            self.file = h5py.File(self.path, "r")
        except OSError as e:
            raise Sc2DataError(f"{self.path} is not a readable HDF5 file ({_first_line(e)}); "
                               f"it is truncated or not an sc2data shard") from None
        try:
            self.attrs: dict[str, Any] = {k: _attr(v) for k, v in self.file.attrs.items()}
            SHARD.check(self.attrs, self.path)
            try:
                self.schema = Schema.from_dict(self.attrs["schema"])
            except SchemaError as e:
                raise Sc2DataError(f"{self.path}: {e}") from None
            self.episodes = {c: self.file[f"episodes/{c}"][:] for c in EPISODE_COLUMNS}
        except (KeyError, OSError, ValueError) as e:
            self.file.close()
            raise _damaged(self.path, _first_line(e)) from None
        except Sc2DataError:
            self.file.close()
            raise
        self._sources: dict[str, FrameSource] = {}
        self._fd: int | None = None
        self._index: dict[str, np.ndarray] | None = None

    def chunk_index(self) -> dict[str, np.ndarray]:
        """The stored chunk index by block name (empty when a shard has none)."""
        if self._index is None:
            self._index = {}
            if CHUNK_INDEX in self.file:
                try:
                    stored = self.file[CHUNK_INDEX][()]
                except OSError as e:
                    raise _damaged(self.path, _first_line(e)) from None
                names = [b.name for b in self.schema.blocks()]
                if stored.ndim != 3 or len(stored) != len(names):
                    raise _damaged(self.path, "its chunk index does not fit its schema")
                self._index = dict(zip(names, stored))
        return self._index

    def frames(self, block: str) -> FrameSource:
        """The chunk reader of frame dataset ``block`` (a :class:`~sc2data.schema.Block`
        name)."""
        if block not in self._sources:
            if self._fd is None:
                self._fd = os.open(self.path, os.O_RDONLY)
            try:
                ds = self.file[f"frames/{block}"]
            except KeyError:
                raise _damaged(self.path, f"frames/{block} is missing") from None
            self._sources[block] = FrameSource(ds, self._fd, f"{self.path.name}:frames/{block}",
                                               self.chunk_index().get(block))
        return self._sources[block]

    def steps(self) -> dict[str, np.ndarray]:
        """``function`` (S,), ``args`` (S, ARG_WIDTH) and ``reward`` (S,) of every step."""
        try:
            return {k: self.file[f"steps/{k}"][:] for k in ("function", "args", "reward")}
        except OSError as e:
            raise _damaged(self.path, _first_line(e)) from None

    def masks(self) -> np.ndarray | None:
        """``(F, MASK_BYTES)`` packed action masks of every frame (:func:`unpack_available`),
        None for a shard written before they were kept (format 3 and older)."""
        if MASKS not in self.file:
            return None
        try:
            return self.file[MASKS][:]
        except OSError as e:
            raise _damaged(self.path, _first_line(e)) from None

    def close(self) -> None:
        self._sources.clear()
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        self.file.close()


def _attr(v: Any) -> Any:
    """An HDF5 attribute as Python: the writer's JSON strings decoded, numpy scalars unwrapped."""
    if isinstance(v, bytes):
        v = v.decode()
    if isinstance(v, str):
        return loads(v)  # a foreign shard: too deep, non-finite → ValueError
    return v.item() if isinstance(v, np.generic) else v


def _first_line(e: BaseException) -> str:
    return str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__


__all__ = ["ARG_WIDTH", "CHUNK_INDEX", "MASKS", "MASK_BYTES", "ChecksumError", "FrameSource",
           "ObservationError", "Shard", "ShardWriter", "chunk_table", "flatten_args",
           "function_call", "pack_available", "unpack_available"]
