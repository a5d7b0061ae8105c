"""Vectorised BuildMarines env throughput for RL, with and without the MEM narration reward.

Steps ``--envs`` environments (one subprocess each, SB3's ``SubprocVecEnv``; in-process for 1)
with uniformly random *masked* macro actions and reports decisions/s and pysc2 steps/s (median
of ``--repeats``) for the sparse reward and for narration shaping with the MEM of ``--mem``
(each subprocess loads it, torch on one thread). Policy learning is not included.

    .venv/bin/python benchmarks/bench_rl.py --mem demo-out/run --envs 1 2 --decisions 600
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from sc2data.rl.train import RLConfig, make_vec_env


def measure(cfg: RLConfig, decisions: int) -> tuple[float, float]:
    """(decisions/s, pysc2 steps/s) over ``decisions`` vector steps, after a warm-up step."""
    vec = make_vec_env(cfg)
    rng = np.random.default_rng(0)
    try:
        vec.seed(0)
        vec.reset()
        steps = 0
        t0 = 0.0
        for i in range(decisions + 1):
            masks = vec.env_method("action_masks")
            actions = np.array([rng.choice(np.flatnonzero(m)) for m in masks])
            _, _, _, infos = vec.step(actions)
            if i == 0:  # warm-up: subprocess start, MEM load, first forward
                t0 = time.perf_counter()
                continue
            steps += sum(int(info.get("env_steps", 1)) for info in infos)
        dt = time.perf_counter() - t0
    finally:
        vec.close()
    return decisions * cfg.envs / dt, steps / dt


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mem", help="MEM run for the narration reward (omit: sparse only)")
    p.add_argument("--envs", type=int, nargs="+", default=[1, 2])
    p.add_argument("--decisions", type=int, default=600, help="vector steps per repeat")
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    rewards = ["sparse"] + (["narration"] if a.mem else [])
    print(f"| reward | envs | decisions/s (median) | pysc2 steps/s (median) |")
    print("| --- | --- | --- | --- |")
    for reward in rewards:
        for k in a.envs:
            cfg = RLConfig(out="unused", reward=reward, envs=k,
                           mem=a.mem if reward == "narration" else None)
            runs = [measure(cfg, a.decisions) for _ in range(a.repeats)]
            d = statistics.median(r[0] for r in runs)
            s = statistics.median(r[1] for r in runs)
            print(f"| {reward} | {k} | {d:,.0f} | {s:,.0f} |", flush=True)


if __name__ == "__main__":
    main()
