"""The observation dict, built the way ``features.Features.transform_obs`` builds it.

Same keys, shapes, dtypes (int32) and classes: ``NamedDict`` at the top, ``NamedNumpyArray``
with pysc2's index names where pysc2 names them (``feature_screen``, ``feature_minimap``,
``player``, ``score_*``, ``single_select``/``multi_select``/``build_queue``/
``production_queue`` when non-empty), plain arrays elsewhere.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sc2data._pysc2 import actions, features
from sc2data.game.sim import mapdata as md
from sc2data.game.sim.commands import Commands
from sc2data.game.sim.game import Game
from sc2data.game.sim.store import PLAYER_SELF, Unit
from sc2data.ground.vocab import MAP_NAME

named_array = features.named_array
"""pysc2's ``named_array`` module (``NamedDict``, ``NamedNumpyArray``), as ``features`` uses it."""

HOME_RACE = 1
"""``home_race_requested`` as SC2Env reports it for a Terran agent (``sc_common.Terran``)."""

_EMPTY_UNITS = np.array([], dtype=np.int32).reshape((0, len(features.UnitLayer)))
_EMPTY_PQ = np.array([], dtype=np.int32).reshape((0, len(features.ProductionQueue)))
_EMPTY = np.array([], dtype=np.int32)
"""Empty arrays are shared by every observation, as pysc2 shares its ``empty_unit``."""


def _derive(names: list[Any]) -> list[dict[str, int] | None]:
    out: list[dict[str, int] | None] = []
    for o in names:
        if o is None:
            out.append(None)
        elif hasattr(o, "_member_names_"):
            out.append({n: j for j, n in enumerate(o._member_names_)})
        else:
            out.append({n: j for j, n in enumerate(o._fields)})
    return out


_SCREEN_NAMES = _derive([features.ScreenFeatures, None, None])
_MINIMAP_NAMES = _derive([features.MinimapFeatures, None, None])
_PLAYER_NAMES = _derive([features.Player])
_SCORE_NAMES = _derive([features.ScoreCumulative])
_CAT_NAMES = _derive([features.ScoreByCategory, features.ScoreCategories])
_VITAL_NAMES = _derive([features.ScoreByVital, features.ScoreVitals])
_UNIT_NAMES = _derive([None, features.UnitLayer])
_PQ_NAMES = _derive([None, features.ProductionQueue])


def named(arr: np.ndarray, index_names: list[dict[str, int] | None]) -> np.ndarray:
    """``arr`` as a ``NamedNumpyArray`` without a copy (equal to pysc2's constructor's result)."""
    out = arr.view(named_array.NamedNumpyArray)
    object.__setattr__(out, "_index_names", index_names)  # what its own __setattr__ does
    return out


def unit_vec(g: Game, u: Unit) -> list[int]:
    """pysc2's ``unit_vec``: type, relation, health, shields, energy, cargo slots, build %."""
    t = float(g.loop)
    prog = u.progress(t)
    rel = features.PlayerRelative.SELF if u.owner == PLAYER_SELF else \
        features.PlayerRelative.NEUTRAL
    return [u.utype, int(rel), int(max(u.hp(t), 0.0)), 0, 0, 0,
            int(prog * 100) if prog < 1.0 else 0]


def unit_rows(g: Game, units: list[Unit], hp: np.ndarray, prog: np.ndarray) -> np.ndarray:
    """:func:`unit_vec` for many units at once, from the drawing's per-slot hp and progress."""
    slots = np.fromiter((u.slot for u in units), dtype=np.intp, count=len(units))
    out = np.zeros((len(units), len(features.UnitLayer)), dtype=np.int32)
    out[:, 0] = g.table.utype[slots]
    out[:, 1] = g.table.attr[1, slots + 1]
    out[:, 2] = hp[slots]
    p = prog[slots]
    out[:, 6] = (p < 1.0) * (p * 100.0)
    return out


def _queue_vec(g: Game, b: Unit, i: int, utype: int) -> list[int]:
    d = md.UNIT_DATA[utype]
    prog = g.item_progress(b, float(g.loop)) if i == 0 else 0.0
    return [utype, int(features.PlayerRelative.SELF), d.hp, 0, 0, 0, int(prog * 100)]


_TRAIN_ABILITY = {md.SCV: actions.FUNCTIONS.Train_SCV_quick.ability_id,
                  md.MARINE: actions.FUNCTIONS.Train_Marine_quick.ability_id}


