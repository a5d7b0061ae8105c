"""How much of PPO's clipped gradient is the value loss's: a run's policy at its start and at its
end, on the trained policy's own states (and, in the macro space, the macro-rules agent's).

SB3's PPO clips one gradient norm (``--max-grad-norm``, 0.5 by default) over the policy loss, the
entropy bonus and ``--vf-coef`` × the value loss together. When the value's part is much the
larger, clipping shrinks the policy's step with it. This script measures, per minibatch of 256
decisions, the norm of each part's gradient at the start of an update (probability ratio 1), the
factor the clip multiplies the step by, and so the policy's share of what moves the weights —
for the run's own ``--reward-scale`` and, for the initial policy, others given with
``--scales``.

The states are the trained policy's own (sampled) and, in the macro space, the macro-rules
agent's on the run's env (:func:`demonstrate`: the agent asked at each decision which macro it
would start, the env playing it), on episodes seeded apart from training and evaluation; the
advantages are the discounted game returns from each decision less the value's estimate,
normalised per minibatch where the run does (``--normalize-advantage``).

    python benchmarks/ppo_gradients.py RUN [--episodes 2] [--scales 1 0.01]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import torch

from sc2data.game.agents import MacroRulesAgent
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.vocab import STEP_MUL
from sc2data.rl import runs
from sc2data.rl.envs import BuildMarinesGym
from sc2data.rl.obs import MACROS
from sc2data.rl.train import RLConfig, game_loops, load_config, make_vec_env, new_model

DEMO_SEED = 500_000_000
"""Episode ``e`` resets the env with ``DEMO_SEED + e`` (training seeds lie below 1,000,000,
evaluation's from 1,000,000)."""


@dataclasses.dataclass
class Demonstrations:
    """An agent's decisions on the run's env, each key stacked ``(n, …)``."""

    obs: dict[str, np.ndarray]
    masks: np.ndarray
    actions: np.ndarray
    returns: np.ndarray
    """The game's return from each decision on, γ per pysc2 step (``--smdp``) or per decision."""
    marines: list[int]
    episodes: np.ndarray
    """Which episode (0-based) each decision is of."""


def demonstrate(cfg: RLConfig, episodes: int, model: Any = None, *, label: bool = False,
                deterministic: bool = False, first_seed: int = DEMO_SEED) -> Demonstrations:
    """Play ``episodes`` of the run's env (episode ``e`` seeded ``first_seed + e``) with the
    macro-rules agent choosing (macro space), or ``model``'s policy when given (argmax with
    ``deterministic``, else sampled). ``label`` (with ``model``): the policy plays and each
    decision records the macro the rules would choose there instead (DAgger's labels), the
    rules' timers read from the policy's own choices (when it last chose each macro)."""
    env = BuildMarinesGym(cfg.action_space, backend=cfg.backend, obs=cfg.obs_config(),
                          game_loops=game_loops(cfg), merge_waits=cfg.merge_waits,
                          sites=cfg.macro_sites)
    agent = MacroRulesAgent(0, sites=cfg.macro_sites)
    obs, masks, chosen, returns, marines, episode = [], [], [], [], [], []
    try:
        for e in range(episodes):
            o, info = env.reset(seed=first_seed + e)
            agent.reset()
            if model is not None:
                model.set_random_seed(first_seed + e)
            rewards, steps, done = [], [], False
            last: dict[str, int] = {}  # the policy's choices, as the rules keep their own
            while not done:
                step = info["game_loop"] // STEP_MUL
                if model is None:
                    agent.view, agent.steps = env.view, step
                    played = action = MACROS.index(agent.choose())
                else:
                    played = action = int(model.predict(o, action_masks=env.action_masks(),
                                                        deterministic=deterministic)[0])
                    if label:  # the rules' timers set to the policy's history, then asked
                        agent.view, agent.steps, agent._last = env.view, step, dict(last)
                        action = MACROS.index(agent.choose())
                    last[MACROS[played]] = step
                obs.append(o)
                masks.append(env.action_masks())
                chosen.append(action)
                episode.append(e)
                o, reward, done, _, info = env.step(played)
                rewards.append(float(reward))
                steps.append(int(info["env_steps"]) if cfg.smdp else 1)
            g, back = 0.0, []
            for r, k in zip(reversed(rewards), reversed(steps), strict=True):
                g = r + cfg.gamma ** k * g
                back.append(g)
            returns += back[::-1]
            marines.append(int(info["marines"]))
    finally:
        env.close()
    return Demonstrations({k: np.stack([x[k] for x in obs]) for k in obs[0]}, np.stack(masks),
                          np.asarray(chosen, np.int64), np.asarray(returns, np.float32), marines,
                          np.asarray(episode, np.int64))


def joined(a: Demonstrations, b: Demonstrations) -> Demonstrations:
    """``a``'s decisions then ``b``'s (``b``'s episodes numbered after ``a``'s)."""
    return Demonstrations({k: np.concatenate([a.obs[k], b.obs[k]]) for k in a.obs},
                          np.concatenate([a.masks, b.masks]),
                          np.concatenate([a.actions, b.actions]),
                          np.concatenate([a.returns, b.returns]), a.marines + b.marines,
                          np.concatenate([a.episodes, b.episodes + len(a.marines)]))


def norm(loss: torch.Tensor, params: list[torch.nn.Parameter]) -> float:
    grads = torch.autograd.grad(loss, params, retain_graph=True, allow_unused=True)
    return float(torch.sqrt(sum((g ** 2).sum() for g in grads if g is not None)))


def shares(model: object, demos: Demonstrations, scale: float,
           batch: int = 256) -> dict[str, float]:
    """Median over minibatches of each part's gradient norm and the clip's factor."""
    policy = model.policy  # type: ignore[attr-defined]
    params = [p for p in policy.parameters() if p.requires_grad]
    rows = []
    order = np.random.default_rng(0).permutation(len(demos.actions))
    for idx in np.array_split(order, max(1, len(order) // batch)):
        obs = {k: torch.as_tensor(v[idx]).float() for k, v in demos.obs.items()}
        values, log_prob, entropy = policy.evaluate_actions(
            obs, torch.as_tensor(demos.actions[idx]), action_masks=demos.masks[idx])
        values = values.flatten()
        target = torch.as_tensor(demos.returns[idx] * scale)
        adv = target - values.detach()
        if model.normalize_advantage:  # type: ignore[attr-defined]
            adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        ratio = torch.exp(log_prob - log_prob.detach())
        pg = -(adv * ratio).mean() - model.ent_coef * entropy.mean()  # type: ignore[attr-defined]
        vf = model.vf_coef * torch.nn.functional.mse_loss(values, target)  # type: ignore[attr-defined]
        g_pi, g_vf, g_all = norm(pg, params), norm(vf, params), norm(pg + vf, params)
        clip = min(1.0, model.max_grad_norm / g_all)  # type: ignore[attr-defined]
        rows.append((g_pi, g_vf, g_all, clip, g_pi * clip))
    med = np.median(np.array(rows), axis=0)
    return dict(zip(("policy", "value", "total", "clip", "policy_after_clip"),
                    (float(x) for x in med)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--episodes", type=int, default=2)
    ap.add_argument("--scales", type=float, nargs="*", default=[])
    args = ap.parse_args()
    if args.episodes < 1 or any(not 0 < x < float("inf") for x in args.scales):
        raise SystemExit("ppo_gradients.py: --episodes must be at least 1 and --scales positive")
    try:
        cfg = load_config(args.run)
    except Sc2DataError as e:
        raise SystemExit(f"ppo_gradients.py: {e}") from None
    # The game's reward only: the returns are the game's whatever the run was shaped with.
    cfg = dataclasses.replace(cfg, envs=1, processes=0, reward="sparse", shaping="event",
                              mem=None, narration=None)
    vec = make_vec_env(cfg)
    try:
        models = {"initial": new_model(cfg, vec, cfg.seed),
                  "trained": runs.load_model(args.run, vec)}
        states = {"the trained policy's": demonstrate(cfg, args.episodes, models["trained"])}
        if cfg.action_space == "macro":
            states = {"the rules'": demonstrate(cfg, args.episodes), **states}
        for name, demos in states.items():
            print(f"{name} states: {len(demos.actions)} decisions, "
                  f"{np.mean(demos.marines):.1f} marines an episode; returns up to "
                  f"{demos.returns.max():.1f}")
        print("| policy | states | reward scale | ‖∇ policy loss‖ | ‖∇ value loss‖ | clip factor "
              "| policy's step after the clip |")
        print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
        for name, model in models.items():  # a trained value predicts its own scale only
            for where, demos in states.items():
                for scale in [cfg.reward_scale, *(args.scales if name == "initial" else [])]:
                    s = shares(model, demos, scale)
                    print(f"| {name} | {where} | {scale:g} | {s['policy']:.3f} | "
                          f"{s['value']:.3f} | {s['clip']:.4f} | {s['policy_after_clip']:.4f} |")
    finally:
        vec.close()


if __name__ == "__main__":
    main()
