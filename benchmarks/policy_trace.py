"""One evaluation episode of a trained ``sc2data rl`` run, decision by decision: what the policy
was offered, how likely it made each allowed action, what it chose, and the state.

A diagnostic for "why does argmax play make nothing": a policy whose probabilities barely move
with the state plays one action again and again under argmax, however well its sampled mix
scores (BENCHMARKS.md, "Far sites, 10 seeds: the sparse learner, and why argmax play makes
0"). In the paper space a line shows the three most likely functions, the chosen point and
what the full-resolution screen holds there (a click one pixel off its target fails, and argmax
play sends it again: BENCHMARKS.md, "PPO held near the scripted agent's clone"); the episode
ends with the longest run of one repeated call.

    python benchmarks/policy_trace.py RUN                 # argmax, the first evaluation episode
    python benchmarks/policy_trace.py RUN --sampled --episode 3 --every 5
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
import torch

from sc2data._pysc2 import features
from sc2data.rl import evaluate as ev
from sc2data.rl.envs import MACROS, PAPER_FUNCTIONS

_P = features.Player
_UNIT_TYPE = features.SCREEN_FEATURES.unit_type.index


def state_dependence(by_mask: dict[tuple[bool, ...], list[np.ndarray]]) -> float:
    """How far the policy's probabilities move with the state beyond what the mask does: over
    the decisions whose allowed actions were the same, the mean total-variation distance of each
    distribution from their mean (decisions alone with their mask are left out)."""
    distances = []
    for probs in by_mask.values():
        if len(probs) > 1:
            stack = np.stack(probs)
            distances += list(0.5 * np.abs(stack - stack.mean(axis=0)).sum(axis=1))
    return float(np.mean(distances)) if distances else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--sampled", action="store_true", help="Sample actions (default: argmax).")
    ap.add_argument("--episode", type=int, default=0, help="Which evaluation episode (0-based).")
    ap.add_argument("--every", type=int, default=1, help="Print every Nth decision.")
    a = ap.parse_args()
    if a.episode < 0 or a.every < 1:
        raise SystemExit("policy_trace.py: --episode must be 0 or more and --every at least 1")
    torch.set_num_threads(1)
    ev._load_player(str(a.run))
    assert ev._PLAYER is not None
    _, model, env = ev._PLAYER
    seeds, sides = ev.eval_seeds(max(10, a.episode + 1))  # rl evaluate's episodes
    seed = seeds[a.episode]
    if env.kind == "paper":
        return paper_trace(model, env, seed, sides[a.episode], a)
    names = MACROS
    model.set_random_seed(seed)
    obs, _ = env.reset(seed=seed)
    print(f"{a.run}: episode seed {seed} ({sides[a.episode]} start), "
          f"{'sampled' if a.sampled else 'argmax'}")
    print("decision  loop  minerals  supply   workers idle  chose               "
          "probabilities of the allowed actions")
    done, i, info = False, 0, {}
    entropies = []
    by_mask: dict[tuple[bool, ...], list[np.ndarray]] = {}
    while not done:
        mask = env.action_masks()
        with torch.no_grad():
            o, _ = model.policy.obs_to_tensor(obs)
            dist = model.policy.get_distribution(o, action_masks=mask)
            probs = dist.distribution.probs.numpy()[0]
        allowed = mask[:len(names)]
        p = probs[allowed]
        by_mask.setdefault(tuple(bool(m) for m in allowed), []).append(probs)
        entropies.append(float(-(p * np.log(np.maximum(p, 1e-12))).sum()))
        action, _ = model.predict(obs, deterministic=not a.sampled, action_masks=mask)
        player = env.frames[-1]["player"]
        if i % a.every == 0:
            chose = names[int(np.asarray(action).reshape(-1)[0])]
            shown = " ".join(f"{n}={q:.2f}" for n, q, ok in zip(names, probs, allowed) if ok)
            print(f"{state(i, env.frames[-1]['game_loop'], player)}  {chose:19s} {shown}")
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        i += 1
    print(f"marines {info['marines']}, {i} decisions; entropy of the allowed actions' "
          f"distribution: median {np.median(entropies):.2f} nats")
    print(f"state dependence: {state_dependence(by_mask):.3f} (mean total variation between a "
          f"decision's distribution and the mean of the decisions offered the same actions; "
          f"0: the probabilities follow the mask alone)")
    ev._close_player()


def state(i: int, game_loop: Any, player: Any) -> str:
    """A trace line's first columns: decision, game loop, minerals, supply, workers, idle."""
    return (f"{i:8d} {int(game_loop[0]):5d} {int(player[_P.minerals]):9d} "
            f"{int(player[_P.food_used]):4d}/{int(player[_P.food_cap]):<4d} "
            f"{int(player[_P.food_workers]):7d} {int(player[_P.idle_worker_count]):4d}")


def longest_repeat(calls: list[tuple[int, int, int]]) -> tuple[int, int]:
    """The length of the longest run of one call sent again and again, and where it began."""
    best, start, run = (0, 0), 0, 0
    for i, call in enumerate(calls):
        run = run + 1 if i and call == calls[i - 1] else 1
        if run == 1:
            start = i
        if run > best[0]:
            best = (run, start)
    return best


def paper_trace(model: Any, env: Any, seed: int, side: str, a: argparse.Namespace) -> None:
    """The paper space's trace: function probabilities, the chosen point and the unit there."""
    from sc2data.rl.spatial import POINT_FUNCTIONS

    model.set_random_seed(seed)
    obs, _ = env.reset(seed=seed)
    print(f"{a.run}: episode seed {seed} ({side} start), {'sampled' if a.sampled else 'argmax'}")
    print("decision  loop  minerals  supply   workers idle  chose                      at "
          "(unit type)   most likely functions")
    done, i, info = False, 0, {}
    calls: list[tuple[int, int, int]] = []
    while not done:
        mask = env.action_masks()
        with torch.no_grad():
            o, _ = model.policy.obs_to_tensor(obs)
            dist = model.policy.get_distribution(o, action_masks=mask[None])
            probs = torch.softmax(dist.function_logits, 1).numpy()[0]
            action = dist.get_actions(deterministic=not a.sampled).numpy()[0]  # as predict
        f, x, y = (int(v) for v in action)
        name = PAPER_FUNCTIONS[f]
        takes = name in POINT_FUNCTIONS
        calls.append((f, x, y) if takes else (f, -1, -1))
        ts = env.timestep
        player = ts.observation["player"]
        if i % a.every == 0:
            where = ""
            if takes:
                unit = int(np.asarray(ts.observation["feature_screen"][_UNIT_TYPE])[y, x])
                where = f"({x:2d}, {y:2d}) {unit:4d}"
            top = np.argsort(probs)[::-1][:3]
            shown = " ".join(f"{PAPER_FUNCTIONS[j]}={probs[j]:.2f}" for j in top)
            print(f"{state(i, ts.observation['game_loop'], player)}  {name:26s} {where:17s} "
                  f"{shown}")
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        i += 1
    length, start = longest_repeat(calls)
    f, x, y = calls[start]
    print(f"marines {info['marines']}, {i} decisions; the longest run of one call: {length} "
          f"decisions of {PAPER_FUNCTIONS[f]}" + (f" at ({x}, {y})" if x >= 0 else "")
          + f" from decision {start}")
    ev._close_player()


if __name__ == "__main__":
    main()
