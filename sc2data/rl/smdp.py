"""Semi-MDP discounting for macro decisions: a decision that lasted k pysc2 steps is discounted γᵏ.

A macro decision waits for minerals and sends its calls, 1 to 64 pysc2 steps; discounting every
decision by γ would make a reward 60 steps away look as near as one a step away. SB3's GAE uses
one γ; :class:`SMDPRolloutBuffer` uses γᵏ (and λ as is) per decision, with k the decision's
``info["env_steps"]``, recorded by the training callback before SB3 adds the step. With every
k = 1 (the paper space) it computes exactly SB3's advantages.

    δ_t = r_t + γ^{k_t} V(s_{t+1}) (1 − done) − V(s_t)
    A_t = δ_t + γ^{k_t} λ (1 − done) A_{t+1}
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from sb3_contrib.common.maskable.buffers import MaskableDictRolloutBuffer


class SMDPRolloutBuffer(MaskableDictRolloutBuffer):
    """sb3-contrib's masked dict rollout buffer with per-decision discounts (module docstring)."""

    def reset(self) -> None:
        super().reset()
        self.steps = np.ones((self.buffer_size, self.n_envs), dtype=np.float32)
        """k: pysc2 steps each decision took (set by the callback before each ``add``)."""

    def record_steps(self, steps: Any) -> None:
        """The pysc2 steps of the decisions about to be added (one per env)."""
        if self.pos < self.buffer_size:
            self.steps[self.pos] = np.asarray(steps, dtype=np.float32)

    def compute_returns_and_advantage(self, last_values: torch.Tensor, dones: np.ndarray) -> None:
        last = last_values.clone().cpu().numpy().flatten()
        gae = np.zeros(self.n_envs, dtype=np.float32)
        for step in reversed(range(self.buffer_size)):
            if step == self.buffer_size - 1:
                not_done = 1.0 - dones.astype(np.float32)
                next_values = last
            else:
                not_done = 1.0 - self.episode_starts[step + 1]
                next_values = self.values[step + 1]
            discount = self.gamma ** self.steps[step]
            delta = self.rewards[step] + discount * next_values * not_done - self.values[step]
            gae = delta + discount * self.gae_lambda * not_done * gae
            self.advantages[step] = gae
        self.returns = self.advantages + self.values
