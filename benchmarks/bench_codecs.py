"""Choose the frame chunking and compression by measurement, on real simulator frames.

Records a few reduced-random BuildMarines episodes from the embedded simulator (paper layers),
then stores them one HDF5 dataset per key, ``fletcher32`` on, with each filter at several chunk
lengths (frames per chunk), and prints, per setting: bytes per frame on disk, write speed, and
random 2-frame-stack reads of every key. Filters go through HDF5's own pipeline (h5py slices);
Zstd is measured a second time through sc2data's direct chunk path (``ShardWriter`` /
``open_dataset``, keys stored in blocks: one dataset per group and dtype), which is what the
rollout uses. Medians of ``--repeats`` runs.

    .venv/bin/python benchmarks/bench_codecs.py [--episodes 2] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import hdf5plugin
import numpy as np

from sc2data.data.chunks import Codec
from sc2data.data.dataset import open_dataset, shard_settings, write_dataset_record, write_index
from sc2data.data.rollout import RolloutConfig, dataset_record_for, index_rows
from sc2data.data.shards import ShardWriter
from sc2data.game.agents import make_agent, play
from sc2data.game.env import make_env
from sc2data.schema import Schema

FILTERS: dict[str, dict[str, Any]] = {
    "gzip-1": {"compression": "gzip", "compression_opts": 1},
    "lzf": {"compression": "lzf"},
    "lz4": dict(hdf5plugin.LZ4()),
    "zstd-1": dict(hdf5plugin.Zstd(clevel=1)),
    "zstd-3": dict(hdf5plugin.Zstd(clevel=3)),
    "blosc-lz4-shuffle": dict(hdf5plugin.Blosc(cname="lz4", clevel=5,
                                               shuffle=hdf5plugin.Blosc.SHUFFLE)),
    "blosc-zstd-shuffle": dict(hdf5plugin.Blosc(cname="zstd", clevel=3,
                                                shuffle=hdf5plugin.Blosc.SHUFFLE)),
}


def record(schema: Schema, episodes: int) -> list[dict[str, np.ndarray]]:
    """Frames of ``episodes`` reduced-random episodes, one ``{key: (T+1, …)}`` dict each."""
    out = []
    for e in range(episodes):
        env = make_env("sim", seed=e)
        frames = [schema.extract(ts.observation)
                  for ts in play(env, make_agent("reduced-random", seed=e))]
        env.close()
        out.append({k: np.stack([f[k] for f in frames]) for k in schema.keys()})
    return out


def median_time(fn: Callable[[], Any], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def random_stacks(n_frames: int, episode_len: int, count: int, seed: int = 0) -> np.ndarray:
    """First-frame indices of random stacks (never the last frame of an episode)."""
    rng = np.random.default_rng(seed)
    f = rng.integers(0, n_frames - 1, count)
    return f[(f + 1) % episode_len != 0]


def bench_filter(name: str, kw: dict[str, Any], chunk: int, data: dict[str, np.ndarray],
                 episode_len: int, tmp: Path, repeats: int) -> dict[str, float]:
    path = tmp / f"{name}-{chunk}.h5"
    n = len(next(iter(data.values())))

    def write() -> None:
        with h5py.File(path, "w", libver="latest") as f:
            for k, v in data.items():
                f.create_dataset(k, data=v, chunks=(chunk, *v.shape[1:]), fletcher32=True, **kw)

    t_write = median_time(write, repeats)
    starts = random_stacks(n, episode_len, 300)
    with h5py.File(path, "r") as f:
        dss = [f[k] for k in data]

        def read() -> None:
            for s in starts:
                for ds in dss:
                    ds[s:s + 2]

        t_read = median_time(read, repeats)
    return {"bytes_per_frame": path.stat().st_size / n, "write_fps": n / t_write,
            "random_sps": len(starts) / t_read}


SUBSET = ("screen/unit_type", "screen/unit_hit_points", "player")
"""Keys a typical rule reads (e.g. "a barracks' pixel count rose")."""


def build_direct(level: int, chunk: int, episodes: list[dict[str, np.ndarray]], schema: Schema,
                 tmp: Path) -> tuple[Path, Callable[[], None]]:
    """A dataset folder written by sc2data's ShardWriter (direct chunk writes); its writer."""
    folder = tmp / f"direct-{level}-{chunk}"
    folder.mkdir()
    config = RolloutConfig(episodes=len(episodes), codec=Codec(level, chunk),
                           episodes_per_shard=len(episodes))
    path = folder / "shard-00000.h5"
    per_frame = [[dict(zip(ep, f)) for f in zip(*ep.values())] for ep in episodes]

    def write() -> None:
        w = ShardWriter(path, schema, config.codec, {"settings": shard_settings(config.settings())})
        for i, frames in enumerate(per_frame):
            w.begin_episode(i, i, i)
            w.add_frame(frames[0])
            for f in frames[1:]:
                w.add_frame(f)
                w.add_step(0, [], 0.0)
            w.end_episode()
        w.close()

    write()
    write_dataset_record(folder, dataset_record_for(config))
    write_index(folder, index_rows(path))
    return folder, write


