"""``train_marine`` — "train a marine".

Meaning: a Marine finished training between the two frames, read from
``score_cumulative.score``. On BuildMarines that field is the map's curriculum score, which adds
one for every marine created and never goes down, so it counts marines made whatever happens to
them: a marine dying in the same step (the strong strategies kill their own marines to stay
under the supply cap) neither hides a new one nor fakes one. ``player.army_count`` would be the
obvious alternative, but a death in the same step cancels a completion there.
"""

from __future__ import annotations

import numpy as np

from sc2data.rulebase import Rule, rose
from sc2data.schema import StackBatch


class TrainMarine(Rule):
    """A marine was completed: BuildMarines' cumulative score (marines made) rose."""

    id = "train_marine"
    command = "train a marine"
    version = 1
    requires = ("score_cumulative",)

    def __call__(self, batch: StackBatch) -> np.ndarray:
        return rose(batch.vector("score_cumulative", "score"))
