"""Where one rollout step's time goes: agent, simulator (game, drawing, observation) and writer.

Plays reduced-random episodes into a shard exactly as ``sc2data rollout`` does (same env, agent and
``ShardWriter``), timing each part of every step with ``perf_counter``; the simulator's drawing
and observation assembly are timed by wrapping ``Renderer.draw`` and ``obsdict.build``, and the
writer's chunk compression and its flushes (compression, then every 64th flush the checksums and
HDF5 writes of the batch) by wrapping ``ChunkEncoder.compress`` and ``ShardWriter._flush``.
Prints µs per step (median over repeats) for BENCHMARKS.md ("Rollout and storage").

    .venv/bin/python benchmarks/bench_step.py [--episodes 2] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.data.chunks import ChunkEncoder
from sc2data.data.dataset import keep_freed_memory
from sc2data.data.rollout import RolloutConfig, episode_seeds, shard_attrs
from sc2data.data.shards import ShardWriter
from sc2data.game.agents import make_agent
from sc2data.game.env import make_env
from sc2data.game.sim import env as sim_env
from sc2data.game.sim import observe

TOTALS: dict[str, float] = defaultdict(float)


def timed(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
    def wrapper(*args: Any, **kw: Any) -> Any:
        t = time.perf_counter()
        try:
            return fn(*args, **kw)
        finally:
            TOTALS[name] += time.perf_counter() - t
    return wrapper


def one_repeat(episodes: int, folder: Path, r: int) -> dict[str, float]:
    TOTALS.clear()
    keep_freed_memory()  # as rollout.write_shard does
    config = RolloutConfig(episodes=episodes)
    writer = ShardWriter(folder / f"bench-{r}.h5", config.schema, config.codec,
                         shard_attrs(config, 0))
    steps = 0
    for e in range(episodes):
        env_seed, agent_seed = episode_seeds(r, e)
        np.random.seed(agent_seed)
        env, agent = make_env("sim", seed=env_seed), make_agent("reduced-random", seed=agent_seed)
        agent.setup(env.observation_spec()[0], env.action_spec()[0])
        agent.reset()
        writer.begin_episode(e, env_seed, agent_seed)
        ts = env.reset()[0]
        writer.add_observation(ts.observation)
        while not ts.last():
            t0 = time.perf_counter()
            call = agent.step(ts)
            t1 = time.perf_counter()
            ts = env.step([call])[0]
            t2 = time.perf_counter()
            writer.add_observation(ts.observation)
            writer.add_step(int(call.function), call.arguments, ts.reward)
            t3 = time.perf_counter()
            TOTALS["agent"] += t1 - t0
            TOTALS["env"] += t2 - t1
            TOTALS["writer"] += t3 - t2
            steps += 1
        writer.end_episode()
        env.close()
    writer.close()
    return {k: v / steps * 1e6 for k, v in TOTALS.items()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=2)
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    observe.Renderer.draw = timed("env: draw layers", observe.Renderer.draw)  # type: ignore
    sim_env.obsdict.build = timed("env: observation dict", sim_env.obsdict.build)  # type: ignore
    ChunkEncoder.compress = timed("writer: compress", ChunkEncoder.compress)  # type: ignore
    ShardWriter._flush = timed("writer: flush (compress, checksum, HDF5)",  # type: ignore
                               ShardWriter._flush)
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(a.repeats):
            runs.append(one_repeat(a.episodes, Path(tmp), r))
    order = ["agent", "env", "env: draw layers", "env: observation dict", "writer",
             "writer: flush (compress, checksum, HDF5)", "writer: compress"]
    print(f"{a.episodes} reduced-random episodes × {a.repeats} repeats; µs per step, median")
    print("| part | µs/step |\n| --- | ---: |")
    for k in order:
        print(f"| {k} | {statistics.median(run[k] for run in runs):.0f} |")
    total = statistics.median(run["agent"] + run["env"] + run["writer"] for run in runs)
    print(f"| total (agent + env + writer) | {total:.0f} |")
    print(f"≈ {1e6 / total:,.0f} steps/s for one worker, before process start-up and hashing")


if __name__ == "__main__":
    main()
