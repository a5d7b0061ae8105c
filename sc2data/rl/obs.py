"""What the policy sees: the stored layers, or a compact encoding made for learning fast.

* ``stored`` — one array per key of a stored schema (``Schema.named(layers)``: the paper's 13
  screen + 7 minimap layers by default) plus the non-spatial vectors, exactly what
  ``Schema.extract`` stores for a frame. Categorical ids stay raw ids (``unit_type`` up to 1,962).
* ``compact`` — made for a small CNN (BENCHMARKS.md, "RL at speed", measured):

  - ``screen``: ``(C, S, S)`` uint8. One channel per unit type that exists on BuildMarines
    (:data:`UNIT_TYPES`: an SCV and a marine are two channels, not 0.0229 and 0.0245 of one),
    ``player_relative`` SELF and NEUTRAL, ``selected``, then the scalar layers
    ``unit_hit_points_ratio``, ``build_progress`` (0–255) and ``unit_density`` (clipped at 255).
    Layers that never change on this map (height, visibility, creep, power, energy, shields,
    effects, …) are left out. ``S`` is 64, or 32: each channel summed over 2×2 pixels (one-hot
    channels count 0–4 pixels, scalars are averaged).
  - ``minimap`` (optional): ``player_relative`` SELF and NEUTRAL, ``selected`` and ``camera``,
    at the same size. The camera is locked on BuildMarines and the screen shows the whole
    playable area, so it adds little; off by default.
  - ``vector``: float32, ``log1p`` of the ``player`` fields, the episode's elapsed fraction of
    its 14,400 game loops, and which :data:`PAPER_FUNCTIONS` are available; with ``history``,
    then per macro (macro space) or per function (paper space) the game time since it last
    acted (:class:`MacroClock`).
    pysc2 hands an agent its ``last_actions`` for the same reason: a feed-forward policy cannot
    otherwise tell that it sent a builder a moment ago (one that has not reached its site shows
    nowhere on the screen), and the macro-rules agent's own timers are what keep it from sending
    a second one.

An :class:`Observer` turns one pysc2 observation into its arrays (writing into given arrays when
asked: the vector env writes straight into shared memory) and names the feature layers it reads,
so the simulator draws only those.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from sc2data._pysc2 import actions, features, units
from sc2data.game.agents import ReducedRandomAgent
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.vocab import SCREEN_SIZE
from sc2data.schema import Schema

PAPER_FUNCTIONS: tuple[str, ...] = (
    "no_op", "select_point", "select_rect", "select_idle_worker", "select_army",
    "Build_SupplyDepot_screen", "Build_Barracks_screen", "Train_SCV_quick", "Train_Marine_quick",
    "Harvest_Gather_screen",
)
"""The reduced pysc2 function set of the paper action space, in action-index order (here because
the observation reports which of them are available; :mod:`sc2data.rl.envs` acts with them)."""

OBSERVATIONS: tuple[str, ...] = ("stored", "compact")

MACROS: tuple[str, ...] = ReducedRandomAgent.MACROS
"""The macro actions, in action-index order (the reduced-random agent's set; the macro space of
:mod:`sc2data.rl.envs` acts with them)."""

UNIT_TYPES: tuple[int, ...] = (
    units.Terran.CommandCenter, units.Terran.SupplyDepot, units.Terran.Barracks,
    units.Terran.SCV, units.Terran.Marine, units.Neutral.MineralField,
    units.Neutral.MineralField750,
)
"""The unit types a BuildMarines game shows (both mineral field kinds of the real maps)."""

_S = features.SCREEN_FEATURES
_M = features.MINIMAP_FEATURES
_REL = (features.PlayerRelative.SELF, features.PlayerRelative.NEUTRAL)
_SCALARS = (("unit_hit_points_ratio", 255, 255.0), ("build_progress", 255, 255.0),
            ("unit_density", 255, 4.0))
"""Scalar screen layers: name, the value they are clipped at, what the policy divides them by."""
_MINIMAP_LAYERS = ("player_relative", "selected", "camera")
GAME_LOOPS = 14_400
"""The map's timer (900 game seconds): the vector's elapsed fraction is ``game_loop / this``."""


@dataclass(frozen=True)
class ObsConfig:
    """Which observation the policy gets (picklable: sent to the vector env's processes)."""

    kind: str = "stored"
    layers: str = "paper"
    """``stored``: the stored schema preset (``paper`` or ``full``)."""
    size: int = SCREEN_SIZE
    """``compact``: 64 or 32 pixels a side."""
    minimap: bool = False
    """``compact``: add the minimap channels."""
    history: bool = False
    """``compact``: the vector ends with :class:`MacroClock`'s features."""
    action_space: str = "macro"
    """With ``history``: whose actions the clock times (:func:`history_actions`)."""

    def check(self) -> None:
        if self.kind not in OBSERVATIONS:
            raise Sc2DataError(f"unknown observation {self.kind!r}; choose one of: "
                               f"{', '.join(OBSERVATIONS)}")
        if self.history and self.kind != "compact":
            raise Sc2DataError("--history needs --obs compact (the stored observation is the "
                               "schema's, nothing added)")
        if self.size not in (SCREEN_SIZE, SCREEN_SIZE // 2):
            raise Sc2DataError(f"--obs-size must be {SCREEN_SIZE} or {SCREEN_SIZE // 2}, "
                               f"got {self.size}")
        try:
            Schema.named(self.layers)
        except ValueError as e:
            raise Sc2DataError(str(e)) from None


class Observer:
    """One pysc2 observation → the policy's arrays (see the module docstring)."""

    def __init__(self, cfg: ObsConfig) -> None:
        cfg.check()
        self.cfg = cfg
        self.schema = Schema.named(cfg.layers)
        n_funcs = len(_paper_ids())
        if cfg.kind == "stored":
            boxes: dict[str, spaces.Space[Any]] = {}
            for l in self.schema.layers:
                n = self.schema.size(l.group)
                boxes[l.key] = spaces.Box(0, l.limit - 1, (n, n), l.dtype)
            for v in self.schema.vectors:
                boxes[v.name] = spaces.Box(0, np.iinfo(v.dtype).max, (v.size,), v.dtype)
            self.space = spaces.Dict(boxes)
            self.layers = frozenset(l.key for l in self.schema.layers)
            return
        s = cfg.size
        self._lut = np.full(max(UNIT_TYPES) + 2, 255, np.uint8)
        self._lut[list(UNIT_TYPES)] = np.arange(len(UNIT_TYPES))
        self.screen_channels: tuple[str, ...] = (
            tuple(f"unit_type={units.get_unit_type(u).name}" for u in UNIT_TYPES)
            + tuple(f"player_relative={features.PlayerRelative(r).name}" for r in _REL)
            + ("selected",) + tuple(name for name, _, _ in _SCALARS))
        self.minimap_channels: tuple[str, ...] = (
            tuple(f"player_relative={features.PlayerRelative(r).name}" for r in _REL)
            + ("selected", "camera")) if cfg.minimap else ()
        boxes = {"screen": spaces.Box(0, 255, (len(self.screen_channels), s, s), np.uint8)}
        if cfg.minimap:
            boxes["minimap"] = spaces.Box(0, 255, (len(self.minimap_channels), s, s), np.uint8)
        self._n_history = len(history_actions(cfg.action_space)) if cfg.history else 0
        n_vec = len(features.Player) + 1 + n_funcs + self._n_history
        boxes["vector"] = spaces.Box(0.0, 32.0, (n_vec,), np.float32)  # log1p(2**31) < 22
        self.space = spaces.Dict(boxes)
        self.layers = frozenset(
            ["screen/unit_type", "screen/player_relative", "screen/selected"]
            + [f"screen/{name}" for name, _, _ in _SCALARS]
            + ([f"minimap/{n}" for n in _MINIMAP_LAYERS] if cfg.minimap else []))
        """The feature layers this observer reads (what the simulator must draw)."""

    def scales(self) -> dict[str, list[float]]:
        """``compact``: each image channel's largest value (what the policy divides by)."""
        if self.cfg.kind != "compact":
            return {}
        count = float((SCREEN_SIZE // self.cfg.size) ** 2)  # pixels summed into one cell
        n_screen = len(self.screen_channels) - len(_SCALARS)
        out = {"screen": [count] * n_screen + [scale for _, _, scale in _SCALARS]}
        if self.cfg.minimap:
            out["minimap"] = [count] * len(self.minimap_channels)
        return out

    def empty(self) -> dict[str, np.ndarray]:
        """Zeroed arrays of one observation."""
        return {k: np.zeros(b.shape, b.dtype) for k, b in self.space.spaces.items()}

    def __call__(self, obs: Mapping[str, Any], out: Mapping[str, np.ndarray] | None = None,
                 clock: MacroClock | None = None) -> dict[str, np.ndarray]:
        """The policy's arrays of ``obs``, written into ``out`` when given (and returned);
        ``clock`` is the episode's :class:`MacroClock`, needed with ``history``."""
        if self.cfg.kind == "stored":
            arrays = self.schema.extract(obs)
            if out is None:
                return arrays
            for k, a in arrays.items():
                out[k][...] = a
            return dict(out)
        dest = dict(out) if out is not None else self.empty()
        screen = np.asarray(obs["feature_screen"])
        self._screen(screen, dest["screen"])
        if self.cfg.minimap:
            self._minimap(np.asarray(obs["feature_minimap"]), dest["minimap"])
        self._vector(obs, dest["vector"])
        if self.cfg.history:
            if clock is None:
                raise ValueError("an observation with history needs the episode's MacroClock")
            dest["vector"][-self._n_history:] = clock.features(game_loop(obs))
        return dest

    # -- compact ---------------------------------------------------------------------------------

    def _screen(self, screen: np.ndarray, out: np.ndarray) -> None:
        n_units = len(UNIT_TYPES)
        codes = self._lut[np.minimum(screen[_S.unit_type.index], len(self._lut) - 1)]
        planes = np.empty((len(self.screen_channels), SCREEN_SIZE, SCREEN_SIZE), np.uint8)
        np.equal(codes[None], np.arange(n_units, dtype=np.uint8)[:, None, None],
                 out=planes[:n_units].view(bool))
        rel = screen[_S.player_relative.index]
        for j, r in enumerate(_REL):
            np.equal(rel, r, out=planes[n_units + j].view(bool))
        c = n_units + len(_REL)
        np.not_equal(screen[_S.selected.index], 0, out=planes[c].view(bool))
        for j, (name, top, _) in enumerate(_SCALARS):
            np.minimum(screen[getattr(_S, name).index], top, out=planes[c + 1 + j],
                       casting="unsafe")
        _fit(planes, out, n_onehot=c + 1)

    def _minimap(self, minimap: np.ndarray, out: np.ndarray) -> None:
        planes = np.empty((len(self.minimap_channels), SCREEN_SIZE, SCREEN_SIZE), np.uint8)
        rel = minimap[_M.player_relative.index]
        for j, r in enumerate(_REL):
            np.equal(rel, r, out=planes[j].view(bool))
        np.not_equal(minimap[_M.selected.index], 0, out=planes[2].view(bool))
        np.not_equal(minimap[_M.camera.index], 0, out=planes[3].view(bool))
        _fit(planes, out, n_onehot=len(planes))

    def _vector(self, obs: Mapping[str, Any], out: np.ndarray) -> None:
        player = np.asarray(obs["player"], dtype=np.float64).reshape(-1)
        n = len(player)
        np.log1p(np.maximum(player, 0.0), out=out[:n], casting="unsafe")
        out[n] = game_loop(obs) / GAME_LOOPS
        table = np.zeros(len(actions.FUNCTIONS), dtype=bool)
        table[np.asarray(obs["available_actions"])] = True
        out[n + 1:n + 1 + len(PAPER_FUNCTIONS)] = table[_paper_ids()]


def history_actions(action_space: str) -> tuple[str, ...]:
    """The actions ``history`` times in ``action_space``: the macros, or the paper space's
    functions."""
    return MACROS if action_space == "macro" else PAPER_FUNCTIONS


class MacroClock:
    """When each action last *acted* in an episode. Macro space (the default ``names``): a
    macro acts when it sends its first call that is not a wait (the ``no_op`` macro: its
    ``no_op``); one that gave up waiting for minerals or sent nothing did not act; a forced wait
    (``merge_waits``) is no choice and not recorded. Paper space (``names`` the
    :data:`PAPER_FUNCTIONS`): a function acts when its call is sent (:meth:`acted`); an
    unavailable one is sent as ``no_op``, which then acts.

    The features are ``log(1 + loops since) / log(1 + 14,400)`` per action, in ``names``
    order, 1 for one that has not acted this episode: fine over the first few hundred loops
    (a builder's walk, a marine's 400 loops of training) and bounded. The gymnasium env and the
    ``policy:RUN`` rollout agent keep one each, fed the same way.
    """

    def __init__(self, names: tuple[str, ...] = MACROS) -> None:
        self.names = names
        """The actions it times, in feature order."""
        self.last = np.full(len(names), -1, np.int64)
        self._running = -1  # the macro being played out that has not acted yet, or -1

    def reset(self) -> None:
        self.last[:] = -1
        self._running = -1

    def start(self, name: str) -> None:
        """Macro ``name`` was chosen and is about to send its calls."""
        self._running = self.names.index(name)

    def sent(self, call: actions.FunctionCall, game_loop: int) -> None:
        """The running macro sends ``call`` on the observation of ``game_loop``: it acts now
        unless the call is a wait (the ``no_op`` macro's own ``no_op`` is its act)."""
        i = self._running
        if i >= 0 and (self.names[i] == "no_op" or call.function != actions.FUNCTIONS.no_op.id):
            self.acted(i, game_loop)
            self._running = -1

    def acted(self, action: int, game_loop: int) -> None:
        """Action ``action`` (its index) sent a call on the observation of ``game_loop``."""
        self.last[action] = game_loop

    def features(self, game_loop: int) -> np.ndarray:
        since = np.where(self.last < 0, GAME_LOOPS,
                         np.clip(game_loop - self.last, 0, GAME_LOOPS))
        return (np.log1p(since) / np.log1p(GAME_LOOPS)).astype(np.float32)


def game_loop(obs: Mapping[str, Any]) -> int:
    """The game loop of a pysc2 observation (its ``game_loop`` array's one value)."""
    return int(np.asarray(obs["game_loop"]).reshape(-1)[0])


def _fit(planes: np.ndarray, out: np.ndarray, n_onehot: int) -> None:
    """``planes`` (C, 64, 64) into ``out`` (C, S, S): copied at 64, else 2×2 sums of the first
    ``n_onehot`` (one-hot) channels and 2×2 means of the rest."""
    if out.shape[-1] == planes.shape[-1]:
        out[...] = planes
        return
    # Rows first, then columns, each a pair of contiguous halves: numpy's sum over the inner
    # axes of a (C, S, 2, S, 2) view took 520 µs for the 13 screen channels, this ~25 µs.
    c, n = planes.shape[0], out.shape[-1]
    v = planes.reshape(c * n, 2, n, 2)
    rows = v[:, 0].astype(np.uint16)
    rows += v[:, 1]
    sums = (rows[..., 0] + rows[..., 1]).reshape(c, n, n)
    sums[n_onehot:] >>= 2
    out[...] = sums


@functools.cache
def _paper_ids() -> np.ndarray:
    return np.array([int(actions.FUNCTIONS[name].id) for name in PAPER_FUNCTIONS])
