"""The shaping rewards of :mod:`sc2data.rl.rewards`, for every game of a vector env at once.

:class:`~sc2data.rl.vector.BuildMarinesVecEnv` hands a shaping object, once per vector step, the
pysc2 frames of each game's last decision (its first frame the previous decision's last, then
one per pysc2 step; the arrays the worker processes wrote) and which games ended — of every
game, or of games ``first`` onwards when a pipelined rollout steps the games a part at a time
(:mod:`sc2data.rl.pipeline`). The object
forms every game's two-frame stacks, judges them all in one batch (one MEM call for the
narration reward) and returns each game's bonus. The bonuses are those of the per-game wrappers
(:class:`~sc2data.rl.rewards.RuleShaping`, :class:`~sc2data.rl.rewards.NarrationShaping`) on the
same frames, narration state included, in both forms of payment (``event`` and
``potential``, :data:`~sc2data.rl.rewards.SHAPINGS`; tests/rl/test_vector.py holds this).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from sc2data.ground.errors import Sc2DataError
from sc2data.rl.narration import Narration
from sc2data.rulebase import schema_for
from sc2data.schema import Schema, StackBatch


def decision_stacks(frames: Mapping[str, np.ndarray], n_frames: np.ndarray, schema: Schema
                    ) -> tuple[StackBatch, np.ndarray]:
    """Every game's two-frame stacks of its last decision, game by game in order, and how many
    each game has. ``frames[key]`` is ``(games, slots, …)``; game i's frames are its first
    ``n_frames[i]`` slots."""
    counts = np.maximum(np.asarray(n_frames, dtype=np.int64) - 1, 0)
    keys = schema.keys()
    if len(counts) and (counts == 1).all():  # one pysc2 step each: the first two slots, as is
        return StackBatch({k: frames[k][:, :2] for k in keys}, schema), counts
    game = np.repeat(np.arange(len(counts)), counts)
    starts = np.cumsum(counts) - counts
    j = np.arange(int(counts.sum())) - np.repeat(starts, counts) + 1
    arrays = {k: np.stack((frames[k][game, j - 1], frames[k][game, j]), axis=1) for k in keys}
    return StackBatch(arrays, schema), counts


def potential_step(before: np.ndarray, after: np.ndarray, done: np.ndarray, gamma: float,
                   steps: np.ndarray | None = None) -> np.ndarray:
    """Potential-based shaping for every game: ``γ·Φ(s') − Φ(s)``, ``Φ(s') = 0`` where the
    episode ended (as :class:`~sc2data.rl.rewards._Shaping` pays it)."""
    # Python's float power, game by game: numpy's vectorised power may differ in the last bit
    # from the per-game wrappers' (the equality test holds the two to the bit).
    discount = gamma if steps is None else np.array([gamma ** int(k) for k in steps])
    return discount * np.where(np.asarray(done, dtype=bool), 0.0, after) - before


class _Potential:
    smdp = False
    """Potential-based: Φ(s') discounted γᵏ for a decision of k pysc2 steps (SMDP), as the
    per-game wrappers do (:attr:`sc2data.rl.rewards._Shaping.smdp`)."""


class BatchedRules(_Potential):
    """:class:`~sc2data.rl.rewards.RuleShaping` for all games: ``bonus`` per rule firing on
    each stack of the decision, or (``shaping="potential"``) ``γ·Φ(s') − Φ(s)`` with
    ``Φ = bonus · progress`` (:func:`~sc2data.rl.rewards.progress`) of the decision's first and
    last frames."""

    def __init__(self, *, bonus: float = 0.1, rule_ids: Sequence[str] | None = None,
                 shaping: str = "event", gamma: float = 0.99) -> None:
        from sc2data.labels.registry import load_registry
        from sc2data.rl.rewards import check_shaping

        check_shaping(shaping, gamma)
        self.shaping, self.gamma = shaping, float(gamma)
        self.bonus = float(bonus)
        self.entries = list(load_registry().select(rule_ids))
        self.schema = schema_for(k for e in self.entries for k in e.rule.requires if "/" in k)

    def reset(self, n: int) -> None:
        """A new vector of ``n`` games (nothing to remember between decisions)."""

    def __call__(self, frames: Mapping[str, np.ndarray], n_frames: np.ndarray,
                 done: np.ndarray, first: int = 0) -> tuple[np.ndarray, list[dict[str, Any]]]:
        if self.shaping == "potential":
            from sc2data.rl.rewards import progress

            score = frames["score_cumulative"]
            last = np.asarray(n_frames, dtype=np.int64) - 1
            before = self.bonus * progress(score[:, 0])
            after = self.bonus * progress(score[np.arange(len(last)), last])
            return potential_step(before, after, done, self.gamma,
                                  last if self.smdp else None), [{} for _ in last]
        batch, counts = decision_stacks(frames, n_frames, self.schema)
        from sc2data.labels.registry import call

        fired = np.zeros(len(batch), dtype=np.int64)
        for e in self.entries:  # each on a read-only view, as labelling runs them
            fired += np.asarray(call(e.rule, e.source, batch, "an RL decision's stacks"),
                                dtype=bool)
        game = np.repeat(np.arange(len(counts)), counts)
        per_game = np.bincount(game, weights=fired, minlength=len(counts))
        return self.bonus * per_game, [{} for _ in counts]


class BatchedNarration(_Potential):
    """:class:`~sc2data.rl.rewards.NarrationShaping` for all games: each game's current command
    ``k`` advances (and pays ``bonus``) on the first of its stacks, in order, the MEM puts within
    ``threshold`` of it; ``patience`` > 0 skips a command not matched in that many decisions; a
    game that ends starts its narration again. Every stack is scored against every command of
    the narration in one MEM call (the state embedding is the cost; the commands are cached).
    ``shaping="potential"``: ``γ·Φ(s') − Φ(s)`` with ``Φ = bonus ·`` (commands each game has
    matched this episode) instead of ``bonus`` per match."""

    def __init__(self, scorer: Any, narration: Narration, *, bonus: float = 1.0,
                 threshold: float = 0.5, patience: int = 0, shaping: str = "event",
                 gamma: float = 0.99) -> None:
        from sc2data.rl.rewards import check_narration, check_shaping

        check_shaping(shaping, gamma)
        self.shaping, self.gamma = shaping, float(gamma)
        check_narration(narration, scorer, patience)
        self.scorer, self.narration = scorer, narration
        self.commands = list(narration.commands)
        self.bonus, self.threshold, self.patience = float(bonus), float(threshold), int(patience)
        self.schema: Schema = scorer.schema
        scorer.embed_texts(self.commands)
        self.index = np.zeros(0, dtype=np.int64)
        self.waited = np.zeros(0, dtype=np.int64)
        self.matched = np.zeros(0, dtype=np.int64)

    def reset(self, n: int) -> None:
        """A new vector of ``n`` games: every narration at its first command."""
        self.index = np.zeros(n, dtype=np.int64)
        self.waited = np.zeros(n, dtype=np.int64)
        self.matched = np.zeros(n, dtype=np.int64)

    def __call__(self, frames: Mapping[str, np.ndarray], n_frames: np.ndarray,
                 done: np.ndarray, first: int = 0) -> tuple[np.ndarray, list[dict[str, Any]]]:
        batch, counts = decision_stacks(frames, n_frames, self.schema)
        rows = slice(first, first + len(counts))  # these games' narration state, as views
        index, waited_for, matched = self.index[rows], self.waited[rows], self.matched[rows]
        m = len(self.commands)
        hit = (np.asarray(self.scorer.distances(batch, self.commands)) < self.threshold
               if len(batch) else np.zeros((0, m), dtype=bool))
        bonus = np.zeros(len(counts))
        made = np.zeros(len(counts), dtype=np.int64)  # commands matched in this decision
        infos: list[dict[str, Any]] = []
        end = np.cumsum(counts)
        for i, n in enumerate(counts):
            mine = hit[end[i] - n:end[i]]
            k, start = int(index[i]), 0
            while start < n:
                js = np.flatnonzero(mine[start:, k])
                if not len(js):
                    break
                bonus[i] += self.bonus
                made[i] += 1
                k = (k + 1) % m
                start += int(js[0]) + 1
            waited = 0 if made[i] else int(waited_for[i]) + 1
            if self.patience and waited >= self.patience:
                k, waited = (k + 1) % m, 0
            infos.append({"narration_index": k})
            index[i], waited_for[i] = (0, 0) if done[i] else (k, waited)
        if self.shaping == "potential":
            before = self.bonus * matched
            after = self.bonus * (matched + made)
            bonus = potential_step(before, after, done, self.gamma,
                                   counts if self.smdp else None)
        matched[:] = np.where(np.asarray(done, dtype=bool), 0, matched + made)
        return bonus, infos


class BatchedZero:
    """:class:`~sc2data.rl.rewards.ZeroReward` for all games: the game's reward taken away."""

    schema = None
    game_weight = 0.0

    def reset(self, n: int) -> None:
        """Nothing to remember."""

    def __call__(self, frames: Mapping[str, np.ndarray], n_frames: np.ndarray,
                 done: np.ndarray, first: int = 0) -> tuple[np.ndarray, list[dict[str, Any]]]:
        return np.zeros(len(n_frames)), [{} for _ in n_frames]


def make_shaping(reward: str, *, scorer: Any = None, narration: Narration | None = None,
                 bonus: float | None = None, threshold: float = 0.5, patience: int = 0,
                 shaping: str = "event", gamma: float = 0.99, smdp: bool = False) -> Any:
    """The batched shaping of ``reward`` (None for the game's sparse reward), its bonus paid as
    ``shaping`` (:data:`~sc2data.rl.rewards.SHAPINGS`; γ per pysc2 step with ``smdp``)."""
    made = _make(reward, scorer=scorer, narration=narration, bonus=bonus, threshold=threshold,
                 patience=patience, shaping=shaping, gamma=gamma)
    if isinstance(made, _Potential):
        made.smdp = smdp
    return made


def _make(reward: str, *, scorer: Any, narration: Narration | None, bonus: float | None,
          threshold: float, patience: int, shaping: str, gamma: float) -> Any:
    from sc2data.rl.rewards import REWARDS, check_shaping

    check_shaping(shaping, gamma)
    if reward == "sparse":
        return None
    if reward == "zero":
        return BatchedZero()
    if reward == "rules":
        return BatchedRules(bonus=0.1 if bonus is None else bonus, shaping=shaping, gamma=gamma)
    if reward == "narration":
        if scorer is None or narration is None:
            raise Sc2DataError("the narration reward needs a MEM run (--mem) and a narration")
        return BatchedNarration(scorer, narration, bonus=1.0 if bonus is None else bonus,
                                threshold=threshold, patience=patience, shaping=shaping,
                                gamma=gamma)
    raise Sc2DataError(f"unknown reward {reward!r}; choose one of: {', '.join(REWARDS)}")
