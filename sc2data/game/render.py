"""Draw feature layers as a PNG, coloured the way pysc2 does: a live frame, or a stored stack.

Each layer is coloured by its own pysc2 palette (``features.SCREEN_FEATURES.<name>.color``, what
pysc2's ``renderer_human.draw_feature_layer`` blits), scaled up by whole pixels with no smoothing,
and titled with its name. The tiles are placed pixel-exactly, so a tile's pixel is the palette
colour of the layer value under it (palette floats truncated to uint8, as pygame does). A stack's
two frames are drawn as two rows per band of layers, the previous frame above the current one.

A column on the right is the legend: for every categorical layer, the ids present in the drawn
frames with their colour and pysc2 name (``Terran.Barracks``, ``PlayerRelative.SELF``, …); id 0,
black in every pysc2 palette, is the background and not listed. A layer that is all zero in a
frame says "empty" on that frame's tile.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sc2data._pysc2 import buffs, features, units
from sc2data.ground.errors import Sc2DataError, reason
from sc2data.ground.files import write_atomic
from sc2data.schema import StackBatch

COLUMNS = 7
"""Tiles per band; screen layers fill the first bands, minimap layers start on a fresh band."""
SCALE = 4
"""Screen pixels per layer pixel."""
TITLE_PX = 16
PAD_PX = 4
LINE_PX = 14
"""Height of a header or legend line."""
LEGEND_PX = 320
"""Width of the legend column."""
SWATCH_PX = 10
DPI = 100

Frame = Mapping[str, np.ndarray]
"""One frame: ``screen/<name>`` and ``minimap/<name>`` planes, and any of the vectors ``player``,
``score_cumulative``, ``game_loop``."""

_TABLES = {"screen": features.SCREEN_FEATURES, "minimap": features.MINIMAP_FEATURES}
_ENUMS: dict[str, Any] = {"player_relative": features.PlayerRelative,
                          "visibility_map": features.Visibility, "effects": features.Effects,
                          "buffs": buffs.Buffs}


@dataclass(frozen=True)
class Entry:
    """One colour of a categorical layer's legend."""

    id: int
    name: str
    """pysc2's name for the id (``Terran.CommandCenter``); a two-valued layer's 1 is the layer's
    name (``selected``); an id pysc2 has no name for is the id itself."""
    color: tuple[int, int, int]
    frames: tuple[int, ...]
    """Which of the drawn frames hold it (0 = the first)."""


def feature(key: str) -> Any:
    """pysc2's feature for a layer key, ``screen/<name>`` or ``minimap/<name>``."""
    group, name = key.split("/")
    return getattr(_TABLES[group], name)


def colorize(feature: Any, plane: np.ndarray) -> np.ndarray:
    """A layer as an (H, W, 3) uint8 image in pysc2's palette for that feature.

    Values beyond the palette (which pysc2's own renderer would fail on) are clipped to its last
    colour.
    """
    plane = np.clip(np.asarray(plane), 0, len(feature.palette) - 1)
    return np.clip(feature.color(plane), 0, 255).astype(np.uint8)


def id_name(key: str, value: int) -> str:
    """pysc2's name for one id of a categorical layer."""
    name = key.split("/")[1]
    if name == "unit_type":
        unit = units.get_unit_type(value)
        return f"{type(unit).__name__}.{unit.name}" if unit is not None else str(value)
    if name == "player_id":
        return "neutral" if value == 16 else f"player {value}"
    if name in _ENUMS:
        try:
            return f"{_ENUMS[name].__name__}.{_ENUMS[name](value).name}"
        except ValueError:
            return str(value)
    return name if feature(key).scale == 2 and value == 1 else str(value)


def legend(key: str, planes: Sequence[np.ndarray]) -> list[Entry]:
    """The non-zero ids of a categorical layer present in ``planes`` (one per frame), ascending;
    nothing for a scalar layer."""
    f = feature(key)
    if f.type != features.FeatureType.CATEGORICAL:
        return []
    present = [set(np.unique(p).tolist()) - {0} for p in planes]
    out = []
    for value in sorted(set().union(*present)):
        rgb = colorize(f, np.array([value]))[0]
        out.append(Entry(int(value), id_name(key, int(value)),
                         (int(rgb[0]), int(rgb[1]), int(rgb[2])),
                         tuple(i for i, p in enumerate(present) if value in p)))
    return out


