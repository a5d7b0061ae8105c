"""The embedded BuildMarines simulator, speaking pysc2's environment interface.

Modules, one job each: :mod:`~sc2data.sim.mapdata` (map geometry and game numbers),
:mod:`~sc2data.sim.store` (unit records and the column store drawing reads),
:mod:`~sc2data.sim.game` (economy, production, construction, orders, combat),
:mod:`~sc2data.sim.commands` (pysc2 ``FunctionCall`` validation and execution,
``available_actions``), :mod:`~sc2data.sim.observe` (feature-layer drawing),
:mod:`~sc2data.sim.obsdict` (the observation dict) and :mod:`~sc2data.sim.env` (the
``environment.Base`` wrapper).
"""

from sc2data.sim.env import BuildMarinesEnv
from sc2data.sim.store import EVENT_KINDS, Event

__all__ = ["BuildMarinesEnv", "EVENT_KINDS", "Event"]
