"""``Game``: the whole BuildMarines game, its core and its rules put together."""

from __future__ import annotations

from sc2data.game.sim.building import Building
from sc2data.game.sim.combat import Combat
from sc2data.game.sim.core import GameCore, category
from sc2data.game.sim.mining import Mining


class Game(Mining, Building, Combat):
    """All game state of one BuildMarines episode, advanced by :meth:`advance`.

    :class:`~sc2data.game.sim.core.GameCore` holds the state, the clock and the orders; the mining,
    building (construction and production) and combat rules come from the three parents.
    """


__all__ = ["Game", "GameCore", "category"]
