"""``build_scv`` — "build an SCV".

Meaning: an SCV finished training between the two frames. The value of units says so:
``score_cumulative.total_value_units`` grows by an SCV's or a marine's cost (50 minerals each)
when one is created, and ``score_cumulative.score`` — BuildMarines' curriculum score — counts
marines created. So an SCV appeared when the units' value rose by more than the marines made
explain::

    Δ total_value_units > MARINE_MINERALS × Δ score

(``player.food_used`` will not do: supply is taken when an SCV is *queued*, 272 game loops before
it exists. ``player.food_workers`` counts only workers that exist, as the game's does, but an SCV
dying in the same step cancels a completion there.)

This holds whether the game counts ``total_value_units`` over living units (the simulator; a unit
dying lowers it, which can only hide an event, never fake one) or over all units ever made. It
misses an SCV finishing in the very step a unit dies (rare: only marines die on BuildMarines,
killed by the player's own army near the supply cap).
"""

from __future__ import annotations

import numpy as np

from sc2data.rulebase import Rule, change
from sc2data.schema import StackBatch

MARINE_MINERALS = 50
"""A marine's mineral cost (Legacy of the Void game data)."""


class BuildScv(Rule):
    """An SCV was completed: the units' value rose by more than the marines made account for."""

    id = "build_scv"
    command = "build an SCV"
    version = 1
    requires = ("score_cumulative",)

    def __call__(self, batch: StackBatch) -> np.ndarray:
        value = change(batch.vector("score_cumulative", "total_value_units"))
        marines = change(batch.vector("score_cumulative", "score"))
        return value > MARINE_MINERALS * marines
