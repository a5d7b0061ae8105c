"""Reward wrappers: the game's sparse reward, hand-made rule shaping, and narration shaping.

Each wraps a :class:`~sc2data.rl.envs.BuildMarinesGym` (possibly under other wrappers) and reads
the pysc2 observations of the last decision from ``env.unwrapped.frames`` — ``frames[0]`` the one
before the decision, then one per pysc2 step — as two-frame stacks ``(frames[i-1], frames[i])``,
i = 1…n, the same (previous, current) stacks the rules label and the MEM was trained on. So an
event in any pysc2 step of a multi-step macro is seen, once.

Every wrapper leaves ``info["game_reward"]`` (the game's own reward: +1 per marine) untouched
and adds ``info["shaping"]`` (what it added), so agents trained on any reward are scored alike.

Shaping (``shaping``, :data:`SHAPINGS`) is paid in one of two forms:

* ``event`` — ``bonus`` each time an event fires (a rule, a narration command matched). An
  event that can be made to fire again and again (a loop) can be farmed.
* ``potential`` — potential-based shaping (Ng, Harada & Russell 1999): each decision pays
  ``F = γ·Φ(s') − Φ(s)`` for a potential Φ of the state, with ``Φ = 0`` once the episode has
  ended (the game's timer: a terminal state). Along any episode the discounted sum of F
  telescopes to ``−Φ(s_0)``, the same for every policy, so the optimal policy is the game's
  own and no loop earns anything; the bonus only tells the value function early where
  progress lies. γ is the run's ``gamma``. What Φ is for each reward is in its class.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from sc2data._pysc2 import features
from sc2data.ground.errors import Sc2DataError
from sc2data.rl.narration import Narration, check_readable
from sc2data.rulebase import Rule, schema_for, stack
from sc2data.schema import Schema, StackBatch

REWARDS: tuple[str, ...] = ("sparse", "rules", "narration", "zero")
"""``zero`` is a control: no reward at all, to see what PPO's updates do with no signal."""

SHAPINGS: tuple[str, ...] = ("event", "potential")
"""How the rules and narration rewards pay their bonus (see the module docstring)."""

_SCORE = features.ScoreCumulative
VALUE_UNIT = 50
"""Minerals of an SCV (and of a marine): the unit of :func:`progress`."""
START_VALUE = 400 + 12 * VALUE_UNIT
"""Minerals' worth the map starts the player with: a command centre and 12 SCVs."""


def progress(score_cumulative: np.ndarray) -> np.ndarray:
    """The rules reward's potential per unit of ``bonus``, from pysc2's ``score_cumulative``
    vector (last axis): the minerals' worth of the units and structures the player has made
    since the start, in SCVs (``(total_value_units + total_value_structures − 1,000) / 50``),
    plus the marines made (``score``). 0 at the start; an SCV adds 1, a supply depot 2, a
    barracks 3 (at placement, as the rules see a footprint appear), a marine 2 (its value and
    the score).

    Why this potential: it is a function of the state that the labelling rules' own inputs
    show (the score vector ``build_scv`` and ``train_marine`` read; the footprints the depot and
    barracks rules see are in the structures' value), so it rewards exactly the build order the
    rules reward, and it grows only by building — time passing, mining and selecting (the
    ``collect_minerals`` rule) leave it unchanged. A count of rule firings would depend on the
    history, not the state. Counted from the start (Φ(s_0) = 0), the episode's discounted
    shaping sums to 0 and each decision's drift ``−(1 − γ)·Φ`` is only what was built."""
    s = np.asarray(score_cumulative, dtype=np.float64)
    return ((s[..., _SCORE.total_value_units] + s[..., _SCORE.total_value_structures]
             - START_VALUE) / VALUE_UNIT + s[..., _SCORE.score])


def check_narration(narration: Narration, scorer: Any, patience: int) -> None:
    """One line unless the narration can be followed: commands, a patience of 0 or more, and
    words the scorer reads (per-game and batched narration rewards alike)."""
    if not narration.commands:
        raise Sc2DataError("the narration holds no command")
    if patience < 0:
        raise Sc2DataError(f"patience must be 0 or more, got {patience}")
    check_readable(narration, scorer)


def check_shaping(shaping: str, gamma: float) -> None:
    """One-line error unless ``shaping`` is one of :data:`SHAPINGS` and γ lies in [0, 1]."""
    if shaping not in SHAPINGS:
        raise Sc2DataError(f"unknown shaping {shaping!r}; choose one of: {', '.join(SHAPINGS)}")
    if not 0.0 <= gamma <= 1.0:
        raise Sc2DataError(f"gamma must lie in [0, 1], got {gamma}")


