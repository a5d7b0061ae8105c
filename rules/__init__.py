"""Built-in labelling rules, installed as ``sc2data.rules``.

They reach the registry the way a third-party plugin does: through the ``sc2data.rules``
entry-point group (``builtin = "sc2data.rules"`` in pyproject.toml), which names this module and
its ``RULES``. Each rule lives in its own module, whose docstring says what it means.
"""

from __future__ import annotations

from sc2data.rulebase import Rule
from sc2data.rules.build_barracks import BuildBarracks
from sc2data.rules.build_scv import BuildScv
from sc2data.rules.build_supply_depot import BuildSupplyDepot
from sc2data.rules.collect_minerals import CollectMinerals
from sc2data.rules.train_marine import TrainMarine

RULES: tuple[Rule, ...] = (
    BuildScv(),
    CollectMinerals(),
    BuildSupplyDepot(),
    BuildBarracks(),
    TrainMarine(),
)

__all__ = ["RULES", "BuildBarracks", "BuildScv", "BuildSupplyDepot", "CollectMinerals",
           "TrainMarine"]
