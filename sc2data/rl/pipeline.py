"""Pipelined rollouts: the learner acts for one group of games while another group steps.

MaskablePPO collects a rollout in lockstep: the policy acts for every game, then every game
steps while the learner waits, then the reward is scored for every game while the games wait.
:class:`PipelinedPPO` splits the games into ``groups`` contiguous parts (as the worker processes
hold them, :func:`~sc2data.rl.vector.spans`) and takes them in turn: while group 0's games step
in their worker, the learner waits for group 1's and acts for it, and so on — Sample Factory's
double-buffered sampling. The reward of every group is scored once a vector step, after the
last group's next decision is sent (one MEM call of all the games' stacks, the frames copied
aside: :meth:`~sc2data.rl.vector.BuildMarinesVecEnv.score_waited`), while the groups step
again. The learner's work and the games' then overlap instead of adding up (BENCHMARKS.md,
"Pipelined rollouts" and "Fewer copies in the update, one MEM call a vector step").

The data are what lockstep collects: every decision of a rollout is taken by that rollout's
policy, a rollout has the same decisions, and the buffer, the callback and the update see one
row per vector step, every game in order. What differs is the order of the random draws (the
policy samples a group at a time), so ``groups`` is part of a run's settings, and the same seed
and the same ``groups`` give the same run whatever the worker processes are. (SB3's bootstrap of
a game cut by a time limit has nothing to do here: a BuildMarines game ends by the map's own
timer, the true end of its episode, never reported as a truncation.)
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from sb3_contrib import MaskablePPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.utils import obs_as_tensor

from sc2data.rl.spatial import PointDistribution
from sc2data.rl.vector import spans


def masked_kl(p: Any, q: Any) -> th.Tensor:
    """KL(p ‖ q) per sample between two masked distributions of one action space: sb3-contrib's
    categoricals (a multi-categorical sums over its heads), or the paper policy's joint
    function-and-point distribution (its own ``kl``). Actions the mask rules out have
    probability 0 under both and add nothing."""
    if isinstance(p, PointDistribution):
        return p.kl(q)
    ps = getattr(p, "distributions", None) or [p.distribution]
    qs = getattr(q, "distributions", None) or [q.distribution]
    total = th.zeros(ps[0].probs.shape[0], device=ps[0].probs.device)
    for a, b in zip(ps, qs):
        allowed = a.probs > 0
        terms = a.probs * (a.logits - b.logits)
        total = total + th.where(allowed, terms, th.zeros_like(terms)).sum(-1)
    return total


class PipelinedPPO(MaskablePPO):
    """MaskablePPO that collects its rollouts a group of games at a time (module docstring) on
    an env with ``step_async_rows``/``step_wait_rows``
    (:class:`~sc2data.rl.vector.BuildMarinesVecEnv`); with one group, or on any other env,
    MaskablePPO's own collection."""

    groups: int = 1
    """Groups of games (set after building or loading: it is not saved with the model)."""
    teacher: Any = None
    """A policy to stay near (``rl train --kickstart``; set after building or loading)."""
    kickstart_coef: float = 1.0
    """Weight of the KL to :attr:`teacher`."""

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "groups", "teacher", "kickstart_coef"]

    def train(self) -> None:
        """PPO's update, then with a :attr:`teacher` one pass over the rollout lowering
        ``kickstart_coef`` × KL(teacher ‖ policy) on its states, under its masks."""
        super().train()
        if self.teacher is not None:
            self._kickstart()

    def _kickstart(self) -> None:
        self.policy.set_training_mode(True)
        kls = []
        for data in self.rollout_buffer.get(self.batch_size):
            with th.no_grad():
                teacher = self.teacher.get_distribution(data.observations, data.action_masks)
            student = self.policy.get_distribution(data.observations, data.action_masks)
            kl = masked_kl(teacher, student).mean()
            self.policy.optimizer.zero_grad()
            (self.kickstart_coef * kl).backward()
            th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
            kls.append(kl.item())
        self.logger.record("train/kickstart_kl", float(np.mean(kls)))

    def collect_rollouts(self, env: Any, callback: BaseCallback, rollout_buffer: Any,
                         n_rollout_steps: int, use_masking: bool = True) -> bool:
        parts = spans(env.num_envs, min(self.groups, env.num_envs))
        if len(parts) < 2 or not use_masking or not hasattr(env, "step_async_rows"):
            return bool(super().collect_rollouts(env, callback, rollout_buffer,
                                                 n_rollout_steps, use_masking))
        threads = th.get_num_threads()
        th.set_num_threads(1)  # the other cores step the games meanwhile; the update has them all
        try:
            return self._collect(env, parts, callback, rollout_buffer, n_rollout_steps)
        finally:
            th.set_num_threads(threads)

    def _collect(self, env: Any, parts: list[tuple[int, int]], callback: BaseCallback,
                 rollout_buffer: Any, n_rollout_steps: int) -> bool:
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        rollout_buffer.reset()
        callback.on_rollout_start()
        obs: dict[str, np.ndarray] = self._last_obs  # type: ignore[assignment]
        masks = env.action_masks()
        taking = [self._act(env, lo, hi, {k: v[lo:hi] for k, v in obs.items()}, masks[lo:hi])
                  for lo, hi in parts]  # each group's decision, stepping
        for n_steps in range(n_rollout_steps):
            last = n_steps == n_rollout_steps - 1
            stepped, taken = [], taking
            taking = []
            for lo, hi in parts:
                part_obs, _ = env.step_wait_rows_unscored(lo, hi)
                part_masks = env.action_masks(lo, hi)
                stepped.append((part_obs, part_masks))
                if not last:  # the group's next decision, taken while the next group steps
                    taking.append(self._act(env, lo, hi, part_obs, part_masks))
            # Every group's reward in one call (one MEM call of all the games' stacks), while
            # the groups step again: rewards are not read before the buffer takes them.
            rewards, dones, infos = env.score_waited()
            actions = np.concatenate([a for a, _, _ in taken])
            values = th.cat([v for _, v, _ in taken])
            log_probs = th.cat([p for _, _, p in taken])
            new_obs = {k: np.concatenate([s[0][k] for s in stepped]) for k in obs}
            self.num_timesteps += env.num_envs
            callback.update_locals(locals())
            if not callback.on_step():
                for lo, hi in parts[:len(taking)]:  # nothing left stepping
                    env.step_wait_rows(lo, hi)
                return False
            self._update_info_buffer(infos, dones)
            rollout_buffer.add(self._last_obs, actions.reshape(env.num_envs, -1), rewards,
                               self._last_episode_starts, values, log_probs,
                               action_masks=masks)
            self._last_obs = obs = new_obs  # type: ignore[assignment]
            self._last_episode_starts = dones
            masks = np.concatenate([s[1] for s in stepped])
        with th.no_grad():
            values = self.policy.predict_values(obs_as_tensor(obs, self.device))  # type: ignore[arg-type]
        rollout_buffer.compute_returns_and_advantage(last_values=values, dones=dones)
        callback.on_rollout_end()
        return True

    def _act(self, env: Any, lo: int, hi: int, obs: dict[str, np.ndarray], masks: np.ndarray
             ) -> tuple[np.ndarray, th.Tensor, th.Tensor]:
        """The policy's decision for games ``lo`` to ``hi``, sent to step."""
        with th.no_grad():
            actions, values, log_probs = self.policy(obs_as_tensor(obs, self.device),  # type: ignore[arg-type]
                                                     action_masks=masks)
        taken = actions.cpu().numpy()
        env.step_async_rows(lo, hi, taken)
        return taken, values, log_probs
