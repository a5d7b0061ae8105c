"""Drawing the 27 screen and 11 minimap feature layers, and assembling pysc2's observation.

Units are filled disks of radius ``unit radius × px per unit`` sampled at pixel centres (as
the real game draws them at 64×64: an SCV or marine is a 2×2 square), structures under ground units. A frame is drawn as one "top unit" image (which unit is on
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
per world unit (pysc2's transform with ``crop_to_playable_area=False``): structures as disks at
least 1 px in radius, each SCV or marine (smaller than a pixel) on the pixel it stands in; and
``camera`` marks the screen's world rectangle. Only the 7 minimap layers of unit and terrain
meaning are drawn from units (no density layers exist on the minimap).
"""

from __future__ import annotations

import numpy as np

from sc2data._pysc2 import features
from sc2data.game.sim import mapdata as md
from sc2data.game.sim.game import Game

S = features.SCREEN_FEATURES
M = features.MINIMAP_FEATURES
_UNIT_SCREEN = [S.player_id.index, S.player_relative.index, S.unit_type.index,
                S.selected.index, S.unit_hit_points.index, S.unit_hit_points_ratio.index,
                S.build_progress.index]
_UNIT_MINIMAP = [M.player_id.index, M.player_relative.index, M.unit_type.index,
                 M.selected.index]
_N = md.SCREEN
_NM = md.MINIMAP
MINIMAP_MIN_RADIUS = 1.0
"""Smallest drawn minimap radius of a structure in pixels; ground units (0.375 world units,
smaller than a minimap pixel) mark the one pixel they stand in."""


