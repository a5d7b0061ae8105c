"""BuildMarines as data: map geometry, camera, start state, and the game numbers of its units.

Everything here is a constant read from the map or from StarCraft II's game data (LotV),
plus the coordinate transforms between world units, feature-screen pixels and minimap pixels,
and the static grids (playable, pathable, buildable) the simulator and its drawing share.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sc2data._pysc2 import units
from sc2data.ground.vocab import MINIMAP_SIZE, SCREEN_SIZE

# --- Map geometry (BuildMarines.SC2Map: MapScript.galaxy, Objects, Regions) -------------------------------------------

MAP_SIZE = 64
"""The map is 64×64 world units."""
PLAYABLE = (19.94, 19.00, 45.94, 37.00)
"""Playable region (x0, y0, x1, y1) in world units."""

CC_POS = (29.83, 28.01)
"""The Command Center's position."""
MINERAL_POS: tuple[tuple[float, float], ...] = (
    (23.0, 28.5), (24.0, 29.5), (23.0, 26.5), (25.0, 22.5),
    (25.0, 32.5), (24.0, 23.5), (24.0, 31.5), (24.0, 25.5),
)
"""The 8 ``MineralField`` positions."""
MINERAL_AMOUNT = 1800
"""Minerals in each field at the start."""
CC_RALLY = (23.0, 26.5)
"""The CC's rally targets this mineral field at the start."""

SCV_X_OFFSETS = (3.5, 4.5)
"""The 12 SCVs stand in 2 columns this far from the CC in x, on a side chosen per episode."""
SCV_Y_OFFSETS = (2.5, 1.5, 0.5, -0.5, -1.5, -2.5)
"""... and in 6 rows at these y offsets from the CC."""

START_MINERALS = 50
START_WORKERS = 12

GAME_LOOPS = 14_400
"""The map's 900 game-second timer at 16 loops per game second."""

# --- Camera (measured on real pysc2 observations: the screen spans 24 world units) --------------------------------------------

SCREEN = SCREEN_SIZE
MINIMAP = MINIMAP_SIZE
CAMERA_WIDTH = 24.0
"""pysc2's ``camera_width_world_units`` for feature layers."""
CAMERA_CENTER = ((PLAYABLE[0] + PLAYABLE[2]) / 2, (PLAYABLE[1] + PLAYABLE[3]) / 2 - 3.0)
"""Locked on the playable region's centre moved 3 units south: (32.94, 25.0)."""
PX_PER_UNIT = SCREEN / CAMERA_WIDTH
"""k = 64/24 screen pixels per world unit."""
SCREEN_X0 = CAMERA_CENTER[0] - CAMERA_WIDTH / 2
"""World x of the screen's left edge (20.94)."""
SCREEN_Y0 = CAMERA_CENTER[1] + CAMERA_WIDTH / 2
"""World y of the screen's top edge (37.0)."""


def world_to_screen(x: float, y: float) -> tuple[float, float]:
    """Continuous screen-pixel coordinates of a world point: ``((x−20.94)k, (37−y)k)``."""
    return (x - SCREEN_X0) * PX_PER_UNIT, (SCREEN_Y0 - y) * PX_PER_UNIT


def screen_to_world(px: float, py: float) -> tuple[float, float]:
    """The world point an action at integer screen pixel (px, py) aims at: the pixel's centre.

    pysc2's ``transform.PixelToCoord`` maps a pixel back to its centre (``+0.5``).
    """
    return SCREEN_X0 + (px + 0.5) / PX_PER_UNIT, SCREEN_Y0 - (py + 0.5) / PX_PER_UNIT


def world_to_minimap(x: float, y: float) -> tuple[float, float]:
    """Continuous minimap coordinates, as pysc2's ``Features.init_camera`` builds them.

    World → top-left origin ``(x, map_h − y)`` → scale ``minimap / max(map_size)`` = 1 here,
    since the 64×64 map is drawn whole on the 64×64 minimap (``crop_to_playable_area=False``).
    """
    s = MINIMAP / MAP_SIZE
    return x * s, (MAP_SIZE - y) * s


def minimap_to_world(px: float, py: float) -> tuple[float, float]:
    """The world point at the centre of minimap pixel (px, py)."""
    s = MINIMAP / MAP_SIZE
    return (px + 0.5) / s, MAP_SIZE - (py + 0.5) / s


