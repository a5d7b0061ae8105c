"""Packed training data: the stacks one split of a pair set uses, in one sequential HDF5 file.

``sc2data pair`` copies every stack a split refers to into ``packed/<split>.h5`` so that training
reads large contiguous blocks instead of random stacks from the rollout shards. The file holds one
dataset per schema key, shaped ``(N, 2, …)`` (N stacks; axis 1 = previous, current frame), in the
same lossless dtypes as the shards; pairs refer to stacks by row (``state`` column of
``pairs.parquet``). Rows are stored in the order they were written; the trainer shuffles blocks.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import h5py
import hdf5plugin
import numpy as np

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import PARTIAL, publish
from sc2data.ground.formats import PACKED
from sc2data.schema import Schema, SchemaError, StackBatch

BLOCK = 256
"""Stacks per HDF5 chunk: the unit the trainer reads and shuffles."""


def _compression() -> Mapping[str, Any]:
    # LZ4 decodes fastest of the lossless HDF5 filters we measured (BENCHMARKS.md, codecs);
    # training decodes every stack once per epoch, so decode speed matters more than the last few
    # percent of size.
    return dict(hdf5plugin.LZ4())


class PackedWriter:
    """Append stacks to a new packed file; the file gets its final name on :meth:`close`.

    It writes with HDF5's chunk cache off (whole chunks go straight to the file), so that a full
    disk fails the write that hit it; with the cache, the failure surfaced only when the file was
    closed, and HDF5 then crashed the process while closing it (exit 139)."""

    def __init__(self, path: str | os.PathLike[str], schema: Schema, n: int,
                 attrs: Mapping[str, Any] | None = None) -> None:
        self.path = Path(path)
        self.partial = self.path.with_name(self.path.name + PARTIAL)
        self.schema = schema
        self.n = n
        self.pos = 0
        self._f = h5py.File(self.partial, "w", rdcc_nbytes=0)
        self._ds: dict[str, h5py.Dataset] = {}
        try:
            self._f.attrs.update(PACKED.header())
            self._f.attrs["schema"] = json.dumps(schema.to_dict())
            for k, v in (attrs or {}).items():
                self._f.attrs[k] = v if isinstance(v, (int, float, str)) else json.dumps(v)
            for l in schema.layers:
                s = schema.size(l.group)
                self._create(l.key, (n, 2, s, s), l.dtype)
            for v in schema.vectors:
                self._create(v.name, (n, 2, v.size), v.dtype)
        except BaseException:
            self.abort()
            raise

    def _create(self, key: str, shape: tuple[int, ...], dtype: np.dtype) -> None:
        chunks = (min(BLOCK, max(1, shape[0])),) + shape[1:]
        self._ds[key] = self._f.create_dataset(key, shape=shape, dtype=dtype, chunks=chunks,
                                               fletcher32=True, **_compression())

    def write(self, batch: StackBatch) -> None:
        """Append a batch of stacks (all schema keys present)."""
        b = len(batch)
        if self.pos + b > self.n:
            raise ValueError(f"packed file {self.path} holds {self.n} stacks; got more")
        for key in self.schema.keys():
            self._ds[key][self.pos:self.pos + b] = batch.arrays[key]
        self.pos += b

    def close(self) -> Path:
        """Finish: check the row count, flush, and rename to the final name."""
        if self.pos != self.n:
            self.abort()
            raise ValueError(f"packed file {self.path}: wrote {self.pos} of {self.n} stacks")
        try:
            self._ds.clear()
            self._f.close()
        except BaseException:
            self.abort()
            raise
        publish(self.partial, self.path)
        return self.path

    def abort(self) -> None:
        """Drop the partial file. It is emptied first, so that closing it can write what HDF5
        still holds even on a full disk."""
        self._ds.clear()
        with contextlib.suppress(OSError):
            os.truncate(self.partial, 0)
        with contextlib.suppress(Exception):
            if self._f.id.valid:
                self._f.close()
        self.partial.unlink(missing_ok=True)


class PackedSplit:
    """Read a packed split: contiguous blocks of stacks, optionally only some keys."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        try:
            self._f = h5py.File(self.path, "r")
        except (OSError, FileNotFoundError) as e:
            raise Sc2DataError(f"{self.path} is not a readable packed split ({e}); rerun "
                               f"sc2data pair to rebuild it") from None
        try:
            PACKED.check(self._f.attrs, self.path)
        except Sc2DataError:
            self._f.close()
            raise
        try:
            self.schema = Schema.from_dict(json.loads(self._f.attrs["schema"]))
        except SchemaError as e:
            raise Sc2DataError(f"{self.path}: {e}") from None
        self.n = int(self._f[self.schema.keys()[0]].shape[0])
        self.attrs = dict(self._f.attrs)

    def __len__(self) -> int:
        return self.n

    def read(self, start: int, stop: int, keys: Sequence[str] | None = None) -> StackBatch:
        """Stacks ``[start, stop)`` as a :class:`StackBatch` (contiguous read, no fancy
        indexing)."""
        keys = tuple(keys) if keys is not None else self.schema.keys()
        return StackBatch({k: self._f[k][start:stop] for k in keys}, self.schema)

    def blocks(self, rng: np.random.Generator | None = None, block: int = BLOCK,
               keys: Sequence[str] | None = None) -> Iterator[tuple[np.ndarray, StackBatch]]:
        """Yield ``(row indices, stacks)`` block by block; in random block order if ``rng``."""
        starts = np.arange(0, self.n, block)
        if rng is not None:
            starts = rng.permutation(starts)
        for s in starts:
            e = min(int(s) + block, self.n)
            yield np.arange(s, e), self.read(int(s), e, keys)

    def check_chunks(self) -> None:
        """Read every stored chunk through its fletcher32 checksum; one-line error on the first
        that fails."""
        for key in self.schema.keys():
            ds = self._f[key]
            try:
                for s in range(0, self.n, BLOCK):
                    ds[s:s + BLOCK]
            except OSError as e:
                raise Sc2DataError(f"{self.path}:{key}: unreadable chunk "
                                   f"({str(e).strip().splitlines()[0]}); rerun sc2data pair") \
                    from None

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> PackedSplit:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
