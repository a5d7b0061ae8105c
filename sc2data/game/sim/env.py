"""``BuildMarinesEnv``: the embedded simulator behind pysc2's ``environment.Base`` interface.

It behaves as ``sc2_env.SC2Env(map_name="BuildMarines", ...)`` does for one Terran agent with
our interface format (:func:`sc2data._pysc2.interface_format`): ``reset``/``step`` return a tuple
of one ``TimeStep``; the first has reward 0 and discount 0, later ones reward = the change in
``score_cumulative[0]`` (+1 per marine made) and discount 1; the map's timer ends the episode
after 14,400 game loops with a LAST step of discount 0 (pysc2 zeroes it when the game reports
its end); stepping after LAST starts a new episode. Actions are validated exactly as
``features.Features.transform_action`` validates them, against the previous observation.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from sc2data._pysc2 import environment, features, interface_format
from sc2data.game.sim import mapdata as md
from sc2data.game.sim import obsdict
from sc2data.game.sim.commands import Commands
from sc2data.game.sim.game import Game
from sc2data.game.sim.observe import Renderer
from sc2data.game.sim.store import Event
from sc2data.ground.vocab import MAP_NAME, STEP_MUL


class BuildMarinesEnv(environment.Base):
    """The BuildMarines mini-game, simulated; seeded and deterministic.

    Args:
      seed: seeds the per-episode random choice (the side the SCVs start on); the same seed and
        the same actions give identical observations. ``None`` draws a seed from the OS.
      step_mul: game loops per agent step (pysc2's default and the paper's: 8).
      game_loops: episode length in game loops (the map's 900-second timer: 14,400).
      layers: draw only these feature layers (``"screen/unit_type"``, ...; see
        :class:`~sc2data.game.sim.observe.Renderer`), the rest left 0; ``None`` draws all.
    """

    def __init__(self, seed: int | None = None, step_mul: int = STEP_MUL,
                 game_loops: int = md.GAME_LOOPS, layers: frozenset[str] | None = None) -> None:
        if step_mul <= 0:
            raise ValueError("step_mul should be positive, got {}".format(step_mul))
        self._step_mul = int(step_mul)
        self._game_loops = int(game_loops)
        self._seed = seed if seed is not None else int.from_bytes(os.urandom(4), "little")
        self._features = features.Features(interface_format(), map_name=MAP_NAME)
        self._game = Game(self._seed)
        self._commands = Commands(self._game)
        self._renderer = Renderer(layers)
        self._state = environment.StepType.LAST
        self._available: list[int] = []
        self._last_score = 0
        self._episode_count = 0
        self.events: list[Event] = []
        """What happened during the last ``step`` (or ``reset``), in order: see :class:`Event`."""

    # ------------------------------------------------------------------ environment.Base

    def observation_spec(self) -> tuple[Any, ...]:
        """pysc2's own spec for our interface format, as ``SC2Env.observation_spec`` gives."""
        return (self._features.observation_spec(),)

    def action_spec(self) -> tuple[Any, ...]:
        return (self._features.action_spec(),)

    def reset(self) -> tuple[environment.TimeStep, ...]:
        """Start a new episode."""
        if self._episode_count:
            self._game.reset()
        self._episode_count += 1
        self._commands = Commands(self._game)
        self._last_score = 0
        self._state = environment.StepType.FIRST
        self._game.events = []
        self.events = []
        return self._observe(reward=0.0, discount=0.0)

    def step(self, actions_: Sequence[Any], step_mul: int | None = None
             ) -> tuple[environment.TimeStep, ...]:
        """Apply one agent's action(s), advance ``step_mul`` game loops, observe.

        ``actions_`` holds one entry per agent (one here): a ``FunctionCall`` or a list of them.
        """
        if self._state == environment.StepType.LAST:
            return self.reset()
        if len(actions_) != 1:
            raise ValueError(f"BuildMarinesEnv has one agent; got {len(actions_)} actions")
        calls = actions_[0]
        calls = list(calls) if isinstance(calls, list) else [calls]
        game = self._game
        game.events = []
        # All are validated first, as SC2Env transforms all before sending any.
        self._commands.apply_all(calls, self._available)
        mul = step_mul or self._step_mul
        if mul <= 0:
            raise ValueError("step_mul should be positive, got {}".format(mul))
        game.advance(min(game.loop + mul, self._game_loops))
        self.events = game.events
        self._state = environment.StepType.MID
        score = game.score
        reward = score - self._last_score
        self._last_score = score
        discount = 1.0
        if game.loop >= self._game_loops:
            self._state = environment.StepType.LAST
            discount = 0.0
        return self._observe(reward=reward, discount=discount)

    def close(self) -> None:
        """Nothing to release: the simulator holds no process or file."""

    # ------------------------------------------------------------------ internals

    def _observe(self, reward: float, discount: float) -> tuple[environment.TimeStep, ...]:
        screen, minimap, top = self._renderer.draw(self._game)
        self._commands.top = top
        self._available = self._commands.available()
        obs = obsdict.build(self._game, self._commands, screen, minimap, self._available,
                            self._renderer.hp, self._renderer.progress)
        return (environment.TimeStep(step_type=self._state, reward=reward,
                                     discount=discount, observation=obs),)

    @property
    def game(self) -> Game:
        """The simulator's game state (for tests and tools; agents should use observations)."""
        return self._game

    @property
    def state(self) -> environment.StepType:
        return self._state

