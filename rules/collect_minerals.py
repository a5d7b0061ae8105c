"""``collect_minerals`` — "collect minerals".

Meaning: an idle SCV was put back to work. ``player.idle_worker_count`` fell while
``player.food_workers`` (workers that exist) did not, so an idle SCV that simply died does not
count (an SCV completed in that same step would hide the death — rare).

Why not "collected minerals rose": twelve or more SCVs deliver all the time on BuildMarines, so
that fires on about half of all stacks and would leave no null states. Sending idle workers back to
the minerals is the player's decision the command names, and it is a minority event.

Known limits: a two-frame stack cannot tell an idle SCV sent to *build* from one sent to mine —
both leave the idle count at once, and a building's cost is only paid when the SCV arrives, steps
later — and an SCV going idle (its building done) in the very step another is sent to mine keeps
the count level. Our agents take builders off the mineral line, as players do, so the first case is
rare in their data. Against the simulator's record of idle SCVs sent to mine ("gathered"), over 4
reduced-random and 2 scripted episodes: precision 99.2%, recall 98.3% (119 events); on steps where
no SCV went idle, both ≥ 99% (tests/rules/test_sim_agreement.py).
"""

from __future__ import annotations

import numpy as np

from sc2data.rulebase import Rule, fell
from sc2data.schema import StackBatch


class CollectMinerals(Rule):
    """An idle SCV went back to work: the idle-worker count fell without a worker dying."""

    id = "collect_minerals"
    command = "collect minerals"
    version = 1
    requires = ("player",)

    def __call__(self, batch: StackBatch) -> np.ndarray:
        workers = batch.vector("player", "food_workers")
        idle = batch.vector("player", "idle_worker_count")
        return fell(idle) & (workers[:, 1] >= workers[:, 0])
