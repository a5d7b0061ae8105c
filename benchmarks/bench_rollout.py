"""End-to-end rollout and read-back figures for BENCHMARKS.md ("Rollout and storage").

1. Rollout steps/s (embedded sim + reduced-random agent + HDF5 writes), 1 and 2 workers, through
   the same call as ``sc2data rollout``; wall time includes starting the workers. The same
   episodes are also played without storage, so the cost of writing shows as a ratio.
2. Bytes per frame on disk (paper layers).
3. Read-back stacks/s of the dataset just written: sequential (all keys), random batches of 256
   (all keys, and a rule's 3 keys), one stack at a time.
4. Barracks placed and marines completed per reduced-random episode (the simulator's own event
   record), extrapolated to the paper's ≥ 10,000 of each.

Medians of ``--repeats``, each repeat running every variant once (round-robin), because the
machine is shared. Also prints CPU seconds of this process and its workers where useful.

    .venv/bin/python benchmarks/bench_rollout.py [--episodes 8] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import sc2data
from sc2data._pysc2 import units
from sc2data.data.rollout import RolloutConfig, episode_seeds, rollout
from sc2data.game.agents import make_agent
from sc2data.game.env import make_env
from sc2data.ground.vocab import EPISODE_STEPS

SUBSET = ("screen/unit_type", "screen/unit_hit_points", "player")
TARGET_EVENTS = 10_000


def cpu_seconds() -> float:
    """CPU time of this process and of its finished children (the workers)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def play_only(config: RolloutConfig) -> tuple[float, int, dict[str, list[int]]]:
    """Play the rollout's episodes without storing anything; (seconds, steps, events)."""
    events: dict[str, list[int]] = {"barracks": [], "marines": [], "depots": [], "scvs": []}
    steps = 0
    t = time.perf_counter()
    for e in range(config.episodes):
        env_seed, agent_seed = episode_seeds(config.seed, e)
        np.random.seed(agent_seed)
        env, agent = make_env("sim", seed=env_seed), make_agent(config.agent, seed=agent_seed)
        agent.setup(env.observation_spec()[0], env.action_spec()[0])
        agent.reset()
        ts = env.reset()[0]
        counts = dict.fromkeys(events, 0)
        while not ts.last():
            ts = env.step([agent.step(ts)])[0]
            steps += 1
            for ev in env.events:
                if ev.kind == "placed" and ev.unit_type == units.Terran.Barracks:
                    counts["barracks"] += 1
                elif ev.kind == "placed" and ev.unit_type == units.Terran.SupplyDepot:
                    counts["depots"] += 1
                elif ev.kind == "completed" and ev.unit_type == units.Terran.Marine:
                    counts["marines"] += 1
                elif ev.kind == "completed" and ev.unit_type == units.Terran.SCV:
                    counts["scvs"] += 1
        env.close()
        for k, v in counts.items():
            events[k].append(v)
    return time.perf_counter() - t, steps, events


def read_figures(folder: Path) -> dict[str, float]:
    ds = sc2data.open_dataset(folder, cache_bytes=0)
    n = len(ds)
    rng = np.random.default_rng(0)
    r: dict[str, float] = {}
    t = time.perf_counter()
    m = sum(len(b) for _, _, b in ds.iter_batches(1024))
    r["sequential"] = m / (time.perf_counter() - t)
    for name, keys in (("random", None), ("random_subset", SUBSET)):
        pos = rng.integers(0, n, (8, 256))
        t = time.perf_counter()
        for p in pos:
            ds.read(*ds.locate_positions(p), keys=keys)
        r[name] = pos.size / (time.perf_counter() - t)
    pos = rng.integers(0, n, 300)
    t = time.perf_counter()
    for p in pos:
        ds.stack(*(int(x[0]) for x in ds.locate_positions(np.array([p]))))
    r["single"] = len(pos) / (time.perf_counter() - t)
    ds.close()
    return r