# --- Unit data (LotV game data: SC2GameData / sc2-techtree, Liquipedia) ----------------------------------------------------

LOOPS_PER_GAME_SECOND = 16


@dataclass(frozen=True)
class UnitData:
    """Game numbers of one unit type; times in game loops, speeds in world units per loop."""

    unit_type: int
    radius: float
    hp: int
    armor: int = 0
    minerals: int = 0
    build_loops: int = 0
    supply_cost: int = 0
    supply_provided: int = 0
    footprint: tuple[int, int] = (0, 0)
    """Placement footprint in grid cells (structures and mineral fields)."""
    speed: float = 0.0
    structure: bool = False


SCV = units.Terran.SCV
MARINE = units.Terran.Marine
CC = units.Terran.CommandCenter
DEPOT = units.Terran.SupplyDepot
BARRACKS = units.Terran.Barracks
MINERAL = units.Neutral.MineralField

UNIT_DATA: dict[int, UnitData] = {
    # Radii and hit points as the game's API reports them for these unit types (a raw-unit dump
    # of SC2 4.x: SCV and Marine 0.375, CC 2.75, SupplyDepot 1.25, Barracks 1.8125, and 1.125
    # for mineral fields). Speeds are the data's per-game-second values (SCV 2.8125,
    # Marine 2.25) / 16 loops.
    SCV: UnitData(SCV, 0.375, 45, minerals=50, build_loops=272, supply_cost=1,
                  speed=2.8125 / LOOPS_PER_GAME_SECOND),
    MARINE: UnitData(MARINE, 0.375, 45, minerals=50, build_loops=400, supply_cost=1,
                     speed=2.25 / LOOPS_PER_GAME_SECOND),
    CC: UnitData(CC, 2.75, 1500, armor=1, minerals=400, build_loops=1600, supply_provided=15,
                 footprint=(5, 5), structure=True),
    DEPOT: UnitData(DEPOT, 1.25, 400, armor=1, minerals=100, build_loops=480,
                    supply_provided=8, footprint=(2, 2), structure=True),
    BARRACKS: UnitData(BARRACKS, 1.8125, 1000, armor=1, minerals=150, build_loops=1040,
                       footprint=(3, 3), structure=True),
    MINERAL: UnitData(MINERAL, 1.125, 0, footprint=(2, 1), structure=True),
}

MAX_SUPPLY = 200
QUEUE_LIMIT = 5
"""Train queues hold 5 units."""

# Marine weapon (Gauss Rifle): 6 damage, period 0.8608 game seconds, range 5.
MARINE_DAMAGE = 6
MARINE_COOLDOWN = 0.8608 * LOOPS_PER_GAME_SECOND
MARINE_RANGE = 5.0

# Mining (LotV). A trip: walk to the field, harvest 5 minerals (the field is taken meanwhile),
# walk back to the CC and deliver. The numbers the game shows (TL.net's LotV production
# spreadsheet; real replays, ``benchmarks/real_game.py``): the first two workers on a field each
# bring 55–63 minerals per real minute (1,344 loops), 944 for 16 workers on 8 fields; a field
# gives at most ≈143 a minute, so a third worker adds ≈25 (1,144 for 24 workers). A timed test in
# the game (PiousFlea, TL.net 2010, the same 2.786-second harvest, at Normal speed) agrees: 672 a
# game minute with 16 SCVs all mining (941 a real minute), 816 with 24 (1,142), each of the first
# 16 adding about the same.
HARVEST_LOOPS = 44.6
"""Loops a worker spends harvesting, the field taken (LotV: 2.786 game seconds)."""
CARRY = 5
PATCH_CLEAR_LOOPS = 2.4
"""Loops after a harvest before the next worker can start on the same field. With
``HARVEST_LOOPS`` it caps a field at 5 × 1344 / 47 ≈ 143 minerals per real minute, the game's
figure: a third worker on a field waits for it and adds ≈25, as in the game."""
MINING_LEG_OVERHEAD = 22.0
"""Loops added to each mining leg (field→CC, CC→field) beyond distance / SCV speed.

The straight-line legs here are 1.5–3 world units (≈8–17 loops at full speed); a real SCV
accelerates, decelerates and turns at each end, and delivers on touching the CC. This one
number is set so that a worker's round trip takes ≈114 loops on the average field: 59 minerals
per real minute per worker with two to a field, 944 for 16 workers (the spreadsheet's 944), and
713 for the 12 workers of the start (the real replays' median, 713). Fields nearer the CC give
more, farther ones less, from the map's own positions. ``tests/game/sim/test_economy.py`` holds
these figures.
"""
COLLECTION_WINDOW = 240
"""Loops over which the game's ``minerals_collection_rate`` counts deliveries."""
WORKERS_PER_PATCH = 2
"""Workers spread to another field when theirs already has this many, as the game spreads
them; a third comes only once every field has two, and then waits its turn at the field."""
QUEUE_HANDOFF_LOOPS = 1
"""A unit produced back to back from a queue appears ``build_loops − 1`` after the one before
it (SCV every 271 loops, marine every 399), one from an idle building ``build_loops`` after the
order (272, 400): real replays show both, on every sample."""

