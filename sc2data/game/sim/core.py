"""The core of the game: state, clock, supply, orders, events, death.

The game is event driven: every unit's state changes only at known game loops (a worker
arrives, a harvest ends, a unit finishes training, a marine fires), kept in a heap. Advancing
the game pops the events up to the target loop; between events units move on straight lines and
structures build at a constant rate, which :class:`~sc2data.game.sim.store.UnitTable` evaluates at
drawing time. This keeps a step's cost proportional to what happens in it, not to the number of
game loops or units. The rules themselves live in three subclasses that
:class:`sc2data.game.sim.game.Game` combines: :mod:`~sc2data.game.sim.mining`,
:mod:`~sc2data.game.sim.building` (construction and production) and :mod:`~sc2data.game.sim.combat`;
:class:`GameCore` declares the hooks it calls on them.

Numbers come from :mod:`sc2data.game.sim.mapdata` (the map file and StarCraft II's game data). Simplifications, each chosen because
BuildMarines never exercises the difference: units move in straight lines and do not collide or
path around structures (a structure placed on units leaves them where they stand); the
``queued`` (shift) flag of commands is ignored (a queued command replaces the current one, so a
builder never has queued orders and always goes idle when done); there is no enemy, so marines
only fight what they are ordered to and never acquire targets on their own.
"""

from __future__ import annotations

import abc
import collections
import heapq
import math
import random

import numpy as np

from sc2data.game.sim import mapdata as md
from sc2data.game.sim.codes import (
    ARRIVE,
    BUILD_DONE,
    FIRE,
    HARVEST_DONE,
    PRODUCE_DONE,
    RECHECK,
)
from sc2data.game.sim.store import (
    ATTACK,
    BUILD,
    CONSTRUCT,
    GATHER,
    HARVESTING,
    HOLD,
    IDLE,
    MOVE,
    PATROL,
    PLAYER_NEUTRAL,
    PLAYER_SELF,
    RETURN,
    TO_PATCH,
    WAITING,
    Event,
    Unit,
    UnitTable,
)


