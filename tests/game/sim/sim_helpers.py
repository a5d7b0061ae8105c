"""Helpers for the simulator's tests: acting through pysc2 FunctionCalls as an agent would."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sc2data._pysc2 import actions, environment
from sc2data.game.sim import BuildMarinesEnv
from sc2data.game.sim import mapdata as md
from sc2data.game.sim.store import Unit

F = actions.FUNCTIONS


def new_env(seed: int = 0, **kwargs: Any) -> tuple[BuildMarinesEnv, Any]:
    """A reset env and its first observation."""
    env = BuildMarinesEnv(seed=seed, **kwargs)
    return env, env.reset()[0].observation


def pixel(x: float, y: float) -> list[int]:
    """The screen pixel [x, y] under a world point."""
    px, py = md.world_to_screen(x, y)
    return [int(px), int(py)]


def unit_pixel(env: BuildMarinesEnv, u: Unit) -> list[int]:
    return pixel(*u.pos(float(env.game.loop)))


def step(env: BuildMarinesEnv, call: Any = None) -> environment.TimeStep:
    return env.step([call if call is not None else F.no_op()])[0]


def wait(env: BuildMarinesEnv, steps: int) -> environment.TimeStep:
    ts = None
    for _ in range(steps):
        ts = step(env)
    assert ts is not None
    return ts


def wait_until(env: BuildMarinesEnv, pred: Callable[[], bool], limit: int = 2000
               ) -> environment.TimeStep:
    """No-ops until ``pred()`` holds (at most ``limit`` steps)."""
    for _ in range(limit):
        ts = step(env)
        if pred():
            return ts
    raise AssertionError("condition never held")


def scvs(env: BuildMarinesEnv) -> list[Unit]:
    return sorted((u for u in env.game.units.values() if u.utype == md.SCV), key=lambda u: u.tag)


def of_type(env: BuildMarinesEnv, utype: int) -> list[Unit]:
    return sorted((u for u in env.game.units.values() if u.utype == utype), key=lambda u: u.tag)


def select(env: BuildMarinesEnv, u: Unit) -> environment.TimeStep:
    return step(env, F.select_point("select", unit_pixel(env, u)))


def build(env: BuildMarinesEnv, fn: Any, x: float, y: float) -> environment.TimeStep:
    """Select the first SCV and order it to build at world (x, y)."""
    select(env, scvs(env)[0])
    return step(env, fn("now", pixel(x, y)))


DEPOT_SITE = (33.0, 34.0)
"""Free buildable ground north-east of the CC, on screen."""
BARRACKS_SITE = (38.5, 30.5)
