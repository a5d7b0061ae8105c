"""Draw one observation's 27 screen and 11 minimap layers as a PNG, coloured the way pysc2 does.

Each layer is coloured by its own pysc2 palette (``features.SCREEN_FEATURES.<name>.color``, what
pysc2's ``renderer_human.draw_feature_layer`` blits), scaled up by whole pixels with no smoothing,
and titled with its name. The tiles are placed pixel-exactly, so a tile's pixel is the palette
colour of the layer value under it (palette floats truncated to uint8, as pygame does).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sc2data._pysc2 import features
from sc2data.errors import Sc2DataError

COLUMNS = 7
"""Tiles per row; screen layers fill the first rows, minimap layers start on a fresh row."""
SCALE = 4
"""Screen pixels per layer pixel."""
TITLE_PX = 16
PAD_PX = 4
HEADER_PX = 22
DPI = 100

_GROUPS = (("screen", "feature_screen", features.SCREEN_FEATURES),
           ("minimap", "feature_minimap", features.MINIMAP_FEATURES))


def colorize(feature: Any, plane: np.ndarray) -> np.ndarray:
    """A layer as an (H, W, 3) uint8 image in pysc2's palette for that feature.

    Values beyond the palette (which pysc2's own renderer would fail on) are clipped to its last
    colour.
    """
    plane = np.clip(np.asarray(plane), 0, len(feature.palette) - 1)
    return np.clip(feature.color(plane), 0, 255).astype(np.uint8)


def tiles(observation: Any) -> list[tuple[str, np.ndarray]]:
    """``(group/name, coloured image)`` for every screen then every minimap layer."""
    out = []
    for group, key, table in _GROUPS:
        stack = np.asarray(observation[key])
        for f in table:
            out.append((f"{group}/{f.name}", colorize(f, stack[f.index])))
    return out


def layout(n_screen: int, n_minimap: int, size: int) -> tuple[int, int, list[tuple[int, int]]]:
    """Canvas ``(width, height)`` in pixels and each tile's top-left ``(x, y)``."""
    tile = size * SCALE
    cell_w, cell_h = tile + PAD_PX, TITLE_PX + tile + PAD_PX
    rows_s = -(-n_screen // COLUMNS)
    rows_m = -(-n_minimap // COLUMNS)
    width = COLUMNS * cell_w + PAD_PX
    height = HEADER_PX + (rows_s + rows_m) * cell_h + PAD_PX
    origins = []
    for i in range(n_screen + n_minimap):
        row, col = divmod(i, COLUMNS) if i < n_screen else divmod(i - n_screen, COLUMNS)
        if i >= n_screen:
            row += rows_s
        origins.append((PAD_PX + col * cell_w, HEADER_PX + row * cell_h + TITLE_PX))
    return width, height, origins


def _header(observation: Any) -> str:
    p = np.asarray(observation["player"])
    loop = int(np.asarray(observation["game_loop"]).ravel()[0])
    score = int(np.asarray(observation["score_cumulative"])[0])
    return (f"game loop {loop}   minerals {p[features.Player.minerals]}   "
            f"supply {p[features.Player.food_used]}/{p[features.Player.food_cap]}   "
            f"workers {p[features.Player.food_workers]}   army {p[features.Player.army_count]}   "
            f"score {score}")


def render_frame(obs: Any, path: str | Path) -> Path:
    """Write a PNG of every feature layer of ``obs`` (a pysc2 TimeStep or its observation)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    observation = getattr(obs, "observation", obs)
    named = tiles(observation)
    n_screen = len(features.SCREEN_FEATURES)
    size = named[0][1].shape[0]
    if any(img.shape[:2] != (size, size) for _, img in named):
        raise Sc2DataError("render needs square screen and minimap layers of one size; "
                           "use the project's interface format (64×64)")
    width, height, origins = layout(n_screen, len(named) - n_screen, size)
    canvas = np.full((height, width, 3), 255, np.uint8)
    for (_, img), (x, y) in zip(named, origins, strict=True):
        canvas[y:y + size * SCALE, x:x + size * SCALE] = img.repeat(SCALE, 0).repeat(SCALE, 1)

    fig = Figure(figsize=(width / DPI, height / DPI), dpi=DPI)
    fig.figimage(canvas, 0, 0, origin="upper", resize=False)
    for (name, _), (x, y) in zip(named, origins, strict=True):
        fig.text(x / width, 1 - (y - 2) / height, name, fontsize=8, va="bottom", ha="left")
    fig.text(PAD_PX / width, 1 - 4 / height, _header(observation), fontsize=9, va="top",
             ha="left")
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        FigureCanvasAgg(fig).print_png(str(path))
    except OSError as e:
        raise Sc2DataError(f"cannot write the PNG to {path}: {e.strerror or e}; "
                           "choose a writable --out path") from e
    return path


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