def empty_tiles(frames: Sequence[Frame], keys: Sequence[str]) -> list[tuple[str, int]]:
    """``(key, frame)`` of every layer that is all zero in that frame: its tile says "empty"."""
    return [(k, i) for k in keys for i, fr in enumerate(frames) if not np.asarray(fr[k]).any()]


def layout(n_screen: int, n_minimap: int, size: int, frames: int = 1, header_lines: int = 1
           ) -> tuple[int, int, list[list[tuple[int, int]]]]:
    """Canvas ``(width, height)`` in pixels before the legend's own needs, and each layer's
    tile top-left ``(x, y)``, one per frame."""
    tile = size * SCALE
    cell_w, band_h = tile + PAD_PX, TITLE_PX + frames * (tile + PAD_PX)
    top = header_px(header_lines)
    bands_s = -(-n_screen // COLUMNS)
    bands_m = -(-n_minimap // COLUMNS)
    width = COLUMNS * cell_w + PAD_PX + LEGEND_PX
    height = top + (bands_s + bands_m) * band_h + PAD_PX
    origins = []
    for i in range(n_screen + n_minimap):
        band, col = divmod(i, COLUMNS) if i < n_screen else divmod(i - n_screen, COLUMNS)
        if i >= n_screen:
            band += bands_s
        x, y = PAD_PX + col * cell_w, top + band * band_h + TITLE_PX
        origins.append([(x, y + j * (tile + PAD_PX)) for j in range(frames)])
    return width, height, origins


def header_px(lines: int) -> int:
    """Height of a header of ``lines`` lines."""
    return PAD_PX + lines * LINE_PX + PAD_PX


def stats(frame: Frame) -> str:
    """The frame's game loop, minerals, supply, workers, army and score, as far as stored."""
    parts = []
    if "game_loop" in frame:
        parts.append(f"game loop {int(np.asarray(frame['game_loop']).ravel()[0])}")
    if "player" in frame:
        p, P = np.asarray(frame["player"]), features.Player
        parts += [f"minerals {p[P.minerals]}", f"supply {p[P.food_used]}/{p[P.food_cap]}",
                  f"workers {p[P.food_workers]}", f"idle {p[P.idle_worker_count]}",
                  f"army {p[P.army_count]}"]
    if "score_cumulative" in frame:
        parts.append(f"score {int(np.asarray(frame['score_cumulative'])[0])}")
    return "   ".join(parts)


def draw(frames: Sequence[Frame], keys: Sequence[str], header: Sequence[str],
         path: str | Path) -> Path:
    """Write a PNG of layers ``keys`` (screen keys first) of one or more frames, atomically."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n_screen = sum(k.startswith("screen/") for k in keys)
    size = np.asarray(frames[0][keys[0]]).shape[0]
    if any(np.asarray(fr[k]).shape != (size, size) for fr in frames for k in keys):
        raise Sc2DataError("render needs square screen and minimap layers of one size; "
                           "use the project's interface format (64×64)")
    width, height, origins = layout(n_screen, len(keys) - n_screen, size, len(frames),
                                    len(header))
    legends = [(k, legend(k, [fr[k] for fr in frames])) for k in keys]
    legends = [(k, e) for k, e in legends if e]
    top = header_px(len(header))
    lines = sum(1 + len(e) for _, e in legends)
    height = max(height, top + lines * LINE_PX + PAD_PX)
    canvas = np.full((height, width, 3), 255, np.uint8)
    tile = size * SCALE
    for k, tiles in zip(keys, origins, strict=True):
        f = feature(k)
        for fr, (x, y) in zip(frames, tiles, strict=True):
            img = colorize(f, fr[k])
            canvas[y:y + tile, x:x + tile] = img.repeat(SCALE, 0).repeat(SCALE, 1)

    fig = Figure(figsize=(width / DPI, height / DPI), dpi=DPI)

    def text(x: float, y: float, s: str, **kw: Any) -> None:
        fig.text(x / width, 1 - y / height, s, **kw)

    for k, tiles in zip(keys, origins, strict=True):
        text(tiles[0][0], tiles[0][1] - 2, k, fontsize=8, va="bottom", ha="left")
    index = {k: i for i, k in enumerate(keys)}
    for k, j in empty_tiles(frames, keys):
        x, y = origins[index[k]][j]
        text(x + tile / 2, y + tile / 2, "empty", fontsize=10, color="#b0b0b0", va="center",
             ha="center")
    for i, line in enumerate(header):
        text(PAD_PX, PAD_PX + i * LINE_PX, line, fontsize=9, va="top", ha="left")
    x0, y = width - LEGEND_PX + PAD_PX, top
    for k, entries in legends:
        text(x0, y, k, fontsize=8, va="top", ha="left", weight="bold")
        y += LINE_PX
        for e in entries:
            canvas[y + 2:y + 2 + SWATCH_PX, x0:x0 + SWATCH_PX] = e.color
            only = "" if len(e.frames) == len(frames) else \
                f"   ({'previous' if e.frames == (0,) else 'current'} only)"
            text(x0 + SWATCH_PX + 4, y, f"{e.id} {e.name}{only}", fontsize=7, va="top",
                 ha="left")
            y += LINE_PX
    fig.figimage(canvas, 0, 0, origin="upper", resize=False, zorder=0)
    return _save(fig, FigureCanvasAgg, Path(path))


def _save(fig: Any, agg: Any, path: Path) -> Path:
    """The figure as a PNG at ``path``, written whole or not at all."""
    buf = io.BytesIO()
    agg(fig).print_png(buf)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, buf.getvalue())
    except OSError as e:
        raise Sc2DataError(f"cannot write the PNG to {path}: {reason(e)}; "
                           "choose a writable --out path") from e
    return path


def observation_frame(obs: Any) -> dict[str, np.ndarray]:
    """Every pysc2 layer and the kept vectors of a pysc2 TimeStep or its observation."""
    observation = getattr(obs, "observation", obs)
    out: dict[str, np.ndarray] = {}
    for group, key in (("screen", "feature_screen"), ("minimap", "feature_minimap")):
        planes = np.asarray(observation[key])
        out.update({f"{group}/{f.name}": planes[f.index] for f in _TABLES[group]})
    for name in ("player", "score_cumulative", "game_loop"):
        if name in observation:
            out[name] = np.asarray(observation[name])
    return out


def render_frame(obs: Any, path: str | Path) -> Path:
    """Write a PNG of every feature layer of ``obs`` (a pysc2 TimeStep or its observation)."""
    frame = observation_frame(obs)
    keys = [k for k in frame if "/" in k]
    return draw([frame], keys, [stats(frame)], path)


def stack_frames(batch: StackBatch) -> list[dict[str, np.ndarray]]:
    """The previous and the current frame of a batch of one stack."""
    if len(batch) != 1:
        raise ValueError(f"draw one stack at a time, not {len(batch)}")
    return [{k: a[0, j] for k, a in batch.arrays.items()} for j in (0, 1)]


def render_stack(batch: StackBatch, title: str, path: str | Path) -> Path:
    """Write a PNG of a stored stack (a batch of one): every layer it holds, previous frame
    above current, under ``title`` and each frame's figures."""
    frames = stack_frames(batch)
    keys = [l.key for l in batch.schema.layers if l.key in batch.arrays]
    header = [f"{title}   (each layer: previous frame above, current frame below)",
              f"previous:  {stats(frames[0])}", f"current:   {stats(frames[1])}"]
    return draw(frames, keys, header, path)


def render_episode(out: str | Path, *, env: str = "sim", seed: int = 0, steps: int = 300,
                   agent: str = "scripted") -> Path:
    """Play ``steps`` agent steps of one episode and draw the last observation."""
    from sc2data.game.agents import make_agent, play
    from sc2data.game.env import make_env

    if steps < 0:
        raise Sc2DataError(f"--steps must be 0 or more, got {steps}")
    player = make_agent(agent, seed=seed)
    environment = make_env(env, seed=seed)
    try:
        *_, last = play(environment, player, steps + 1)
        return render_frame(last, out)
    finally:
        environment.close()
