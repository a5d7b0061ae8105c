"""``collect_minerals`` — "collect minerals".

Meaning: an idle SCV went back to mining. ``player.idle_worker_count`` fell while
``player.food_workers`` did not (so no idle SCV simply died). The obvious reading, "collected
minerals rose", fires on about half of all stacks on BuildMarines (twelve SCVs deliver all the
time), which makes it useless as a label; sending an idle worker back to the minerals is the
player's decision the command names, and it is a minority event.
"""

from __future__ import annotations

import numpy as np

from sc2data.rulebase import Rule, fell
from sc2data.schema import StackBatch


class CollectMinerals(Rule):
    """An idle SCV started gathering: the idle-worker count fell without a worker dying."""

    id = "collect_minerals"
    command = "collect minerals"
    version = 1
    requires = ("player",)

    def __call__(self, batch: StackBatch) -> np.ndarray:
        workers = batch.vector("player", "food_workers")
        idle = batch.vector("player", "idle_worker_count")
        return fell(idle) & (workers[:, 1] >= workers[:, 0])
