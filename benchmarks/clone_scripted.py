"""Can the paper space's policy play the scripted agent's game? Behaviour cloning of the scripted
agent in pysc2's own action space, as a diagnostic of the RL experiment.

The paper-space learners of a million decisions make 50–70 marines sampled and 0 by argmax
(BENCHMARKS.md, "Paper-space runs of 1,000,000 decisions"): their most likely action is one
call repeated. Either the spatial policy (:mod:`sc2data.rl.spatial`: a function, then its screen
point given the function) cannot hold a plan on its observation, or PPO has not taught one. This
script separates the two, as ``clone_rules.py`` does for the macro space. It plays
``--episodes`` of the scripted agent (:class:`~sc2data.game.agents.ScriptedAgent`, the
build order that makes ≈ 137 marines) in the run's paper-space env: at every pysc2 step the agent
reads the env's observation and its call is sent as the paper action ``(function, x, y)`` that
:func:`~sc2data.rl.envs.paper_call` turns back into the very same call (checked); a call the
paper space cannot express (``Attack_screen``, which the agent uses to kill a marine at the
supply cap) is sent as ``no_op``. Seeds 500,000,000 on, which training and evaluation never use.
It fits a fresh policy of the run's settings to those actions by maximum likelihood under the
action masks (the function, and the point where the function takes one; Adam, minibatches of
256; the value head untouched; ``--balanced`` weights each function by the inverse of its
share), reports on ``--held-out`` episodes it did not see how often the policy's most likely
function is the agent's (per function and their mean) and, for the functions with a point, how
often its most likely point lies within 4 pixels of the agent's, and writes the clone as a run
folder that ``sc2data rl evaluate OUT`` plays sampled and argmax like any run and ``sc2data rl
train --init-policy OUT`` starts PPO from; ``OUT/clone.json`` records the fit.

``--dagger R`` then runs R rounds of DAgger (Ross et al. 2011), as ``clone_rules.py`` does: the
clone plays ``--dagger-episodes`` episodes of its own (argmax on even episodes, sampled on odd),
the scripted agent — stepped on the same observations, its build order going on from what the
clone did — labels every state with the call it would send, those decisions join the training
set and the fit goes on; the policy kept is the one whose round made the most marines by argmax
(on training-side seeds: the evaluation episodes stay unseen).

    python benchmarks/clone_scripted.py RUN --out OUT [--episodes 16] [--held-out 2]
        [--epochs 20] [--lr 1e-3] [--balanced] [--dagger 0] [--dagger-episodes 4]
        [--dagger-epochs 5] [--dagger-lr 3e-4] [--init CLONE]

``--init CLONE`` starts the fit from an earlier clone's policy; a clone with the ``cell`` point
head starts one with ``--point-head pixel`` (the run's setting) as exactly itself: what the
pixel head adds (the within-cell convolution, the pixels' preferences) starts at zero.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from clone_rules import (
    DAGGER_SEED,
    add_options,
    checked_config,
    class_weights,
    clone,
    likelihood_epoch,
    policy_optimizer,
    predictions,
    split,
    write_clone,
)
from ppo_gradients import DEMO_SEED, Demonstrations, joined

from sc2data._pysc2 import actions
from sc2data.game.agents import ScriptedAgent
from sc2data.rl.envs import PAPER_FUNCTIONS, RECT_HALF, BuildMarinesGym, paper_call
from sc2data.rl.spatial import POINT_FUNCTIONS
from sc2data.rl.train import game_loops

_F = actions.FUNCTIONS
NO_OP = np.zeros(3, np.int64)
NEAR = 4
"""Pixels within which a point counts as the agent's (a cell of the 32-cell map is 2 pixels)."""


def _arguments(call: actions.FunctionCall) -> list[list[int]]:
    return [[int(v) for v in arg] for arg in call.arguments]


TIMERS: dict[str, tuple[str, int]] = {
    "Build_SupplyDepot_screen": ("depot", 25), "Build_Barracks_screen": ("barracks", 25),
    "Harvest_Gather_screen": ("gather", 4), "Train_SCV_quick": ("scv", 8),
    "Train_Marine_quick": ("marine", 2),
}
"""The scripted agent's timers (:meth:`ScriptedAgent.next_macro`: the steps it holds off a
macro after choosing it), set in DAgger from the call the policy sent."""