def stacks_of(frames: Sequence[Mapping[str, Any]], schema: Schema) -> StackBatch:
    """The ``len(frames) - 1`` consecutive two-frame stacks of ``frames``, in ``schema``."""
    extracted = [schema.extract(f) for f in frames]
    return stack(list(zip(extracted, extracted[1:])), schema)


class _Shaping(gym.Wrapper):  # type: ignore[type-arg]
    """Common part: masks pass through; ``shape`` says what to add to the game's reward (an
    event bonus), ``potential`` what Φ is (potential-based shaping, ``shaping="potential"``)."""

    shaping = "event"
    gamma = 0.99
    smdp = False
    """Potential-based: discount Φ(s') by γᵏ for a decision of k pysc2 steps, as PPO does with
    SMDP discounting (:mod:`sc2data.rl.smdp`), so the shaping stays potential-based."""

    def action_masks(self) -> np.ndarray:
        return self.env.unwrapped.action_masks()  # type: ignore[attr-defined, no-any-return]

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        game = float(info.get("game_reward", reward))
        frames = self.env.unwrapped.frames  # type: ignore[attr-defined]
        if self.shaping == "potential":
            before = self.potential(frames[0])
            self.shape(frames)  # advances what the potential reads (the narration's progress)
            after = 0.0 if terminated or truncated else self.potential(frames[-1])
            discount = self.gamma ** (len(frames) - 1) if self.smdp else self.gamma
            extra = discount * after - before
        else:
            extra = self.shape(frames)
        info = {**info, "game_reward": game, "shaping": extra}
        return obs, game + extra, terminated, truncated, info

    def shape(self, frames: Sequence[Mapping[str, Any]]) -> float:
        """The bonus for the decision whose pysc2 observations are ``frames`` (the decision's
        first frame is the previous decision's last); each reward mode defines it."""
        raise NotImplementedError

    def potential(self, frame: Mapping[str, Any]) -> float:
        """Φ of the state whose pysc2 observation is ``frame`` (potential-based shaping)."""
        raise NotImplementedError


class ZeroReward(_Shaping):
    """No reward: ``r = 0`` (the game's score still counts in ``info["game_reward"]``)."""

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, 0.0, terminated, truncated, {**info, "shaping": -info["game_reward"]}

    def shape(self, frames: Sequence[Mapping[str, Any]]) -> float:
        return 0.0


class SparseReward(_Shaping):
    """The game's reward, unchanged: ``r = r_game`` (+1 per marine made during the decision)."""

    def shape(self, frames: Sequence[Mapping[str, Any]]) -> float:
        return 0.0


class RuleShaping(_Shaping):
    """Hand-made shaping from the built-in labelling rules.

    ``r = r_game + bonus · Σ_i Σ_rules rule(stack_i)``: for each two-frame stack of the decision
    (i = 1…n, see the module docstring) and each rule, ``bonus`` when the rule fires. The rules
    are the ``rules/`` plugins (build an SCV, collect minerals, build a supply depot, build a
    barracks, train a marine), loaded through ``sc2data.labels.registry.load_registry``;
    ``rule_ids`` picks some of them.

    ``shaping="potential"``: ``r = r_game + γ·Φ(s') − Φ(s)`` with ``Φ = bonus · progress(s)``
    (:func:`progress`: what the player has built, in SCVs' worth, plus marines made).
    """

    def __init__(self, env: gym.Env, *, bonus: float = 0.1,  # type: ignore[type-arg]
                 rule_ids: Sequence[str] | None = None, shaping: str = "event",
                 gamma: float = 0.99) -> None:
        super().__init__(env)
        from sc2data.labels.registry import load_registry

        check_shaping(shaping, gamma)
        self.shaping, self.gamma = shaping, float(gamma)
        self.bonus = float(bonus)
        self.entries = list(load_registry().select(rule_ids))
        self.rules: list[Rule] = [e.rule for e in self.entries]
        self.schema = schema_for(k for r in self.rules for k in r.requires if "/" in k)

    def shape(self, frames: Sequence[Mapping[str, Any]]) -> float:
        from sc2data.labels.registry import call

        if self.shaping == "potential":
            return 0.0  # paid through the potential alone
        batch = stacks_of(frames, self.schema)
        fired = sum(int(np.count_nonzero(call(e.rule, e.source, batch, "an RL decision's stacks")))
                    for e in self.entries)
        return self.bonus * fired

    def potential(self, frame: Mapping[str, Any]) -> float:
        return self.bonus * float(progress(frame["score_cumulative"]))


