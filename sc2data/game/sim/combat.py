"""Combat: marines attack what they are ordered to, with the Marine's real weapon.

No enemy exists on BuildMarines; the scripted agents attack their own units (Attack on a unit
is allowed on any target) to stay under the 200 supply cap. A marine walks into range
(5 + both radii), then fires every ``MARINE_COOLDOWN`` loops for 6 damage less armour; a
moving target is re-aimed every ``CHASE_RECHECK`` loops.
"""

from __future__ import annotations

import math

from sc2data.game.sim import mapdata as md
from sc2data.game.sim.codes import CHASE_RECHECK, FIRE, RECHECK
from sc2data.game.sim.core import GameCore
from sc2data.game.sim.store import ATTACK, Unit


class Combat(GameCore):
    """Attack orders, chasing and firing (part of :class:`~sc2data.game.sim.game.Game`)."""

    def order_attack(self, u: Unit, target: Unit, t: float) -> None:
        self._set_order(u, ATTACK, t)
        u.target = target
        self._attack_update(u, t)

    def _reach(self, u: Unit, v: Unit) -> float:
        return md.MARINE_RANGE + u.data.radius + v.data.radius

    def _live_target(self, u: Unit, t: float) -> Unit | None:
        """``u``'s target if it still lives; otherwise ``u`` goes idle and None is returned."""
        v = u.target
        if v is None or not v.alive:
            self.order_idle(u, t)
            return None
        return v

    def _attack_update(self, u: Unit, t: float) -> None:
        v = self._live_target(u, t)
        if v is None:
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
        v = self._live_target(u, t)
        if v is None:
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
