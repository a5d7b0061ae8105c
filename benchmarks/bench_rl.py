"""`sc2data rl train` end to end: decisions and pysc2 steps per second, PPO updates included.

Each measurement is a fresh process that imports a code tree (``--code NAME=PATH``: this
checkout, or another one such as a ``git worktree`` of an older commit, so old and new are
measured in one sitting), builds ``RLConfig(**settings)`` and times ``train()`` alone (imports
excluded; worker start-up, MEM loading and every PPO update included). Settings an older tree's
``RLConfig`` lacks are dropped for it. Runs alternate between cases, ``--repeats`` rounds; the
table gives the median of each case and the CPU seconds (this process and its children) per
1,000 decisions.

    .venv/bin/python benchmarks/bench_rl.py --mem demo-out/run --steps 8192 \\
        --code new=. --code old=/tmp/sc2data-old \\
        --case old:paper:narration:envs=1 --case new:paper:narration:envs=16,obs_size=32

A case is ``CODE:SPACE:REWARD[:key=value,...]`` (values parsed as Python literals where they can
be: ``envs=16,obs=stored,processes=0``). A key in capitals is an environment variable of the
measurement's process instead (``OMP_WAIT_POLICY=PASSIVE``), set before torch loads.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = r"""
import dataclasses, json, os, resource, sys, time
sys.path.insert(0, sys.argv[1])
from sc2data.rl.train import RLConfig, train
settings = json.loads(sys.argv[2])
known = {f.name for f in dataclasses.fields(RLConfig)}
dropped = sorted(set(settings) - known)
cfg = RLConfig(**{k: v for k, v in settings.items() if k in known})
import torch  # noqa: F401  (imported before the clock starts, as train() would)
t0, r0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
train(cfg)
dt = time.perf_counter() - t0
r1, rc = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime) + rc.ru_utime + rc.ru_stime
state = json.load(open(os.path.join(cfg.out, "state.json")))
print(json.dumps({"seconds": dt, "cpu": cpu, "timesteps": state["timesteps"],
                  "env_steps": state["env_steps"], "dropped": dropped}))
"""


def parse_case(text: str) -> tuple[str, str, str, dict[str, object]]:
    parts = text.split(":", 3)
    if len(parts) < 3:
        raise SystemExit(f"bad --case {text!r}: CODE:SPACE:REWARD[:key=value,...]")
    extra: dict[str, object] = {}
    for item in (parts[3].split(",") if len(parts) > 3 and parts[3] else []):
        k, _, v = item.partition("=")
        try:
            extra[k] = ast.literal_eval(v)
        except (ValueError, SyntaxError):
            extra[k] = v
    return parts[0], parts[1], parts[2], extra


def measure(code: Path, settings: dict[str, object]) -> dict[str, object]:
    """One measurement in a fresh process; settings keyed in capitals go to its environment."""
    variables = {k: str(v) for k, v in settings.items() if k.isupper()}
    settings = {k: v for k, v in settings.items() if not k.isupper()}
    env = {**os.environ, **variables, "PYTHONPATH": str(code)}
    out = subprocess.run([sys.executable, "-c", CHILD, str(code), json.dumps(settings)],
                         capture_output=True, text=True, env=env, check=False)
    if out.returncode:
        raise SystemExit(f"measurement failed ({settings}):\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--code", action="append", default=[], help="NAME=PATH of a code tree")
    p.add_argument("--case", action="append", required=True, help="CODE:SPACE:REWARD[:k=v,..]")
    p.add_argument("--mem", help="MEM run for the narration reward")
    p.add_argument("--steps", type=int, default=8192, help="decisions per measurement")
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    codes = {"new": Path(".").resolve()}
    codes.update({k: Path(v).resolve() for k, v in (c.split("=", 1) for c in a.code)})
    cases = [parse_case(c) for c in a.case]
    results: dict[int, list[dict[str, object]]] = {i: [] for i in range(len(cases))}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(a.repeats):
            for i, (code, space, reward, extra) in enumerate(cases):
                settings: dict[str, object] = {
                    "out": f"{tmp}/run-{i}-{r}", "action_space": space, "reward": reward,
                    "steps": a.steps, "seed": r, "progress": False,
                    "checkpoint_every": 10 ** 9, **extra}
                if reward == "narration":
                    settings["mem"] = a.mem
                res = measure(codes[code], settings)
                results[i].append(res)
                print(f"# round {r}: {a.case[i]}: {res['timesteps'] / res['seconds']:,.0f} "
                      f"decisions/s", file=sys.stderr, flush=True)
    print(f"machine: {platform.platform()}, {os.cpu_count()} cores; --steps {a.steps}, median "
          f"of {a.repeats}")
    print("| code | space | reward | settings | decisions/s | pysc2 steps/s | CPU-s per 1k "
          "decisions |")
    print("| --- | --- | --- | --- | ---: | ---: | ---: |")
    for i, (code, space, reward, extra) in enumerate(cases):
        rs = results[i]
        dps = statistics.median(float(x["timesteps"]) / float(x["seconds"]) for x in rs)
        sps = statistics.median(float(x["env_steps"]) / float(x["seconds"]) for x in rs)
        cpu = statistics.median(1000 * float(x["cpu"]) / float(x["timesteps"]) for x in rs)
        dropped = rs[0]["dropped"]
        shown = ", ".join(f"{k}={v}" for k, v in extra.items() if k not in dropped) or "-"
        print(f"| {code} | {space} | {reward} | {shown} | {dps:,.0f} | {sps:,.0f} | {cpu:.2f} |")


if __name__ == "__main__":
    main()
