"""Why argmax play makes no marine: each paper-space run's most likely action over the first
decisions of an evaluation episode, and the function head's probabilities at its first state.

``sc2data rl evaluate`` records the functions each mode chose (``eval.json``'s ``actions``); this
script adds the head's probabilities, which say how near to uniform the mode is.

    python benchmarks/rl_argmax.py RUN... --decisions 300 --out argmax.json
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import numpy as np
import torch

from sc2data.rl.envs import BuildMarinesGym
from sc2data.rl.evaluate import eval_seeds
from sc2data.rl.runs import load_model
from sc2data.rl.train import game_loops, load_config


def argmax_play(run: Path, decisions: int) -> dict[str, object]:
    """The functions argmax play chooses over ``decisions`` decisions of the first evaluation
    episode, the top three function probabilities at its first state, and the most likely
    function's probability along the way (how far from a tie each argmax choice is)."""
    cfg = load_config(run)
    if cfg.action_space != "paper":
        raise SystemExit(f"{run} plays the {cfg.action_space} space; this script reads the paper "
                         "space's function head (rl evaluate's actions cover both)")
    env = BuildMarinesGym(cfg.action_space, backend=cfg.backend, obs=cfg.obs_config(),
                          game_loops=game_loops(cfg))
    try:
        model = load_model(run, env)
        obs, _ = env.reset(seed=eval_seeds(1)[0][0])
        obs_t, _ = model.policy.obs_to_tensor(obs)
        with torch.no_grad():
            dist = model.policy.get_distribution(obs_t, action_masks=env.action_masks())
            p = dist._function_log_probs().exp()[0].numpy()
        chosen: Counter[str] = Counter()
        top: list[float] = []
        for _ in range(decisions):
            with torch.no_grad():
                o, _ = model.policy.obs_to_tensor(obs)
                d = model.policy.get_distribution(o, action_masks=env.action_masks())
                top.append(float(d._function_log_probs().exp().max()))
            action, _ = model.predict(obs, deterministic=True, action_masks=env.action_masks())
            obs, _, terminated, truncated, info = env.step(action)
            chosen[info["action"]] += 1
            if terminated or truncated:
                break
    finally:
        env.close()
    return {"argmax": dict(chosen.most_common()),
            "first_state_top_p": [round(float(x), 3) for x in np.sort(p)[::-1][:3]],
            "top_p_median": round(float(np.median(top)), 3),
            "top_p_range": [round(min(top), 3), round(max(top), 3)]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--decisions", type=int, default=300)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    torch.set_num_threads(1)
    result = {}
    for run in a.runs:
        result[str(run)] = argmax_play(run, a.decisions)  # runs of several grids share names
        print(run, result[str(run)], flush=True)
    if a.out:
        a.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
