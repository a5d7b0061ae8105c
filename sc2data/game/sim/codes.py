"""Shared codes: heap event kinds, and action results from s2clientprotocol's ``error.proto``."""

from __future__ import annotations

# isort: off
import sc2data._pysc2  # noqa: F401  (sets up protobuf before s2clientprotocol loads)
from s2clientprotocol import error_pb2
# isort: on

# Heap event codes. Production/construction events check the producer's ``qtoken``, the others
# the unit's order ``token``: a newer order or a cancel makes older events stale.
ARRIVE, HARVEST_DONE, FIRE, RECHECK, PRODUCE_DONE, BUILD_DONE = range(6)

# Action results the game reports (``ActionResult``), shown in ``obs["action_result"]``.
NOT_ENOUGH_MINERALS: int = error_pb2.NotEnoughMinerals
NOT_ENOUGH_FOOD: int = error_pb2.NotEnoughFood
QUEUE_IS_FULL: int = error_pb2.QueueIsFull
CANT_BUILD_LOCATION_INVALID: int = error_pb2.CantBuildLocationInvalid
CANT_TARGET_THAT_UNIT: int = error_pb2.CantTargetThatUnit
MUST_TARGET_UNIT: int = error_pb2.MustTargetUnit
ERROR: int = error_pb2.Error

CHASE_RECHECK = 8.0
"""Loops between re-aiming at a moving attack target."""
