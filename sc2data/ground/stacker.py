"""Live observations into two-frame stacks: what a rule or the MEM reads, one step at a time.

A dataset stores stacks (previous frame, current frame); an agent playing live sees one
observation per step. :class:`Stacker` keeps the previous frame and turns each new observation
into a one-stack :class:`~sc2data.schema.StackBatch`, exactly as the rollout writer pairs
frames::

    stacker = sc2data.Stacker(mem.schema)
    timestep = env.reset()[0]
    stacker.push(timestep)                     # first step: (first frame, first frame)
    timestep = env.step([agent.step(timestep)])[0]
    mem.distance(stacker.push(timestep), "build a barracks")   # (previous frame, this frame)

The first observation of an episode has no previous frame, so its stack repeats it: (first,
first). Nothing has changed in such a stack, so no rule fires on it and the MEM sees no event.
A pysc2 ``TimeStep`` whose ``first()`` is true starts a new episode on its own; a bare
observation dict does so after :meth:`Stacker.reset`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from sc2data.schema import Schema, StackBatch


class Stacker:
    """Turns successive pysc2 observations into two-frame stacks of ``schema``'s keys."""

    def __init__(self, schema: Schema | None = None) -> None:
        self.schema = schema if schema is not None else Schema.paper()
        """The keys kept: a model's (``mem.schema``), a dataset's, or the paper's by default."""
        self._previous: dict[str, np.ndarray] | None = None

    def __repr__(self) -> str:
        return (f"Stacker(layers={len(self.schema.layers)}, "
                f"primed={self._previous is not None})")

    def reset(self) -> None:
        """Forget the previous frame: the next push starts an episode."""
        self._previous = None

    def push(self, obs: Mapping[str, Any] | Any) -> StackBatch:
        """The stack (previous frame, this frame) of one observation, as a batch of one.

        ``obs`` is a pysc2 observation or a ``TimeStep`` holding one (a first ``TimeStep``
        resets). The first push of an episode gives (this frame, this frame).
        """
        if hasattr(obs, "observation"):
            if callable(getattr(obs, "first", None)) and obs.first():
                self.reset()
            obs = obs.observation
        frame = self.schema.extract(obs)
        previous = frame if self._previous is None else self._previous
        self._previous = {k: v.copy() for k, v in frame.items()}  # the env may reuse its arrays
        return StackBatch({k: np.stack([previous[k], frame[k]])[None] for k in frame},
                          self.schema)
