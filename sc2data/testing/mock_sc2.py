"""The ``--env sc2`` code path without the game: pysc2's mock SC2 environment behind ``SC2Env``.

pysc2 ships ``mock_sc2_env.SC2TestEnv``: the real observation and action specs of a given
interface format, and a constant dummy observation (zero screen, a fixed ``player`` vector with
idle workers and an army, a few available actions) for 10 steps an episode. :class:`MockSC2Env`
is that environment with ``SC2Env``'s constructor, and it checks every action as ``SC2Env`` does
(pysc2's ``Features.transform_action``: an unavailable function or a bad argument raises), so
agents, rollout, verify, label and the MEM reward run the real interface end to end in tests.

For tests only (the frames are dummies), and chosen by injection, never by a switch in the
library: ``rollout(config, out, env_factory=mock_env_factory())`` with ``config.env == "sc2"``
runs the real game's code path on it, in worker processes too (the factory pickles).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

from sc2data._pysc2 import environment
from sc2data.game.env import sc2_env_kwargs
from sc2data.ground.vocab import STEP_MUL

from pysc2.env import mock_sc2_env  # isort: skip  (after sc2data._pysc2: pysc2 on 3.11)

EPISODE_STEPS = 10
"""Agent steps per mock episode (pysc2's ``SC2TestEnv`` default)."""


class MockSC2Env(mock_sc2_env.SC2TestEnv):
    """pysc2's ``SC2TestEnv`` accepting ``SC2Env``'s keyword arguments, validating actions."""

    def __init__(self, **kwargs: Any) -> None:
        self._protos: list[Any] = []
        super().__init__(**kwargs)

    def _default_observation(self, obs_spec: Any, agent_index: int) -> Any:
        obs = super()._default_observation(obs_spec, agent_index)
        # The proto the observation was made from: what SC2Env checks the next actions against.
        from pysc2.tests import dummy_observation

        proto = dummy_observation.Builder(obs_spec).game_loop(0).build().observation
        self._protos.append(proto)
        return obs

    def step(self, actions: Sequence[Any], step_mul: int | None = None
             ) -> list[environment.TimeStep]:
        """Check each action as ``SC2Env`` does (``ValueError`` when invalid), then step."""
        if self._episode_steps > 0:  # reset() steps with [None] actions
            for features, proto, call in zip(self._features, self._protos, actions,
                                             strict=True):
                features.transform_action(proto, call, skip_available=False)
        return super().step(actions, step_mul)

    def close(self) -> None:
        """Nothing to close (no game process)."""


def make_mock_env(step_mul: int, seed: int | None) -> MockSC2Env:
    """The mock built as ``make_env("sc2", seed=seed, step_mul=step_mul)`` builds ``SC2Env``."""
    return MockSC2Env(**sc2_env_kwargs(seed, step_mul))


def mock_env_factory(step_mul: int = STEP_MUL) -> functools.partial[MockSC2Env]:
    """A picklable ``env_factory`` for :func:`sc2data.rollout`: ``factory(seed)`` is the mock."""
    return functools.partial(make_mock_env, step_mul)
