"""The RL vector env's own pace, no learner: what stepping the games and scoring their reward cost.

``sc2data rl train``'s vector env (its defaults: 16 games, worker processes as a run starts them
— one per core, one fewer with the narration reward — the run's reward batched in this process,
for the narration reward one MEM call a vector step over every game's new two-frame stacks)
stepped in lockstep with uniformly random allowed actions (a masked macro; a masked paper
function at a random screen point): no policy, no PPO update. Lockstep steps the games, then
scores them; a pipelined training run overlaps the two and may run faster than this.
Each case is a fresh process; the table gives medians over ``--repeats``.

    .venv/bin/python benchmarks/bench_rl_env.py --mem demo-out/run --decisions 16000 \\
        --case macro:sparse --case macro:narration --case paper:sparse --case paper:narration
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import sys
from pathlib import Path

CHILD = r"""
import json, sys, time
import numpy as np
from sc2data.rl.train import RLConfig, make_vec_env
space, reward, mem, decisions = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
cfg = RLConfig(out="unused", action_space=space, reward=reward, mem=mem or None)
vec = make_vec_env(cfg)
rng = np.random.default_rng(0)
vec.seed(0)
vec.reset()
steps = done = 0
start = time.perf_counter()
while done < decisions:
    masks = vec.action_masks()
    if space == "macro":
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in masks])
    else:
        f = [rng.choice(np.flatnonzero(m[:10])) for m in masks]
        actions = np.column_stack([f, rng.integers(0, 64, size=(len(masks), 2))])
    _, _, _, infos = vec.step(actions)
    steps += sum(i["env_steps"] for i in infos)
    done += len(infos)
wall = time.perf_counter() - start
vec.close()
print(json.dumps({"decisions_s": done / wall, "steps_s": steps / wall}))
"""


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--case", action="append", required=True, help="SPACE:REWARD")
    p.add_argument("--mem", default="", help="MEM run for the narration reward")
    p.add_argument("--decisions", type=int, default=16000, help="decisions per measurement")
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    for case in args.case:
        if len(case.split(":")) != 2 or not all(case.split(":")):
            p.error(f"--case {case!r}: expected SPACE:REWARD, e.g. macro:narration")
    root = Path(__file__).resolve().parent.parent
    results: dict[str, list[dict[str, float]]] = {c: [] for c in args.case}
    for r in range(args.repeats):
        for case in args.case:
            space, reward = case.split(":")
            out = subprocess.run([sys.executable, "-c", CHILD, space, reward, args.mem,
                                  str(args.decisions)], capture_output=True, text=True,
                                 cwd=root, check=False)
            if out.returncode:
                sys.exit(f"{case}: {out.stderr.strip().splitlines()[-1]}")
            results[case].append(json.loads(out.stdout.strip().splitlines()[-1]))
            print(f"# round {r}: {case}: {results[case][-1]['steps_s']:,.0f} pysc2 steps/s",
                  flush=True)
    print(f"machine: {platform.platform()}, --decisions {args.decisions}, "
          f"median of {args.repeats}")
    print("| space | reward | decisions/s | pysc2 steps/s |\n| --- | --- | ---: | ---: |")
    for case, rows in results.items():
        space, reward = case.split(":")
        d = statistics.median(x["decisions_s"] for x in rows)
        s = statistics.median(x["steps_s"] for x in rows)
        print(f"| {space} | {reward} | {d:,.0f} | {s:,.0f} |")


if __name__ == "__main__":
    main()