def stamp(cx: np.ndarray, cy: np.ndarray, radius: float, size: int
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pixels of disks of ``radius`` px centred at (cx, cy) on a ``size``² image (exact).

    Returns (unit index, flat pixel, inside-disk flag, anti-aliased coverage in [0, 1]) for every
    pixel with non-zero coverage; the disk itself is the pixels whose centres lie within
    ``radius``. Used for the few static structures; moving units use :class:`DiskStamp`.
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


def stamp_many(cx: np.ndarray, cy: np.ndarray, radii: np.ndarray, size: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`stamp` for disks of several radii, unit by unit in the order given.

    One :func:`stamp` call per distinct radius; the pixels are then put back in unit order
    (each unit's own in ``stamp``'s order), so a later unit overwrites an earlier one when
    assigned, and each pixel's coverage is summed in unit order by ``np.bincount``, exactly as
    stamping the units one at a time would.
    """
    parts = [(np.zeros(0, np.intp), np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0))]
    for r in np.unique(radii):
        group = np.flatnonzero(radii == r)
        n, flat, disk, cov = stamp(cx[group], cy[group], float(r), size)
        parts.append((group[n], flat, disk, cov))
    unit, flat, disk, cov = (np.concatenate(p) for p in zip(*parts))
    order = np.argsort(unit, kind="stable")
    return unit[order], flat[order], disk[order], cov[order]


class DiskStamp:
    """Disk pixels of one radius for many moving units, from precomputed sub-pixel tables.

    A unit's centre is split into a whole pixel and a sub-pixel offset quantised to 1/16 px
    (0.02 world units on the screen); for each of the 16×16 offsets the disk's pixels and the
    pixels of non-zero coverage around it are tabulated once, so a frame costs a few array
    operations whatever the number of units. Pixels are addressed on a canvas padded by ``pad``
    on every side, so units at the screen's edge need no bounds checks (the caller crops).
    """

    Q = 16

    def __init__(self, radius: float, size: int, pad: int = 8) -> None:
        self.radius = radius
        self.size = size
        self.pad = pad
        self.width = size + 2 * pad
        w = int(2 * radius + 1) + 2
        o = np.arange(w)
        q = (np.arange(self.Q) + 0.5) / self.Q
        d1 = o[None, :] - radius - q[:, None]  # (Q, w): pixel centre − unit centre
        d2 = d1[:, None, :, None] ** 2 + d1[None, :, None, :] ** 2  # (Qy, Qx, wy, wx)
        d2 = d2.reshape(self.Q * self.Q, w * w)
        disk = d2 <= radius * radius
        cov = np.clip(radius + 0.5 - np.sqrt(d2), 0.0, 1.0)
        oy, ox = np.divmod(np.arange(w * w), w)
        window = oy * self.width + ox  # canvas offset of each window pixel from its corner
        self.sentinel = self.width * self.width
        # Per sub-pixel offset, only the window pixels that matter, in window order: a disk of
        # radius 1 px covers 3–5 of the 5×5 window, its coverage ~12. Rows are padded to one
        # length: disk rows with an offset past the canvas (clipped to the sentinel), coverage
        # rows with coverage 0 on the window's corner (adding 0 changes no sum).
        n_disk, n_cov = disk.sum(1).max(), (cov > 0).sum(1).max()
        self.disk_offsets = np.full((self.Q * self.Q, n_disk), self.sentinel, dtype=np.intp)
        self.cov_offsets = np.zeros((self.Q * self.Q, n_cov), dtype=np.intp)
        self.cov = np.zeros((self.Q * self.Q, n_cov))
        for v in range(self.Q * self.Q):
            inside, covered = np.flatnonzero(disk[v]), np.flatnonzero(cov[v] > 0)
            self.disk_offsets[v, :len(inside)] = window[inside]
            self.cov_offsets[v, :len(covered)] = window[covered]
            self.cov[v, :len(covered)] = cov[v, covered]
        self._qoff = (pad - radius - 0.5) * self.Q
        self._qmax = (self.width - w) * self.Q - 1

    def __call__(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For units at screen pixel coordinates ``xy`` (a (2, N) array of x and y): canvas
        pixels inside the disks (or the sentinel), canvas pixels of their coverage and that
        coverage, each (N, row length)."""
        # x and y go through each step together, as one (2, N) array: half the numpy calls.
        q = xy * float(self.Q)
        q += self._qoff
        np.maximum(q, 0.0, out=q)
        np.minimum(q, self._qmax, out=q)
        q = q.astype(np.intp)
        sub, whole = q & (self.Q - 1), q >> 4  # sub-pixel offset, whole pixel
        v = sub[1] * self.Q + sub[0]
        base = (whole[1] * self.width + whole[0])[:, None]
        inside = np.minimum(base + self.disk_offsets[v], self.sentinel)
        return inside, base + self.cov_offsets[v], self.cov[v]

    def crop(self, canvas: np.ndarray) -> np.ndarray:
        """The ``size``² image inside a flat padded canvas (sentinel entry ignored)."""
        w, p, n = self.width, self.pad, self.size
        return canvas[: w * w].reshape(w, w)[p:p + n, p:p + n]


class _Layer:
    """The stamped pixels of a set of units on one image (screen or minimap).

    ``top`` has one extra sentinel entry at the end for pixels that fall off the image.
    """

    def __init__(self, size: int) -> None:
        self.size = size
        self.top = np.zeros(size * size + 1, dtype=np.intp)
        self.density2d = np.zeros((size, size), dtype=np.int64)
        self.aa2d = np.zeros((size, size), dtype=np.float64)
        self.density = self.density2d.reshape(-1)  # flat views of the same memory
        self.aa = self.aa2d.reshape(-1)


def _runs(rows: list[int]) -> list[tuple[int, int]]:
    """Sorted row indices as contiguous [lo, hi) runs."""
    out: list[tuple[int, int]] = []
    for r in rows:
        if out and out[-1][1] == r:
            out[-1] = (out[-1][0], r + 1)
        else:
            out.append((r, r + 1))
    return out


ENV_SCREEN: frozenset[str] = frozenset({"unit_type", "player_relative", "selected", "buildable"})
"""Screen layers the simulator's own users read (``ScreenView``: masks, the macro agents), always
drawn when a :class:`Renderer` draws only some layers."""


class Renderer:
    """Draws a :class:`Game` into pysc2-shaped feature arrays.

    ``layers`` (pysc2 names as ``"screen/unit_type"``, ``"minimap/camera"``) draws only those
    (and :data:`ENV_SCREEN`); every other layer is left 0, the minimap entirely so when none of
    its layers is asked for. ``None`` (the default) draws all 27 + 11, as pysc2 returns them.
    An RL learner reading a few layers skips the rest of the work (BENCHMARKS.md, "RL at speed").
    """

    def __init__(self, layers: frozenset[str] | None = None) -> None:
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
        # The screen's only non-zero rows that are not drawn from units (the rest stay 0).
        self._terrain_runs = _runs(sorted([S.height_map.index, S.visibility_map.index,
                                           S.pathable.index, S.buildable.index]))
        self._version = -1
        self._s_static = _Layer(_N)
        self._m_static = _Layer(_NM)
        small = md.UNIT_DATA[md.SCV].radius  # every ground unit here: SCV and Marine, 0.375
        self._s_disk = DiskStamp(small * md.PX_PER_UNIT, _N)
        self._s_canvas = np.zeros(self._s_disk.sentinel + 1, dtype=np.intp)
        self._ids_for: np.ndarray | None = None
        self._ids_cached = np.zeros(0, dtype=np.intp)
        self._mm_key: tuple[int, int] = (-1, -1)
        self._mm_cached = self.minimap_base.copy()
        self._attr = np.zeros((7, 1), dtype=np.int32)
        self.hp = np.zeros(0)
        self.progress = np.zeros(0)
        self._attr_key: tuple[object, int] | None = None  # (table, its version) drawn last
        self._progressing = True  # whether something was being built then
        want = None if layers is None else {k for k in layers} | {f"screen/{n}" for n in ENV_SCREEN}
        self._unit_rows = [(row, i) for row, i in enumerate(_UNIT_SCREEN)
                           if want is None or f"screen/{S[i].name}" in want]
        self._density = want is None or "screen/unit_density" in want
        self._density_aa = want is None or "screen/unit_density_aa" in want
        self._minimap_on = want is None or any(k.startswith("minimap/") for k in want)
        self._minimap_off = np.zeros_like(self.minimap_base)
        self._minimap_off.flags.writeable = False

    # ------------------------------------------------------------------ static part

    def _refresh_static(self, g: Game) -> None:
        """Re-stamp structures and mineral fields and the grids, after a footprint changed."""
        self._version = g.grid_version
        self._mm_key = (-1, -1)
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
            cx, cy = to_px(tab.x1[slots], tab.y1[slots])
            radii = np.maximum(tab.radius[slots] * scale, rmin)
            unit, flat, disk, cov = stamp_many(cx, cy, radii, layer.size)
            size2 = layer.size ** 2
            layer.top[:] = 0
            layer.top[flat[disk]] = (slots + 1)[unit[disk]]  # later units overwrite earlier
            layer.density[:] = np.bincount(flat[disk], minlength=size2)
            layer.aa[:] = np.bincount(flat, weights=cov, minlength=size2)
        d = self._s_disk
        self._s_canvas = np.zeros(d.sentinel + 1, dtype=np.intp)
        d.crop(self._s_canvas)[...] = self._s_static.top[:-1].reshape(_N, _N)

    # ------------------------------------------------------------------ frame

    def _screen(self, slots: np.ndarray, xy: np.ndarray, attr: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """``feature_screen`` and its top-unit image (slot + 1, flat): the cached terrain and
        structures, with the ground units at screen pixel coordinates ``xy`` (2, N) on top."""
        disk = self._s_disk
        inside, covered, cov = disk(xy)
        canvas = self._s_canvas.copy()
        # Later (higher-tag) units overwrite earlier ones: numpy assigns repeated indices in
        # order, and the sentinel entry takes the padding entries of the disk rows.
        canvas[inside.ravel()] = self._ids(slots, inside.shape[1])
        top = disk.crop(canvas).ravel()
        # Zeroed memory (calloc) and the few terrain rows copied: cheaper than copying every
        # row of screen_base, most of which are always 0.
        screen = np.zeros(self.screen_base.shape, np.int32)
        for lo, hi in self._terrain_runs:
            screen[lo:hi] = self.screen_base[lo:hi]
        flat = screen.reshape(len(S), _N * _N)
        for row, layer in self._unit_rows:
            attr[row].take(top, out=flat[layer], mode="clip")
        # Density and coverage are summed in int64 / float64 and cast into the int32 rows by the
        # last operation itself (``casting="unsafe"``: what assigning them would do).
        n = disk.sentinel + 1
        if self._density:
            np.add(disk.crop(np.bincount(inside.ravel(), minlength=n)), self._s_static.density2d,
                   out=screen[S.unit_density.index], casting="unsafe")
        if self._density_aa:
            aa = disk.crop(np.bincount(covered.ravel(), weights=cov.ravel(), minlength=n)) + \
                self._s_static.aa2d
            aa *= 16.0
            aa += 0.5
            np.minimum(aa, 255.0, out=screen[S.unit_density_aa.index], casting="unsafe")
        return screen, top

    def _ids(self, slots: np.ndarray, k: int) -> np.ndarray:
        """``slot + 1`` of each ground unit repeated ``k`` times (cached: it changes only when a
        ground unit is made or dies)."""
        if self._ids_for is not slots:
            self._ids_cached, self._ids_for = np.repeat(slots + 1, k), slots
        return self._ids_cached

    def _attributes(self, g: Game, t: float) -> np.ndarray:
        """The table's per-slot layer values with hit points, ratio and progress at ``t``."""
        tab = g.table
        # Unchanged columns and nothing under construction give last frame's values again
        # (progress only grows, and stays clipped at 1 once there): about half the frames.
        key = (tab, tab.version)
        if key == self._attr_key and not self._progressing:
            return tab.attr
        prog = np.minimum(tab.prog0 + tab.prate * (t - tab.pt0), 1.0)
        hp = np.maximum(tab.hpmax * (0.1 + 0.9 * prog) - tab.dmg, 0.0)
        a = tab.attr
        a[4, 1:] = hp
        a[5, 1:] = hp * tab.ratio_k
        a[6, 1:] = (prog < 1.0) * (prog * 255.0)
        self.hp, self.progress = hp, prog
        self._attr_key = key
        self._progressing = bool(((tab.prate != 0.0) & (prog < 1.0)).any())
        return a

    def _minimap(self, g: Game, attr: np.ndarray, slots: np.ndarray, wx: np.ndarray,
                 wy: np.ndarray) -> np.ndarray:
        """The minimap: terrain and structures (cached until a footprint or the selection
        changes), then each ground unit on the pixel it stands in, later tags on top."""
        key = (g.grid_version, g.selection_version)
        if key != self._mm_key:
            if key[0] != self._mm_key[0]:
                self._mm_cached = self.minimap_base.copy()
                rows = list(range(len(_UNIT_MINIMAP)))
            else:  # only the selection changed: redraw just the row that shows it
                rows = [_UNIT_MINIMAP.index(M.selected.index)]
            cflat = self._mm_cached.reshape(len(M), _NM * _NM)  # never handed out: editable
            for row in rows:
                attr[row].take(self._m_static.top[:-1], out=cflat[_UNIT_MINIMAP[row]], mode="clip")
            self._mm_key = key
        minimap = self._mm_cached.copy()
        if len(slots):
            ms = _NM / md.MAP_SIZE
            px = np.minimum(np.maximum(wx * ms, 0), _NM - 1).astype(np.intp)
            py = np.minimum(np.maximum((md.MAP_SIZE - wy) * ms, 0), _NM - 1).astype(np.intp)
            flat = py * _NM + px
            mflat = minimap.reshape(len(M), _NM * _NM)
            for row, layer in enumerate(_UNIT_MINIMAP):
                mflat[layer][flat] = attr[row][slots + 1]
        return minimap

    def draw(self, g: Game) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(feature_screen, feature_minimap, top-unit image) at the game's current loop."""
        if self._version != g.grid_version:
            self._refresh_static(g)
        t = float(g.loop)
        slots = g.table.ground()
        wx, wy = g.table.positions(slots, t)
        attr = self._attributes(g, t)

        xy = np.empty((2, len(slots)))  # screen pixel coordinates: x right, y down
        np.subtract(wx, md.SCREEN_X0, out=xy[0])
        np.subtract(md.SCREEN_Y0, wy, out=xy[1])
        xy *= md.PX_PER_UNIT
        screen, top = self._screen(slots, xy, attr)
        minimap = self._minimap(g, attr, slots, wx, wy) if self._minimap_on else \
            self._minimap_off
        return screen, minimap, top.reshape(_N, _N)
