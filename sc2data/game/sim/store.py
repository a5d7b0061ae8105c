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

from sc2data.game.sim.mapdata import UNIT_DATA, UnitData


@dataclass(frozen=True)
class Event:
    """Something that happened in the game during one agent step (``BuildMarinesEnv.events``).

    ``loop`` is the game loop it happened on, within ``[L − step_mul, L]`` for a step that
    ends on loop ``L`` (what the step's action did at once happens on ``L − step_mul``);
    ``unit_type`` a pysc2 ``units`` id; ``tag`` a unit's unique tag. Kinds
    (:data:`EVENT_KINDS`):

    - ``placed``: an SCV placed a structure, construction started (the new structure).
    - ``queued``: a unit was added to a train queue (the unit's type, the producer's tag).
    - ``completed``: a unit finished training or a structure finished building (the new unit).
    - ``died``: a unit was killed, or a mineral field ran out (the unit).
    - ``cancelled``: a queued unit was cancelled and refunded (its type, the producer's tag).
    - ``gathered``: an idle SCV was ordered to mine (the SCV).
    - ``returned``: an SCV delivered minerals to the CC (the SCV).
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
    """Struct of arrays over unit slots: what the feature layers are drawn from.

    ``f`` holds float columns (:data:`FLOAT_COLS`), ``i`` integer ones; ``attr`` holds the
    int32 values of the per-unit layers with one leading "no unit" entry, so a layer is
    ``attr[row].take(top)`` for a top-unit image of slot + 1. Rows 0–3 (player_id,
    player_relative, unit_type, selected) change only on creation, death and selection; the
    drawing fills rows 4–6 (hit points, their ratio, build progress) each frame.
    """

    FLOAT_COLS = ("x0", "y0", "t0", "x1", "y1", "t1", "prog0", "pt0", "prate", "dmg",
                  "radius", "hpmax", "ratio_k")
    INT_COLS = ("utype", "owner", "layer", "tag")
    ATTR_ROWS = 7

    # Views into ``f`` / ``i`` / ``attr`` (rebound when the table grows).
    x0: np.ndarray
    y0: np.ndarray
    t0: np.ndarray
    x1: np.ndarray
    y1: np.ndarray
    t1: np.ndarray
    prog0: np.ndarray
    pt0: np.ndarray
    prate: np.ndarray
    dmg: np.ndarray
    radius: np.ndarray
    hpmax: np.ndarray
    ratio_k: np.ndarray
    """255 / max hit points (0 for mineral fields): hit points → ``unit_hit_points_ratio``."""
    utype: np.ndarray
    owner: np.ndarray
    layer: np.ndarray
    """0 for structures and mineral fields, 1 for ground units (drawn on top)."""
    tag: np.ndarray
    selected: np.ndarray

    def __init__(self, capacity: int = 512) -> None:
        self.capacity = 0
        self.version = 0
        """Bumped whenever a unit is added or removed or its progress/damage columns change: the
        drawing recomputes hit points and progress only then, or while something is built."""
        self.alive = np.zeros(0, dtype=bool)
        self.f = np.zeros((len(self.FLOAT_COLS), 0), dtype=np.float64)
        self.i = np.zeros((len(self.INT_COLS), 0), dtype=np.int64)
        self.attr = np.zeros((self.ATTR_ROWS, 1), dtype=np.int32)
        self._free: list[int] = []
        self._ground: list[int] = []
        self._ground_arr: np.ndarray | None = None
        self._grow(capacity)

    def _grow(self, extra: int) -> None:
        self.version += 1
        old = self.capacity
        self.capacity = old + extra
        self.alive = np.concatenate([self.alive, np.zeros(extra, dtype=bool)])
        self.f = np.concatenate([self.f, np.zeros((self.f.shape[0], extra))], axis=1)
        self.i = np.concatenate([self.i, np.zeros((self.i.shape[0], extra), np.int64)], axis=1)
        self.attr = np.concatenate([self.attr, np.zeros((self.ATTR_ROWS, extra), np.int32)],
                                   axis=1)
        for n, k in enumerate(self.FLOAT_COLS):
            setattr(self, k, self.f[n])
        for n, k in enumerate(self.INT_COLS):
            setattr(self, k, self.i[n])
        self.selected = self.attr[3, 1:]
        self._free = sorted(self._free + list(range(old, self.capacity)), reverse=True)

    def allocate(self) -> int:
        """A free slot (the lowest), growing the table when full."""
        if not self._free:
            self._grow(self.capacity)
        return self._free.pop()

    def add(self, u: Unit) -> None:
        """Mirror a new unit into its slot."""
        self.version += 1
        s = u.slot
        d = u.data
        self.alive[s] = True
        self.f[:, s] = (u.x0, u.y0, u.t0, u.x1, u.y1, u.t1, u.prog0, u.pt0, u.prate, u.dmg,
                        d.radius, d.hp, 255.0 / d.hp if d.hp else 0.0)
        self.i[:, s] = (u.utype, u.owner, 0 if d.structure else 1, u.tag)
        rel = 1 if u.owner == PLAYER_SELF else 3  # features.PlayerRelative SELF / NEUTRAL
        self.attr[:4, s + 1] = (u.owner, rel, u.utype, 0)
        if not d.structure:
            self._ground.append(s)  # tags only grow, so this list stays in tag order
            self._ground_arr = None

    def remove(self, u: Unit) -> None:
        self.version += 1
        s = u.slot
        self.alive[s] = False
        self.attr[:, s + 1] = 0
        self._free.append(s)
        self._free.sort(reverse=True)
        if not u.data.structure:
            self._ground.remove(s)
            self._ground_arr = None

    def ground(self) -> np.ndarray:
        """Slots of the ground units (SCVs, marines), in tag order (later ones drawn on top)."""
        if self._ground_arr is None:
            self._ground_arr = np.array(self._ground, dtype=np.intp)
        return self._ground_arr

    def positions(self, slots: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """World positions of ``slots`` at loop ``t``."""
        x0, y0, t0, x1, y1, t1 = self.f[:6].take(slots, axis=1)
        f = np.minimum(np.maximum((t - t0) / np.maximum(t1 - t0, 1e-9), 0.0), 1.0)
        return x0 + (x1 - x0) * f, y0 + (y1 - y0) * f

    def motion(self, u: Unit) -> None:
        self.f[:6, u.slot] = (u.x0, u.y0, u.t0, u.x1, u.y1, u.t1)

    def build(self, u: Unit) -> None:
        self.version += 1
        self.f[6:10, u.slot] = (u.prog0, u.pt0, u.prate, u.dmg)

    def snapshot(self) -> dict[str, Any]:
        """Copies of all columns (for determinism checks and debugging)."""
        return {"alive": self.alive.copy(), "f": self.f.copy(), "i": self.i.copy(),
                "attr": self.attr.copy()}
