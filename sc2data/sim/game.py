"""The BuildMarines game rules: economy, production, construction, orders and combat.

The game is event driven: every unit's state changes only at known game loops (a worker
arrives, a harvest ends, a unit finishes training, a marine fires), kept in a heap. Advancing
the game pops the events up to the target loop; between events units move on straight lines and
structures build at a constant rate, which :class:`~sc2data.sim.store.UnitTable` evaluates at
drawing time. This keeps a step's cost proportional to what happens in it, not to the number of
game loops or units.

Numbers come from :mod:`sc2data.sim.mapdata` (brief §3–4). Simplifications, each chosen because
BuildMarines never exercises the difference: units move in straight lines and do not collide or
path around structures; the ``queued`` (shift) flag of commands is ignored (a queued command
replaces the current one); there is no enemy, so marines only fight what they are ordered to.
"""

from __future__ import annotations

import heapq
import math
import random
from collections.abc import Iterable

import numpy as np

from sc2data.sim import mapdata as md
from sc2data.sim.store import (ATTACK, BUILD, CONSTRUCT, GATHER, HARVESTING, HOLD, IDLE, MOVE,
                               PATROL, PLAYER_NEUTRAL, PLAYER_SELF, RETURN, TO_CC, TO_PATCH,
                               WAITING, Event, Unit, UnitTable)

# Heap event codes. Production/construction events check the producer's ``qtoken``, the others
# the unit's order ``token``: a newer order or a cancel makes older events stale.
ARRIVE, HARVEST_DONE, FIRE, RECHECK, PRODUCE_DONE, BUILD_DONE = range(6)

# Action results (s2clientprotocol error.proto ``ActionResult``).
NOT_ENOUGH_MINERALS = 9
NOT_ENOUGH_FOOD = 13
QUEUE_IS_FULL = 7
CANT_BUILD_LOCATION_INVALID = 44
CANT_TARGET_THAT_UNIT = 36
MUST_TARGET_UNIT = 81
ERROR = 3

CHASE_RECHECK = 8.0
"""Loops between re-aiming at a moving attack target."""


