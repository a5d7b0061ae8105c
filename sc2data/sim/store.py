"""Unit records and the column store the drawing reads.

Game logic works on :class:`Unit` objects (plain Python, fast for the few units an event
touches); every attribute the feature layers need is mirrored into :class:`UnitTable`, numpy
columns indexed by the unit's slot, so drawing a frame is a handful of vectorised operations
over all units at once. Positions are stored as linear motions ``(x0, y0, t0) → (x1, y1, t1)``
and progress as ``prog0 + rate·(t − pt0)``: nothing is updated per game loop, the drawing
evaluates both at the frame's loop.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sc2data.sim.mapdata import UNIT_DATA, UnitData


@dataclass(frozen=True)
class Event:
    """Something that happened in the game during one agent step (see ``BuildMarinesEnv.events``).

    ``kind`` is one of :data:`EVENT_KINDS`; ``unit_type`` is a pysc2 ``units`` id; ``tag`` the
    unit's unique tag (for ``queued``/``cancelled``: the producer's tag).
    """

    loop: int
    kind: str
    unit_type: int
    tag: int


EVENT_KINDS: tuple[str, ...] = (
    "placed", "queued", "completed", "died", "cancelled", "gathered", "returned",
)

# Orders.
IDLE, MOVE, GATHER, RETURN, BUILD, CONSTRUCT, ATTACK, PATROL, HOLD = range(9)
# Gather phases.
TO_PATCH, WAITING, HARVESTING, TO_CC = range(4)

PLAYER_SELF = 1
PLAYER_NEUTRAL = 16
"""pysc2's absolute player ids: us, and the neutral player that owns mineral fields."""


class Unit:
    """One unit, structure or mineral field."""

    __slots__ = (
        "tag", "slot", "utype", "data", "owner", "alive",
        "x0", "y0", "t0", "x1", "y1", "t1",
        "prog0", "pt0", "prate", "dmg",
        "order", "token", "phase", "patch", "target", "tx", "ty", "px", "py",
        "cargo", "build_type", "building", "builder", "queue", "qtoken", "qt0", "rally",
        "ready", "minerals", "harvester", "waiting", "assigned",
    )

    def __init__(self, tag: int, slot: int, utype: int, owner: int, x: float, y: float) -> None:
        self.tag = tag
        self.slot = slot
        self.utype = utype
        self.data: UnitData = UNIT_DATA[utype]
        self.owner = owner
        self.alive = True
        self.x0 = self.x1 = x
        self.y0 = self.y1 = y
        self.t0 = self.t1 = 0.0
        self.prog0, self.pt0, self.prate = 1.0, 0.0, 0.0
        self.dmg = 0.0
        self.order = IDLE
        self.token = 0
        self.phase = 0
        self.patch: Unit | None = None
        self.target: Unit | None = None
        self.tx = self.ty = self.px = self.py = 0.0
        self.cargo = 0
        self.build_type = 0
        self.building: Unit | None = None
        self.builder: Unit | None = None
        self.queue: list[int] = []
        self.qtoken = 0
        self.qt0 = 0.0
        self.rally: tuple[float, float, Unit | None] | None = None
        self.ready = 0.0
        self.minerals = 0
        self.harvester: Unit | None = None
        self.waiting: list[Unit] = []
        self.assigned = 0

    def pos(self, t: float) -> tuple[float, float]:
        """Position at game loop ``t`` (linear motion between two way points)."""
        if t >= self.t1:
            return self.x1, self.y1
        if t <= self.t0:
            return self.x0, self.y0
        f = (t - self.t0) / (self.t1 - self.t0)
        return self.x0 + (self.x1 - self.x0) * f, self.y0 + (self.y1 - self.y0) * f

    def progress(self, t: float) -> float:
        """Build progress in [0, 1] at loop ``t`` (1 for finished units)."""
        p = self.prog0 + self.prate * (t - self.pt0)
        return 1.0 if p >= 1.0 else p

    def hp(self, t: float) -> float:
        """Hit points: a structure rises from 10% to full while built, less damage taken."""
        return self.data.hp * (0.1 + 0.9 * self.progress(t)) - self.dmg

    @property
    def complete(self) -> bool:
        return self.prog0 >= 1.0

    def __repr__(self) -> str:
        return f"Unit({self.utype}, tag={self.tag}, pos=({self.x1:.2f}, {self.y1:.2f}))"


class UnitTable:
    """Struct of arrays over unit slots: what the feature layers are drawn from."""

    FLOAT_COLS = ("x0", "y0", "t0", "x1", "y1", "t1", "prog0", "pt0", "prate", "dmg",
                  "radius", "hpmax")
    INT_COLS = ("utype", "owner", "layer", "tag", "selected")

    def __init__(self, capacity: int = 512) -> None:
        self.capacity = capacity
        self.alive = np.zeros(capacity, dtype=bool)
        self.f = np.zeros((len(self.FLOAT_COLS), capacity), dtype=np.float64)
        self.i = np.zeros((len(self.INT_COLS), capacity), dtype=np.int64)
        for n, k in enumerate(self.FLOAT_COLS):
            setattr(self, k, self.f[n])
        for n, k in enumerate(self.INT_COLS):
            setattr(self, k, self.i[n])
        self._free: list[int] = list(range(capacity - 1, -1, -1))

    def allocate(self) -> int:
        """A free slot (the lowest), growing the table when full."""
        if not self._free:
            self._grow()
        return self._free.pop()

    def _grow(self) -> None:
        old = self.capacity
        self.capacity *= 2
        self.alive = np.concatenate([self.alive, np.zeros(old, dtype=bool)])
        self.f = np.concatenate([self.f, np.zeros_like(self.f)], axis=1)
        self.i = np.concatenate([self.i, np.zeros_like(self.i)], axis=1)
        for n, k in enumerate(self.FLOAT_COLS):
            setattr(self, k, self.f[n])
        for n, k in enumerate(self.INT_COLS):
            setattr(self, k, self.i[n])
        self._free = list(range(self.capacity - 1, old - 1, -1))

    def add(self, u: Unit) -> None:
        """Mirror a new unit into its slot."""
        s = u.slot
        d = u.data
        self.alive[s] = True
        self.f[:, s] = (u.x0, u.y0, u.t0, u.x1, u.y1, u.t1, u.prog0, u.pt0, u.prate, u.dmg,
                        d.radius, d.hp)
        self.i[:, s] = (u.utype, u.owner, 0 if d.structure else 1, u.tag, 0)

    def remove(self, u: Unit) -> None:
        s = u.slot
        self.alive[s] = False
        self.selected[s] = 0
        self._free.append(s)
        self._free.sort(reverse=True)

    def motion(self, u: Unit) -> None:
        s = u.slot
        self.f[:6, s] = (u.x0, u.y0, u.t0, u.x1, u.y1, u.t1)

    def build(self, u: Unit) -> None:
        s = u.slot
        self.f[6:10, s] = (u.prog0, u.pt0, u.prate, u.dmg)

    def snapshot(self) -> dict[str, Any]:
        """Copies of all columns (for determinism checks and debugging)."""
        return {"alive": self.alive.copy(), "f": self.f.copy(), "i": self.i.copy()}
