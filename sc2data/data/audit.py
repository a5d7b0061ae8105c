"""``sc2data info`` and ``sc2data verify``: what a dataset folder holds, and whether it is intact.

``verify`` trusts nothing: it reads every chunk of every dataset through HDF5's own filter
pipeline (so each fletcher32 checksum is checked), recomputes every shard's sha256 against the
index, and cross-checks the dataset record, the shards' attributes and tables, and the index.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from sc2data._pysc2 import actions
from sc2data.data.dataset import (
    DATASET_RECORD,
    INDEX,
    read_dataset_record,
    read_index,
    record_schema,
    shard_settings,
)
from sc2data.data.shards import (
    CHUNK_INDEX,
    EPISODE_COLUMNS,
    MASK_BYTES,
    MASKS,
    Shard,
    chunk_table,
    unpack_available,
)
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import PARTIAL, sha256_file
from sc2data.schema import Block

_BLOCK = 1024
"""Frames read per call while verifying."""


@dataclass(frozen=True)
class ShardStats:
    """One shard as ``sc2data info`` reports it."""

    name: str
    episodes: int
    steps: int
    frames: int
    bytes: int
    block_bytes: dict[str, int]
    """Stored (compressed) bytes of each frame dataset (storage block)."""


def shard_stats(path: Path) -> ShardStats:
    shard = Shard(path)
    try:
        names = [b.name for b in shard.schema.blocks()]
        try:
            block_bytes = {n: int(shard.file[f"frames/{n}"].id.get_storage_size()) for n in names}
        except KeyError as e:
            raise Sc2DataError(f"{path} is damaged (a frame dataset is missing: {e}); run "
                               f"`sc2data verify` on its folder") from None
        return ShardStats(path.name, len(shard.episodes["episode"]),
                          int(shard.episodes["n_steps"].sum()), int(shard.attrs["n_frames"]),
                          path.stat().st_size, block_bytes)
    finally:
        shard.close()


def _codec(codec: Any) -> str:
    """A dataset's codec record in words: ``zstd+fletcher32, level 3, 4 frames a chunk``."""
    if not isinstance(codec, dict):
        return str(codec)
    parts = [str(codec.get("name", "?"))]
    if "level" in codec:
        parts.append(f"level {codec['level']}")
    if "chunk_frames" in codec:
        parts.append(f"{codec['chunk_frames']} frames a chunk")
    parts += [f"{k} {v}" for k, v in codec.items() if k not in ("name", "level", "chunk_frames")]
    return ", ".join(parts)


def info(folder: Path) -> list[str]:
    """A plain-text report: totals, settings, the schema with stored bytes per key, shards."""
    record = read_dataset_record(folder)
    schema = record_schema(record, folder / DATASET_RECORD)
    table = read_index(folder)
    names = sorted(set(table.column("shard").to_pylist()))
    stats = [shard_stats(folder / n) for n in names]
    frames = sum(s.frames for s in stats)
    size = sum(s.bytes for s in stats)
    steps = int(np.sum(table.column("n_steps").to_numpy()))
    per_frame = size / frames if frames else 0.0
    lines = [f"dataset   {folder}",
             f"episodes  {table.num_rows}   stacks {steps:,}   frames {frames:,}   "
             f"shards {len(stats)}",
             f"bytes     {size:,} on disk   {per_frame:,.0f} B/frame   "
             f"(raw {schema.frame_bytes():,} B/frame, "
             f"{schema.frame_bytes() / max(per_frame, 1):,.0f}x)",
             "settings  " + "  ".join(f"{k}={v}" for k, v in record["settings"].items()
                                      if k != "codec"),
             f"codec     {_codec(record['settings'].get('codec'))}",
             f"versions  {'  '.join(f'{k} {v}' for k, v in record.get('versions', {}).items())}",
             f"format    {record['format_version']}   action masks "
             + ("kept (available_actions per frame)" if record["format_version"] >= 4
                else "none (written before format 4)"),
             "", f"{'key':28s} {'dtype':7s} {'shape':10s} {'scale':>6s} {'kind':12s} "
                 "stored in"]
    block_of = {k: b.name for b in schema.blocks() for k in b.keys}
    for l in schema.layers:
        side = schema.size(l.group)
        lines.append(f"{l.key:28s} {l.dtype.name:7s} {f'{side}x{side}':10s} {l.scale:6d} "
                     f"{'categorical' if l.categorical else 'scalar':12s} {block_of[l.key]}")
    for v in schema.vectors:
        lines.append(f"{v.name:28s} {v.dtype.name:7s} {str(v.size):10s} {'':>6s} "
                     f"{'vector':12s} {block_of[v.name]}")
    lines += ["", f"{'block':16s} {'frame shape':14s} {'keys':>4s} {'raw B/frame':>11s} "
                  f"{'B/frame':>8s}"]
    for b in schema.blocks():
        stored = sum(s.block_bytes[b.name] for s in stats) / max(frames, 1)
        raw = int(np.prod(b.frame_shape)) * b.dtype.itemsize
        shape = "x".join(map(str, b.frame_shape))
        lines.append(f"{b.name:16s} {shape:14s} {len(b.keys):4d} {raw:11,d} {stored:8.1f}")
    lines += ["", f"{'shard':18s} {'episodes':>8s} {'steps':>9s} {'frames':>9s} {'bytes':>13s} "
                  f"{'B/frame':>8s}"]
    for s in stats:
        lines.append(f"{s.name:18s} {s.episodes:8d} {s.steps:9,d} {s.frames:9,d} {s.bytes:13,d} "
                     f"{s.bytes / max(s.frames, 1):8.0f}")
    return lines


