"""Where an agent's minerals go in a BuildMarines episode: what it placed and completed (the
simulator's events), and the minerals each took. Policies of ``sc2data rl`` runs play sampled
on the evaluation seeds (1,000,000 …); named agents (scripted, reduced-random) the same seeds.

    python spend.py RUN_OR_AGENT ... --episodes 3
"""

from __future__ import annotations

import argparse
import collections

import numpy as np

import sc2data.rl  # noqa: F401  (registers policy agents)
from sc2data._pysc2 import units
from sc2data.game.agents import make_agent
from sc2data.game.env import make_env

T = units.Terran
COST = {("completed", T.SCV): 50, ("completed", T.Marine): 50, ("placed", T.SupplyDepot): 100,
        ("placed", T.Barracks): 150}
NAMES = {("completed", T.SCV): "SCVs", ("placed", T.SupplyDepot): "depots",
         ("placed", T.Barracks): "barracks", ("completed", T.Marine): "marines"}
SEED = 1_000_000


def episode(who: str, seed: int) -> collections.Counter:
    """Counts of the events in NAMES over one episode of agent or policy ``who``."""
    name = who if who in ("scripted", "reduced-random", "random") else f"policy:{who}"
    env = make_env("sim", seed=seed)
    agent = make_agent(name, seed=seed)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    ts = env.reset()[0]
    agent.reset()
    seen: collections.Counter = collections.Counter()
    while not ts.last():
        ts = env.step([agent.step(ts)])[0]
        seen.update((e.kind, e.unit_type) for e in env.events if (e.kind, e.unit_type) in NAMES)
    env.close()
    return seen


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("who", nargs="+", help="run folders or agent names")
    ap.add_argument("--episodes", type=int, default=3)
    args = ap.parse_args()
    print("| agent | " + " | ".join(NAMES.values()) + " | minerals spent | on marines |")
    print("| --- |" + " ---: |" * (len(NAMES) + 2))
    for who in args.who:
        runs = [episode(who, SEED + e) for e in range(args.episodes)]
        mean = {k: float(np.mean([r[k] for r in runs])) for k in NAMES}
        spent = sum(COST[k] * v for k, v in mean.items())
        marines = COST[("completed", T.Marine)] * mean[("completed", T.Marine)]
        print(f"| {who} | " + " | ".join(f"{mean[k]:.1f}" for k in NAMES) +
              f" | {spent:,.0f} | {100 * marines / spent:.0f} % |")


if __name__ == "__main__":
    main()
