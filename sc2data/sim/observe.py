"""Drawing the 27 screen and 11 minimap feature layers, and assembling pysc2's observation.

Units are filled disks of radius ``unit radius × px per unit`` sampled at pixel centres (brief
§3), structures under ground units. A frame is drawn as one "top unit" image (which unit is on
top at each pixel); every per-unit layer is then a lookup ``table[top]``. Structures and mineral
fields never move, so their pixels are stamped once per change of the footprint grid; only
ground units are stamped every frame, all in one vectorised pass.

Layer by layer (pysc2 names): ``height_map`` a flat plateau (:data:`~mapdata.HEIGHT_VALUE`)
inside the playable area, 0 outside; ``visibility_map`` 2 (visible: the map turns fog off)
inside, 0 outside; ``creep``, ``power``, ``unit_energy(_ratio)``, ``unit_shields(_ratio)``,
``effects``, ``hallucinations``, ``cloaked``, ``blip``, ``buffs``, ``buff_duration``,
``active``, ``placeholder`` and the minimap ``alerts`` are 0, as a Terran-only map without
effects, buffs or enemies gives; ``player_id`` 1 for us, 16 for the neutral mineral fields;
``player_relative`` SELF 1 / NEUTRAL 3; ``unit_hit_points`` hit points, ``..._ratio`` hit
points / max × 255 (0 for mineral fields, which have none); ``unit_density`` the number of unit
disks covering a pixel, ``unit_density_aa`` 16 × the covered fraction summed over units
(pysc2's docs: "a maximum of 16 per unit per pixel", up to 255), the fraction approximated by
``clip(R + ½ − distance, 0, 1)``; ``build_progress`` progress × 255 for a structure under
construction, 0 otherwise; ``pathable``/``buildable`` the playable ground less every
structure's and mineral field's footprint. The minimap draws the whole 64×64 map at one pixel
per world unit (pysc2's transform with ``crop_to_playable_area=False``), units at least
0.75 px in radius so each shows, and ``camera`` marks the screen's world rectangle.
"""

from __future__ import annotations

import numpy as np

from sc2data._pysc2 import features
from sc2data.sim import mapdata as md
from sc2data.sim.game import Game

S = features.SCREEN_FEATURES
M = features.MINIMAP_FEATURES
_UNIT_SCREEN = [S.player_id.index, S.player_relative.index, S.unit_type.index,
                S.selected.index, S.unit_hit_points.index, S.unit_hit_points_ratio.index,
                S.build_progress.index]
_UNIT_MINIMAP = [M.player_id.index, M.player_relative.index, M.unit_type.index,
                 M.selected.index]
_N = md.SCREEN
_NM = md.MINIMAP
MINIMAP_MIN_RADIUS = 0.75
"""Smallest drawn minimap radius in pixels (a 0.375 unit would often cover no pixel centre)."""