def _read_all(ds: h5py.Dataset) -> Iterator[np.ndarray]:
    """Every element of ``ds`` through HDF5's filters, block by block (checksums checked)."""
    for start in range(0, ds.shape[0], _BLOCK):
        yield ds[start:start + _BLOCK]


def _check_shard(path: Path, rows: dict[str, Any], record: dict[str, Any],
                 digest: str) -> list[str]:
    faults: list[str] = []
    try:
        shard = Shard(path)
    except Sc2DataError as e:
        return [str(e)]
    try:
        if shard.schema.to_dict() != record["schema"]:
            faults.append(f"{path.name}: schema differs from {DATASET_RECORD}")
        version = record.get("format_version")
        if shard.attrs.get("format_version") != version:
            faults.append(f"{path.name}: shard format {shard.attrs.get('format_version')} in a "
                          f"dataset of format {version}")
        elif shard.attrs.get("settings") != shard_settings(record["settings"], version):
            faults.append(f"{path.name}: settings differ from {DATASET_RECORD}")
        if rows["shard_sha256"] and any(h != digest for h in rows["shard_sha256"]):
            faults.append(f"{path.name}: sha256 {digest[:12]}… does not match the index")
        eps = shard.episodes
        for col in ("episode", "n_steps", "frame_start", "step_start"):
            if not np.array_equal(eps[col], np.asarray(rows[col])):
                faults.append(f"{path.name}: episode table column {col!r} disagrees with {INDEX}")
        n_steps = int(eps["n_steps"].sum())
        n_frames = n_steps + len(eps["episode"])
        if int(shard.attrs.get("n_frames", -1)) != n_frames:
            faults.append(f"{path.name}: holds {shard.attrs.get('n_frames')} frames, its episodes "
                          f"need {n_frames}")
        expected_starts = np.concatenate([[0], np.cumsum(eps["n_steps"] + 1)[:-1]])
        if len(eps["episode"]) and not np.array_equal(eps["frame_start"], expected_starts):
            faults.append(f"{path.name}: episode frame offsets are not contiguous")
        for block in shard.schema.blocks():
            faults += _check_block(shard, block, n_frames)
        faults += _check_chunk_index(shard)
        for key in ("function", "args", "reward"):
            faults += _check_dataset(shard, f"steps/{key}", n_steps)
        if isinstance(version, int) and version >= 4:
            faults += _check_masks(shard, n_frames)
        if not faults:
            fn = shard.steps()["function"]
            if len(fn) and int(fn.max()) >= len(actions.FUNCTIONS):
                faults.append(f"{path.name}: action function ids outside pysc2's table")
        for col in EPISODE_COLUMNS:
            faults += _check_dataset(shard, f"episodes/{col}", len(eps["episode"]))
    finally:
        shard.close()
    return faults


def _check_masks(shard: Shard, n_frames: int) -> list[str]:
    """A format 4 shard keeps one packed action mask per frame, no bit beyond pysc2's table."""
    faults = _check_dataset(shard, MASKS, n_frames)
    if faults:
        return faults
    ds = shard.file[MASKS]
    if ds.shape[1:] != (MASK_BYTES,) or ds.dtype != np.uint8:
        return [f"{shard.path.name}:{MASKS}: shape {ds.shape[1:]} {ds.dtype}, not "
                f"({MASK_BYTES},) uint8"]
    rows = ds[:]
    if len(rows) and not np.array_equal(np.packbits(unpack_available(rows), axis=-1,
                                                    bitorder="little"), rows):
        return [f"{shard.path.name}:{MASKS}: bits set beyond pysc2's function table"]
    return []


