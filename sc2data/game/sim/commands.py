"""pysc2 ``FunctionCall``s in, game orders out; and the ``available_actions`` they are checked by.

Validation mirrors ``features.Features.transform_action`` of pysc2 4.0.0 line for line (same
exceptions, same messages, including its lenient range check that only rejects negative
values), so an agent that works here fails or succeeds the same way on ``SC2Env``.
``available_actions`` follows ``features.Features.available_actions``: pysc2's always-available
UI functions plus the general functions of the abilities on the selection's command cards, the
cards cut down as BuildMarines cuts them (SCV: gather, return, depot, barracks; CC: SCV, rally;
Barracks: marine; Marine: move, stop, hold, attack, patrol). What each function then does is in
:mod:`sc2data.game.sim.handlers`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from sc2data._pysc2 import actions
from sc2data.game.sim import mapdata as md
from sc2data.game.sim.game import Game
from sc2data.game.sim.handlers import HANDLERS
from sc2data.game.sim.store import PLAYER_SELF, Unit

F = actions.FUNCTIONS
_SCREEN_SIZES = (md.SCREEN, md.SCREEN)
_MINIMAP_SIZES = (md.MINIMAP, md.MINIMAP)

# Abilities on each (cut-down) command card, as (ability_id, requires_point), by pysc2's own
# function table. Smart (right-click) is not a card button, so the map leaves it to every unit
# that can take it.
_SMART = (F.Smart_screen.ability_id, True)
_CARD: dict[int, tuple[tuple[int, bool], ...]] = {
    md.SCV: ((F.Harvest_Gather_SCV_screen.ability_id, True),
             (F.Build_SupplyDepot_screen.ability_id, True), _SMART),
    md.CC: ((F.Train_SCV_quick.ability_id, False),
            (F.Rally_CommandCenter_screen.ability_id, True), _SMART),
    md.BARRACKS: ((F.Train_Marine_quick.ability_id, False), _SMART),
    md.DEPOT: (),
    md.MARINE: ((F.Attack_Attack_screen.ability_id, True), (F.Move_Move_screen.ability_id, True),
                (F.Patrol_Patrol_screen.ability_id, True),
                (F.HoldPosition_Hold_quick.ability_id, False),
                (F.Stop_Stop_quick.ability_id, False), _SMART),
    md.MINERAL: (),
}
_RETURN_CARGO = (F.Harvest_Return_SCV_quick.ability_id, False)
"""Shown only while the SCV carries minerals."""
_BUILD_BARRACKS = (F.Build_Barracks_screen.ability_id, True)
"""Shown only once a Supply Depot is finished (the Barracks' requirement)."""

_PRODUCERS = (md.CC, md.BARRACKS)


def functions_for(abilities: frozenset[tuple[int, bool]]) -> frozenset[int]:
    """Function ids for a set of available abilities, exactly as pysc2 derives them.

    ``features.Features.available_actions`` with ``hide_specific_actions=True``: each ability's
    functions of the right point-type are offered through their general function.
    """
    out: set[int] = set()
    for ability_id, requires_point in abilities:
        found = False
        for func in actions.ABILITY_IDS[ability_id]:
            if func.function_type in actions.POINT_REQUIRED_FUNCS[requires_point]:
                if func.general_id == 0:
                    out.add(int(func.id))
                    found = True
                if func.general_id != 0:
                    for general in actions.ABILITY_IDS[func.general_id]:
                        if general.function_type is func.function_type:
                            out.add(int(general.id))
                            found = True
                            break
        if not found:
            raise ValueError(f"Failed to find applicable action for {ability_id}")
    return frozenset(out)


class Commands:
    """Applies validated ``FunctionCall``s to a :class:`Game` and reports what is available."""

    def __init__(self, game: Game) -> None:
        self.game = game
        self._cache: dict[frozenset[tuple[int, bool]], frozenset[int]] = {}
        self.top: np.ndarray = np.zeros((md.SCREEN, md.SCREEN), dtype=np.int64)
        """Slot + 1 of the unit drawn on top at each screen pixel (0: none), set by drawing."""
        self.action_result: list[int] = []
        self.last_actions: list[int] = []
        self.last_idle_tag = 0
        self._groups: dict[int, list[Unit]] = {}
        self._groups_version = -1

    # ------------------------------------------------------------------ availability

    def _selected_by_type(self) -> dict[int, list[Unit]]:
        """The selection's own units grouped by type (cached until the selection changes)."""
        g = self.game
        if self._groups_version != g.selection_version:
            groups: dict[int, list[Unit]] = {}
            for u in g.selection:
                if u.owner == PLAYER_SELF:
                    groups.setdefault(u.utype, []).append(u)
            self._groups = groups
            self._groups_version = g.selection_version
        return self._groups

    def abilities(self) -> frozenset[tuple[int, bool]]:
        """The abilities of the selection's command cards (the union over selected units).

        A structure under construction shows nothing (its card, Cancel, is cut).
        """
        g = self.game
        out: set[tuple[int, bool]] = set()
        for utype, us in self._selected_by_type().items():
            if utype == md.SCV:
                out.update(_CARD[utype])
                if any(u.cargo for u in us):
                    out.add(_RETURN_CARGO)
                if g.has_completed(md.DEPOT):
                    out.add(_BUILD_BARRACKS)
            elif utype == md.MARINE or any(u.complete for u in us):
                out.update(_CARD[utype])
        return frozenset(out)

    def production_unit(self) -> Unit | None:
        """The producer shown in the production panel: a lone selected, finished CC/Barracks."""
        sel = self.game.selection
        if len(sel) == 1 and sel[0].utype in _PRODUCERS and sel[0].complete:
            return sel[0]
        return None

    def available(self) -> list[int]:
        """``available_actions``: pysc2's UI functions whose conditions hold, plus the cards'."""
        g = self.game
        out = [0, 1, 2, 3, 4]
        if len(g.selection) > 1:
            out.append(5)
        if g.idle_workers:
            out.append(6)
        if g.army_count:
            out.append(7)
        if self.production_unit() is not None:
            out.append(11)
        ab = self.abilities()
        funcs = self._cache.get(ab)
        if funcs is None:
            funcs = self._cache[ab] = functions_for(ab)
        out.extend(funcs)
        return out

    # ------------------------------------------------------------------ validation

    def validate(self, func_call: Any, available: Sequence[int]) -> dict[str, Any]:
        """Check a ``FunctionCall`` as ``features.Features.transform_action`` does.

        Raises the same ``ValueError``s (and lets the argument converters raise theirs);
        returns the converted keyword arguments.
        """
        func_id = func_call.function
        try:
            func = F[func_id]
        except KeyError:
            raise ValueError("Invalid function id: %s." % func_id) from None
        if func_id not in available:
            raise ValueError("Function %s/%s is currently not available" % (func_id, func.name))
        if len(func_call.arguments) != len(func.args):
            raise ValueError("Wrong number of arguments for function: %s, got: %s" % (
                func, func_call.arguments))
        for t, arg in zip(func.args, func_call.arguments):
            if t.count:
                if 1 <= len(arg) <= t.count:
                    continue
                raise ValueError("Wrong number of values for argument of %s, got: %s" % (
                    func, func_call.arguments))
            if t.name in ("screen", "screen2"):
                sizes: Sequence[int] = _SCREEN_SIZES
            elif t.name == "minimap":
                sizes = _MINIMAP_SIZES
            else:
                sizes = t.sizes
            if len(sizes) != len(arg):
                raise ValueError("Wrong number of values for argument of %s, got: %s" % (
                    func, func_call.arguments))
            for s, a in zip(sizes, arg):
                # pysc2's own check, kept as is: only negative values fail it.
                if type(a) is int:  # the common case, without numpy's overhead
                    if not 0 <= a and a < s:
                        raise ValueError("Argument is out of range for %s, got: %s" % (
                            func, func_call.arguments))
                elif not np.all(0 <= a) and np.all(a < s):
                    raise ValueError("Argument is out of range for %s, got: %s" % (
                        func, func_call.arguments))
        return {t.name: t.fn(a) for t, a in zip(func.args, func_call.arguments)}

    # ------------------------------------------------------------------ execution

    def apply_all(self, calls: Sequence[Any], available: Sequence[int]) -> None:
        """Validate every call (raising before any takes effect), then carry them out in order.

        ``last_actions`` lists the functions that took effect (no_op sends nothing), and
        ``action_result`` the game's error for each that did not.
        """
        checked = [(int(c.function), self.validate(c, available)) for c in calls]
        self.last_actions = []
        self.action_result = []
        for fid, kw in checked:
            if fid == 0:
                continue
            handler = HANDLERS.get(fid)
            err = handler(self, kw) if handler is not None else 0  # None: the camera is locked
            if err:
                self.action_result.append(err)
            else:
                self.last_actions.append(fid)

    # ---- helpers

    @property
    def t(self) -> float:
        return float(self.game.loop)

    def unit_at_screen(self, p: Any) -> Unit | None:
        """The unit drawn on top at a screen pixel (what a click there hits)."""
        x, y = int(p.x), int(p.y)
        if not (0 <= x < md.SCREEN and 0 <= y < md.SCREEN):
            return None
        s = int(self.top[y, x])
        return self.game.units.get(s - 1) if s else None

    def unit_at_world(self, x: float, y: float) -> Unit | None:
        """The unit whose disk covers a world point: ground units over structures."""
        best: tuple[int, int, Unit] | None = None
        for u in self.game.units.values():
            ux, uy = u.pos(self.t)
            if (ux - x) ** 2 + (uy - y) ** 2 <= u.data.radius ** 2:
                key = (0 if u.data.structure else 1, u.tag)
                if best is None or key > best[:2]:
                    best = (*key, u)
        return best[2] if best else None

    def own_selected(self, utypes: tuple[int, ...]) -> list[Unit]:
        return [u for u in self.game.selection
                if u.utype in utypes and u.owner == PLAYER_SELF and u.complete]

    def set_selection(self, units: list[Unit]) -> None:
        g = self.game
        sel = g.table.selected
        for u in g.selection:
            sel[u.slot] = 0
        g.selection = sorted(set(units), key=lambda u: u.tag)
        g.selection_version += 1
        for u in g.selection:
            sel[u.slot] = 1

    def own_on_screen(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Own units' slots with their screen centres and pixel radii."""
        tab = self.game.table
        slots = np.flatnonzero(tab.alive & (tab.owner == PLAYER_SELF))
        wx, wy = tab.positions(slots, self.t)
        sx = (wx - md.SCREEN_X0) * md.PX_PER_UNIT
        sy = (md.SCREEN_Y0 - wy) * md.PX_PER_UNIT
        return slots, sx, sy, tab.radius[slots] * md.PX_PER_UNIT

    def world_target(self, kw: dict[str, Any]) -> tuple[float, float, Unit | None]:
        """The world point (and unit under it) of a screen or minimap argument."""
        if "screen" in kw:
            p = kw["screen"]
            x, y = md.screen_to_world(p.x, p.y)
            return x, y, self.unit_at_screen(p)
        p = kw["minimap"]
        x, y = md.minimap_to_world(p.x, p.y)
        return x, y, self.unit_at_world(x, y)
