"""``build_barracks`` — "build a barracks".

Meaning: construction of a new Barracks began between the two frames: at least
:data:`MIN_NEW_PIXELS` screen pixels became ``Barracks`` on ground that was empty (unit_type 0) in
the previous frame. The same reasoning as ``build_supply_depot``: a new barracks (3×3 world units)
covers 73–80 px at 64×64 (about two thirds of that at the screen's left or right edge), while a
marine or SCV walking off one uncovers only pixels that were its own, never empty ground. A
barracks cancelled or finishing, or a marine leaving it, adds no pixels.
"""

from __future__ import annotations

import numpy as np

from sc2data._pysc2 import units
from sc2data.rulebase import Rule, appeared_pixels
from sc2data.schema import StackBatch

BARRACKS_TYPES: tuple[int, ...] = (int(units.Terran.Barracks),)
MIN_NEW_PIXELS = 20
"""Well under an edge-clipped new barracks (~45 px), far above any rendering jitter."""


class BuildBarracks(Rule):
    """A new barracks' footprint appeared on empty ground."""

    id = "build_barracks"
    command = "build a barracks"
    version = 1
    requires = ("screen/unit_type",)

    def __call__(self, batch: StackBatch) -> np.ndarray:
        return appeared_pixels(batch, "screen/unit_type", BARRACKS_TYPES) >= MIN_NEW_PIXELS