def _check_chunk_index(shard: Shard) -> list[str]:
    """The stored chunk index (shards written before it existed have none) says what HDF5's
    own chunk index says, for every frame dataset."""
    try:
        stored = shard.chunk_index()
    except Sc2DataError as e:
        return [str(e)]
    for name, table in stored.items():
        if f"frames/{name}" not in shard.file:
            continue  # reported by _check_block
        if not np.array_equal(table, chunk_table(shard.file[f"frames/{name}"])):
            return [f"{shard.path.name}:{CHUNK_INDEX}: disagrees with HDF5's chunk index of "
                    f"frames/{name}"]
    return []


def _check_block(shard: Shard, block: Block, n_frames: int) -> list[str]:
    """A frame dataset holds what the schema's block says (keys, shape, dtype), all readable."""
    name = f"frames/{block.name}"
    if name in shard.file:
        ds = shard.file[name]
        what = (ds.shape[1:], ds.dtype, ds.attrs.get("keys"))
        want = (block.frame_shape, block.dtype, json.dumps(list(block.keys)))
        if what != want:
            return [f"{shard.path.name}:{name}: holds {what[0]} {what[1]} frames of "
                    f"{what[2]}, the schema says {want[0]} {want[1]} of {want[2]}"]
    return _check_dataset(shard, name, n_frames)


def _check_dataset(shard: Shard, name: str, length: int) -> list[str]:
    where = f"{shard.path.name}:{name}"
    if name not in shard.file:
        return [f"{where}: missing"]
    ds = shard.file[name]
    if ds.shape[0] != length:
        return [f"{where}: length {ds.shape[0]}, expected {length}"]
    try:
        for _ in _read_all(ds):
            pass
    except OSError as e:
        return [f"{where}: unreadable chunk ({str(e).strip().splitlines()[0]})"]
    return []


def check_shard(path: Path, record: dict[str, Any]) -> list[str]:
    """Every fault of one shard on its own (no index to compare with): its header, schema and
    settings against the dataset record ``record``, its tables, and every chunk read through its
    checksum."""
    try:
        table = Shard(path)
    except Sc2DataError as e:
        return [str(e)]
    try:
        eps = table.episodes
    finally:
        table.close()
    rows: dict[str, Any] = {c: list(eps[c]) for c in eps}
    rows["shard_sha256"] = []
    return _check_shard(path, rows, record, "")


def verify(folder: Path) -> list[str]:
    """Every fault found in ``folder`` (empty: intact). Unreadable basics raise Sc2DataError."""
    record = read_dataset_record(folder)
    record_schema(record, folder / DATASET_RECORD)
    table = read_index(folder)
    faults: list[str] = []
    by_shard: dict[str, dict[str, list[Any]]] = {}
    for row in table.to_pylist():
        cols = by_shard.setdefault(row["shard"], {c: [] for c in row})
        for c, v in row.items():
            cols[c].append(v)
    episodes = table.column("episode").to_pylist()
    if len(set(episodes)) != len(episodes):
        faults.append(f"{INDEX}: an episode is listed twice")
    expected = record["settings"].get("episodes")
    if expected is not None and sorted(episodes) != list(range(expected)):
        faults.append(f"{INDEX}: lists {len(episodes)} episodes, the settings say {expected}")
    on_disk = {p.name for p in folder.glob("shard-*.h5")}
    for name in sorted(on_disk - set(by_shard)):
        faults.append(f"{name}: not in {INDEX}")
    for p in sorted(folder.glob(f"*{PARTIAL}")):
        faults.append(f"{p.name}: a partial file from an unfinished run")
    for name, rows in sorted(by_shard.items()):
        path = folder / name
        if not path.is_file():
            faults.append(f"{name}: listed in {INDEX} but missing")
            continue
        if any(b != path.stat().st_size for b in rows["shard_bytes"]):
            faults.append(f"{name}: {path.stat().st_size} bytes, the index says "
                          f"{rows['shard_bytes'][0]}")
        faults += _check_shard(path, rows, record, sha256_file(path))
    return faults
