"""Agent steps per second on one core, every layer drawn, for each agent and for the env alone.

Each workload runs in its own fresh process pinned to one CPU core (single-threaded BLAS), so
peak memory is that workload's own: the process's peak RSS (``ru_maxrss``, which includes the
interpreter and pysc2) and, in a separate untimed pass, the peak of Python allocations made while
stepping (``tracemalloc``). A repeat is N agent steps from ``reset`` on (episodes restart as they
end; resets are inside the timing). The table shows medians over the repeats, in wall-clock
steps per second and in steps per second of the process's own CPU time: what one dedicated core
gives; on a shared machine the wall-clock figure also counts time the core gave to others.
"Time in agent" is the share of wall-clock time spent in ``agent.step``.

    python benchmarks/bench_env.py --steps 1800 --repeats 5
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import platform
import resource
import statistics
import time
import tracemalloc
from typing import Any

WORKLOADS: tuple[str, ...] = ("env only (no_op)", "random", "reduced-random", "scripted")
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _run(env: Any, agent: Any, steps: int) -> float:
    """``steps`` agent steps, restarting the episode when it ends; seconds spent in the agent."""
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    timestep = env.reset()[0]
    agent.reset()
    in_agent = 0.0
    clock = time.perf_counter
    for _ in range(steps):
        if timestep.last():
            timestep = env.reset()[0]
            agent.reset()
        t0 = clock()
        call = agent.step(timestep)
        in_agent += clock() - t0
        timestep = env.step([call])[0]
    return in_agent


def _agent(workload: str, seed: int) -> Any:
    from sc2data.game.agents import (
        make_agent,  # imports pysc2 through sc2data._pysc2 first
    )
    from pysc2.agents import base_agent  # isort: skip

    return base_agent.BaseAgent() if workload == WORKLOADS[0] else make_agent(workload, seed=seed)


def _measure(workload: str, backend: str, steps: int, repeats: int, core: int,
             result: Any) -> None:
    """Child process: time the repeats, then an untimed tracemalloc pass; report by the queue."""
    os.sched_setaffinity(0, {core})
    from sc2data.game.env import make_env

    env = make_env(backend, seed=0)
    _run(env, _agent(workload, 0), 50)  # warm up: imports, caches, first reset
    rates, cpu_rates, shares = [], [], []
    for r in range(repeats):
        agent = _agent(workload, r + 1)
        t0, c0 = time.perf_counter(), time.process_time()
        in_agent = _run(env, agent, steps)
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
        rates.append(steps / elapsed)
        cpu_rates.append(steps / cpu)
        shares.append(in_agent / elapsed)
    tracemalloc.start()
    _run(env, _agent(workload, 99), min(steps, 600))
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    env.close()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
    result.put((rates, statistics.median(cpu_rates), statistics.median(shares), rss_mb,
                traced_peak / 2**20))


def machine() -> str:
    """nproc and the CPU model, as /proc/cpuinfo names it."""
    model = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            model = next(line.split(":", 1)[1].strip() for line in f
                         if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return (f"nproc {os.cpu_count()}, {model}, Python {platform.python_version()}, "
            f"{platform.system()} {platform.release()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="sim", help="backend: sim or sc2")
    parser.add_argument("--steps", type=int, default=1800, help="agent steps per repeat")
    parser.add_argument("--repeats", type=int, default=5, help="repeats (median reported)")
    parser.add_argument("--core", type=int, default=0, help="CPU core to pin to")
    parser.add_argument("--workloads", nargs="+", default=list(WORKLOADS), choices=WORKLOADS)
    args = parser.parse_args()
    if args.repeats < 3 and args.repeats != 1:
        parser.error("use --repeats 1 for a smoke run, or 3 or more for a median")
    for var in _THREAD_VARS:
        os.environ[var] = "1"

    ctx = mp.get_context("spawn")
    print(f"machine: {machine()}; load average before: {os.getloadavg()[0]:.2f}")
    print(f"env {args.env}, {args.steps} agent steps × {args.repeats} repeats, one core "
          f"(#{args.core}), every layer drawn\n")
    print("| workload | steps/s (median) | min – max | steps per CPU-second | time in agent "
          "| peak RSS (MB) | traced peak (MB) |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for workload in args.workloads:
        queue = ctx.Queue()
        p = ctx.Process(target=_measure, args=(workload, args.env, args.steps, args.repeats,
                                               args.core, queue))
        p.start()
        rates, cpu_rate, share, rss, traced = queue.get()
        p.join()
        print(f"| {workload} | {statistics.median(rates):,.0f} | "
              f"{min(rates):,.0f} – {max(rates):,.0f} | {cpu_rate:,.0f} | {share:.0%} | "
              f"{rss:,.0f} | {traced:,.1f} |", flush=True)


if __name__ == "__main__":
    main()
