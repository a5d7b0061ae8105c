"""``build_supply_depot`` — "build a supply depot" (the paper's own example rule).

Meaning: construction of a new Supply Depot began between the two frames, seen on the screen's
``unit_type`` layer. The paper's wording is "the number of supply-depot pixels rose"; taken
literally that also fires when a marine or SCV (2×2 px at 64×64) walks off a depot and uncovers
its pixels, and misses a depot placed in the step a unit steps onto another. So we count only
depot pixels that *appeared on empty ground*: pixels that are ``SupplyDepot`` or
``SupplyDepotLowered`` now and were 0 (no unit) in the previous frame, and fire when at least
:data:`MIN_NEW_PIXELS` did. A new depot (2×2 world units, radius 1.125) covers 29–32 px, fewer at
the screen's left or right edge (the playable area is 2 units wider than the screen) or under the
SCV that builds it; a unit leaving a depot uncovers pixels that were the unit's, never empty ones.
A depot cancelled or finishing adds no pixels; lowering one turns ``SupplyDepot`` into
``SupplyDepotLowered`` (both counted) and adds none.
"""

from __future__ import annotations

import numpy as np

from sc2data._pysc2 import units
from sc2data.rulebase import Rule, appeared_pixels
from sc2data.schema import StackBatch

DEPOT_TYPES: tuple[int, ...] = (int(units.Terran.SupplyDepot), int(units.Terran.SupplyDepotLowered))
MIN_NEW_PIXELS = 8
"""Below a half-visible depot at the screen edge (~14 px), above any rendering jitter."""


class BuildSupplyDepot(Rule):
    """A new supply depot's footprint appeared on empty ground."""

    id = "build_supply_depot"
    command = "build a supply depot"
    version = 1
    requires = ("screen/unit_type",)

    def __call__(self, batch: StackBatch) -> np.ndarray:
        return appeared_pixels(batch, "screen/unit_type", DEPOT_TYPES) >= MIN_NEW_PIXELS
