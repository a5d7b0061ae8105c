"""Rollout on Ray against the local process pool, for BENCHMARKS.md ("Scale-out on Ray").

The same episodes for every variant (embedded simulator, reduced-random agent, paper layers, one
episode per shard), through the same calls as ``sc2data rollout [--ray]``:

* local, 1 and 2 workers (``rollout(workers=K)``: 1 runs in this process, 2 spawns processes);
* Ray, 1 and 2 tasks at once, on one local Ray instance with 2 CPUs (``rollout_on_ray``).

Ray's start-up (``ray.init``) is timed on its own, and so is the first Ray run, whose worker
processes import sc2data cold; the Ray rows are the warm runs after it (the instance and its
workers persist between runs, as in a session on a cluster), while every local run starts its
worker processes afresh, as ``sc2data rollout`` does. Each repeat runs every variant once,
round-robin, into a fresh folder, because the machine is shared; figures are medians, and the
ratios compare variants within this one run. Last, ``--tiny`` shards of one step each show
the fixed cost per task and per run. *CPU-s per 1,000 steps* counts every process
involved — this one, its worker processes, and for Ray its raylet, GCS, workers and tracker (all
descendants of this process with a local instance) — so it shows the overhead regardless of how
busy the shared cores are.

    .venv/bin/python benchmarks/bench_ray.py [--episodes 8] [--max-steps 1800] [--repeats 5]
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

from sc2data.data.rollout import RolloutConfig, rollout
from sc2data.scaleout.driver import RayOptions, rollout_on_ray

VARIANTS = ("local 1", "local 2", "ray 1", "ray 2")


def cpu_seconds() -> float:
    """CPU time of this process, of its finished children and of its live descendants."""
    import psutil

    total = sum(getattr(resource.getrusage(who), f) for who in
                (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN) for f in ("ru_utime", "ru_stime"))
    for proc in psutil.Process().children(recursive=True):
        try:
            total += sum(proc.cpu_times()[:4])  # user, system, and its finished children's
        except psutil.Error:
            pass
    return total


def run(variant: str, config: RolloutConfig, out: Path) -> tuple[float, float, float]:
    """(seconds, CPU seconds, peak RSS in MB of a Ray task or 0) of one rollout into ``out``."""
    kind, k = variant.split()
    cpu = cpu_seconds()
    t = time.perf_counter()
    if kind == "local":
        rollout(config, out, workers=int(k), progress=False)
        rss = 0.0
    else:
        _, report = rollout_on_ray(config, out, RayOptions(workers=int(k)), progress=False)
        rss = report.peak_rss_mb
    seconds = time.perf_counter() - t
    cpu = cpu_seconds() - cpu
    shutil.rmtree(out)
    return seconds, cpu, rss


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--max-steps", type=int, default=1800)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--tiny", type=int, default=32, help="one-step shards for fixed costs")
    args = parser.parse_args()
    config = RolloutConfig(env="sim", agent="reduced-random", episodes=args.episodes,
                           episodes_per_shard=1, max_steps=args.max_steps, seed=1)
    steps = args.episodes * args.max_steps

    import ray

    print(f"# {platform.node()}: {os.cpu_count()} cores (shared), Python "
          f"{platform.python_version()}, Ray {ray.__version__}; {args.episodes} episodes × "
          f"{args.max_steps} steps, one per shard; medians of {args.repeats}, load average "
          f"{os.getloadavg()[0]:.1f} at start\n")
    t = time.perf_counter()
    ray.init(address="local", num_cpus=2, include_dashboard=False, object_store_memory=200 << 20,
             log_to_driver=False, logging_level="WARNING")
    startup = time.perf_counter() - t
    seconds: dict[str, list[float]] = {v: [] for v in VARIANTS}
    cpu: dict[str, list[float]] = {v: [] for v in VARIANTS}
    rss: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        cold, _, r = run("ray 2", config, Path(tmp) / "cold")
        rss.append(r)
        for j in range(args.repeats):
            for v in VARIANTS:
                s, c, r = run(v, config, Path(tmp) / f"{v.replace(' ', '')}-{j}")
                seconds[v].append(s)
                cpu[v].append(c)
                if r:
                    rss.append(r)
        # Fixed costs: many one-step shards, where the playing is next to nothing.
        tiny = RolloutConfig(env="sim", agent="reduced-random", episodes=args.tiny,
                             episodes_per_shard=1, max_steps=1, seed=1)
        fixed: dict[str, list[float]] = {"local 1": [], "ray 1": [], "ray 2": []}
        for j in range(args.repeats):
            for v, times in fixed.items():
                times.append(run(v, tiny, Path(tmp) / f"tiny-{v.replace(' ', '')}-{j}")[0])
    t = time.perf_counter()
    ray.shutdown()
    shutdown = time.perf_counter() - t

    rate = {v: steps / statistics.median(s) for v, s in seconds.items()}
    per_k = {v: 1000 * statistics.median(c) / steps for v, c in cpu.items()}
    print("| variant | steps/s (median) | min – max | vs local, same K | CPU-s per 1,000 steps "
          "| vs local, same K |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for v in VARIANTS:
        lo, hi = steps / max(seconds[v]), steps / min(seconds[v])
        kind, k = v.split()
        ratio = "" if kind == "local" else f"{rate[v] / rate[f'local {k}']:.2f}"
        cpu_ratio = "" if kind == "local" else f"{per_k[v] / per_k[f'local {k}']:.2f}"
        print(f"| {v} | {rate[v]:,.0f} | {lo:,.0f} – {hi:,.0f} | {ratio} | {per_k[v]:.2f} | "
              f"{cpu_ratio} |")
    print(f"\n2 vs 1 worker: local {rate['local 2'] / rate['local 1']:.2f}×, "
          f"Ray {rate['ray 2'] / rate['ray 1']:.2f}×")
    print(f"Ray start-up (ray.init, 2 CPUs): {startup:.1f} s; first (cold) Ray run at 2: "
          f"{steps / cold:,.0f} steps/s ({cold:.1f} s); ray.shutdown: {shutdown:.1f} s")
    med = {v: statistics.median(x) for v, x in fixed.items()}
    print(f"{args.tiny} one-step shards: local 1 {med['local 1']:.2f} s, Ray 1 "
          f"{med['ray 1']:.2f} s, Ray 2 {med['ray 2']:.2f} s: Ray costs "
          f"{1000 * (med['ray 1'] - med['local 1']) / args.tiny:.0f} ms more per task, one at a "
          f"time")
    print(f"peak RSS of a simulator task's worker process: {max(rss):.0f} MB "
          f"(median over runs {statistics.median(rss):.0f} MB)")


if __name__ == "__main__":
    main()
