"""A behaviour-cloning start for the macro space: the macro-rules agent's play, cloned into a new
policy before PPO (``sc2data rl train --imitate N``).

PPO from a random policy learns, in the macro space, a fixed ranking of the macros that only the
action mask moves (BENCHMARKS.md, "Far sites, 10 seeds"): argmax play then repeats one macro and
makes no marine. The field's usual remedy is to start from demonstrations — AlphaStar's
supervised start, kickstarting (Schmitt et al. 2018), DQfD — and to let RL go on from there.
Here the demonstrator is :class:`~sc2data.game.agents.MacroRulesAgent`, the scripted agent's
rules within the six macros, asked at each decision of the run's own environment
(:class:`~sc2data.rl.envs.BuildMarinesGym` with the run's observation, sites, merged waits and
episode length) which macro it would start; the env plays that macro as it plays the policy's.

:func:`demonstrate` records the observation, the action mask, the rules' macro and the game's
discounted return of every decision (γ per pysc2 step with ``--smdp``, as PPO's own advantage
estimate discounts); :func:`clone` fits the new policy to them — the masked cross-entropy of the
rules' macro plus ``vf_coef`` × the value's squared error on those returns, with PPO's optimiser
and gradient clipping — so that PPO's first updates start with a value function that is not
noise. The return is the game's (marines) whatever the run's reward: the shaping bonus is
learned by PPO. Demonstration episodes are seeded from :data:`DEMO_SEED`, a range neither
training nor evaluation uses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.vocab import STEP_MUL

DEMO_SEED = 500_000_000
"""Demonstration episode ``e`` of a run of seed ``s`` resets the env with
``DEMO_SEED + 1000·s + e`` (training uses seeds below 1,000,000, evaluation 1,000,000 on)."""

TEACHER = "macro-rules"

LEARNING_RATE = 1e-3
"""Adam's step size when cloning (an optimiser of its own; PPO's starts afresh after)."""


@dataclass
class Demonstrations:
    """The teacher's decisions: ``n`` of them over ``len(marines)`` episodes."""

    obs: dict[str, np.ndarray]
    """Each observation key stacked, ``(n, …)``."""
    masks: np.ndarray
    """``(n, 6)`` bool: the macros allowed at each decision."""
    actions: np.ndarray
    """``(n,)`` int64: the macro the rules chose."""
    returns: np.ndarray
    """``(n,)`` float32: the game's discounted return from each decision on."""
    marines: list[int]
    """Marines the teacher made, per episode."""


def check(cfg: Any) -> None:
    """One-line error unless ``cfg`` (an :class:`~sc2data.rl.train.RLConfig`) can be cloned."""
    if cfg.imitate < 0:
        raise Sc2DataError("--imitate must be 0 or more (episodes of the macro-rules agent)")
    if cfg.imitate and cfg.action_space != "macro":
        raise Sc2DataError("--imitate clones the macro-rules agent: it goes with "
                           "--action-space macro")
    if cfg.imitate_epochs < 1:
        raise Sc2DataError("--imitate-epochs must be at least 1")


def demonstrate(cfg: Any, episodes: int) -> Demonstrations:
    """Play ``episodes`` of the run's macro-space env with the macro-rules agent choosing."""
    from sc2data.game.agents import MacroRulesAgent
    from sc2data.rl.envs import BuildMarinesGym
    from sc2data.rl.obs import MACROS
    from sc2data.rl.train import game_loops

    env = BuildMarinesGym("macro", backend=cfg.backend, obs=cfg.obs_config(),
                          game_loops=game_loops(cfg), merge_waits=cfg.merge_waits,
                          sites=cfg.macro_sites)
    teacher = MacroRulesAgent(cfg.seed, sites=cfg.macro_sites)
    obs: list[dict[str, np.ndarray]] = []
    masks: list[np.ndarray] = []
    chosen: list[int] = []
    returns: list[float] = []
    marines: list[int] = []
    try:
        for e in range(episodes):
            o, info = env.reset(seed=DEMO_SEED + 1000 * cfg.seed + e)
            teacher.reset()
            rewards: list[float] = []
            steps: list[int] = []
            done = False
            while not done:
                mask = env.action_masks()
                teacher.view = env.view
                teacher.steps = info["game_loop"] // STEP_MUL
                action = MACROS.index(teacher.choose())
                obs.append(o)
                masks.append(mask)
                chosen.append(action)
                o, reward, done, _, info = env.step(action)
                rewards.append(float(reward))
                steps.append(int(info["env_steps"]) if cfg.smdp else 1)
            returns.extend(_returns(rewards, steps, cfg.gamma))
            marines.append(int(info["marines"]))
    finally:
        env.close()
    return Demonstrations(
        obs={k: np.stack([x[k] for x in obs]) for k in obs[0]},
        masks=np.stack(masks), actions=np.asarray(chosen, np.int64),
        returns=np.asarray(returns, np.float32), marines=marines)


def _returns(rewards: list[float], steps: list[int], gamma: float) -> list[float]:
    """``G_t = r_t + γ^{k_t} G_{t+1}``: the return from each decision of one episode."""
    out = [0.0] * len(rewards)
    g = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        g = rewards[t] + gamma ** steps[t] * g
        out[t] = g
    return out


def clone(model: Any, demos: Demonstrations, epochs: int, seed: int,
          reward_scale: float = 1.0) -> dict[str, float]:
    """Fit ``model``'s policy (a MaskablePPO) to ``demos`` for ``epochs`` passes, its value to
    the returns × ``reward_scale`` (the run's: what PPO's value will predict); returns the
    figures of the last pass: cross-entropy, value error, and how often the policy's most likely
    allowed macro is the rules' (``agreement``)."""
    import torch

    policy = model.policy
    policy.set_training_mode(True)
    n = len(demos.actions)
    rng = np.random.default_rng(seed)
    device = policy.device
    as_tensor = lambda a: torch.as_tensor(a, device=device)  # noqa: E731
    figures: dict[str, float] = {}
    optimizer = torch.optim.Adam(policy.parameters(), lr=LEARNING_RATE)
    for _ in range(epochs):
        ce = vf = agree = 0.0
        for idx in np.array_split(rng.permutation(n), max(1, n // model.batch_size)):
            obs = {k: as_tensor(v[idx]).float() for k, v in demos.obs.items()}
            masks = demos.masks[idx]
            actions = as_tensor(demos.actions[idx])
            values, log_prob, _ = policy.evaluate_actions(obs, actions, action_masks=masks)
            target = as_tensor(demos.returns[idx] * reward_scale)
            value_loss = torch.nn.functional.mse_loss(values.flatten(), target)
            loss = -log_prob.mean() + model.vf_coef * value_loss
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            with torch.no_grad():
                logits = policy.get_distribution(obs, action_masks=masks).distribution.logits
            agree += float((logits.argmax(-1) == actions).float().sum())
            ce -= float(log_prob.detach().sum())
            vf += float(value_loss.detach()) * len(idx)
        figures = {"cross_entropy": ce / n, "value_mse": vf / n, "agreement": agree / n}
    policy.set_training_mode(False)
    return figures