# --- Static grids ------------------------------------------------------------------------------


def playable_cells() -> np.ndarray:
    """Bool grid [cy, cx] of 1×1 world cells whose centres lie in the playable region."""
    c = np.arange(MAP_SIZE) + 0.5
    x0, y0, x1, y1 = PLAYABLE
    inx = (c >= x0) & (c <= x1)
    iny = (c >= y0) & (c <= y1)
    return iny[:, None] & inx[None, :]


def footprint_cells(x: float, y: float, footprint: tuple[int, int]) -> tuple[slice, slice]:
    """Grid slices (rows, cols) of the cells a footprint centred at (x, y) covers."""
    w, h = footprint
    cx0 = int(math.floor(x - w / 2 + 0.5))
    cy0 = int(math.floor(y - h / 2 + 0.5))
    return slice(cy0, cy0 + h), slice(cx0, cx0 + w)


def snap_to_grid(x: float, y: float, footprint: tuple[int, int]) -> tuple[float, float]:
    """Where the game centres a footprint placed at (x, y): whole cells, like placement does.

    Even sizes centre on grid lines, odd sizes on cell centres.
    """
    w, h = footprint
    sx = round(x) if w % 2 == 0 else math.floor(x) + 0.5
    sy = round(y) if h % 2 == 0 else math.floor(y) + 0.5
    return float(sx), float(sy)


def screen_pixel_cells() -> tuple[np.ndarray, np.ndarray]:
    """For each screen row and column, the world grid cell its pixel centre falls in."""
    c = np.arange(SCREEN) + 0.5
    xs = np.floor(SCREEN_X0 + c / PX_PER_UNIT).astype(np.int64)
    ys = np.floor(SCREEN_Y0 - c / PX_PER_UNIT).astype(np.int64)
    return np.clip(ys, 0, MAP_SIZE - 1), np.clip(xs, 0, MAP_SIZE - 1)


def minimap_pixel_cells() -> tuple[np.ndarray, np.ndarray]:
    """For each minimap row and column, the world grid cell its pixel centre falls in."""
    c = np.arange(MINIMAP) + 0.5
    xs = np.floor(c * MAP_SIZE / MINIMAP).astype(np.int64)
    ys = np.floor(MAP_SIZE - c * MAP_SIZE / MINIMAP).astype(np.int64)
    return np.clip(ys, 0, MAP_SIZE - 1), np.clip(xs, 0, MAP_SIZE - 1)


def camera_minimap_mask() -> np.ndarray:
    """Minimap pixels whose centres lie inside the screen's world rectangle (the camera layer)."""
    c = np.arange(MINIMAP) + 0.5
    wx = c * MAP_SIZE / MINIMAP
    wy = MAP_SIZE - c * MAP_SIZE / MINIMAP
    inx = (wx >= SCREEN_X0) & (wx <= SCREEN_X0 + CAMERA_WIDTH)
    iny = (wy <= SCREEN_Y0) & (wy >= SCREEN_Y0 - CAMERA_WIDTH)
    return iny[:, None] & inx[None, :]


HEIGHT_VALUE = 127
"""height_map value of the flat playable ground.

BuildMarines is one flat plateau; the map's absolute terrain height is not in our sources, so we
draw its encoded value as mid-scale. Outside the playable region the game draws nothing (0).
"""
