"""``collect_minerals`` — "collect minerals".

Meaning: an idle SCV was put back to work. ``player.idle_worker_count`` fell while
``player.food_workers`` did not, so an idle SCV that simply died does not count (an SCV queued in
that same step would hide the death, since supply is taken at queue time — rare).

Why not "collected minerals rose": twelve or more SCVs deliver all the time on BuildMarines, so
that fires on about half of all stacks and would leave no null states. Sending idle workers back to
the minerals is the player's decision the command names, and it is a minority event.

Known limits, measured on simulator rollouts (tests/rules/test_sim_agreement.py): a two-frame
stack cannot tell an idle SCV sent to *build* from one sent to mine — both leave the idle count at
once, and a building's cost is only paid when the SCV arrives, steps later — and an SCV going idle
(its building done) in the very step another is sent to mine keeps the count level. Against the
simulator's record of idle SCVs sent to mine ("gathered"), with the reduced random agent (whose
build macro prefers idle SCVs), precision is 85–92% and recall about 96%; against what the stack
can show — "an idle SCV was given work", on steps where no SCV went idle — both are 100%. The
direction the SCV walks is the only other difference, and over one step (≈4 px) it does not
separate the two reliably.
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