def encode(call: actions.FunctionCall) -> np.ndarray | None:
    """The paper action ``(function, x, y)`` whose :func:`paper_call` is ``call``; None where
    the paper space cannot express it (another function, or other fixed arguments)."""
    name = _F[call.function].name
    if name not in PAPER_FUNCTIONS:
        return None
    x = y = 0
    for spec, value in zip(_F[call.function].args, call.arguments, strict=True):
        if spec.name == "screen":
            x, y = int(value[0]), int(value[1])
            if name == "select_rect":
                x, y = x + RECT_HALF, y + RECT_HALF
    action = np.array([PAPER_FUNCTIONS.index(name), x, y], np.int64)
    back = paper_call(*(int(a) for a in action))
    if int(back.function) != int(call.function) or _arguments(back) != _arguments(call):
        return None
    return action


def demonstrate(cfg: Any, episodes: int, first_seed: int = DEMO_SEED, model: Any = None,
                deterministic: bool = False) -> tuple[Demonstrations, dict[str, int]]:
    """The scripted agent's decisions on ``episodes`` of the run's paper env (episode ``e``
    seeded ``first_seed + e``), and how many of its calls were sent as ``no_op`` by name. With
    ``model`` (DAgger's labels), the model's policy plays (argmax with ``deterministic``, else
    sampled) and the scripted agent, stepped on the same observations, labels each state with
    the call it would send there: while the policy sends the function it was told, the agent's
    build order goes on; where the policy sends another, the agent drops the macro it was
    playing, undoes the timer its choice set, and takes the timer of the call the policy sent
    (:data:`TIMERS`), so that its next label starts from what the policy did."""
    env = BuildMarinesGym("paper", backend=cfg.backend, obs=cfg.obs_config(),
                          game_loops=game_loops(cfg))
    obs, masks, chosen, marines, episode = [], [], [], [], []
    dropped: dict[str, int] = {}
    try:
        for e in range(episodes):
            o, _ = env.reset(seed=first_seed + e)
            agent = ScriptedAgent(first_seed + e)
            agent.reset()
            if model is not None:
                model.set_random_seed(first_seed + e)
            done = False
            while not done:
                before = dict(agent._wait)
                call = agent.step(env.timestep)
                action = encode(call)
                if action is None:
                    name = _F[call.function].name
                    dropped[name] = dropped.get(name, 0) + 1
                    action = NO_OP
                played = action
                if model is not None:
                    played = model.predict(o, action_masks=env.action_masks(),
                                           deterministic=deterministic)[0]
                obs.append(o)
                masks.append(env.action_masks())
                chosen.append(action)
                episode.append(e)
                o, _, done, _, info = env.step(played)
                if model is not None and int(played[0]) != int(action[0]):
                    agent._macro, agent._wait = None, before
                    timer = TIMERS.get(info["action"])
                    if timer is not None and not info["invalid"]:
                        agent._wait[timer[0]] = agent.steps + timer[1]
            marines.append(int(info["marines"]))
    finally:
        env.close()
    demos = Demonstrations({k: np.stack([x[k] for x in obs]) for k in obs[0]}, np.stack(masks),
                           np.stack(chosen), np.zeros(len(chosen), np.float32), marines,
                           np.asarray(episode, np.int64))
    return demos, dropped


def accuracy(policy: Any, demos: Demonstrations, idx: np.ndarray) -> dict[str, float]:
    """Per function the agent called at ``idx``: the share where the policy's most likely
    function is the same (``balanced``: their mean); ``point``: over the agent's calls with a
    point whose function the policy got right, the share of its points within :data:`NEAR`
    pixels (``point_exact``: on the agent's very pixel)."""
    best, truth = predictions(policy, demos, idx), demos.actions[idx]
    out = {name: float(np.mean(best[truth[:, 0] == i, 0] == i))
           for i, name in enumerate(PAPER_FUNCTIONS) if (truth[:, 0] == i).any()}
    out["balanced"] = float(np.mean(list(out.values()))) if out else float("nan")
    takes = np.isin(truth[:, 0], [PAPER_FUNCTIONS.index(n) for n in POINT_FUNCTIONS])
    right = takes & (best[:, 0] == truth[:, 0])
    near = np.abs(best[:, 1:] - truth[:, 1:]).max(axis=1) <= NEAR
    out["point"] = float(np.mean(near[right])) if right.any() else float("nan")
    exact = (best[:, 1:] == truth[:, 1:]).all(axis=1)
    out["point_exact"] = float(np.mean(exact[right])) if right.any() else float("nan")
    return out


