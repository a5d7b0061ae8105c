"""Labelling throughput, stacks per second on one core: the rules alone, and end to end.

* rules only — every built-in rule (with the labeller's shape/dtype checks) over in-memory
  batches of real stacks: one simulator episode per agent, tiled to ``--stacks``;
* end to end — ``sc2data.labels.label.label_dataset`` on a dataset rolled out with
  ``sc2data rollout``
  (``--data DIR``), reading only the keys the rules require, writing the Parquet files.

Prints the median of ``--repeats`` runs, as stacks per second of wall-clock time and per second of
this process's CPU time: on a shared machine the second is the one-core figure (the first also
counts time other processes held the core). Usage::

    OMP_NUM_THREADS=1 python benchmarks/bench_label.py [--stacks 200000] [--data DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from sc2data.labels.apply import label_batches
from sc2data.labels.registry import load_registry
from sc2data.schema import Schema, StackBatch


def episode_stacks(agent_name: str, seed: int, keys: set[str]) -> dict[str, np.ndarray]:
    """All stacks of one simulator episode, only ``keys``, as ``(N, 2, …)`` arrays."""
    from sc2data.game.agents import make_agent
    from sc2data.game.env import make_env

    schema = Schema.paper()
    env = make_env("sim", seed=seed)
    agent = make_agent(agent_name, seed=seed)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    ts = env.reset()[0]
    agent.reset()
    frames = []
    while True:
        frames.append({k: a for k, a in schema.extract(ts.observation).items() if k in keys})
        if ts.last():
            break
        ts = env.step([agent.step(ts)])[0]
    return {k: np.stack([np.stack([p[k], c[k]]) for p, c in zip(frames[:-1], frames[1:])])
            for k in keys}


def rules_only(stacks: int, batch_size: int, repeats: int) -> None:
    rules = list(load_registry())
    keys = {k for e in rules for k in e.rule.requires}
    parts = [episode_stacks(a, 0, keys) for a in ("reduced-random", "scripted")]
    base = {k: np.concatenate([p[k] for p in parts]) for k in keys}
    n = len(next(iter(base.values())))
    reps = -(-stacks // n)
    arrays = {k: np.concatenate([a] * reps)[:stacks] for k, a in base.items()}
    schema = Schema.paper()

    def batches() -> list[tuple[np.ndarray, np.ndarray, StackBatch]]:
        """Fresh batch objects (views): nothing cached from an earlier repeat."""
        out = []
        for i in range(0, stacks, batch_size):
            b = StackBatch({k: a[i:i + batch_size] for k, a in arrays.items()}, schema)
            out.append((np.zeros(len(b), np.int64), np.arange(i, i + len(b)), b))
        return out

    walls, cpus = [], []
    for _ in range(repeats):
        todo = batches()
        w0, c0 = time.perf_counter(), time.process_time()
        table = label_batches(todo, rules)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    fired = {e.id: int(np.count_nonzero(table.column(e.id).to_numpy())) for e in rules}
    print(f"rules only: {len(rules)} rules, {stacks:,} stacks in batches of {batch_size}, "
          f"median of {repeats}: {rate(stacks, walls, cpus)}")
    print(f"  fired: {fired}")
    for e in rules:
        walls, cpus = [], []
        for _ in range(repeats):
            todo = batches()
            w0, c0 = time.perf_counter(), time.process_time()
            for _, _, b in todo:
                e.rule(b)
            walls.append(time.perf_counter() - w0)
            cpus.append(time.process_time() - c0)
        print(f"  {e.id:20s} alone: {rate(stacks, walls, cpus)}")


def rate(stacks: int, walls: list[float], cpus: list[float]) -> str:
    wall, cpu = statistics.median(walls), statistics.median(cpus)
    return (f"{stacks / wall:>12,.0f} stacks/s wall, {stacks / max(cpu, 1e-9):>12,.0f} "
            f"stacks/CPU-s")


def end_to_end(data: Path, batch_size: int, repeats: int) -> None:
    from sc2data.labels.label import label_dataset
    from sc2data.labels.store import LABELS_FILE, STACKS_FILE

    walls, cpus = [], []
    for _ in range(repeats):
        for name in (LABELS_FILE, STACKS_FILE):
            (data / name).unlink(missing_ok=True)
        w0, c0 = time.perf_counter(), time.process_time()
        summary = label_dataset(data, batch_size=batch_size, progress=False)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    print(f"end to end: {summary.stacks:,} stacks, median of {repeats}: "
          f"{rate(summary.stacks, walls, cpus)}")
    print(summary.table())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stacks", type=int, default=200_000)
    ap.add_argument("--batch-size", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--data", type=Path, help="a rolled-out dataset folder (copied first)")
    args = ap.parse_args()
    print(f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}, "
          f"cpus={os.cpu_count()}, load average {os.getloadavg()[0]:.1f}")
    rules_only(args.stacks, args.batch_size, args.repeats)
    if args.data is not None:
        with tempfile.TemporaryDirectory() as tmp:
            copy = Path(shutil.copytree(args.data, Path(tmp) / "data"))
            end_to_end(copy, args.batch_size, args.repeats)


if __name__ == "__main__":
    main()
