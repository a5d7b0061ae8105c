"""Construction and production: SCVs place and build structures; the CC and Barracks train.

Costs follow the game: a unit's minerals and supply are taken when it is queued (queues of 5,
refused without the minerals or free supply) — ``food_used`` counts it from then on, while
``food_workers`` and ``food_army`` count only units that exist, as the game's do; a structure's
minerals when its SCV reaches the site and places it (the order itself is refused when the site
is invalid or the minerals are short). A structure under construction rises from 10% hit
points; it pauses if its SCV is ordered away or dies (another SCV resumes it with a right-click)
and the SCV goes idle when it completes. Supply from a depot or CC counts only once it is complete.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from sc2data.game.sim import mapdata as md
from sc2data.game.sim.codes import (
    ARRIVE,
    BUILD_DONE,
    CANT_BUILD_LOCATION_INVALID,
    ERROR,
    NOT_ENOUGH_FOOD,
    NOT_ENOUGH_MINERALS,
    PRODUCE_DONE,
    QUEUE_IS_FULL,
)
from sc2data.game.sim.core import GameCore
from sc2data.game.sim.store import BUILD, CONSTRUCT, PLAYER_SELF, Unit


class Building(GameCore):
    """Structures and train queues (part of :class:`~sc2data.game.sim.game.Game`)."""

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

    def placement_ok(self, x: float, y: float, footprint: tuple[int, int]) -> bool:
        """Buildable, unoccupied ground inside the playable area (units are pushed aside)."""
        rows, cols = md.footprint_cells(x, y, footprint)
        if rows.start < 0 or cols.start < 0 or rows.stop > md.MAP_SIZE or cols.stop > md.MAP_SIZE:
            return False
        return bool(self.playable[rows, cols].all() and not self.occupied[rows, cols].any())

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
        tech_lost = u.build_type == md.BARRACKS and not self.has_completed(md.DEPOT)
        if tech_lost or not self.placement_ok(u.tx, u.ty, data.footprint) or \
                self.minerals < data.minerals:
            self.order_idle(u, t)
            return
        self.minerals -= data.minerals
        self.spent += data.minerals
        b = self._create(u.build_type, PLAYER_SELF, u.tx, u.ty, t, complete=False)
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
        self._structure_done(b)
        u = b.builder
        b.builder = None
        if u is not None and u.alive and u.order == CONSTRUCT:
            u.building = None  # finished: nothing to pause
            self.order_idle(u, t)

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
        self.food_queued += data.supply_cost
        b.queue.append(utype)
        self._emit(t, "queued", utype, b.tag)
        if len(b.queue) == 1:
            self._start_item(b, t)
        return 0

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
        self.food_queued -= data.supply_cost
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
        cost = md.UNIT_DATA[utype].supply_cost
        self.food_queued -= cost  # the supply stays taken: it moves to the unit that now exists
        self._add_food(utype, cost)
        if utype == md.SCV:
            self._spawn_scv(b, t)
        else:
            self._spawn_marine(b, t)
        if b.queue:  # the next unit has already had this loop (real replays: 271, 399)
            self._start_item(b, t - md.QUEUE_HANDOFF_LOOPS)
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
        rings = _spawn_rings(max(b.data.footprint), r)
        reach = max(b.data.footprint) / 2 + r * (2 * len(rings) + 1)
        ground = self.table.ground()
        gx, gy = self.table.positions(ground, t)
        near = (np.abs(gx - b.x1) < reach) & (np.abs(gy - b.y1) < reach)
        gx, gy = gx[near], gy[near]
        x0, y0, x1, y1 = md.PLAYABLE
        for dx, dy in rings:
            cx, cy = b.x1 + dx, b.y1 + dy
            ok = (cx > x0 + r) & (cx < x1 - r) & (cy > y0 + r) & (cy < y1 - r)
            ok &= ~self.occupied[np.clip(cy.astype(int), 0, 63), np.clip(cx.astype(int), 0, 63)]
            if len(gx):
                d2 = (cx[:, None] - gx[None, :]) ** 2 + (cy[:, None] - gy[None, :]) ** 2
                ok &= (d2 >= (2 * r * 0.95) ** 2).all(axis=1)
            hits = np.flatnonzero(ok)
            if len(hits):
                return float(cx[hits[0]]), float(cy[hits[0]])
        return b.x1, b.y1 - max(b.data.footprint) / 2 - r


@functools.cache
def _spawn_rings(size: int, r: float, count: int = 12) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Offsets of spawn spots around a ``size``-cell footprint, ring by ring outwards, each
    ring's spots ordered from the south side round."""
    out = []
    for ring in range(count):
        half = size / 2 + r + ring * 2 * r
        n = max(4, int(8 * half / (2 * r)))
        ang = -math.pi / 2 + 2 * math.pi * np.arange(n) / n
        order = np.argsort(np.abs(((ang + math.pi / 2 + math.pi) % (2 * math.pi)) - math.pi),
                           kind="stable")
        ang = ang[order]
        out.append((half * np.clip(np.cos(ang) * 1.5, -1, 1),
                    half * np.clip(np.sin(ang) * 1.5, -1, 1)))
    return tuple(out)