class NarrationShaping(_Shaping):
    """Narration shaping with a trained MEM (Waytowich et al., arXiv 1911.00497).

    The narration is an ordered list of commands c_0…c_{m-1}; k (the current command) starts at 0
    each episode. For each two-frame stack s_i of the decision, in order:

        r += bonus   and   k ← (k + 1) mod m      if  MEM.distance(s_i, c_k) < threshold

    so ``r = r_game + bonus · (number of commands matched in turn)``; after the last command
    the narration starts again (it loops). With ``patience`` > 0, a command not matched within
    ``patience`` decisions is skipped (k advances, no bonus); 0 waits for it forever.

    ``scorer`` is a :class:`~sc2data.model.scorer.MEMScorer` (``load_model(RUN)``) or anything
    with the same ``distance(stacks, text) -> (B,) array`` method and a ``schema``. The command
    embeddings are computed once, at construction (the scorer caches them per text).
    ``info["narration_index"]`` is k after the decision.

    ``shaping="potential"``: ``r = r_game + γ·Φ(s') − Φ(s)`` with ``Φ = bonus ·`` (commands
    matched so far this episode, a skipped one not counted): each match is worth ``γ·bonus``
    when made and is paid back by the time the episode ends, so matching early is what pays.
    """

    def __init__(self, env: gym.Env, scorer: Any, narration: Narration, *,  # type: ignore[type-arg]
                 bonus: float = 1.0, threshold: float = 0.5, patience: int = 0,
                 shaping: str = "event", gamma: float = 0.99) -> None:
        super().__init__(env)
        check_shaping(shaping, gamma)
        self.shaping, self.gamma = shaping, float(gamma)
        check_narration(narration, scorer, patience)
        self.scorer, self.narration = scorer, narration
        self.bonus, self.threshold, self.patience = float(bonus), float(threshold), int(patience)
        self.schema: Schema = scorer.schema
        if hasattr(scorer, "embed_texts"):
            scorer.embed_texts(list(narration.commands))  # encode each command once, now
        self.index = 0
        self._waited = 0
        self.matched = 0
        """Commands matched this episode (the potential's count)."""

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self.index, self._waited, self.matched = 0, 0, 0
        obs, info = self.env.reset(**kwargs)
        return obs, {**info, "narration_index": 0}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, reward, terminated, truncated, {**info, "narration_index": self.index}

    def shape(self, frames: Sequence[Mapping[str, Any]]) -> float:
        batch = stacks_of(frames, self.schema)
        extra, start, matched = 0.0, 0, False
        while start < len(batch):
            rest = batch if start == 0 else StackBatch(
                {k: a[start:] for k, a in batch.arrays.items()}, batch.schema)
            d = np.asarray(self.scorer.distance(rest, self.narration.commands[self.index]))
            hits = np.flatnonzero(d < self.threshold)
            if not len(hits):
                break
            extra += self.bonus
            matched = True
            self.matched += 1
            self.index = (self.index + 1) % len(self.narration)
            start += int(hits[0]) + 1
        self._waited = 0 if matched else self._waited + 1
        if self.patience and self._waited >= self.patience:
            self.index = (self.index + 1) % len(self.narration)
            self._waited = 0
        return extra

    def potential(self, frame: Mapping[str, Any]) -> float:
        return self.bonus * self.matched


def wrap_reward(env: gym.Env, reward: str, *, scorer: Any = None,  # type: ignore[type-arg]
                narration: Narration | None = None, bonus: float | None = None,
                threshold: float = 0.5, patience: int = 0, shaping: str = "event",
                gamma: float = 0.99, smdp: bool = False) -> gym.Env:  # type: ignore[type-arg]
    """``env`` under the reward wrapper named ``reward`` (one of :data:`REWARDS`), its bonus
    paid as ``shaping`` (:data:`SHAPINGS`; γ for the potential-based form, per pysc2 step with
    ``smdp``)."""
    wrapped = _wrap(env, reward, scorer=scorer, narration=narration, bonus=bonus,
                    threshold=threshold, patience=patience, shaping=shaping, gamma=gamma)
    if isinstance(wrapped, _Shaping):
        wrapped.smdp = smdp
    return wrapped


def _wrap(env: gym.Env, reward: str, *, scorer: Any, narration: Narration | None,  # type: ignore[type-arg]
          bonus: float | None, threshold: float, patience: int, shaping: str,
          gamma: float) -> gym.Env:  # type: ignore[type-arg]
    check_shaping(shaping, gamma)
    if reward == "sparse":
        return SparseReward(env)
    if reward == "zero":
        return ZeroReward(env)
    if reward == "rules":
        return RuleShaping(env, bonus=0.1 if bonus is None else bonus, shaping=shaping,
                           gamma=gamma)
    if reward == "narration":
        if scorer is None or narration is None:
            raise Sc2DataError("the narration reward needs a MEM run (--mem) and a narration")
        return NarrationShaping(env, scorer, narration, bonus=1.0 if bonus is None else bonus,
                                threshold=threshold, patience=patience, shaping=shaping,
                                gamma=gamma)
    raise Sc2DataError(f"unknown reward {reward!r}; choose one of: {', '.join(REWARDS)}")