class GameCore(abc.ABC):
    """All game state of one BuildMarines episode, advanced by :meth:`advance`."""

    def __init__(self, seed: int | None = None) -> None:
        self._rng = random.Random(seed)
        self.reset()

    # ------------------------------------------------------------------ set-up

    def reset(self) -> None:
        """A fresh episode: the map's start state, workers sent to mine."""
        self.loop = 0
        self.table = UnitTable()
        self.units: dict[int, Unit] = {}
        self._heap: list[tuple[float, int, int, Unit, int]] = []
        self._seq = 0
        self._next_tag = 1
        self.events: list[Event] = []
        self.occupied = np.zeros((md.MAP_SIZE, md.MAP_SIZE), dtype=bool)
        self.playable = md.playable_cells()
        self.grid_version = 0
        """Bumped whenever a footprint is added or removed (static layers are redrawn then)."""
        self.minerals = md.START_MINERALS
        self.food_workers = 0
        """Supply of the workers that exist (the game's ``food_workers``: not those in training)."""
        self.food_army = 0
        """Supply of the army units that exist (the game's ``food_army``)."""
        self.food_queued = 0
        """Supply of the units in production queues: taken when a unit is queued, so it counts in
        ``food_used`` but in neither of the two above until the unit exists."""
        self.food_cap = 0
        self.score = 0
        self.army_count = 0
        """Marines alive (pysc2's ``army_count``)."""
        self.collected = 0
        self.spent = 0
        self.lost_value = 0
        self.value_units = 0
        self.value_structures = 0
        self.value_by_category = [0, 0, 0, 0, 0]
        """Mineral value of living units by pysc2 ``ScoreCategories`` (none, army, economy,
        technology, upgrade)."""
        self.damage_dealt = 0.0
        self.idle_worker_time = 0.0
        self.idle_production_time = 0.0
        self._last_accrue = 0.0
        self._deliveries: collections.deque[tuple[float, int]] = collections.deque()
        self._window_sum = 0
        self.idle_workers: set[Unit] = set()
        self.idle_producers: set[Unit] = set()
        self.selection: list[Unit] = []
        self.selection_version = 0
        """Bumped whenever the selection changes (commands cache what they derive from it)."""
        self.groups: list[list[Unit]] = [[] for _ in range(10)]

        self.patches = [self._create(md.MINERAL, PLAYER_NEUTRAL, x, y) for x, y in md.MINERAL_POS]
        for p in self.patches:
            p.minerals = md.MINERAL_AMOUNT
        self.completed: dict[int, int] = {}
        self.cc = self._create(md.CC, PLAYER_SELF, *md.CC_POS)
        rally_patch = self._patch_at(*md.CC_RALLY)
        assert rally_patch is not None
        self.cc.rally = (*md.CC_RALLY, rally_patch)
        side = self._rng.choice((-1.0, 1.0))
        cx, cy = md.CC_POS
        scvs = [self._create(md.SCV, PLAYER_SELF, cx + side * dx, cy + dy)
                for dx in md.SCV_X_OFFSETS for dy in md.SCV_Y_OFFSETS]
        self.food_workers = len(scvs)
        for u in sorted(scvs, key=lambda u: self._dist_to(u, rally_patch)):
            self.idle_workers.add(u)
            self.order_gather(u, rally_patch, 0.0, emit=False)

    def _create(self, utype: int, owner: int, x: float, y: float, t: float = 0.0,
                complete: bool = True) -> Unit:
        """A new unit at (x, y) on loop ``t``: finished, or a structure just placed."""
        u = Unit(self._next_tag, self.table.allocate(), utype, owner, x, y)
        self._next_tag += 1
        u.t0 = u.t1 = t
        if not complete:
            u.prog0, u.pt0 = 0.0, t
        self.units[u.slot] = u
        self.table.add(u)
        if owner == PLAYER_SELF:
            self._value(u, +1)
        if u.data.structure:
            rows, cols = md.footprint_cells(x, y, u.data.footprint)
            self.occupied[rows, cols] = True
            self.grid_version += 1
            if complete and owner == PLAYER_SELF:
                self._structure_done(u)
        return u

    def _structure_done(self, b: Unit) -> None:
        """Count a finished structure: its supply, the Barracks' requirement, idle production."""
        self.completed[b.utype] = self.completed.get(b.utype, 0) + 1
        if b.data.supply_provided:
            self._recount_supply()
        if b.utype in (md.BARRACKS, md.CC):
            self.idle_producers.add(b)

    def _value(self, u: Unit, sign: int) -> None:
        v = sign * u.data.minerals
        if u.data.structure:
            self.value_structures += v
        else:
            self.value_units += v
        self.value_by_category[category(u.utype)] += v

    # ------------------------------------------------------------------ time

    def advance(self, to: int) -> None:
        """Run the game up to loop ``to``, processing every event due by then."""
        heap = self._heap
        while heap and heap[0][0] <= to:
            t, _, code, u, tok = heapq.heappop(heap)
            if not u.alive or tok != (u.qtoken if code >= PRODUCE_DONE else u.token):
                continue
            self._accrue(t)
            if code == ARRIVE:
                self._arrive(u, t)
            elif code == HARVEST_DONE:
                self._harvest_done(u, t)
            elif code == FIRE:
                self._fire(u, t)
            elif code == RECHECK:
                self._attack_update(u, t)
            elif code == PRODUCE_DONE:
                self._produce_done(u, t)
            elif code == BUILD_DONE:
                self._build_done(u, t)
        self._accrue(float(to))
        self.loop = to

    def _at(self, t: float, code: int, u: Unit) -> None:
        tok = u.qtoken if code >= PRODUCE_DONE else u.token
        self._seq += 1
        heapq.heappush(self._heap, (t, self._seq, code, u, tok))

    def _accrue(self, t: float) -> None:
        dt = t - self._last_accrue
        if dt > 0:
            self.idle_worker_time += len(self.idle_workers) * dt
            self.idle_production_time += len(self.idle_producers) * dt
            self._last_accrue = t

    def _emit(self, t: float, kind: str, u: Unit | int, tag: int | None = None) -> None:
        utype = u if isinstance(u, int) else u.utype
        self.events.append(Event(int(math.ceil(t - 1e-9)), kind, int(utype),
                                 int(tag if tag is not None else u.tag)))  # type: ignore[union-attr]

    # ------------------------------------------------------------------ derived state

    def _add_food(self, utype: int, n: int) -> None:
        """Supply taken (n > 0) or freed (n < 0) by an existing unit of ``utype``."""
        if utype == md.SCV:
            self.food_workers += n
        else:
            self.food_army += n

    @property
    def food_used(self) -> int:
        """All supply taken: existing units and those queued (the game's ``food_used``)."""
        return self.food_workers + self.food_army + self.food_queued

    def _recount_supply(self) -> None:
        cap = sum(u.data.supply_provided for u in self.units.values()
                  if u.owner == PLAYER_SELF and u.complete)
        self.food_cap = min(md.MAX_SUPPLY, cap)

    def has_completed(self, utype: int) -> bool:
        """Whether a finished ``utype`` exists (the Barracks' tech requirement)."""
        return self.completed.get(utype, 0) > 0

    def army(self) -> list[Unit]:
        return sorted((u for u in self.units.values() if u.utype == md.MARINE), key=_tag)

    def collection_rate(self) -> int:
        """Minerals per real ("faster") minute over the last 240 loops (fewer at the start), as
        the game's ``minerals_collection_rate`` counts them: real replays show it in steps of
        5 minerals × 1344 / 240 (a delivery) and, before loop 240, scaled by 1344 / loop."""
        window = float(min(md.COLLECTION_WINDOW, self.loop)) or 1.0
        horizon = self.loop - window
        dq = self._deliveries
        while dq and dq[0][0] <= horizon:
            self._window_sum -= dq.popleft()[1]
        return int(self._window_sum * 1344.0 / window)

    # ------------------------------------------------------------------ motion

    def _move(self, u: Unit, t: float, x: float, y: float, extra: float = 0.0) -> float:
        """Start ``u`` walking to (x, y); returns the arrival loop (``extra`` loops added).

        Targets outside the playable area are pulled to its edge, where the game stops units.
        """
        r = u.data.radius
        x0, y0, x1, y1 = md.PLAYABLE
        x = min(max(x, x0 + r), x1 - r)
        y = min(max(y, y0 + r), y1 - r)
        sx, sy = u.pos(t)
        d = math.hypot(x - sx, y - sy)
        u.x0, u.y0, u.t0 = sx, sy, t
        u.x1, u.y1 = x, y
        u.t1 = t + d / u.data.speed + extra
        self.table.motion(u)
        return u.t1

    def _halt(self, u: Unit, t: float) -> None:
        x, y = u.pos(t)
        u.x0 = u.x1 = x
        u.y0 = u.y1 = y
        u.t0 = u.t1 = t
        self.table.motion(u)

    @staticmethod
    def _dist_to(u: Unit, v: Unit, t: float = 0.0) -> float:
        ux, uy = u.pos(t)
        vx, vy = v.pos(t)
        return math.hypot(ux - vx, uy - vy)

    def _edge_point(self, frm: tuple[float, float], v: Unit, gap: float) -> tuple[float, float]:
        """The point ``gap`` beyond ``v``'s radius on the line from ``v`` towards ``frm``."""
        dx, dy = frm[0] - v.x1, frm[1] - v.y1
        d = math.hypot(dx, dy) or 1.0
        r = v.data.radius + gap
        return v.x1 + dx / d * r, v.y1 + dy / d * r

    # ------------------------------------------------------------------ orders

    def _clear_order(self, u: Unit, t: float) -> None:
        """Undo the side effects of ``u``'s current order (patch slots, construction)."""
        u.token += 1
        if u.order in (GATHER, RETURN) and u.patch is not None:
            p = u.patch
            p.assigned -= 1
            if u.order == GATHER and u.phase == HARVESTING and p.harvester is u:
                p.harvester = None
                self._next_harvester(p, t)
            elif u.order == GATHER and u.phase == WAITING and u in p.waiting:
                p.waiting.remove(u)
        elif u.order == CONSTRUCT and u.building is not None and u.building.alive:
            self._pause_construction(u.building, t)
        u.patch = None
        u.target = None
        u.building = None

    def _set_order(self, u: Unit, order: int, t: float) -> None:
        self._clear_order(u, t)
        u.order = order
        if u.utype == md.SCV:
            if order == IDLE:
                self.idle_workers.add(u)
            else:
                self.idle_workers.discard(u)

    def order_idle(self, u: Unit, t: float, hold: bool = False) -> None:
        """Stop (or hold position): drop the order and stand still."""
        self._set_order(u, HOLD if hold else IDLE, t)
        self._halt(u, t)

    def order_move(self, u: Unit, x: float, y: float, t: float) -> None:
        self._set_order(u, MOVE, t)
        self._at(self._move(u, t, x, y), ARRIVE, u)

    def order_patrol(self, u: Unit, x: float, y: float, t: float) -> None:
        self._set_order(u, PATROL, t)
        u.px, u.py = u.pos(t)
        u.tx, u.ty = x, y
        self._at(self._move(u, t, x, y), ARRIVE, u)

    # ------------------------------------------------------------------ arrival dispatch

    def _arrive(self, u: Unit, t: float) -> None:
        o = u.order
        if o == GATHER:
            if u.phase == TO_PATCH:
                self._reach_patch(u, t)
            else:
                self._deliver(u, t)
                self._to_patch(u, t)
        elif o == RETURN:
            self._deliver(u, t)
            p = u.patch
            if p is not None and p.alive:
                p.assigned -= 1
                u.patch = None
                self.order_gather(u, p, t, emit=False)
            else:
                self.order_idle(u, t)
        elif o == BUILD:
            self._place(u, t)
        elif o == PATROL:
            u.px, u.py, u.tx, u.ty = u.tx, u.ty, u.px, u.py
            self._at(self._move(u, t, u.tx, u.ty), ARRIVE, u)
        elif o == ATTACK:
            self._attack_update(u, t)
        else:
            self.order_idle(u, t)

    # ------------------------------------------------------------------ death

    def _kill(self, u: Unit, t: float) -> None:
        """Remove a unit: free its supply, slots, selection and footprint."""
        self._accrue(t)
        if u.owner == PLAYER_SELF:
            self._clear_order(u, t)
        u.alive = False
        self.units.pop(u.slot, None)
        self.table.remove(u)
        self._emit(t, "died", u)
        self.idle_workers.discard(u)
        self.idle_producers.discard(u)
        if u in self.selection:
            self.selection.remove(u)
            self.selection_version += 1
        for g in self.groups:
            if u in g:
                g.remove(u)
        d = u.data
        if u.owner == PLAYER_SELF:
            self.lost_value += d.minerals
            self._value(u, -1)
        if d.supply_cost:
            self._add_food(u.utype, -d.supply_cost)
        if u.utype == md.MARINE:
            self.army_count -= 1
        if d.structure and u.complete and u.owner == PLAYER_SELF:
            self.completed[u.utype] -= 1
        if d.structure:
            rows, cols = md.footprint_cells(u.x1, u.y1, d.footprint)
            self.occupied[rows, cols] = False
            self.grid_version += 1
            for q in u.queue:
                self.food_queued -= md.UNIT_DATA[q].supply_cost
            u.queue.clear()
            if d.supply_provided:
                self._recount_supply()
            if u.builder is not None and u.builder.alive:
                u.builder.building = None
                self.order_idle(u.builder, t)

    # ------------------------------------------------------------------ rules (subclasses)

    @abc.abstractmethod
    def order_gather(self, u: Unit, patch: Unit | None, t: float, emit: bool = True) -> int:
        raise NotImplementedError

    @abc.abstractmethod
    def _patch_at(self, x: float, y: float) -> Unit | None:
        raise NotImplementedError

    @abc.abstractmethod
    def _to_patch(self, u: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _reach_patch(self, u: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _next_harvester(self, p: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _harvest_done(self, u: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _deliver(self, u: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _place(self, u: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _pause_construction(self, b: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _build_done(self, b: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _produce_done(self, b: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _attack_update(self, u: Unit, t: float) -> None:
        raise NotImplementedError

    @abc.abstractmethod
    def _fire(self, u: Unit, t: float) -> None:
        raise NotImplementedError



def category(utype: int) -> int:
    """pysc2 ``ScoreCategories`` index of a unit type: marines army (1); SCVs, the CC and depots
    economy (2); barracks technology (3)."""
    if utype == md.MARINE:
        return 1
    if utype == md.BARRACKS:
        return 3
    return 2


def _tag(u: Unit) -> int:
    return u.tag