def read_existing(folder: Path, repeats: int) -> None:
    """Read-back figures of an existing dataset (e.g. the paper recipe's), as ``open_dataset``
    gives them by default: random batches of 256 once every shard has been opened (one untimed
    pass over the shards first: opening costs ≈ 10 ms each), sequential over 102,400 stacks."""
    ds = sc2data.open_dataset(folder)
    rng = np.random.default_rng(0)
    n = len(ds)
    for e in ds.episode_ids[::max(1, len(ds.episode_ids) // len(ds.shard_names))]:
        ds.stack(int(e), 0)
    r: dict[str, list[float]] = {"random": [], "sequential": []}
    for i in range(repeats):
        pos = rng.integers(0, n, (8, 256))
        t = time.perf_counter()
        for p in pos:
            ds.read(*ds.locate_positions(p))
        r["random"].append(pos.size / (time.perf_counter() - t))
        start = i * 102_400 % max(1, n - 102_400)
        t = time.perf_counter()
        for b in range(start, start + 102_400, 1024):
            ds.read(*ds.locate(b, min(b + 1024, n)))
        r["sequential"].append(102_400 / (time.perf_counter() - t))
    ds.close()
    print(f"# {folder}: {len(ds.shard_names)} shards, {n:,} stacks; medians of {repeats}\n")
    print("| read-back | stacks/s |\n|---|---:|")
    print(f"| random, read() of 256, all 23 keys | {statistics.median(r['random']):,.0f} |")
    print(f"| sequential, read() of 1024 in order, all 23 keys | "
          f"{statistics.median(r['sequential']):,.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--agent", default="reduced-random")
    parser.add_argument("--read", type=Path, metavar="DIR",
                        help="only measure reading an existing dataset folder")
    args = parser.parse_args()
    if args.read:
        read_existing(args.read, args.repeats)
        return
    config = RolloutConfig(env="sim", agent=args.agent, episodes=args.episodes, seed=1,
                           episodes_per_shard=1)
    print(f"# {platform.node()}: {os.cpu_count()} cores (shared), Python "
          f"{platform.python_version()}; {args.episodes} episodes × {EPISODE_STEPS} steps, "
          f"{args.agent}, paper layers; medians of {args.repeats}\n")
    runs: dict[str, list[float]] = {k: [] for k in ("play", "k1", "k2", "cpu_play", "cpu_k1",
                                                     "cpu_k2")}
    events: dict[str, list[int]] = {}
    reads: list[dict[str, float]] = []
    size = frames = 0
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeats):
            c = cpu_seconds()
            seconds, steps, events = play_only(config)
            runs["play"].append(steps / seconds)
            runs["cpu_play"].append(steps / (cpu_seconds() - c))
            for k in (1, 2):
                out = Path(tmp) / f"k{k}"
                shutil.rmtree(out, ignore_errors=True)
                c = cpu_seconds()
                s = rollout(config, out, workers=k, progress=False)
                runs[f"k{k}"].append(s.steps / s.seconds)
                runs[f"cpu_k{k}"].append(s.steps / (cpu_seconds() - c))
            size = sum(p.stat().st_size for p in (Path(tmp) / "k1").glob("shard-*.h5"))
            frames = s.steps + s.episodes
            reads.append(read_figures(Path(tmp) / "k1"))
    med = {k: statistics.median(v) for k, v in runs.items()}
    print("| rollout (sim + agent + write) | steps/s, wall | steps/s per CPU-second |")
    print("|---|---:|---:|")
    print(f"| sim + agent only, no storage, 1 process | {med['play']:,.0f} | "
          f"{med['cpu_play']:,.0f} |")
    print(f"| 1 worker | {med['k1']:,.0f} | {med['cpu_k1']:,.0f} |")
    print(f"| 2 workers | {med['k2']:,.0f} | {med['cpu_k2']:,.0f} |")
    print(f"\nstorage overhead: 1 worker runs at {med['k1'] / med['play']:.0%} of sim+agent "
          f"alone (wall), {med['cpu_k1'] / med['cpu_play']:.0%} per CPU-second; 2 workers at "
          f"{med['k2'] / med['k1']:.2f}x 1 worker (wall)")
    print(f"bytes per frame on disk: {size / frames:,.0f} (shards only; {frames:,} frames)\n")
    rmed = {k: statistics.median(r[k] for r in reads) for k in reads[0]}
    print("| read-back | stacks/s |")
    print("|---|---:|")
    print(f"| sequential, iter_batches(1024), all 23 keys | {rmed['sequential']:,.0f} |")
    print(f"| random, read() of 256, all 23 keys | {rmed['random']:,.0f} |")
    print(f"| random, read() of 256, {len(SUBSET)} keys ({', '.join(SUBSET)}) | "
          f"{rmed['random_subset']:,.0f} |")
    print(f"| random, stack() one at a time, all keys | {rmed['single']:,.0f} |\n")
    per = {k: float(np.mean(v)) for k, v in events.items()}
    print(f"events per {args.agent} episode (mean of {args.episodes}, sim event record): "
          + ", ".join(f"{k} {v:.1f} (min {min(events[k])}, max {max(events[k])})"
                      for k, v in per.items()))
    need = max(TARGET_EVENTS / max(per[k], 1e-9) for k in ("barracks", "marines"))
    episodes_needed = int(np.ceil(need))
    seconds = episodes_needed * EPISODE_STEPS / med["k2"]
    print(f"≥ {TARGET_EVENTS:,} barracks placed and ≥ {TARGET_EVENTS:,} marines completed need "
          f"≈ {episodes_needed:,} episodes ({episodes_needed * EPISODE_STEPS:,} stacks); at the "
          f"2-worker rate that is ≈ {seconds / 60:.0f} min and "
          f"≈ {episodes_needed * (EPISODE_STEPS + 1) * size / frames / 1e9:.1f} GB on disk "
          f"(extrapolated from {args.episodes} episodes)")


if __name__ == "__main__":
    main()