def fit(policy: Any, demos: Demonstrations, train: np.ndarray, test: np.ndarray, epochs: int,
        lr: float, seed: int, balanced: bool) -> list[dict[str, float]]:
    """Maximum likelihood of the agent's actions under the masks; per epoch the mean negative
    log-likelihood and :func:`accuracy` (balanced, point) on both parts."""
    opt = policy_optimizer(policy, lr)
    rng = np.random.default_rng(seed)
    functions = demos.actions[:, 0]
    weight = class_weights(functions, train, len(PAPER_FUNCTIONS), balanced)
    log = []
    for epoch in range(epochs):
        nll = likelihood_epoch(policy, opt, demos, train, weight, functions, rng)
        a, b = accuracy(policy, demos, train), accuracy(policy, demos, test)
        row = {"epoch": epoch + 1, "nll": nll,
               "train_balanced": a["balanced"], "held_out_balanced": b["balanced"],
               "train_point": a["point"], "held_out_point": b["point"]}
        log.append(row)
        print(f"epoch {row['epoch']:3d}  nll {row['nll']:.3f}  balanced accuracy train "
              f"{a['balanced']:.3f} held out {b['balanced']:.3f}  point within {NEAR} px "
              f"train {a['point']:.3f} held out {b['point']:.3f}", flush=True)
    return log


def dagger_episodes(model: Any, cfg: Any, r: int, episodes: int
                    ) -> tuple[Demonstrations, dict[str, list[int]], float]:
    """Round ``r``'s episodes of the clone (argmax on even ones, sampled on odd), every state
    labelled by the scripted agent (:func:`demonstrate`); the marines of each mode and how often
    the clone's most likely function was the label's (``clone_rules.dagger`` runs the rounds)."""
    played: dict[str, list[int]] = {"argmax": [], "sampled": []}
    new = None
    for e in range(episodes):
        mode = "argmax" if e % 2 == 0 else "sampled"
        d, _ = demonstrate(cfg, 1, DAGGER_SEED + 1000 * r + e, model, mode == "argmax")
        played[mode] += d.marines
        new = d if new is None else joined(new, d)
    assert new is not None
    agree = float(np.mean(predictions(model.policy, new, np.arange(len(new.actions)))[:, 0]
                          == new.actions[:, 0]))
    return new, played, agree


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a paper-space run whose settings the clone takes")
    add_options(ap, epochs=20, lr=1e-3, dagger_episodes=4, dagger_epochs=5, unit="function")
    args = ap.parse_args()
    cfg = checked_config(args, "clone_scripted.py", "paper", "the clone plays the paper space")
    cfg = dataclasses.replace(cfg, envs=1, processes=0, reward="sparse", shaping="event",
                              mem=None, narration=None)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    demos, dropped = demonstrate(cfg, args.episodes)
    train, test = split(demos, args.held_out)
    shares = {name: round(float(np.mean(demos.actions[:, 0] == i)), 4)
              for i, name in enumerate(PAPER_FUNCTIONS)}
    print(f"scripted: {len(demos.actions)} decisions over {args.episodes} episodes, "
          f"{np.mean(demos.marines):.1f} marines an episode ({time.perf_counter() - t0:.0f} s); "
          f"calls {shares}; sent as no_op {dropped}", flush=True)
    model, demos, before, after, log, rounds = clone(cfg, demos, train, test, args, accuracy,
                                                     fit, dagger_episodes)
    record = {"like": str(args.run), "episodes": args.episodes, "held_out": args.held_out,
              "decisions": int(len(demos.actions)), "scripted_marines": demos.marines,
              "scripted_calls": shares, "sent_as_no_op": dropped, "epochs": args.epochs,
              "lr": args.lr, "balanced": args.balanced, "untrained_held_out": before,
              "cloned_held_out": after, "log": log,
              "dagger": {"rounds": rounds, "episodes": args.dagger_episodes,
                         "epochs": args.dagger_epochs, "lr": args.dagger_lr}}
    write_clone(args.out, cfg, model, record)
    print(f"wrote {args.out} ({time.perf_counter() - t0:.0f} s); next: sc2data rl evaluate "
          f"{args.out}")


if __name__ == "__main__":
    main()
