"""``build_scv`` — "build an SCV".

Meaning: an SCV finished training between the two frames. Read from ``player.food_workers``, the
supply held by the player's existing workers: it rises by one when an SCV leaves the Command
Center (queued SCVs do not count until they exist, unlike ``food_used``, which reserves supply at
queue time). An SCV that dies in the same step as another finishes cancels it out and is missed;
nothing on BuildMarines kills SCVs but the player's own marines, so that is rare.
"""

from __future__ import annotations

import numpy as np

from sc2data.rulebase import Rule, rose
from sc2data.schema import StackBatch


class BuildScv(Rule):
    """An SCV was completed: ``player.food_workers`` rose."""

    id = "build_scv"
    command = "build an SCV"
    version = 1
    requires = ("player",)

    def __call__(self, batch: StackBatch) -> np.ndarray:
        return rose(batch.vector("player", "food_workers"))
