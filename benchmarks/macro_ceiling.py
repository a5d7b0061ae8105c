"""What the macro space allows: the reference agents played to their supply ceiling.

A marine takes a free supply; supply comes from depots, and depots need room on the screen. The
six macros of ``sc2data rl`` (the reduced-random agent's) place a building on a free site drawn
at random and have no way to kill a marine, so once the screen holds no site for another depot
and the supply is used, nothing more can be trained: the episode's marines are fixed from then
on. This script plays the reference agents on the evaluation episodes (``sc2data rl
baselines``' seeds) and prints, per agent, the marines, the supply at the end and when (if ever)
the ceiling was reached: the first game loop with no free supply and no site for a depot.

    .venv/bin/python benchmarks/macro_ceiling.py --episodes 10 --out ceiling.json
    .venv/bin/python benchmarks/macro_ceiling.py --episodes 10 --sites far  # --macro-sites far

``uniform-macro`` is the masked uniform policy over the six macros, ``reduced-random`` the
paper's random agent over the same macros, ``macro-rules`` the scripted agent's rules within
them; ``scripted`` places its buildings away from the minerals and kills its own marines at its
ceiling (Attack_screen), which no macro does.
"""

from __future__ import annotations

import argparse
import json
import time
import types
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from sc2data._pysc2 import features, units
from sc2data.game.agents import SITES, make_agent, play
from sc2data.game.env import make_env
from sc2data.game.screen import ScreenView
from sc2data.rl.envs import BuildMarinesGym
from sc2data.rl.evaluate import UniformPolicy, eval_seeds, game_seed
from sc2data.rl.obs import game_loop

_P = features.Player
AGENTS = ("uniform-macro", "reduced-random", "macro-rules", "scripted")


def _frames(agent: str, seed: int, sites: str) -> Iterator[Any]:
    """Every pysc2 observation of one evaluation episode of ``agent``."""
    for obs, events in _observations(agent, seed, sites):
        # what ScreenView reads of a TimeStep, and what the simulator recorded in that step
        yield types.SimpleNamespace(observation=obs, events=events)


def _observations(agent: str, seed: int, sites: str) -> Iterator[Any]:
    if agent == "uniform-macro":
        env = BuildMarinesGym("macro", obs="compact", sites=sites)
        policy = UniformPolicy([6])
        policy.set_random_seed(seed)
        try:
            env.reset(seed=seed)
            yield env.frames[0], ()
            done = False
            while not done:
                action, _ = policy.predict(None, action_masks=env.action_masks())
                _, _, done, _, _ = env.step(action)
                yield from zip(env.frames[1:], env.events, strict=True)
        finally:
            env.close()
        return
    env = make_env("sim", seed=game_seed(seed))
    try:
        for ts in play(env, make_agent(agent, seed=seed, sites=sites)):
            yield ts.observation, tuple(env.events)
    finally:
        env.close()


def episode(agent: str, seed: int, sites: str = "random") -> dict[str, Any]:
    """Marines, the supply at the end, and the first loop at the ceiling (None: never)."""
    ceiling = None
    cap_max = 0
    ts: Any = None
    done: Counter[tuple[str, int]] = Counter()
    for ts in _frames(agent, seed, sites):
        done.update((e.kind, e.unit_type) for e in ts.events)
        obs = ts.observation
        player = obs["player"]
        cap_max = max(cap_max, int(player[_P.food_cap]))
        if ceiling is None and int(player[_P.food_used]) >= int(player[_P.food_cap]):
            if not ScreenView(ts).placements(2).any():
                ceiling = game_loop(obs)
    obs, player = ts.observation, ts.observation["player"]
    t = units.Terran
    return {"marines": int(obs["score_cumulative"][0]), "food_cap": int(player[_P.food_cap]),
            "food_cap_max": cap_max, "food_used": int(player[_P.food_used]),
            "workers": int(player[_P.food_workers]),
            "depots": done["completed", t.SupplyDepot], "barracks": done["completed", t.Barracks],
            "marines_died": done["died", t.Marine],
            "ceiling_loop": ceiling}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--agents", nargs="*", default=list(AGENTS), choices=AGENTS)
    ap.add_argument("--sites", default="random", choices=SITES,
                    help="where the macro agents build (rl train --macro-sites)")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    seeds, _ = eval_seeds(args.episodes)
    record: dict[str, Any] = {"seeds": seeds, "sites": args.sites, "agents": {}}
    print("| agent | marines, mean (range) | supply cap at the end (range) | workers "
          "| depots built | barracks | marines killed | episodes at the ceiling "
          "| its first loop, median |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for agent in args.agents:
        t0 = time.perf_counter()
        eps = [episode(agent, s, args.sites) for s in seeds]
        record["agents"][agent] = eps

        def col(key: str, e: list[dict[str, Any]] = eps) -> np.ndarray:
            return np.array([x[key] for x in e], float)

        hit = [x["ceiling_loop"] for x in eps if x["ceiling_loop"] is not None]
        m, cap = col("marines"), col("food_cap")
        print(f"| {agent} | {m.mean():.1f} ({m.min():.0f}–{m.max():.0f}) "
              f"| {cap.mean():.0f} ({cap.min():.0f}–{cap.max():.0f}) "
              f"| {col('workers').mean():.1f} | {col('depots').mean():.1f} "
              f"| {col('barracks').mean():.1f} | {col('marines_died').mean():.1f} "
              f"| {len(hit)} of {len(eps)} "
              f"| {np.median(hit) if hit else float('nan'):.0f} |"
              f"  ({time.perf_counter() - t0:.0f} s)")
    if args.out:
        args.out.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
