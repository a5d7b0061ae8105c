"""An example sc2data rule plugin: "finish a supply depot".

``finish_supply_depot`` fires when a Supply Depot's construction completed between the two frames:
the supply cap (``player.food_cap``) rose, since a finished depot adds 8 supply. It complements
the built-in ``build_supply_depot``, which fires when construction *starts*. Limitation, written
down: the cap stops at 200, so a depot finishing at the cap is not seen.
"""

from __future__ import annotations

import numpy as np

from sc2data.rulebase import Rule, rose
from sc2data.schema import StackBatch


class FinishSupplyDepot(Rule):
    """A supply depot was completed: the supply cap rose."""

    id = "finish_supply_depot"
    command = "finish a supply depot"
    version = 1
    requires = ("player",)

    def __call__(self, batch: StackBatch) -> np.ndarray:
        return rose(batch.vector("player", "food_cap"))


RULES = [FinishSupplyDepot]