def direct_round(folder: Path, write: Callable[[], None], n_frames: int) -> dict[str, float]:
    """One timing of each access pattern on a fresh reader (cold chunk cache, warm page cache)."""
    r: dict[str, float] = {}
    t = time.perf_counter()
    write()
    r["write_fps"] = n_frames / (time.perf_counter() - t)
    ds = open_dataset(folder, cache_bytes=0)
    rng = np.random.default_rng(len(folder.name))
    n = len(ds)
    for name, keys in (("random_sps", None), ("random_subset_sps", SUBSET)):
        pos = rng.integers(0, n, (4, 256))
        ds.read(*ds.locate(0, 1), keys=keys)  # open the shard, load chunk tables
        t = time.perf_counter()
        for p in pos:
            ds.read(*ds.locate_positions(p), keys=keys)
        r[name] = pos.size / (time.perf_counter() - t)
    # The pair packer's pattern: a sorted 12 % sample of all stacks, read in batches of 1024.
    sample = np.sort(rng.choice(n, n // 8, replace=False))
    t = time.perf_counter()
    for i in range(0, len(sample), 1024):
        ds.read(*ds.locate_positions(sample[i:i + 1024]))
    r["sample_sps"] = len(sample) / (time.perf_counter() - t)
    t = time.perf_counter()
    m = sum(len(b) for _, _, b in ds.iter_batches(1024))
    r["seq_sps"] = m / (time.perf_counter() - t)
    ds.close()
    return r


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--chunks", default="1,2,4,8,16")
    parser.add_argument("--skip-filters", action="store_true",
                        help="only the direct-path table")
    args = parser.parse_args()
    schema = Schema.paper()
    chunks = [int(c) for c in args.chunks.split(",")]
    t = time.perf_counter()
    episodes = record(schema, args.episodes)
    data = {k: np.concatenate([e[k] for e in episodes]) for k in schema.keys()}
    episode_len = len(episodes[0]["game_loop"])
    n = len(data["game_loop"])
    print(f"# {args.episodes} reduced-random sim episodes, {n} frames, paper layers "
          f"({schema.frame_bytes():,} B/frame raw), recorded in {time.perf_counter() - t:.0f} s; "
          f"medians of {args.repeats}\n")
    print("| filter (+fletcher32) | frames/chunk | B/frame | write frames/s | "
          "random stacks/s, h5py slices |")
    print("|---|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, kw in ({} if args.skip_filters else FILTERS).items():
            for c in chunks:
                r = bench_filter(name, kw, c, data, episode_len, Path(tmp), args.repeats)
                print(f"| {name} | {c} | {r['bytes_per_frame']:,.0f} | {r['write_fps']:,.0f} | "
                      f"{r['random_sps']:,.0f} |", flush=True)
                Path(tmp, f"{name}-{c}.h5").unlink()
        print("\nsc2data's direct chunk path (what `sc2data rollout` and `open_dataset` use); "
              "stacks/s of all 23 keys unless noted:\n")
        print("| zstd level | frames/chunk | B/frame | write frames/s | random, B=256 | "
              f"random, B=256, {len(SUBSET)} keys | sorted 12 % sample | sequential |")
        print("|---:|---:|---:|---:|---:|---:|---:|---:|")
        settings = [(1, 2), (3, 2), (1, 4), (3, 4), (1, 8), (3, 8), (1, 16)]
        built = {st: build_direct(*st, episodes, schema, Path(tmp)) for st in settings}
        rounds: dict[tuple[int, int], list[dict[str, float]]] = {st: [] for st in settings}
        for _ in range(args.repeats):  # round-robin, so that load from elsewhere hits all alike
            for st in settings:
                rounds[st].append(direct_round(*built[st], n))
        for (level, c) in settings:
            med = {k: statistics.median(r[k] for r in rounds[(level, c)])
                   for k in rounds[(level, c)][0]}
            size = (built[(level, c)][0] / "shard-00000.h5").stat().st_size / n
            print(f"| {level} | {c} | {size:,.0f} | {med['write_fps']:,.0f} | "
                  f"{med['random_sps']:,.0f} | {med['random_subset_sps']:,.0f} | "
                  f"{med['sample_sps']:,.0f} | {med['seq_sps']:,.0f} |", flush=True)

if __name__ == "__main__":
    main()
