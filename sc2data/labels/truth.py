"""What the built-in rules' commands mean in the simulator's own record of the game.

A rule reads two frames; the embedded simulator knows what happened between them
(:class:`sc2data.game.sim.store.Event`, ``BuildMarinesEnv.events``). For the five built-in
commands the event that *is* the command, in one pysc2 step:

* ``build_scv`` — an SCV ``completed``;  ``train_marine`` — a Marine ``completed``;
* ``build_supply_depot`` / ``build_barracks`` — a SupplyDepot / Barracks ``placed``;
* ``collect_minerals`` — ``gathered``: an idle SCV ordered to mine (not one sent to build).

The rules are held to this record in ``tests/rules/test_sim_agreement.py`` on the data agents'
play, and ``sc2data rl agreement`` holds both the rules and the MEM to it on a trained policy's
own play, where the rules' two frames can say something else (an idle SCV sent to *build*
leaves the idle count exactly as one sent to mine does).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from sc2data._pysc2 import units
from sc2data.game.sim.store import Event

T = units.Terran
EVENT_OF: dict[str, tuple[str, int]] = {
    "build_scv": ("completed", int(T.SCV)),
    "collect_minerals": ("gathered", int(T.SCV)),
    "build_supply_depot": ("placed", int(T.SupplyDepot)),
    "build_barracks": ("placed", int(T.Barracks)),
    "train_marine": ("completed", int(T.Marine)),
}
"""Per built-in rule id, the (kind, unit type) of the event that is its command."""


def truth(events: Iterable[Event], ids: Sequence[str]) -> np.ndarray:
    """``(len(ids),)`` bool: whether the command of each rule id happened in these events (one
    pysc2 step's); False for an id with no event in :data:`EVENT_OF`."""
    seen = {(e.kind, int(e.unit_type)) for e in events}
    return np.array([EVENT_OF.get(i) in seen for i in ids], dtype=bool)
