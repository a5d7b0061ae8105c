"""What each pysc2 function does in BuildMarines: selection, UI and unit commands.

Each handler gets a :class:`Context` (the one implementation is
:class:`~sc2data.game.sim.commands.Commands`, which imports this module) and the call's converted
arguments (pysc2's argument converters: points, enum values), carries the command out on the
game's current loop, and returns 0 or the ``ActionResult`` code the game would report (then
nothing happened). Commands go to the selected units that have the ability, as the game does:
a train command to the least busy producer, a build command to the nearest SCV.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from sc2data._pysc2 import actions
from sc2data.game.sim import mapdata as md
from sc2data.game.sim.codes import CANT_TARGET_THAT_UNIT, ERROR
from sc2data.game.sim.game import Game
from sc2data.game.sim.store import PLAYER_SELF, Unit


class Context(Protocol):
    """What a handler reads and changes besides the call's arguments."""

    game: Game
    last_idle_tag: int
    """The tag of the idle SCV the last ``select_idle_worker`` picked (the next call cycles on)."""

    @property
    def t(self) -> float:
        """The game loop now."""

    def production_unit(self) -> Unit | None:
        """The producer shown in the production panel, if any."""

    def unit_at_screen(self, p: Any) -> Unit | None:
        """The unit drawn on top at a screen pixel."""

    def own_selected(self, utypes: tuple[int, ...]) -> list[Unit]:
        """The selection's own finished units of these types."""

    def set_selection(self, units: list[Unit]) -> None:
        """Make ``units`` the selection."""

    def own_on_screen(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Own units' slots with their screen centres and pixel radii."""

    def world_target(self, kw: dict[str, Any]) -> tuple[float, float, Unit | None]:
        """The world point (and unit under it) of a screen or minimap argument."""

F = actions.FUNCTIONS
_PRODUCERS = (md.CC, md.BARRACKS)


def _select_point(c: Context, kw: dict[str, Any]) -> int:
    act = int(kw["select_point_act"])  # sc2 Select 1, Toggle 2, AllType 3, AddAllType 4
    u = c.unit_at_screen(kw["screen"])
    sel = c.game.selection
    if u is None:
        if act == 1:
            c.set_selection([])
        return 0
    own = u.owner == PLAYER_SELF
    mixed = (not own) or any(s.owner != PLAYER_SELF for s in sel)
    if act == 1 or mixed:
        c.set_selection([u] if act != 2 or u not in sel else [s for s in sel if s is not u])
    elif act == 2:
        c.set_selection([s for s in sel if s is not u] if u in sel else sel + [u])
    else:
        slots, sx, sy, r = c.own_on_screen()
        on = (sx > -r) & (sx < md.SCREEN + r) & (sy > -r) & (sy < md.SCREEN + r)
        on &= c.game.table.utype[slots] == u.utype
        same = [c.game.units[int(s)] for s in slots[on]]
        c.set_selection(same if act == 3 else sel + same)
    return 0


def _select_rect(c: Context, kw: dict[str, Any]) -> int:
    a, b = kw["screen"], kw["screen2"]
    x0, x1 = min(a.x, b.x), max(a.x, b.x) + 1
    y0, y1 = min(a.y, b.y), max(a.y, b.y) + 1
    slots, sx, sy, r = c.own_on_screen()
    nx = np.minimum(np.maximum(sx, x0), x1) - sx
    ny = np.minimum(np.maximum(sy, y0), y1) - sy
    hit = slots[nx * nx + ny * ny < r * r]
    movers = hit[c.game.table.layer[hit] == 1]
    if len(movers):
        hit = movers  # a box over units and structures selects the units only
    hits = [c.game.units[int(s)] for s in hit]
    add = bool(kw["select_add"])
    c.set_selection(c.game.selection + hits if add else hits)
    return 0


def _select_control_group(c: Context, kw: dict[str, Any]) -> int:
    act, gid = int(kw["control_group_act"]), int(kw["control_group_id"])
    groups = c.game.groups  # sc2 Recall 1, Set 2, Append 3, SetAndSteal 4, AppendAndSteal 5
    own = [u for u in c.game.selection if u.owner == PLAYER_SELF]
    if act == 1:
        if groups[gid]:
            c.set_selection(list(groups[gid]))
        return 0
    if act in (4, 5):
        for i, g in enumerate(groups):
            if i != gid:
                g[:] = [u for u in g if u not in own]
    if act in (2, 4):
        groups[gid] = sorted(own, key=lambda u: u.tag)
    else:
        groups[gid] = sorted(set(groups[gid]) | set(own), key=lambda u: u.tag)
    return 0


def _select_unit(c: Context, kw: dict[str, Any]) -> int:
    act, i = int(kw["select_unit_act"]), int(kw["select_unit_id"])
    sel = c.game.selection  # sc2 SingleSelect 1, DeselectUnit 2, SelectAllOfType 3, Deselect... 4
    if i >= len(sel):
        return ERROR
    u = sel[i]
    if act == 1:
        c.set_selection([u])
    elif act == 2:
        c.set_selection([s for s in sel if s is not u])
    elif act == 3:
        c.set_selection([s for s in sel if s.utype == u.utype])
    else:
        c.set_selection([s for s in sel if s.utype != u.utype])
    return 0


def _select_idle_worker(c: Context, kw: dict[str, Any]) -> int:
    act = int(kw["select_worker"])  # sc2 Set 1, Add 2, All 3, AddAll 4
    idle = sorted(c.game.idle_workers, key=lambda u: u.tag)
    if act in (3, 4):
        c.set_selection(idle if act == 3 else c.game.selection + idle)
        return 0
    pool = [u for u in idle if u not in c.game.selection] if act == 2 else idle
    if not pool:
        return 0
    nxt = next((u for u in pool if u.tag > c.last_idle_tag), pool[0])
    c.last_idle_tag = nxt.tag
    c.set_selection([nxt] if act == 1 else c.game.selection + [nxt])
    return 0


def _select_army(c: Context, kw: dict[str, Any]) -> int:
    army = c.game.army()
    c.set_selection(c.game.selection + army if bool(kw["select_add"]) else army)
    return 0


def _build_queue(c: Context, kw: dict[str, Any]) -> int:
    b = c.production_unit()
    if b is None:
        return ERROR
    return c.game.cancel(b, int(kw["build_queue_id"]), c.t)


def _train(utype: int, producer: int) -> Any:
    def handler(c: Context, kw: dict[str, Any]) -> int:
        cands = c.own_selected((producer,))
        if not cands:
            return ERROR
        b = min(cands, key=lambda b: (len(b.queue), b.tag))  # the least busy, like the game
        return c.game.train(b, utype, c.t)
    return handler


def _build(utype: int) -> Any:
    def handler(c: Context, kw: dict[str, Any]) -> int:
        scvs = c.own_selected((md.SCV,))
        if not scvs:
            return ERROR
        x, y, _ = c.world_target(kw)
        builder = min(scvs, key=lambda u: (_d2(u.pos(c.t), (x, y)), u.tag))
        return c.game.order_build(builder, utype, x, y, c.t)
    return handler


def _d2(a: tuple[float, float], b: tuple[float, float]) -> float:
    return (a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2


def _gather(c: Context, kw: dict[str, Any]) -> int:
    x, y, target = c.world_target(kw)
    if target is None or target.utype != md.MINERAL:
        return CANT_TARGET_THAT_UNIT
    err = 0
    for u in c.own_selected((md.SCV,)):
        err = c.game.order_gather(u, target, c.t) or err
    return err


def _return_cargo(c: Context, kw: dict[str, Any]) -> int:
    for u in c.own_selected((md.SCV,)):
        if u.cargo:
            c.game.order_return(u, c.t)
    return 0


def _marines(c: Context) -> list[Unit]:
    return c.own_selected((md.MARINE,))


def _attack(c: Context, kw: dict[str, Any]) -> int:
    x, y, target = c.world_target(kw)
    for u in _marines(c):
        if target is not None and target.owner == PLAYER_SELF and target is not u:
            c.game.order_attack(u, target, c.t)
        else:  # attack-move: nothing hostile on this map, so the marines just walk there
            c.game.order_move(u, x, y, c.t)
    return 0


def _move(c: Context, kw: dict[str, Any]) -> int:
    x, y, _ = c.world_target(kw)
    for u in _marines(c):
        c.game.order_move(u, x, y, c.t)
    return 0


def _patrol(c: Context, kw: dict[str, Any]) -> int:
    x, y, _ = c.world_target(kw)
    for u in _marines(c):
        c.game.order_patrol(u, x, y, c.t)
    return 0


def _stop(hold: bool) -> Any:
    def handler(c: Context, kw: dict[str, Any]) -> int:
        for u in _marines(c):
            c.game.order_idle(u, c.t, hold=hold)
        return 0
    return handler


def _rally(c: Context, kw: dict[str, Any], producers: tuple[int, ...] = (md.CC,)) -> int:
    x, y, target = c.world_target(kw)
    patch = target if target is not None and target.utype == md.MINERAL else None
    for b in c.own_selected(producers):
        b.rally = (x, y, patch if b.utype == md.CC else None)
    return 0


def _smart(c: Context, kw: dict[str, Any]) -> int:
    """Right-click: gather / return / resume building / move for SCVs, move for marines,
    rally for production structures."""
    x, y, target = c.world_target(kw)
    g, t = c.game, c.t
    for u in c.own_selected((md.SCV,)):
        if target is not None and target.utype == md.MINERAL:
            g.order_gather(u, target, t)
        elif target is g.cc and u.cargo:
            g.order_return(u, t)
        elif target is not None and target.owner == PLAYER_SELF and target.data.structure \
                and not target.complete:
            g.order_resume(u, target, t)
        else:
            g.order_move(u, x, y, t)
    for u in _marines(c):
        g.order_move(u, x, y, t)
    _rally(c, kw, _PRODUCERS)
    return 0


HANDLERS: dict[int, Callable[[Context, dict[str, Any]], int]] = {
    # function id -> handler(commands, converted kwargs) -> ActionResult code (0: success)
    int(F.select_point.id): _select_point,
    int(F.select_rect.id): _select_rect,
    int(F.select_control_group.id): _select_control_group,
    int(F.select_unit.id): _select_unit,
    int(F.select_idle_worker.id): _select_idle_worker,
    int(F.select_army.id): _select_army,
    int(F.build_queue.id): _build_queue,
    int(F.Train_SCV_quick.id): _train(md.SCV, md.CC),
    int(F.Train_Marine_quick.id): _train(md.MARINE, md.BARRACKS),
    int(F.Build_SupplyDepot_screen.id): _build(md.DEPOT),
    int(F.Build_Barracks_screen.id): _build(md.BARRACKS),
    int(F.Harvest_Gather_screen.id): _gather,
    int(F.Harvest_Return_quick.id): _return_cargo,
    int(F.Attack_screen.id): _attack,
    int(F.Attack_minimap.id): _attack,
    int(F.Move_screen.id): _move,
    int(F.Move_minimap.id): _move,
    int(F.Patrol_screen.id): _patrol,
    int(F.Patrol_minimap.id): _patrol,
    int(F.HoldPosition_quick.id): _stop(True),
    int(F.Stop_quick.id): _stop(False),
    int(F.Rally_Workers_screen.id): _rally,
    int(F.Rally_Workers_minimap.id): _rally,
    int(F.Smart_screen.id): _smart,
    int(F.Smart_minimap.id): _smart,
}
