"""Check that the simulator and the agents play exactly as a reference commit does.

Plays full episodes (3 reduced-random, 1 scripted, 1 pysc2 ``random``) and hashes, per episode,
every observation (each key's value bytes, dtype, shape, class and ``NamedNumpyArray`` index
names), every action the agent picks, and each step's type, reward and discount. It also checks
that an observation handed out is never changed later (the previous step's observation is hashed
again after the next step) and that consecutive ``feature_screen``/``feature_minimap`` arrays
share no memory. Used to keep performance work output-identical:

    .venv/bin/python benchmarks/check_sim_identical.py --write /tmp/ref.json   # at the base commit
    .venv/bin/python benchmarks/check_sim_identical.py --check /tmp/ref.json   # after a change
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.game.agents import make_agent
from sc2data.game.env import make_env

EPISODES: tuple[tuple[str, int, int], ...] = (
    ("reduced-random", 11, 101), ("reduced-random", 12, 102), ("reduced-random", 13, 103),
    ("scripted", 14, 104), ("random", 15, 105),
)
"""(agent, env seed, agent seed) of each episode played."""


def _feed(h: Any, value: Any) -> None:
    """Everything that identifies one observation value: class, names, dtype, shape, bytes."""
    h.update(type(value).__name__.encode())
    if isinstance(value, np.ndarray):
        names = getattr(value, "_index_names", None)
        h.update(json.dumps(names, sort_keys=True).encode())
        h.update(str(value.dtype).encode() + str(value.shape).encode())
        h.update(np.ascontiguousarray(value).tobytes())
    else:
        h.update(repr(value).encode())


def obs_digest(obs: Any) -> bytes:
    h = hashlib.sha256()
    h.update(type(obs).__name__.encode())
    for key in obs:  # insertion order is part of the dict pysc2 hands out
        h.update(key.encode())
        _feed(h, obs[key])
    return h.digest()


def play(agent_name: str, env_seed: int, agent_seed: int) -> dict[str, Any]:
    """One full episode: its observation and action digests and step count."""
    env, agent = make_env("sim", seed=env_seed), make_agent(agent_name, seed=agent_seed)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    agent.reset()
    h_obs, h_act = hashlib.sha256(), hashlib.sha256()
    ts = env.reset()[0]
    prev, prev_digest = None, b""
    steps = 0
    while True:
        digest = obs_digest(ts.observation)
        h_obs.update(digest + repr((int(ts.step_type), ts.reward, ts.discount)).encode())
        if prev is not None:
            if obs_digest(prev) != prev_digest:
                raise SystemExit(f"{agent_name}: step {steps - 1}'s observation changed later")
            for key in ("feature_screen", "feature_minimap"):
                if np.shares_memory(prev[key], ts.observation[key]):
                    raise SystemExit(f"{agent_name}: step {steps}'s {key} shares memory")
        prev, prev_digest = ts.observation, digest
        if ts.last():
            break
        call = agent.step(ts)
        h_act.update(repr((int(call.function), [list(map(int, a)) for a in call.arguments]))
                     .encode())
        ts = env.step([call])[0]
        steps += 1
    env.close()
    return {"agent": agent_name, "env_seed": env_seed, "agent_seed": agent_seed,
            "steps": steps, "observations": h_obs.hexdigest(), "actions": h_act.hexdigest()}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", type=Path, help="record the digests here (the reference)")
    g.add_argument("--check", type=Path, help="compare with the digests recorded here")
    a = p.parse_args()
    results = []
    for name, env_seed, agent_seed in EPISODES:
        results.append(play(name, env_seed, agent_seed))
        r = results[-1]
        print(f"{name:15s} seeds {env_seed}/{agent_seed}: {r['steps']} steps, "
              f"obs {r['observations'][:12]} actions {r['actions'][:12]}")
    if a.write:
        a.write.write_text(json.dumps(results, indent=1))
        print(f"wrote {a.write}")
        return
    ref = json.loads(a.check.read_text())
    bad = [f"{r['agent']} seeds {r['env_seed']}/{r['agent_seed']}"
           for r, want in zip(results, ref, strict=True) if r != want]
    if bad:
        print("DIFFERENT: " + "; ".join(bad))
        sys.exit(1)
    print(f"identical: all {len(results)} episodes match {a.check}")


if __name__ == "__main__":
    main()
