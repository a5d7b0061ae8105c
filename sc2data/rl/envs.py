"""Gymnasium environments over BuildMarines: a macro action space and the paper's pysc2 space.

:class:`BuildMarinesGym` wraps :func:`sc2data.game.env.make_env` (the embedded simulator by
default; ``backend="sc2"`` is the real game through pysc2) behind gymnasium's ``Env`` API:

* ``action_space="macro"``: ``Discrete(6)`` — train an SCV, build a supply depot, build a
  barracks, train a marine, send idle workers to mine, no-op — each played out as pysc2
  ``FunctionCall``s by the reduced-random agent's own macro code
  (:meth:`sc2data.game.agents.ReducedRandomAgent.macro`), with its random choices (which SCV,
  which free spot, which barracks) drawn from the episode's seeded generator; ``sites="far"``
  builds on the free site farthest from the minerals instead of a random one (the scripted
  agent's choice: more buildings fit, so the supply ceiling is higher). As that agent
  does, a macro that costs minerals first waits for them (``no_op`` steps, up to
  ``ReducedRandomAgent.PATIENCE`` = 60, then gives up): without saving up, a policy that spends
  whenever it can is too poor ever to afford a barracks (a masked uniform random policy made no
  marine in a full episode so).
* ``action_space="paper"``: ``MultiDiscrete([len(PAPER_FUNCTIONS), 64, 64])`` — a function of
  the reduced pysc2 set :data:`PAPER_FUNCTIONS` and one screen point ``(x, y)``; the remaining
  arguments are fixed (see :func:`paper_call`).

Counting. One gymnasium step is one *decision*. A paper decision is exactly one pysc2 step (8
game loops at step_mul 8). A macro decision takes as many pysc2 steps as it waits and sends
calls — the waiting for minerals, then 1 to 2 calls (select, then command) — and at least one: a
macro that sends nothing (its first call is unavailable) plays one ``no_op`` so that time always
advances. With ``merge_waits`` a macro decision also plays on the ``no_op`` steps that follow
it while ``no_op`` is the only macro allowed — once the screen has no room for another depot and
the supply is used, every macro-space agent waits out its episode so (BENCHMARKS.md, "The macro
space's ceiling") — up to :data:`MAX_DECISION_STEPS` steps in all: the policy is asked only when
it has a choice, and the game plays exactly as it would have (the only answer was ``no_op``).
``info["env_steps"]`` says how many pysc2 steps the decision took and
``info["game_loop"]`` the game time after it; learning curves are drawn against pysc2 steps so
that both spaces are compared on the same clock. The reward is the sum of the game's rewards
(+1 per marine made) over those pysc2 steps; ``info["game_reward"]`` carries the same number.
An episode ends (``terminated``) when the game's timer does (1,800 pysc2 steps on the real map;
``game_loops`` shortens it on the simulator).

Masks. :meth:`BuildMarinesGym.action_masks` follows sb3-contrib's ``MaskablePPO`` protocol. For
the paper space it is pysc2's ``available_actions`` over :data:`PAPER_FUNCTIONS` followed by all
64 x and all 64 y values (MultiDiscrete masks are per-dimension masks laid end to end). For the
macro space it is what the observation says can be started now: free supply, the units the
macro selects, free ground for a building, a completed depot for a barracks, an idle worker to
send (minerals are waited for, not masked). A call that is unavailable is never sent: a
masked-out action (from an agent that ignores the mask) plays ``no_op`` instead, with
``info["invalid"] = True`` (``info["action"]`` names the function or macro chosen, played or
not), and a macro whose next call turns out unavailable (say, a barracks
still under construction cannot train) ends there.

Observations (:mod:`sc2data.rl.obs`): ``obs="stored"`` (the default here) is a ``Dict`` with one
``Box`` per key of the schema (``Schema.named(layers)``, the paper's 13 screen + 7 minimap
layers by default) in the stored dtypes, plus its non-spatial vectors (``player``,
``score_cumulative``, ``game_loop``) — exactly what ``Schema.extract`` stores for a frame;
``obs="compact"`` the one-hot encoding made for a small CNN (with ``history`` also the game
time since each macro — paper space: each function — last acted: the env keeps the episode's
:class:`~sc2data.rl.obs.MacroClock`). The raw pysc2 observations of the
last decision are kept in :attr:`BuildMarinesGym.frames` for the reward wrappers (never put in
``info``), and on the simulator what happened in each of its pysc2 steps in
:attr:`BuildMarinesGym.events` (for judging rewards against the game's record). ``draw``
(feature layer keys) makes the simulator draw only those and what the observation and the
masks read, the rest left 0: for a caller who knows what it reads (the
vector env, :mod:`sc2data.rl.vector`).

Seeding: ``reset(seed=s)`` seeds gymnasium's ``np_random``; each episode then draws the
simulator's seed and the macro generator's seed from it, so the same seed and the same actions
give the same trajectory, and ``reset()`` without a seed plays the next episode of that stream.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sc2data._pysc2 import actions
from sc2data.game.agents import ReducedRandomAgent, macro_feasible  # noqa: F401  (re-exported)
from sc2data.game.env import make_env
from sc2data.game.screen import ScreenView
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.vocab import SCREEN_SIZE, STEP_MUL
from sc2data.rl.obs import (
    MACROS,
    PAPER_FUNCTIONS,
    MacroClock,
    ObsConfig,
    Observer,
    game_loop,
    history_actions,
)

ACTION_SPACES: tuple[str, ...] = ("macro", "paper")


MAX_DECISION_STEPS = ReducedRandomAgent.PATIENCE + 4
"""Most pysc2 steps one macro decision takes: the wait for minerals, then its calls (and, with
``merge_waits``, the forced waits after them, up to this many steps in all)."""

RECT_HALF = 4
"""``select_rect`` selects the box of ±4 pixels around the chosen point (one point, not two)."""

_F = actions.FUNCTIONS
NO_OP = _F.no_op()
_PAPER_IDS = tuple(int(_F[name].id) for name in PAPER_FUNCTIONS)
_PAPER_NO_OP = PAPER_FUNCTIONS.index("no_op")
"""What an unavailable paper action is sent as (and timed as, with ``history``)."""

_FIXED_ARGS: dict[str, list[int]] = {
    "queued": [0],            # now, not shift-queued
    "select_point_act": [0],  # select (not toggle / all of type)
    "select_add": [0],        # replace the selection
    "select_worker": [2],     # select_all idle workers
}


def paper_call(index: int, x: int, y: int) -> actions.FunctionCall:
    """The pysc2 call of paper action ``(index, x, y)``: screen arguments from the point, the rest
    fixed (act now, replace the selection, all idle workers)."""
    func = _F[_PAPER_IDS[index]]
    args: list[list[int]] = []
    for arg in func.args:
        if arg.name == "screen" and func.name == "select_rect":
            args.append([max(0, x - RECT_HALF), max(0, y - RECT_HALF)])
        elif arg.name == "screen":
            args.append([x, y])
        elif arg.name == "screen2":
            last = SCREEN_SIZE - 1
            args.append([min(last, x + RECT_HALF), min(last, y + RECT_HALF)])
        else:
            args.append(_FIXED_ARGS[arg.name])
    return actions.FunctionCall(func.id, args)


class BuildMarinesGym(gym.Env[dict[str, np.ndarray], Any]):
    """BuildMarines as a gymnasium env; see the module docstring for spaces, counting, masks."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, action_space: str = "macro", *, backend: str = "sim",
                 layers: str = "paper", game_loops: int | None = None,
                 step_mul: int = STEP_MUL, obs: str | ObsConfig = "stored",
                 draw: Iterable[str] | None = None, merge_waits: bool = False,
                 sites: str = "random", **env_kwargs: Any) -> None:
        if action_space not in ACTION_SPACES:
            raise Sc2DataError(f"unknown action space {action_space!r}; choose one of: "
                               f"{', '.join(ACTION_SPACES)}")
        obs_cfg = obs if isinstance(obs, ObsConfig) else ObsConfig(kind=obs, layers=layers)
        self.observer = Observer(obs_cfg)
        self.schema = self.observer.schema
        self.kind = action_space
        self.merge_waits = merge_waits and action_space == "macro"
        self.backend = backend
        self.step_mul = step_mul
        self._env_kwargs = dict(env_kwargs)
        if game_loops is not None:
            if backend != "sim":
                raise Sc2DataError("game_loops (a shorter episode) needs the simulator backend")
            self._env_kwargs["game_loops"] = int(game_loops)
        if draw is not None and backend == "sim":
            self._env_kwargs["layers"] = frozenset(draw) | self.observer.layers
        self.observation_space = self.observer.space
        if action_space == "macro":
            self.action_space = spaces.Discrete(len(MACROS))
        else:
            self.action_space = spaces.MultiDiscrete([len(PAPER_FUNCTIONS), SCREEN_SIZE,
                                                      SCREEN_SIZE])
        self._env: Any = None
        self._ts: Any = None
        self._view: ScreenView | None = None
        self.sites = sites
        self._expander = ReducedRandomAgent(0, sites=sites)
        if self.observer.cfg.history and self.observer.cfg.action_space != action_space:
            raise ValueError(f"a {action_space}-space env with history needs an ObsConfig of "
                             f"that space, not {self.observer.cfg.action_space!r}")
        self._clock = MacroClock(history_actions(action_space))
        self.frames: list[Any] = []
        """pysc2 observations of the last decision: the one before it, then one per pysc2 step."""
        self.events: list[tuple[Any, ...]] = []
        """On the simulator, what happened in each pysc2 step of the last decision (its
        ``events``, one tuple per step, aligned with ``frames[1:]``); empty tuples elsewhere."""

    # -- gymnasium API ---------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        env_seed, macro_seed = (int(s) for s in self.np_random.integers(2**31 - 1, size=2))
        if self.backend == "sim" or self._env is None:
            if self._env is not None:
                self._env.close()
            self._env = make_env(self.backend, seed=env_seed, step_mul=self.step_mul,
                                 **self._env_kwargs)
        self._expander = ReducedRandomAgent(macro_seed, sites=self.sites)
        self._clock.reset()
        self._ts = self._env.reset()[0]
        self._view = ScreenView(self._ts)
        self.frames = [self._ts.observation]
        self.events = []
        return self._obs(), {"game_reward": 0.0, "env_steps": 0, "game_loop": self._loop(),
                             "marines": self._marines()}

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        if self._ts is None:
            raise RuntimeError("call reset() before step()")
        self.frames = [self._ts.observation]
        self.events = []
        reward = 0.0
        invalid = not self._allowed(action)
        if self.kind == "paper":
            fn, x, y = (int(a) for a in np.asarray(action).reshape(3))
            name = PAPER_FUNCTIONS[fn]
            self._clock.acted(_PAPER_NO_OP if invalid else fn, self._loop())
            reward += self._send(NO_OP if invalid else paper_call(fn, x, y))
        else:
            name = MACROS[int(action)]
            reward += self._send(NO_OP) if invalid else self._play_macro(name)
        if self.merge_waits:
            reward += self._wait_while_forced()
        info = {"game_reward": reward, "env_steps": len(self.frames) - 1, "invalid": invalid,
                "game_loop": self._loop(), "marines": self._marines(), "action": name}
        return self._obs(), reward, bool(self._ts.last()), False, info

    def action_masks(self) -> np.ndarray:
        """Which actions are allowed now (sb3-contrib's protocol; see the module docstring)."""
        assert self._view is not None, "call reset() first"
        if self.kind == "macro":
            return macro_feasible(self._view)
        available = self._view.available
        funcs = np.array([i in available for i in _PAPER_IDS], dtype=bool)
        return np.concatenate([funcs, np.ones(2 * SCREEN_SIZE, dtype=bool)])

    @property
    def view(self) -> ScreenView:
        """The latest pysc2 observation, parsed as macro agents read it (for an agent that
        chooses this env's macros, as ``benchmarks/ppo_gradients.py`` has the macro-rules
        agent do)."""
        assert self._view is not None, "call reset() first"
        return self._view

    @property
    def timestep(self) -> Any:
        """The latest pysc2 ``TimeStep`` (for a pysc2 agent that plays this env's paper space,
        as ``benchmarks/clone_scripted.py`` has the scripted agent do)."""
        assert self._ts is not None, "call reset() first"
        return self._ts

    def close(self) -> None:
        if self._env is not None:
            self._env.close()
            self._env = None

    # -- internals -------------------------------------------------------------------------------

    def _allowed(self, action: Any) -> bool:
        if self.kind == "macro":
            return bool(self.action_masks()[int(action)])
        assert self._view is not None
        return _PAPER_IDS[int(np.asarray(action).reshape(3)[0])] in self._view.available

    def _send(self, call: actions.FunctionCall) -> float:
        """One pysc2 step with ``call`` (already checked against ``available_actions``)."""
        self._ts = self._env.step([call])[0]
        self._view = ScreenView(self._ts)
        self.frames.append(self._ts.observation)
        self.events.append(tuple(getattr(self._env, "events", ())))
        return float(self._ts.reward or 0.0)

    def _play_macro(self, name: str) -> float:
        """Send the macro's calls one pysc2 step each, as ``MacroAgent.step`` does: the view is
        the latest observation when each call is drawn; an unavailable call ends the macro."""
        agent = self._expander
        agent.view = self._view
        reward = 0.0
        macro = agent.macro(name)
        cost = agent.COST.get(name, 0)
        self._clock.start(name)
        for call in agent.save_up(cost, macro, agent.PATIENCE) if cost else macro:
            if not self._view.can(call):  # type: ignore[union-attr]
                break
            self._clock.sent(call, self._loop())
            reward += self._send(call)
            agent.view = self._view
            if self._ts.last():
                break
        if len(self.frames) == 1:
            reward += self._send(NO_OP)
        return reward

    def _wait_while_forced(self) -> float:
        """``no_op`` while it is the only macro allowed (no free supply and no room for a depot,
        say), up to :data:`MAX_DECISION_STEPS` pysc2 steps for the decision: the policy is asked
        again only when it has a choice, or after that many steps, or at the episode's end."""
        reward = 0.0
        while (not self._ts.last() and len(self.frames) - 1 < MAX_DECISION_STEPS
               and macro_feasible(self._view).sum() == 1):  # type: ignore[arg-type]
            reward += self._send(NO_OP)
        return reward

    def _obs(self) -> dict[str, np.ndarray]:
        return self.observer(self._ts.observation, clock=self._clock)

    def _loop(self) -> int:
        return game_loop(self._ts.observation)

    def _marines(self) -> int:
        """The game's score so far: marines made this episode (``score_cumulative.score``)."""
        return int(np.asarray(self._ts.observation["score_cumulative"])[0])
