"""The embedded BuildMarines simulator, speaking pysc2's environment interface.

Modules, one job each: :mod:`~sc2data.game.sim.mapdata` (map geometry and game numbers),
:mod:`~sc2data.game.sim.store` (unit records and the column store drawing reads),
:mod:`~sc2data.game.sim.core` (state, clock, orders, death) with its rules in
:mod:`~sc2data.game.sim.mining`, :mod:`~sc2data.game.sim.building` and :mod:`~sc2data.game.sim.combat`, put
together as :class:`~sc2data.game.sim.game.Game`,
:mod:`~sc2data.game.sim.codes` (event and result codes), :mod:`~sc2data.game.sim.commands` (pysc2
``FunctionCall`` validation, ``available_actions``) with :mod:`~sc2data.game.sim.handlers` (what
each function does), :mod:`~sc2data.game.sim.observe` (feature-layer drawing),
:mod:`~sc2data.game.sim.obsdict` (the observation dict) and :mod:`~sc2data.game.sim.env` (the
``environment.Base`` wrapper).
"""

from sc2data.game.sim.env import BuildMarinesEnv
from sc2data.game.sim.store import EVENT_KINDS, Event

__all__ = ["BuildMarinesEnv", "EVENT_KINDS", "Event"]
