"""The paper space's policy: a pysc2 function, then its screen point *given* the function.

SC2LE (Vinyals et al. 2017) chooses a function, then each argument given the function; a screen
point comes from a convolutional map with one logit per pixel, so one distribution can put mass
on several units ("click this SCV or that one"). :class:`PaperPolicy` does that, small:

* a trunk over the ``compact`` observation (:class:`~sc2data.rl.policy.CompactExtractor`'s: an
  S/8 stride-S/8 convolution to 8×8×32, a 3×3 stride-2 one to 4×4×32, the vector, a linear layer
  to 256 features) gives the function logits (masked by ``available_actions``) and the value;
* for each of the functions that take a screen point (:data:`POINT_FUNCTIONS`) a map of logits at
  the observation's resolution (S×S cells of 64/S pixels): a *fine* term, a 1×1 convolution over
  the observation's channels (where SCVs, minerals, free ground are), plus a *coarse* one, a 1×1
  convolution over the trunk's 8×8 map plus a learnt 8×8 preference given the features,
  upsampled to S×S. With the ``cell`` point head a pixel's probability is its cell's shared
  evenly by the cell's pixels: at S = 32 the maps are a quarter of 64×64's cost. With ``pixel``
  a 3×3 convolution over the observation gives each cell's 64/S × 64/S pixels a logit of their
  own (the sub-pixel convolution of Shi et al. 2016: its (64/S)² channels rearranged into the
  cell), added to the cell's, so the map is one logit per screen pixel: the cell cannot tell its
  pixels apart, but its neighbours can ("the mineral field is to the left"), and the most likely
  point is a pixel the policy chose, not a cell's centre (which was an SCV beside the mineral the
  scripted agent clicks: BENCHMARKS.md, "PPO held near the scripted agent's clone"). The
  ``pixel`` head also learns a preference of its own for every pixel per function (at any S): the
  other terms see what is under a pixel, not where it is, so free ground ties and the first such
  pixel, on the screen's top edge, was the most likely depot site. With the convolution and the
  preferences zero it is the ``cell`` head exactly;
* :class:`PointDistribution`: ``log π(a) = log π(f) + [f takes a point] · log π(x, y | f)`` and
  entropy ``H(f) + Σ_f π(f) H(x, y | f)``: an argument the chosen function ignores counts in
  neither (the value is the joint entropy; its gradient holds π(f) fixed in the second term, so
  the bonus does not favour functions for having a point to spread). The most likely action is
  the most likely function and, for it, the centre of its most likely cell (a pixel, with the
  ``pixel`` head).

The env's action stays ``MultiDiscrete([10, 64, 64])``: ``(function, x, y)``, x the column and y
the row, as :func:`~sc2data.rl.envs.paper_call` reads it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib.common.maskable.policies import MaskableMultiInputActorCriticPolicy
from stable_baselines3.common.preprocessing import preprocess_obs
from torch import nn
from torch.nn import functional as F

from sc2data.ground.vocab import SCREEN_SIZE
from sc2data.rl.envs import PAPER_FUNCTIONS
from sc2data.rl.policy import CompactExtractor

POINT_FUNCTIONS: tuple[str, ...] = ("select_point", "select_rect", "Build_SupplyDepot_screen",
                                    "Build_Barracks_screen", "Harvest_Gather_screen")
"""The paper functions whose call takes a screen point (:func:`~sc2data.rl.envs.paper_call`)."""

_N = SCREEN_SIZE
_COARSE = 8
_POINT_COLUMNS = [PAPER_FUNCTIONS.index(n) for n in POINT_FUNCTIONS]
"""The columns of the function logits whose function takes a point, in POINT_FUNCTIONS' order."""


