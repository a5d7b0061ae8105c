"""The embedded BuildMarines simulator, speaking pysc2's environment interface.

Modules, one job each: :mod:`~sc2data.sim.mapdata` (map geometry and game numbers),
:mod:`~sc2data.sim.store` (unit records and the column store drawing reads),
:mod:`~sc2data.sim.core` (state, clock, orders, death) with its rules in
:mod:`~sc2data.sim.mining`, :mod:`~sc2data.sim.building` and :mod:`~sc2data.sim.combat`, put
together as :class:`~sc2data.sim.game.Game`,
:mod:`~sc2data.sim.codes` (event and result codes), :mod:`~sc2data.sim.commands` (pysc2
``FunctionCall`` validation, ``available_actions``) with :mod:`~sc2data.sim.handlers` (what
each function does), :mod:`~sc2data.sim.observe` (feature-layer drawing),
:mod:`~sc2data.sim.obsdict` (the observation dict) and :mod:`~sc2data.sim.env` (the
``environment.Base`` wrapper).
"""

from sc2data.sim.env import BuildMarinesEnv
from sc2data.sim.store import EVENT_KINDS, Event

__all__ = ["BuildMarinesEnv", "EVENT_KINDS", "Event"]
