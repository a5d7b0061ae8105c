"""The policy's feature extractors: small CNNs over the observation's images plus its vector.

:class:`StateExtractor` reads the ``stored`` observation (:mod:`sc2data.rl.obs`),
:class:`CompactExtractor` the ``compact`` one (and is the trunk of the paper space's
:class:`~sc2data.rl.spatial.PaperPolicy`). SB3's default ``CombinedExtractor`` would flatten every
64×64 layer into one MLP input (80k
inputs with the paper's layers). Instead each layer is scaled to [0, 1] by its pysc2 scale,
screen and minimap layers go through their own two-layer strided CNN (64 → 16 → 8 pixels), and
the non-spatial vectors through ``log1p`` and a linear layer; the three are concatenated and
mapped to ``features_dim``.
"""

from __future__ import annotations

import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from sc2data.schema import layer


def _cnn(channels: int) -> nn.Sequential:
    # 4×4 cells first (64 → 16), then 3×3 stride 2 (→ 8): the first convolution is where the
    # time goes, and a 5×5 stride-2 one over 64×64 made PPO's updates 3× slower per decision
    # (cProfile of `sc2data rl train`: backward 260 ms a minibatch of 64 on a loaded core).
    return nn.Sequential(
        nn.Conv2d(channels, 16, 4, stride=4), nn.ReLU(),
        nn.Conv2d(16, 32, 3, stride=2, padding=1), nn.ReLU(),
        nn.AdaptiveAvgPool2d(8), nn.Flatten())


class StateExtractor(BaseFeaturesExtractor):
    """Features of a ``BuildMarinesGym`` observation (see the module docstring)."""

    def __init__(self, observation_space: spaces.Dict, features_dim: int = 256) -> None:
        super().__init__(observation_space, features_dim)
        keys = list(observation_space.spaces)
        self.groups = {g: [k for k in keys if k.startswith(g + "/")] for g in ("screen", "minimap")}
        self.vectors = [k for k in keys if "/" not in k]
        for g, ks in self.groups.items():
            scale = torch.tensor([float(layer(g, k.split("/", 1)[1]).scale) for k in ks])  # type: ignore[arg-type]
            self.register_buffer(f"scale_{g}", scale.view(1, -1, 1, 1))
        self.cnns = nn.ModuleDict({g: _cnn(len(ks)) for g, ks in self.groups.items() if ks})
        n_vec = sum(int(observation_space.spaces[k].shape[0]) for k in self.vectors)  # type: ignore[index]
        self.vec = nn.Sequential(nn.Linear(n_vec, 64), nn.ReLU())
        self.head = nn.Sequential(nn.Linear(len(self.cnns) * 32 * 64 + 64, features_dim),
                                  nn.ReLU())

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        parts = []
        for g, cnn in self.cnns.items():
            x = torch.stack([obs[k].float() for k in self.groups[g]], dim=1)
            parts.append(cnn(x / getattr(self, f"scale_{g}")))
        v = torch.cat([obs[k].float().clamp(min=0) for k in self.vectors], dim=1)
        parts.append(self.vec(torch.log1p(v)))
        return self.head(torch.cat(parts, dim=1))  # type: ignore[no-any-return]


class CompactExtractor(BaseFeaturesExtractor):
    """Features of a ``compact`` observation: each image (``screen``, optionally ``minimap``)
    divided by its channels' ``scales`` (``Observer.scales``) through its own two-layer CNN
    down to 4×4×32 (an 8×8 stride-8 convolution at 64 pixels, 4×4 stride 4 at 32, to 8×8×32;
    then a 3×3 stride-2 one), the ``vector`` through a linear layer, the three mapped to
    ``features_dim``. Small on purpose: PPO's updates are most of a CPU learner's time, and
    a stride-2 first layer over 16×16 cells doubled their cost (BENCHMARKS.md, "RL at speed")."""

    def __init__(self, observation_space: spaces.Dict, features_dim: int = 256,
                 scales: dict[str, list[float]] | None = None) -> None:
        super().__init__(observation_space, features_dim)
        self.images = [k for k in ("screen", "minimap") if k in observation_space.spaces]
        self.cnns = nn.ModuleDict()
        for k in self.images:
            c, size, _ = observation_space.spaces[k].shape  # type: ignore[misc]
            scale = torch.tensor((scales or {}).get(k, [255.0] * c), dtype=torch.float32)
            self.register_buffer(f"scale_{k}", scale.view(1, -1, 1, 1))
            first = max(1, size // 8)
            self.cnns[k] = nn.Sequential(
                nn.Conv2d(c, 32, first, stride=first), nn.ReLU(),
                nn.Conv2d(32, 32, 3, stride=2, padding=1), nn.ReLU(), nn.Flatten())
        n_vec = int(observation_space.spaces["vector"].shape[0])  # type: ignore[index]
        self.vec = nn.Sequential(nn.Linear(n_vec, 64), nn.ReLU())
        self.head = nn.Sequential(nn.Linear(len(self.images) * 32 * 4 * 4 + 64, features_dim),
                                  nn.ReLU())

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        screen = self.cnns["screen"][:2](obs["screen"].float() / self.scale_screen)
        return self.head_from(screen, obs)

    def head_from(self, screen: torch.Tensor, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """The features, from the screen tower's first layer's output (``PaperPolicy`` reads
        that map too) and the rest of the observation."""
        parts = [self.cnns["screen"][2:](screen)]
        parts += [self.cnns[k](obs[k].float() / getattr(self, f"scale_{k}"))
                  for k in self.images if k != "screen"]
        parts.append(self.vec(obs["vector"].float()))
        return self.head(torch.cat(parts, dim=1))  # type: ignore[no-any-return]