def score_arrays(g: Game) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``score_cumulative``, ``score_by_category``, ``score_by_vital`` of the game so far.

    ``score`` counts marines made (the map's curriculum score); idle times are in game seconds;
    values are mineral costs of living units (``total_value_*``, ``used_minerals``) or totals
    (``collected``, ``spent``, ``lost``); every loss here is friendly fire. Categories: marines
    army, SCVs, the CC and depots economy, barracks technology.
    """
    cum = np.array([
        g.score, int(g.idle_production_time / md.LOOPS_PER_GAME_SECOND),
        int(g.idle_worker_time / md.LOOPS_PER_GAME_SECOND), g.value_units, g.value_structures,
        0, 0, g.collected, 0, g.collection_rate(), 0, g.spent, 0,
    ], dtype=np.int32)
    cat = np.zeros((len(features.ScoreByCategory), len(features.ScoreCategories)), np.int32)
    cat[_FOOD, _ARMY] = g.food_army
    cat[_FOOD, _ECONOMY] = g.food_workers
    cat[_USED] = g.value_by_category
    cat[_LOST, 0] = g.lost_value
    cat[_FRIENDLY, 0] = g.lost_value
    cat[_TOTAL_USED, 0] = g.spent
    vit = np.zeros((len(features.ScoreByVital), len(features.ScoreVitals)), np.int32)
    vit[0, 0] = vit[1, 0] = int(g.damage_dealt)  # dealt and taken: all of it is friendly
    return (named(cum, _SCORE_NAMES), named(cat, _CAT_NAMES), named(vit, _VITAL_NAMES))


_FOOD = int(features.ScoreByCategory.food_used)
_USED = int(features.ScoreByCategory.used_minerals)
_LOST = int(features.ScoreByCategory.lost_minerals)
_FRIENDLY = int(features.ScoreByCategory.friendly_fire_minerals)
_TOTAL_USED = int(features.ScoreByCategory.total_used_minerals)
_ARMY = int(features.ScoreCategories.army)
_ECONOMY = int(features.ScoreCategories.economy)


def build(g: Game, c: Commands, screen: np.ndarray, minimap: np.ndarray,
          available: list[int], hp: np.ndarray, prog: np.ndarray) -> dict[str, Any]:
    """The observation ``NamedDict`` at the game's current loop (``hp``/``prog``: per slot)."""
    out = named_array.NamedDict({
        "single_select": _EMPTY_UNITS,
        "multi_select": _EMPTY_UNITS,
        "build_queue": _EMPTY_UNITS,
        "cargo": _EMPTY_UNITS,
        "production_queue": _EMPTY_PQ,
        "last_actions": _EMPTY,
        "cargo_slots_available": np.array([0], dtype=np.int32),
        "home_race_requested": np.array([0], dtype=np.int32),
        "away_race_requested": np.array([0], dtype=np.int32),
        "map_name": MAP_NAME,
    })
    out["feature_screen"] = named(screen, _SCREEN_NAMES)
    out["feature_minimap"] = named(minimap, _MINIMAP_NAMES)
    out["last_actions"] = np.array(c.last_actions, dtype=np.int32) if c.last_actions else _EMPTY
    out["action_result"] = (np.array(c.action_result, dtype=np.int32) if c.action_result
                            else _EMPTY)
    out["alerts"] = _EMPTY
    out["game_loop"] = np.array([g.loop], dtype=np.int32)
    out["score_cumulative"], out["score_by_category"], out["score_by_vital"] = score_arrays(g)
    out["player"] = named(np.array([
        1, g.minerals, 0, g.food_used, g.food_cap, g.food_army, g.food_workers,
        len(g.idle_workers), g.army_count, 0, 0], dtype=np.int32), _PLAYER_NAMES)
    groups = np.zeros((10, 2), dtype=np.int32)
    for i, grp in enumerate(g.groups):
        if grp:
            groups[i] = (grp[0].utype, len(grp))
    out["control_groups"] = groups
    sel = g.selection
    if len(sel) == 1:
        out["single_select"] = named(np.array([unit_vec(g, sel[0])], dtype=np.int32),
                                     _UNIT_NAMES)
        b = c.production_unit()
        if b is not None and b.queue:
            out["build_queue"] = named(np.array(
                [_queue_vec(g, b, i, q) for i, q in enumerate(b.queue)], dtype=np.int32),
                _UNIT_NAMES)
            first = g.item_progress(b, float(g.loop))
            out["production_queue"] = named(np.array(
                [(_TRAIN_ABILITY[q], first * 100 if i == 0 else 0)
                 for i, q in enumerate(b.queue)], dtype=np.int32), _PQ_NAMES)
    elif sel:
        out["multi_select"] = named(unit_rows(g, sel, hp, prog), _UNIT_NAMES)
    out["upgrades"] = _EMPTY
    out["available_actions"] = np.array(available, dtype=np.int32)
    out["home_race_requested"] = np.array([HOME_RACE], dtype=np.int32)
    return out