class Game:
    """All game state of one BuildMarines episode, advanced by :meth:`advance`."""

    def __init__(self, seed: int | None = None) -> None:
        self._rng = random.Random(seed)
        self.reset()

    # ------------------------------------------------------------------ set-up

    def reset(self) -> None:
        """A fresh episode: the map's start state, workers sent to mine (brief §3)."""
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
        self.food_army = 0
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
        self._deliveries: list[tuple[float, int]] = []
        self.idle_workers: set[Unit] = set()
        self.idle_producers: set[Unit] = set()
        self.selection: list[Unit] = []
        self.selection_version = 0
        """Bumped whenever the selection changes (commands cache what they derive from it)."""
        self.groups: list[list[Unit]] = [[] for _ in range(10)]

        self.patches = [self._create(md.MINERAL, PLAYER_NEUTRAL, x, y) for x, y in md.MINERAL_POS]
        for p in self.patches:
            p.minerals = md.MINERAL_AMOUNT
        self.cc = self._create(md.CC, PLAYER_SELF, *md.CC_POS)
        self.completed: dict[int, int] = {md.CC: 1}
        self.cc.rally = (*md.CC_RALLY, self._patch_at(*md.CC_RALLY))
        self._recount_supply()
        self.idle_producers.add(self.cc)
        side = self._rng.choice((-1.0, 1.0))
        cx, cy = md.CC_POS
        scvs = [self._create(md.SCV, PLAYER_SELF, cx + side * dx, cy + dy)
                for dx in md.SCV_X_OFFSETS for dy in md.SCV_Y_OFFSETS]
        self.food_workers = len(scvs)
        for u in sorted(scvs, key=lambda u: self._dist_to(u, self.cc.rally[2])):
            self.idle_workers.add(u)
            self.order_gather(u, self.cc.rally[2], 0.0, emit=False)

    def _create(self, utype: int, owner: int, x: float, y: float, t: float = 0.0) -> Unit:
        u = Unit(self._next_tag, self.table.allocate(), utype, owner, x, y)
        self._next_tag += 1
        u.t0 = u.t1 = t
        self.units[u.slot] = u
        self.table.add(u)
        if owner == PLAYER_SELF:
            self._value(u, +1)
        if u.data.structure:
            rows, cols = md.footprint_cells(x, y, u.data.footprint)
            self.occupied[rows, cols] = True
            self.grid_version += 1
        return u

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
            else:
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

    @property
    def food_used(self) -> int:
        return self.food_workers + self.food_army

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
        """Minerals per (real, "faster") minute over the last 15 s, as the game's income shows."""
        window = 336.0
        horizon = self.loop - window
        self._deliveries = [d for d in self._deliveries if d[0] > horizon]
        got = sum(n for _, n in self._deliveries)
        return int(got * 1344.0 / window)

    # ------------------------------------------------------------------ motion

    def _move(self, u: Unit, t: float, x: float, y: float, extra: float = 0.0) -> float:
        """Start ``u`` walking to (x, y); returns the arrival loop (``extra`` loops added)."""
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

    def order_gather(self, u: Unit, patch: Unit | None, t: float, emit: bool = True) -> int:
        """Send an SCV to mine ``patch`` (spreading to a less busy field like the game does)."""
        if patch is None or not patch.alive:
            return MUST_TARGET_UNIT
        if emit and u.order == IDLE:
            self._emit(t, "gathered", u)
        self._set_order(u, GATHER, t)
        patch = self._spread(patch)
        u.patch = patch
        patch.assigned += 1
        if u.cargo:
            u.phase = TO_CC
            self._to_cc(u, t)
        else:
            self._to_patch(u, t)
        return 0

    def order_return(self, u: Unit, t: float) -> None:
        """Return cargo to the CC, then resume mining the last field (if any)."""
        patch = u.patch if u.order in (GATHER, RETURN) else None
        self._set_order(u, RETURN, t)
        if patch is not None and patch.alive:
            u.patch = patch
            patch.assigned += 1
        self._to_cc(u, t)

    def order_build(self, u: Unit, utype: int, x: float, y: float, t: float) -> int:
        """Send an SCV to build ``utype`` at (x, y); checks placement and cost as the game does.

        The cost is only spent when the SCV arrives and the structure is placed.
        """
        data = md.UNIT_DATA[utype]
        sx, sy = md.snap_to_grid(x, y, data.footprint)
        if not self.placement_ok(sx, sy, data.footprint):
            return CANT_BUILD_LOCATION_INVALID
        if self.minerals < data.minerals:
            return NOT_ENOUGH_MINERALS
        self._set_order(u, BUILD, t)
        u.build_type, u.tx, u.ty = utype, sx, sy
        ux, uy = u.pos(t)
        d = math.hypot(sx - ux, sy - uy)
        reach = max(data.footprint) / 2 + u.data.radius
        if d <= reach:
            self._at(t, ARRIVE, u)
        else:
            f = (d - reach) / d
            self._at(self._move(u, t, ux + (sx - ux) * f, uy + (sy - uy) * f), ARRIVE, u)
        return 0

    def order_resume(self, u: Unit, b: Unit, t: float) -> None:
        """An SCV resumes building an unfinished structure whose builder stopped."""
        if b.builder is not None:
            self.order_move(u, b.x1, b.y1, t)
            return
        self._set_order(u, BUILD, t)
        u.build_type, u.tx, u.ty = b.utype, b.x1, b.y1
        u.building = b
        x, y = self._edge_point(u.pos(t), b, u.data.radius)
        self._at(self._move(u, t, x, y), ARRIVE, u)

    def order_attack(self, u: Unit, target: Unit, t: float) -> None:
        self._set_order(u, ATTACK, t)
        u.target = target
        self._attack_update(u, t)

    def placement_ok(self, x: float, y: float, footprint: tuple[int, int]) -> bool:
        """Buildable, unoccupied ground inside the playable area (units are pushed aside)."""
        rows, cols = md.footprint_cells(x, y, footprint)
        if rows.start < 0 or cols.start < 0 or rows.stop > md.MAP_SIZE or cols.stop > md.MAP_SIZE:
            return False
        return bool(self.playable[rows, cols].all() and not self.occupied[rows, cols].any())

    # ------------------------------------------------------------------ mining

    def _patch_at(self, x: float, y: float) -> Unit | None:
        for p in self.patches:
            if p.alive and abs(p.x1 - x) < 0.01 and abs(p.y1 - y) < 0.01:
                return p
        return None

    def _spread(self, patch: Unit) -> Unit:
        """The field a worker sent to ``patch`` ends up mining: itself unless it is full and a
        field with fewer workers exists, then the nearest such one."""
        if patch.assigned < md.WORKERS_PER_PATCH:
            return patch
        alive = [p for p in self.patches if p.alive]
        least = min(p.assigned for p in alive)
        if least >= patch.assigned:
            return patch
        cands = [p for p in alive if p.assigned == least]
        return min(cands, key=lambda p: (math.hypot(p.x1 - patch.x1, p.y1 - patch.y1), p.tag))

    def _to_patch(self, u: Unit, t: float) -> None:
        u.phase = TO_PATCH
        x, y = self._edge_point((self.cc.x1, self.cc.y1), u.patch, u.data.radius)  # type: ignore[arg-type]
        self._at(self._move(u, t, x, y, md.MINING_LEG_OVERHEAD), ARRIVE, u)

    def _to_cc(self, u: Unit, t: float) -> None:
        if not self.cc.alive:
            self.order_idle(u, t)
            return
        src = (u.patch.x1, u.patch.y1) if u.patch is not None else u.pos(t)
        x, y = self._edge_point(src, self.cc, u.data.radius)
        self._at(self._move(u, t, x, y, md.MINING_LEG_OVERHEAD), ARRIVE, u)

    def _next_harvester(self, p: Unit, t: float) -> None:
        while p.waiting and p.harvester is None:
            w = p.waiting.pop(0)
            if w.alive and w.order == GATHER and w.phase == WAITING and w.patch is p:
                self._start_harvest(w, p, t)

    def _start_harvest(self, u: Unit, p: Unit, t: float) -> None:
        """``u`` takes the field: it mines once the previous miner has cleared it."""
        u.phase = HARVESTING
        p.harvester = u
        self._at(max(t, p.ready) + md.HARVEST_LOOPS, HARVEST_DONE, u)

    def _harvest_done(self, u: Unit, t: float) -> None:
        p = u.patch
        assert p is not None
        p.harvester = None
        p.ready = t + md.PATCH_CLEAR_LOOPS
        take = min(md.CARRY, p.minerals)
        p.minerals -= take
        u.cargo = take
        self._next_harvester(p, t)
        if p.minerals <= 0:
            self._deplete(p, t)
        u.phase = TO_CC
        self._to_cc(u, t)

    def _deplete(self, p: Unit, t: float) -> None:
        self._kill(p, t)
        for w in [w for w in self.units.values() if w.patch is p]:
            alive = [q for q in self.patches if q.alive]
            if not alive:
                self.order_idle(w, t)
                continue
            nearest = min(alive, key=lambda q: (math.hypot(q.x1 - p.x1, q.y1 - p.y1), q.tag))
            if w.order == GATHER and w.phase == TO_CC:
                w.patch = nearest
                p.assigned -= 1
                nearest.assigned += 1
            else:
                self.order_gather(w, nearest, t, emit=False)

    def _deliver(self, u: Unit, t: float) -> None:
        if u.cargo:
            self.minerals += u.cargo
            self.collected += u.cargo
            self._deliveries.append((t, u.cargo))
            u.cargo = 0
            self._emit(t, "returned", u)

    # ------------------------------------------------------------------ arrival dispatch

    def _arrive(self, u: Unit, t: float) -> None:
        o = u.order
        if o == GATHER:
            if u.phase == TO_PATCH:
                p = u.patch
                assert p is not None
                if p.harvester is None:
                    self._start_harvest(u, p, t)
                else:
                    u.phase = WAITING
                    p.waiting.append(u)
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

    # ------------------------------------------------------------------ construction

    def _place(self, u: Unit, t: float) -> None:
        """The builder reached its site: start the structure, or give up as the game would."""
        b = u.building
        if b is not None:  # resuming an unfinished structure
            if not b.alive or b.builder is not None or b.complete:
                self.order_idle(u, t)
                return
            self._start_construction(u, b, t)
            return
        data = md.UNIT_DATA[u.build_type]
        if not self.placement_ok(u.tx, u.ty, data.footprint) or self.minerals < data.minerals:
            self.order_idle(u, t)
            return
        self.minerals -= data.minerals
        self.spent += data.minerals
        b = self._create(u.build_type, PLAYER_SELF, u.tx, u.ty, t)
        b.prog0, b.pt0 = 0.0, t
        self.table.build(b)
        self._emit(t, "placed", b)
        self._start_construction(u, b, t)

    def _start_construction(self, u: Unit, b: Unit, t: float) -> None:
        self._set_order(u, CONSTRUCT, t)
        self._halt(u, t)
        u.building = b
        b.builder = u
        b.prog0, b.pt0 = b.progress(t), t
        b.prate = 1.0 / b.data.build_loops
        b.qtoken += 1
        self.table.build(b)
        self._at(t + (1.0 - b.prog0) * b.data.build_loops, BUILD_DONE, b)

    def _pause_construction(self, b: Unit, t: float) -> None:
        b.prog0, b.pt0, b.prate = b.progress(t), t, 0.0
        b.qtoken += 1
        b.builder = None
        self.table.build(b)

    def _build_done(self, b: Unit, t: float) -> None:
        b.prog0, b.pt0, b.prate = 1.0, t, 0.0
        self.table.build(b)
        self._emit(t, "completed", b)
        self.completed[b.utype] = self.completed.get(b.utype, 0) + 1
        if b.data.supply_provided:
            self._recount_supply()
        if b.utype in (md.BARRACKS, md.CC):
            self.idle_producers.add(b)
        u = b.builder
        b.builder = None
        if u is not None and u.alive and u.order == CONSTRUCT:
            u.building = None  # finished: nothing to pause
            self.order_idle(u, t)

    # ------------------------------------------------------------------ production

    def train(self, b: Unit, utype: int, t: float) -> int:
        """Queue a unit: cost and supply are taken now; refused when full, poor or capped."""
        data = md.UNIT_DATA[utype]
        if len(b.queue) >= md.QUEUE_LIMIT:
            return QUEUE_IS_FULL
        if self.minerals < data.minerals:
            return NOT_ENOUGH_MINERALS
        if self.food_used + data.supply_cost > self.food_cap:
            return NOT_ENOUGH_FOOD
        self.minerals -= data.minerals
        self.spent += data.minerals
        self._add_food(utype, data.supply_cost)
        b.queue.append(utype)
        self._emit(t, "queued", utype, b.tag)
        if len(b.queue) == 1:
            self._start_item(b, t)
        return 0

    def _add_food(self, utype: int, n: int) -> None:
        if utype == md.SCV:
            self.food_workers += n
        else:
            self.food_army += n

    def _start_item(self, b: Unit, t: float) -> None:
        self.idle_producers.discard(b)
        b.qt0 = t
        b.qtoken += 1
        self._at(t + md.UNIT_DATA[b.queue[0]].build_loops, PRODUCE_DONE, b)

    def item_progress(self, b: Unit, t: float) -> float:
        """Progress in [0, 1] of the first unit in ``b``'s queue."""
        if not b.queue:
            return 0.0
        return min(1.0, (t - b.qt0) / md.UNIT_DATA[b.queue[0]].build_loops)

    def cancel(self, b: Unit, index: int, t: float) -> int:
        """Cancel the ``index``-th queued unit: refund its cost and supply."""
        if index >= len(b.queue):
            return ERROR
        utype = b.queue.pop(index)
        data = md.UNIT_DATA[utype]
        self.minerals += data.minerals
        self.spent -= data.minerals
        self._add_food(utype, -data.supply_cost)
        self._emit(t, "cancelled", utype, b.tag)
        if index == 0:
            b.qtoken += 1
            if b.queue:
                self._start_item(b, t)
            else:
                self.idle_producers.add(b)
        return 0

    def _produce_done(self, b: Unit, t: float) -> None:
        utype = b.queue.pop(0)
        if utype == md.SCV:
            self._spawn_scv(b, t)
        else:
            self._spawn_marine(b, t)
        if b.queue:
            self._start_item(b, t)
        else:
            self.idle_producers.add(b)

    def _spawn_scv(self, cc: Unit, t: float) -> None:
        rally = cc.rally
        toward = (rally[0], rally[1]) if rally else (cc.x1 - 1.0, cc.y1)
        x, y = self._edge_point(toward, cc, md.UNIT_DATA[md.SCV].radius)
        u = self._create(md.SCV, PLAYER_SELF, x, y, t)
        self._emit(t, "completed", u)
        self.idle_workers.add(u)
        if rally and rally[2] is not None and rally[2].alive:
            self.order_gather(u, rally[2], t, emit=False)
        elif rally:
            self.order_move(u, rally[0], rally[1], t)

    def _spawn_marine(self, b: Unit, t: float) -> None:
        x, y = self._spawn_spot(b, t)
        u = self._create(md.MARINE, PLAYER_SELF, x, y, t)
        self.score += 1
        self.army_count += 1
        self._emit(t, "completed", u)
        if b.rally:
            self.order_move(u, b.rally[0], b.rally[1], t)

    def _spawn_spot(self, b: Unit, t: float) -> tuple[float, float]:
        """A free spot next to ``b``: rings around its footprint, south side first."""
        r = md.UNIT_DATA[md.MARINE].radius
        ground = self.table.ground()
        if len(ground):
            gx, gy = self.table.positions(ground, t)
        x0, y0, x1, y1 = md.PLAYABLE
        for ring in range(12):
            half = max(b.data.footprint) / 2 + r + ring * 2 * r
            n = max(4, int(8 * half / (2 * r)))
            ang = -math.pi / 2 + 2 * math.pi * np.arange(n) / n
            order = np.argsort(np.abs(((ang + math.pi / 2 + math.pi) % (2 * math.pi)) - math.pi),
                               kind="stable")
            ang = ang[order]
            cx = b.x1 + half * np.clip(np.cos(ang) * 1.5, -1, 1)
            cy = b.y1 + half * np.clip(np.sin(ang) * 1.5, -1, 1)
            ok = (cx > x0 + r) & (cx < x1 - r) & (cy > y0 + r) & (cy < y1 - r)
            cells = self.occupied[np.clip(cy.astype(int), 0, 63), np.clip(cx.astype(int), 0, 63)]
            ok &= ~cells
            if len(ground):
                d2 = (cx[:, None] - gx[None, :]) ** 2 + (cy[:, None] - gy[None, :]) ** 2
                ok &= (d2 >= (2 * r * 0.95) ** 2).all(axis=1)
            hits = np.flatnonzero(ok)
            if len(hits):
                return float(cx[hits[0]]), float(cy[hits[0]])
        return b.x1, b.y1 - max(b.data.footprint) / 2 - r

    # ------------------------------------------------------------------ combat

    def _reach(self, u: Unit, v: Unit) -> float:
        return md.MARINE_RANGE + u.data.radius + v.data.radius

    def _attack_update(self, u: Unit, t: float) -> None:
        v = u.target
        if v is None or not v.alive:
            self.order_idle(u, t)
            return
        ux, uy = u.pos(t)
        vx, vy = v.pos(t)
        d = math.hypot(vx - ux, vy - uy)
        reach = self._reach(u, v)
        if d <= reach + 1e-6:
            self._halt(u, t)
            self._at(max(t, u.ready), FIRE, u)
            return
        step = d - reach + 0.05
        arrive = self._move(u, t, ux + (vx - ux) / d * step, uy + (vy - uy) / d * step)
        moving = v.t1 > t
        self._at(min(arrive, t + CHASE_RECHECK) if moving else arrive, RECHECK, u)

    def _fire(self, u: Unit, t: float) -> None:
        v = u.target
        if v is None or not v.alive:
            self.order_idle(u, t)
            return
        ux, uy = u.pos(t)
        vx, vy = v.pos(t)
        if math.hypot(vx - ux, vy - uy) > self._reach(u, v) + 1e-6:
            self._attack_update(u, t)
            return
        dmg = max(0.5, md.MARINE_DAMAGE - v.data.armor)
        v.dmg += dmg
        self.damage_dealt += dmg
        self.table.build(v)
        u.ready = t + md.MARINE_COOLDOWN
        if v.hp(t) <= 1e-9:
            self._kill(v, t)
            self.order_idle(u, t)
        else:
            self._at(u.ready, FIRE, u)

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
                self._add_food(q, -md.UNIT_DATA[q].supply_cost)
            u.queue.clear()
            if d.supply_provided:
                self._recount_supply()
            if u.builder is not None and u.builder.alive:
                u.builder.building = None
                self.order_idle(u.builder, t)


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


def sorted_by_tag(us: Iterable[Unit]) -> list[Unit]:
    return sorted(us, key=_tag)