def stamp(cx: np.ndarray, cy: np.ndarray, radius: float, size: int
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pixels of disks of ``radius`` px centred at (cx, cy) on a ``size``² image.

    Returns (unit index, flat pixel, inside-disk flag, anti-aliased coverage in [0, 1]) for every
    pixel with non-zero coverage; the disk itself is the pixels whose centres lie within
    ``radius``.
    """
    w = int(2 * radius + 1) + 2
    x0 = np.floor(cx - radius - 0.5).astype(np.int64)
    y0 = np.floor(cy - radius - 0.5).astype(np.int64)
    o = np.arange(w)
    px = x0[:, None] + o
    py = y0[:, None] + o
    dx = px + 0.5 - cx[:, None]
    dy = py + 0.5 - cy[:, None]
    d2 = dy[:, :, None] ** 2 + dx[:, None, :] ** 2
    cov = np.clip(radius + 0.5 - np.sqrt(d2), 0.0, 1.0)
    keep = (cov > 0) & ((px >= 0) & (px < size))[:, None, :] & ((py >= 0) & (py < size))[:, :, None]
    n, i, j = np.nonzero(keep)
    flat = (y0[n] + i) * size + (x0[n] + j)
    return n, flat, d2[keep] <= radius * radius, cov[keep]


class _Layer:
    """The stamped pixels of a set of units on one image (screen or minimap)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self.top = np.zeros(size * size, dtype=np.int64)
        self.density = np.zeros(size * size, dtype=np.int64)
        self.aa = np.zeros(size * size, dtype=np.float64)


class Renderer:
    """Draws a :class:`Game` into pysc2-shaped feature arrays."""

    def __init__(self) -> None:
        playable = md.playable_cells()
        srows, scols = md.screen_pixel_cells()
        mrows, mcols = md.minimap_pixel_cells()
        self._sidx = (srows[:, None], scols[None, :])
        self._midx = (mrows[:, None], mcols[None, :])
        c = np.arange(_N) + 0.5
        wx = md.SCREEN_X0 + c / md.PX_PER_UNIT
        wy = md.SCREEN_Y0 - c / md.PX_PER_UNIT
        x0, y0, x1, y1 = md.PLAYABLE
        s_play = ((wy >= y0) & (wy <= y1))[:, None] & ((wx >= x0) & (wx <= x1))[None, :]
        cm = (np.arange(_NM) + 0.5) * md.MAP_SIZE / _NM
        m_play = ((md.MAP_SIZE - cm >= y0) & (md.MAP_SIZE - cm <= y1))[:, None] & \
            ((cm >= x0) & (cm <= x1))[None, :]
        self._playable = playable
        self.screen_base = np.zeros((len(S), _N, _N), dtype=np.int32)
        self.screen_base[S.height_map.index] = np.where(s_play, md.HEIGHT_VALUE, 0)
        self.screen_base[S.visibility_map.index] = np.where(s_play, 2, 0)
        self.minimap_base = np.zeros((len(M), _NM, _NM), dtype=np.int32)
        self.minimap_base[M.height_map.index] = np.where(m_play, md.HEIGHT_VALUE, 0)
        self.minimap_base[M.visibility_map.index] = np.where(m_play, 2, 0)
        self.minimap_base[M.camera.index] = md.camera_minimap_mask()
        self._version = -1
        self._s_static = _Layer(_N)
        self._m_static = _Layer(_NM)

    # ------------------------------------------------------------------ static part

    def _refresh_static(self, g: Game) -> None:
        """Re-stamp structures and mineral fields and the grids, after a footprint changed."""
        self._version = g.grid_version
        free = self._playable & ~g.occupied
        for base, idx, name in ((self.screen_base, self._sidx, S),
                                (self.minimap_base, self._midx, M)):
            grid = free[idx].astype(np.int32)
            base[name.pathable.index] = grid
            base[name.buildable.index] = grid
        tab = g.table
        slots = np.flatnonzero(tab.alive & (tab.layer == 0))
        slots = slots[np.argsort(tab.tag[slots], kind="stable")]
        for layer, to_px, scale, rmin in ((self._s_static, md.world_to_screen, md.PX_PER_UNIT, 0.0),
                                          (self._m_static, md.world_to_minimap, _NM / md.MAP_SIZE,
                                           MINIMAP_MIN_RADIUS)):
            layer.top[:] = 0
            layer.density[:] = 0
            layer.aa[:] = 0.0
            for s in slots:
                cx, cy = to_px(tab.x1[s], tab.y1[s])
                r = max(tab.radius[s] * scale, rmin)
                _, flat, disk, cov = stamp(np.array([cx]), np.array([cy]), r, layer.size)
                layer.top[flat[disk]] = s + 1
                layer.density += np.bincount(flat[disk], minlength=layer.size ** 2)
                layer.aa += np.bincount(flat, weights=cov, minlength=layer.size ** 2)

    # ------------------------------------------------------------------ frame

    def _ground(self, g: Game, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        tab = g.table
        slots = np.flatnonzero(tab.alive & (tab.layer == 1))
        if len(slots) > 1:
            slots = slots[np.argsort(tab.tag[slots], kind="stable")]
        t0, t1 = tab.t0[slots], tab.t1[slots]
        f = np.clip((t - t0) / np.maximum(t1 - t0, 1e-9), 0.0, 1.0)
        x = tab.x0[slots] + (tab.x1[slots] - tab.x0[slots]) * f
        y = tab.y0[slots] + (tab.y1[slots] - tab.y0[slots]) * f
        return slots, x, y

    @staticmethod
    def _compose(static: _Layer, slots: np.ndarray, cx: np.ndarray, cy: np.ndarray,
                 radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        size = static.size
        n, flat, disk, cov = stamp(cx, cy, radius, size)
        dn, dflat = n[disk], flat[disk]
        order = np.zeros(size * size, dtype=np.int64)
        np.maximum.at(order, dflat, dn + 1)
        top = np.where(order > 0, slots[np.maximum(order - 1, 0)] + 1, static.top)
        density = static.density + np.bincount(dflat, minlength=size * size)
        aa = static.aa + np.bincount(flat, weights=cov, minlength=size * size)
        return top, density, aa

    def draw(self, g: Game) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(feature_screen, feature_minimap, top-unit image) at the game's current loop."""
        if self._version != g.grid_version:
            self._refresh_static(g)
        t = float(g.loop)
        tab = g.table
        slots, wx, wy = self._ground(g, t)

        # Per-slot attribute table; row 0 is "no unit".
        prog = np.minimum(tab.prog0 + tab.prate * (t - tab.pt0), 1.0)
        hp = tab.hpmax * (0.1 + 0.9 * prog) - tab.dmg
        ratio = np.where(tab.hpmax > 0, hp / np.maximum(tab.hpmax, 1.0) * 255.0, 0.0)
        under = prog < 1.0
        cap = tab.capacity
        table = np.zeros((7, cap + 1), dtype=np.int32)
        table[0, 1:] = tab.owner
        table[1, 1:] = np.where(tab.owner == 1, features.PlayerRelative.SELF,
                                features.PlayerRelative.NEUTRAL)
        table[2, 1:] = tab.utype
        table[3, 1:] = tab.selected
        table[4, 1:] = np.maximum(hp, 0.0)
        table[5, 1:] = np.maximum(ratio, 0.0)
        table[6, 1:] = np.where(under, prog * 255.0, 0.0)

        small = md.UNIT_DATA[md.SCV].radius
        sx = (wx - md.SCREEN_X0) * md.PX_PER_UNIT
        sy = (md.SCREEN_Y0 - wy) * md.PX_PER_UNIT
        top, density, aa = self._compose(self._s_static, slots, sx, sy, small * md.PX_PER_UNIT)
        screen = self.screen_base.copy()
        screen[_UNIT_SCREEN] = table[:, top].reshape(7, _N, _N)
        screen[S.unit_density.index] = density.reshape(_N, _N)
        screen[S.unit_density_aa.index] = np.minimum(np.rint(aa * 16.0), 255).reshape(_N, _N)

        ms = _NM / md.MAP_SIZE
        mtop, _, _ = self._compose(self._m_static, slots, wx * ms, (md.MAP_SIZE - wy) * ms,
                                   max(small * ms, MINIMAP_MIN_RADIUS))
        minimap = self.minimap_base.copy()
        minimap[_UNIT_MINIMAP] = table[:4, mtop].reshape(4, _NM, _NM)
        return screen, minimap, top.reshape(_N, _N)