def sample(logits: torch.Tensor) -> torch.Tensor:
    """One index per row, drawn with probability ``softmax(logits)`` by inverting the CDF: one
    uniform number a row (``torch.distributions.Categorical`` draws one exponential per entry,
    1,024 a point map, and took a quarter of a policy call at 8 games: BENCHMARKS.md,
    "Pipelined rollouts"). An entry of probability 0 (a masked function) is never drawn."""
    cdf = F.softmax(logits, dim=1).cumsum(dim=1)
    u = torch.rand(len(cdf), 1, device=cdf.device, dtype=cdf.dtype) * cdf[:, -1:]
    # right=True: the first entry whose cumulative probability exceeds u, so one that adds
    # nothing to the sum (probability 0) is never it; u < the total keeps it in range.
    return torch.searchsorted(cdf, u, right=True).squeeze(1).clamp(max=cdf.shape[1] - 1)


class PointDistribution:
    """The joint distribution of ``(function, x, y)`` (see the module docstring), with
    sb3-contrib's masked-distribution methods."""

    def __init__(self, function_logits: torch.Tensor, point_logits: torch.Tensor,
                 side: int | None = None) -> None:
        self.function_logits = function_logits
        """(B, functions)"""
        self.point_logits = point_logits
        """(B, point functions, K): K = S·S, one logit per cell of 64/S × 64/S pixels (its
        pixels share it evenly), or K = 64·64, one per pixel, ordered by the pixel's place in
        its cell, then the cell: index ``(dy·c + dx)·S·S + cell`` (at S = 64: row-major)"""
        self.side = side or int(round(point_logits.shape[2] ** 0.5))
        """S: cells a side"""
        self.cell = _N // self.side
        """c: pixels a cell's side"""
        self.per_pixel = point_logits.shape[2] == _N * _N
        """whether the maps have a logit per pixel (else per cell)"""
        n = function_logits.shape[1]
        slot = torch.full((n,), -1, dtype=torch.long)
        for j, name in enumerate(POINT_FUNCTIONS):
            slot[PAPER_FUNCTIONS.index(name)] = j
        self.slot = slot.to(function_logits.device)
        """function index → its point map, or -1"""

    @property
    def _share(self) -> float:
        """log of the pixels sharing each entry of the maps (0 when each entry is a pixel)."""
        return 0.0 if self.per_pixel else 2.0 * float(np.log(self.cell))

    def apply_masking(self, masks: Any) -> None:
        """Mask the functions (the first entries of sb3-contrib's per-dimension masks; the
        screen point is never masked)."""
        if masks is None:
            return
        m = torch.as_tensor(np.asarray(masks), device=self.function_logits.device)
        m = m.reshape(len(self.function_logits), -1)[:, :self.function_logits.shape[1]].bool()
        self.function_logits = torch.where(m, self.function_logits,
                                           torch.full_like(self.function_logits, -1e8))

    def _function_log_probs(self) -> torch.Tensor:
        return F.log_softmax(self.function_logits, dim=1)

    def _point_map(self, functions: torch.Tensor) -> torch.Tensor:
        """(B, S·S) logits of each row's function (zeros where it takes no point)."""
        slot = self.slot[functions]
        maps = self.point_logits.gather(1, slot.clamp(min=0)[:, None, None].expand(
            -1, 1, self.point_logits.shape[2])).squeeze(1)
        return maps * (slot >= 0)[:, None]

    def log_prob(self, actions: torch.Tensor) -> torch.Tensor:
        a = actions.long().reshape(-1, 3)
        f, x, y = a[:, 0], a[:, 1], a[:, 2]
        lp = self._function_log_probs().gather(1, f[:, None]).squeeze(1)
        c, s = self.cell, self.side
        entry = (y // c) * s + x // c
        if self.per_pixel:
            entry = entry + ((y % c) * c + x % c) * s * s
        point = F.log_softmax(self._point_map(f), dim=1).gather(1, entry[:, None]).squeeze(1)
        point = point - self._share  # a pixel's share of its entry
        return lp + point * (self.slot[f] >= 0)

    def entropy(self) -> torch.Tensor:
        logp = self._function_log_probs()
        p = logp.exp()
        h_f = -(p * logp).sum(1)
        lq = F.log_softmax(self.point_logits, dim=2)
        h_point = -(lq.exp() * lq).sum(2) + self._share  # (B, point functions)
        # π(f) held constant in the point term: each head's entropy regularises its own head.
        # Differentiated through π(f), Σ π(f)·H(x, y | f) pays the policy for choosing the
        # functions that take a point (their 4,096 pixels' entropy), whatever the reward:
        # a zero-reward control drifted to them (tests/rl/test_control.py).
        p_point = p[:, _POINT_COLUMNS].detach()
        return h_f + (p_point * h_point).sum(1)

    def kl(self, other: PointDistribution) -> torch.Tensor:
        """KL(self ‖ other) per row, of the joint distribution of ``(function, x, y)``:
        ``KL(π(f)) + Σ_f π(f) KL(π(x, y | f))`` over the functions that take a point (the
        pixel's share of its cell cancels). A function masked here has π(f) = 0 and adds
        nothing; ``other`` must allow every function this one does."""
        lp, lq = self._function_log_probs(), other._function_log_probs()
        p = lp.exp()
        on = p > 0
        total = torch.where(on, p * (lp - lq), torch.zeros_like(p)).sum(1)
        mp = F.log_softmax(self.point_logits, dim=2)
        mq = F.log_softmax(other.point_logits, dim=2)
        point_kl = (mp.exp() * (mp - mq)).sum(2)  # (B, point functions)
        p_point = p[:, _POINT_COLUMNS]
        return total + (p_point * point_kl).sum(1)

    def get_actions(self, deterministic: bool = False) -> torch.Tensor:
        c, s = self.cell, self.side
        if deterministic:  # the most likely function and entry (a cell's centre, or a pixel)
            f = self.function_logits.argmax(1)
            entry = self._point_map(f).argmax(1)
        else:
            f = sample(self.function_logits)
            entry = sample(self._point_map(f))
        if self.per_pixel:
            within, cell = entry // (s * s), entry % (s * s)
            dy, dx = within // c, within % c
        elif deterministic:
            cell, dx, dy = entry, *(torch.full_like(entry, c // 2) for _ in range(2))
        else:
            cell = entry
            dx, dy = (torch.randint(c, cell.shape, device=cell.device) for _ in range(2))
        x = (cell % s) * c + dx
        y = (cell // s) * c + dy
        return torch.stack([f, x, y], dim=1)


class PaperPolicy(MaskableMultiInputActorCriticPolicy):
    """MaskablePPO's policy for the paper space on the ``compact`` observation (see the module
    docstring). Built with ``features_extractor_class=CompactExtractor``, whose trunk it reuses;
    SB3's MLP extractor is left empty."""

    def __init__(self, *args: Any, point_head: str = "cell", **kwargs: Any) -> None:
        kwargs.setdefault("features_extractor_class", CompactExtractor)
        kwargs["net_arch"] = []
        self.point_head = point_head
        super().__init__(*args, **kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), "point_head": self.point_head}

    def _build(self, lr_schedule: Any) -> None:
        self._build_mlp_extractor()
        fe = self.features_extractor
        assert isinstance(fe, CompactExtractor), "PaperPolicy reads a compact observation"
        screen = self.observation_space["screen"]  # type: ignore[index]
        channels, size = int(screen.shape[0]), int(screen.shape[1])
        n_fn, n_pt = len(PAPER_FUNCTIONS), len(POINT_FUNCTIONS)
        self.side = size
        self.action_net = nn.Linear(fe.features_dim, n_fn)
        self.value_net = nn.Linear(fe.features_dim, 1)
        # 1×1 convolutions as matrix products: mkldnn's backward of a 13 → 5 channel 1×1
        # convolution took longer than the whole trunk (torch profiler, batch 256, one thread).
        self.fine = nn.Linear(channels, n_pt)
        self.coarse = nn.Linear(32, n_pt)
        self.where = nn.Linear(fe.features_dim, n_pt * _COARSE * _COARSE)
        c = _N // size
        pixel = self.point_head == "pixel"
        self.within = nn.Conv2d(channels, n_pt * c * c, 3, padding=1) if pixel and c > 1 else None
        # Every pixel's learnt preference per function, as the sub-pixel maps are laid out (see
        # PointDistribution.point_logits). Zero: the cell head. Without it free ground ties, and
        # argmax took the first such pixel, on the screen's top edge, as the depot's site.
        self.place = nn.Parameter(torch.zeros(n_pt, c * c, size * size)) if pixel else None
        heads = [(fe, np.sqrt(2)), (self.action_net, 0.01), (self.value_net, 1.0),
                 (self.fine, 0.01), (self.coarse, 0.01), (self.where, 0.01)]
        if self.within is not None:
            heads.append((self.within, 0.01))
        if self.ortho_init:
            for module, gain in heads:
                module.apply(lambda m, g=gain: self.init_weights(m, gain=g))
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1),
                                              **self.optimizer_kwargs)

    def _heads(self, obs: Any) -> tuple[PointDistribution, torch.Tensor]:
        x = preprocess_obs(obs, self.observation_space, normalize_images=False)
        fe: CompactExtractor = self.features_extractor  # type: ignore[assignment]
        screen = x["screen"].float() / fe.scale_screen  # type: ignore[index, operator]
        trunk = fe.cnns["screen"]
        first = torch.relu(trunk[0](screen))  # (B, 32, 8, 8)
        h = fe.head_from(first, x)
        b = len(h)
        n_pt, s, r = len(POINT_FUNCTIONS), self.side, self.side // _COARSE
        coarse = (_pointwise(self.coarse, first)
                  + self.where(h).view(b, n_pt, _COARSE, _COARSE))  # (B, P, 8, 8)
        fine = _pointwise(self.fine, screen).view(b, n_pt, _COARSE, r, _COARSE, r)
        points = (fine + coarse[:, :, :, None, :, None]).reshape(b, n_pt, 1, s * s)
        if self.within is not None:  # each cell's logit over its c×c pixels, plus theirs
            points = points + self.within(screen).view(b, n_pt, -1, s * s)
        if self.place is not None:
            points = points + self.place
        return (PointDistribution(self.action_net(h), points.flatten(2), s),
                self.value_net(h))

    def forward(self, obs: Any, deterministic: bool = False,
                action_masks: np.ndarray | None = None
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        dist, values = self._heads(obs)
        dist.apply_masking(action_masks)
        actions = dist.get_actions(deterministic=deterministic)
        return actions, values, dist.log_prob(actions)

    def evaluate_actions(self, obs: Any, actions: torch.Tensor,
                         action_masks: Any = None) -> tuple[torch.Tensor, torch.Tensor,
                                                            torch.Tensor]:
        dist, values = self._heads(obs)
        dist.apply_masking(action_masks)
        return values, dist.log_prob(actions), dist.entropy()

    def get_distribution(self, obs: Any, action_masks: np.ndarray | None = None
                         ) -> PointDistribution:  # type: ignore[override]
        dist, _ = self._heads(obs)
        dist.apply_masking(action_masks)
        return dist

    def predict_values(self, obs: Any) -> torch.Tensor:
        return self._heads(obs)[1]


def _pointwise(layer: nn.Linear, x: torch.Tensor) -> torch.Tensor:
    """A 1×1 convolution by ``layer`` of ``x`` (B, C, H, W) → (B, out, H, W), as one batched
    product with the weight broadcast over the batch. ``matmul`` of the weight and ``x`` copied
    ``x`` into (B·H·W, C) first, forward and backward: PPO's whole update took 1.37× as long
    (BENCHMARKS.md, "Fewer copies in the update, one MEM call a vector step")."""
    b, c, hh, ww = x.shape
    out = layer.weight.shape[0]
    y = torch.baddbmm(layer.bias[None, :, None].expand(b, out, hh * ww),
                      layer.weight.expand(b, out, c), x.reshape(b, c, hh * ww))
    return y.view(b, out, hh, ww)


def supports(observation_space: spaces.Space[Any]) -> bool:
    """Whether :class:`PaperPolicy` can read this observation (a compact one)."""
    return isinstance(observation_space, spaces.Dict) and "screen" in observation_space.spaces
