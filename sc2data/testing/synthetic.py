"""Synthetic BuildMarines-like observations, for storage tests and benchmarks without a simulator.

The frames look like the real game's where it matters to storage: mostly constant planes (height,
visibility, creep, power), a base, eight mineral fields, SCVs shuttling between them, buildings
that appear and grow hit points, marines walking off, a selection that changes, categorical ids
and uint16 hit points, all drawn by the real screen geometry (24 world units across). They are
*not* a game: nothing here obeys BuildMarines' rules (that is :mod:`sc2data.game.sim`'s job).
:class:`SyntheticEnv` serves them through pysc2's ``environment.Base`` so the rollout loop runs
on them unchanged.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np

from sc2data._pysc2 import environment, features, units
from sc2data.schema import MINIMAP_SIZE, SCREEN_SIZE, Schema

_K = SCREEN_SIZE / 24.0
"""Screen pixels per world unit (the screen spans 24 world units)."""
_SCR = features.SCREEN_FEATURES
_MM = features.MINIMAP_FEATURES
_MINERALS = ((23, 28.5), (24, 29.5), (23, 26.5), (25, 22.5), (25, 32.5), (24, 23.5), (24, 31.5),
             (24, 25.5))
_CC = (29.83, 28.01)
_HIT_POINTS = {units.Terran.CommandCenter: 1500, units.Terran.SCV: 45,
               units.Terran.SupplyDepot: 400, units.Terran.Barracks: 1000,
               units.Terran.Marine: 45, units.Neutral.MineralField: 0}
_RADIUS = {units.Terran.CommandCenter: 2.75, units.Terran.SCV: 0.375,
           units.Terran.SupplyDepot: 1.0, units.Terran.Barracks: 1.8,
           units.Terran.Marine: 0.375, units.Neutral.MineralField: 1.125}


def _screen_xy(x: float, y: float) -> tuple[float, float]:
    return (x - 20.94) * _K, (37.0 - y) * _K


class _Scene:
    """A seeded, scripted scene: where every unit is at agent step ``t``."""

    def __init__(self, seed: int) -> None:
        rng = np.random.default_rng(seed)
        self.side = 1.0 if rng.random() < 0.5 else -1.0
        self.phase = rng.uniform(0, 2 * np.pi, 12)
        self.period = rng.uniform(40, 70, 12)
        self.patch = rng.integers(0, len(_MINERALS), 12)
        self.depot_at = int(rng.integers(100, 400))
        self.barracks_at = self.depot_at + int(rng.integers(150, 400))
        self.depot_xy = (rng.uniform(32, 40), rng.uniform(20, 26))
        self.barracks_xy = (rng.uniform(33, 41), rng.uniform(30, 35))
        self.select_every = int(rng.integers(20, 60))

    def units(self, t: int) -> list[tuple[int, float, float, int, bool, int]]:
        """(unit type, x, y, owner, selected, hit points) of every unit at step ``t``."""
        out: list[tuple[int, float, float, int, bool, int]] = []
        x: float
        y: float
        out.append((units.Terran.CommandCenter, *_CC, 1, False, 1500))
        for x, y in _MINERALS:
            out.append((units.Neutral.MineralField, x, y, 16, False, 0))
        chosen = (t // self.select_every) % 14
        for i in range(12):
            mx, my = _MINERALS[self.patch[i]]
            u = 0.5 - 0.5 * np.cos(2 * np.pi * t / self.period[i] + self.phase[i])
            x = _CC[0] - 2.0 + (mx + 1.0 - _CC[0] + 2.0) * u
            y = _CC[1] + (my - _CC[1]) * u
            out.append((units.Terran.SCV, x, y, 1, chosen == i, 45))
        for kind, start, (x, y), build in ((units.Terran.SupplyDepot, self.depot_at,
                                            self.depot_xy, 240),
                                           (units.Terran.Barracks, self.barracks_at,
                                            self.barracks_xy, 520)):
            if t >= start:
                hp = int(_HIT_POINTS[kind] * min(1.0, 0.1 + (t - start) / build))
                out.append((kind, x, y, 1, chosen == 12, hp))
        if t >= self.barracks_at + 520:
            for m in range((t - self.barracks_at - 520) // 50):
                out.append((units.Terran.Marine, self.barracks_xy[0] - 2 - 0.3 * m,
                            self.barracks_xy[1] - 1.5 + 0.2 * (m % 7), 1, chosen == 13, 45))
        return out


def render(scene: _Scene, t: int) -> dict[str, np.ndarray]:
    """One pysc2-shaped observation (int32 arrays, all 27 + 11 layers) of the scene at step t."""
    screen = np.zeros((len(_SCR), SCREEN_SIZE, SCREEN_SIZE), np.int32)
    minimap = np.zeros((len(_MM), MINIMAP_SIZE, MINIMAP_SIZE), np.int32)
    rows, cols = np.mgrid[0:SCREEN_SIZE, 0:SCREEN_SIZE] + 0.5
    in_map = rows < 48
    screen[_SCR.height_map.index] = np.where(in_map, 147, 0)
    screen[_SCR.visibility_map.index] = np.where(in_map, 2, 0)
    screen[_SCR.pathable.index] = in_map
    screen[_SCR.buildable.index] = in_map
    minimap[_MM.height_map.index, 27:45, 20:46] = 147
    minimap[_MM.visibility_map.index, 27:45, 20:46] = 2
    minimap[_MM.camera.index, 30:46, 21:45] = 1
    for kind, x, y, owner, selected, hp in scene.units(t):
        px, py = _screen_xy(x, y)
        r = _RADIUS[kind] * _K
        disk = (cols - px) ** 2 + (rows - py) ** 2 <= r * r
        edge = disk & ((cols - px) ** 2 + (rows - py) ** 2 > (r - 1) ** 2)
        screen[_SCR.unit_type.index][disk] = kind
        screen[_SCR.player_id.index][disk] = owner
        screen[_SCR.player_relative.index][disk] = 1 if owner == 1 else 3
        screen[_SCR.unit_hit_points.index][disk] = hp
        screen[_SCR.unit_hit_points_ratio.index][disk] = 255 if hp else 0
        screen[_SCR.unit_density.index][disk] += 1
        screen[_SCR.unit_density_aa.index][disk] += 16
        screen[_SCR.unit_density_aa.index][edge] -= 8
        screen[_SCR.pathable.index][disk] = 0
        screen[_SCR.buildable.index][disk] = 0
        if selected:
            screen[_SCR.selected.index][disk] = 1
        mx, my = int(x), int(MINIMAP_SIZE - y)
        minimap[_MM.player_id.index, my, mx] = owner
        minimap[_MM.player_relative.index, my, mx] = 1 if owner == 1 else 3
        minimap[_MM.unit_type.index, my, mx] = kind
        minimap[_MM.selected.index, my, mx] = int(selected)
    np.clip(screen[_SCR.unit_density.index], 0, 15, out=screen[_SCR.unit_density.index])
    np.clip(screen[_SCR.unit_density_aa.index], 0, 255, out=screen[_SCR.unit_density_aa.index])
    loop = 8 * t
    minerals = (50 + (loop * 52) // 100 - 100 * (t >= scene.depot_at)
                - 150 * (t >= scene.barracks_at))
    player = np.array([1, max(0, minerals) % 100000, 0, 12, 15, 0, 12, 0, 0, 0, 0], np.int32)
    score = np.zeros(13, np.int32)
    score[features.ScoreCumulative.collected_minerals] = (loop * 52) // 100
    score[features.ScoreCumulative.idle_worker_time] = t // 3
    return {"feature_screen": screen, "feature_minimap": minimap, "player": player,
            "score_cumulative": score, "game_loop": np.array([loop], np.int32)}


def synthetic_episode(schema: Schema, n_steps: int, seed: int) -> dict[str, np.ndarray]:
    """The ``n_steps + 1`` frames of one synthetic episode, as ``{key: (T+1, …) array}``."""
    scene = _Scene(seed)
    frames = [schema.extract(render(scene, t)) for t in range(n_steps + 1)]
    return {k: np.stack([f[k] for f in frames]) for k in schema.keys()}


class SyntheticEnv(environment.Base):
    """pysc2's mock env (real specs) serving synthetic frames; episodes last ``episode_steps``.

    Seeded: the same seed gives the same frames. Actions are accepted and ignored, as pysc2's own
    ``SC2TestEnv`` does, so any pysc2 agent (its ``RandomAgent`` included) can drive it.
    """

    def __init__(self, seed: int | None = None, episode_steps: int = 64) -> None:
        from pysc2.env import mock_sc2_env

        from sc2data.game.env import interface_format

        self._mock = mock_sc2_env.SC2TestEnv(agent_interface_format=interface_format())
        self._seed = 0 if seed is None else seed
        self._episode_steps = episode_steps
        self._t = 0
        self._episode = 0
        self._scene = _Scene(self._seed)

    def _timestep(self, step_type: environment.StepType, reward: float) -> environment.TimeStep:
        from pysc2.lib import named_array

        obs = named_array.NamedDict(self._mock.next_timestep[0].observation)
        obs.update(render(self._scene, self._t))
        return environment.TimeStep(step_type=step_type, reward=reward,
                                    discount=0.0 if step_type != environment.StepType.MID else 1.0,
                                    observation=obs)

    def reset(self) -> tuple[environment.TimeStep]:
        self._scene = _Scene(self._seed + self._episode)
        self._episode += 1
        self._t = 0
        return (self._timestep(environment.StepType.FIRST, 0.0),)

    def step(self, actions: Sequence[Any], step_mul: int | None = None
             ) -> tuple[environment.TimeStep]:
        del actions, step_mul
        self._t += 1
        last = self._t >= self._episode_steps
        reward = float(self._t >= self._scene.barracks_at + 520 and
                       (self._t - self._scene.barracks_at - 520) % 50 == 0)
        return (self._timestep(environment.StepType.LAST if last else environment.StepType.MID,
                               reward),)

    def observation_spec(self) -> Any:
        return self._mock.observation_spec()

    def action_spec(self) -> Any:
        return self._mock.action_spec()

    def close(self) -> None:
        self._mock.close()


def synthetic_env_factory(episode_steps: int = 64) -> functools.partial[SyntheticEnv]:
    """A picklable ``seed -> SyntheticEnv`` factory for :func:`sc2data.data.rollout.rollout`."""
    return functools.partial(SyntheticEnv, episode_steps=episode_steps)


def pysc2_random_agent(seed: int) -> Any:
    """pysc2's own uniform ``RandomAgent``, unchanged (it draws from the global numpy generator,
    which the rollout seeds per episode)."""
    from pysc2.agents.random_agent import RandomAgent

    del seed
    return RandomAgent()
