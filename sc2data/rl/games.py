"""The games of a vector env, on the worker's side: what a game is, the shared arrays' layout, and
the loop a worker process runs (:mod:`sc2data.rl.vector` is the learner's side).

A worker process imports this module and not :mod:`sc2data.rl.vector`, whose ``VecEnv`` base
brings stable-baselines3 and torch: a worker steps the simulator and needs neither, and not
loading them is most of its start-up (BENCHMARKS.md, "A worker without torch, a core for the
learner").
"""

from __future__ import annotations

import signal
from collections.abc import Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
from gymnasium import spaces

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import one_line
from sc2data.rl.arena import Arena, Field
from sc2data.rl.envs import MAX_DECISION_STEPS, BuildMarinesGym
from sc2data.rl.obs import ObsConfig
from sc2data.schema import Schema


@dataclass(frozen=True)
class GameConfig:
    """What every game of a vector is (picklable: sent to the worker processes)."""

    action_space: str = "macro"
    backend: str = "sim"
    obs: ObsConfig = field(default_factory=ObsConfig)
    game_loops: int | None = None
    """Episode length in game loops (simulator only); None: the map's 14,400."""
    frames: Schema | None = None
    """The layers and vectors of each decision's pysc2 frames kept for the reward (None: none)."""
    merge_waits: bool = False
    """Macro space: forced ``no_op`` steps join the decision before them (``BuildMarinesGym``)."""
    sites: str = "random"
    """Macro space: where buildings go (``BuildMarinesGym``)."""

    def make(self) -> BuildMarinesGym:
        draw = None if self.frames is None else frozenset(l.key for l in self.frames.layers)
        if self.frames is None and self.backend == "sim":
            draw = frozenset()
        return BuildMarinesGym(self.action_space, backend=self.backend, obs=self.obs,
                               game_loops=self.game_loops, draw=draw,
                               merge_waits=self.merge_waits, sites=self.sites)

    def max_steps(self) -> int:
        return 1 if self.action_space == "paper" else MAX_DECISION_STEPS


def layout(cfg: GameConfig, n: int, env: BuildMarinesGym) -> list[Field]:
    """The shared arrays of a vector of ``n`` games like ``env``."""
    obs_space = env.observation_space
    assert isinstance(obs_space, spaces.Dict)
    fields: list[Field] = []
    for k, b in obs_space.spaces.items():
        fields.append(Field(f"obs/{k}", (n, *b.shape), np.dtype(b.dtype)))
        fields.append(Field(f"final/{k}", (n, *b.shape), np.dtype(b.dtype)))
    act = env.action_space
    if isinstance(act, spaces.Discrete):
        n_act, n_mask = 1, int(act.n)
    else:
        assert isinstance(act, spaces.MultiDiscrete)
        n_act, n_mask = len(act.nvec), int(np.sum(act.nvec))
    fields += [Field("actions", (n, n_act), np.dtype(np.int64)),
               Field("masks", (n, n_mask), np.dtype(bool)),
               Field("game_reward", (n,), np.dtype(np.float64)),
               Field("done", (n,), np.dtype(bool)),
               Field("invalid", (n,), np.dtype(bool)),
               Field("env_steps", (n,), np.dtype(np.int32)),
               Field("game_loop", (n,), np.dtype(np.int32)),
               Field("marines", (n,), np.dtype(np.int32)),
               Field("n_frames", (n,), np.dtype(np.int32))]
    if cfg.frames is not None:
        f = cfg.max_steps() + 1
        for l in cfg.frames.layers:
            side = cfg.frames.size(l.group)
            fields.append(Field(f"frames/{l.key}", (n, f, side, side), l.dtype))
        for v in cfg.frames.vectors:
            fields.append(Field(f"frames/{v.name}", (n, f, v.size), v.dtype))
    return fields


class FrameWriter:
    """A pysc2 observation's layers and vectors of a schema, copied into arrays without the
    range checks of ``Schema.extract`` (the simulator draws every layer within its scale)."""

    def __init__(self, schema: Schema) -> None:
        self.screen = [(l.key, l.index) for l in schema.screen]
        self.minimap = [(l.key, l.index) for l in schema.minimap]
        self.vectors = [(v.name, v.size) for v in schema.vectors]

    def __call__(self, obs: Any, arrays: dict[str, np.ndarray], i: int, j: int) -> None:
        # Plain ndarray views: indexing pysc2's named arrays costs ~15 µs a layer.
        screen = np.asarray(obs["feature_screen"]).view(np.ndarray)
        minimap = np.asarray(obs["feature_minimap"]).view(np.ndarray)
        for key, index in self.screen:
            arrays[key][i, j] = screen[index]
        for key, index in self.minimap:
            arrays[key][i, j] = minimap[index]
        for name, _ in self.vectors:
            arrays[name][i, j] = np.asarray(obs[name]).view(np.ndarray).reshape(-1)

    def copy(self, arrays: dict[str, np.ndarray], i: int, src: int, dst: int) -> None:
        """Slot ``src`` of game ``i`` into slot ``dst`` (a decision starts where the last ended)."""
        for a in arrays.values():
            a[i, dst] = a[i, src]


class GameSlice:
    """Games ``lo`` to ``hi`` of a vector, stepped in this process, writing into ``arrays``."""

    def __init__(self, cfg: GameConfig, lo: int, hi: int, arrays: dict[str, np.ndarray]) -> None:
        self.cfg, self.lo, self.hi, self.a = cfg, lo, hi, arrays
        self.envs = [cfg.make() for _ in range(lo, hi)]
        self.obs_keys = [k[4:] for k in arrays if k.startswith("obs/")]
        self.frames = {k[7:]: a for k, a in arrays.items() if k.startswith("frames/")}
        self.write_frame = FrameWriter(cfg.frames) if cfg.frames is not None else None
        self.max_steps = cfg.max_steps()
        self.fresh = [True] * (hi - lo)
        """Whether game i's next decision starts from a new episode's first frame (extracted),
        else from the last frame of its previous decision (copied, already extracted)."""

    def reset(self, seeds: Sequence[int | None]) -> None:
        for j, env in enumerate(self.envs):
            i = self.lo + j
            obs, info = env.reset(seed=seeds[j])
            for k in self.obs_keys:
                self.a[f"obs/{k}"][i] = obs[k]
            self.a["masks"][i] = env.action_masks()
            self.a["game_loop"][i] = info["game_loop"]
            self.a["marines"][i] = info["marines"]
            self.a["done"][i] = self.a["invalid"][i] = False
            self.a["game_reward"][i] = 0.0
            self.a["env_steps"][i] = 0
            self.a["n_frames"][i] = 1
            self.fresh[j] = True

    def step(self, lo: int, hi: int) -> None:
        """Step this slice's games among games ``lo`` to ``hi`` of the vector."""
        actions = self.a["actions"]
        for j in range(max(lo, self.lo) - self.lo, min(hi, self.hi) - self.lo):
            i, env = self.lo + j, self.envs[j]
            action = actions[i, 0] if actions.shape[1] == 1 else actions[i]
            obs, reward, terminated, truncated, info = env.step(action)
            self._frames(i, j, env)
            a = self.a
            a["game_reward"][i] = reward
            a["invalid"][i] = info["invalid"]
            a["env_steps"][i] = info["env_steps"]
            a["game_loop"][i] = info["game_loop"]
            a["marines"][i] = info["marines"]
            done = terminated or truncated
            a["done"][i] = done
            self.fresh[j] = done
            if done:
                for k in self.obs_keys:
                    a[f"final/{k}"][i] = obs[k]
                obs, _ = env.reset()
            for k in self.obs_keys:
                a[f"obs/{k}"][i] = obs[k]
            a["masks"][i] = env.action_masks()

    def _frames(self, i: int, j: int, env: BuildMarinesGym) -> None:
        """The decision's frames into game i's slots: the first from the last decision's last
        slot (or extracted, after a reset), then one per pysc2 step."""
        last = int(self.a["n_frames"][i]) - 1
        n = len(env.frames)
        self.a["n_frames"][i] = n
        if self.write_frame is None:
            return
        if n > self.max_steps + 1:
            raise Sc2DataError(f"a decision took {n - 1} pysc2 steps, more than the "
                               f"{self.max_steps} the vector env holds frames for")
        if self.fresh[j]:
            self.write_frame(env.frames[0], self.frames, i, 0)
        elif last:
            self.write_frame.copy(self.frames, i, last, 0)
        for k, f in enumerate(env.frames[1:], 1):
            self.write_frame(f, self.frames, i, k)

    def close(self) -> None:
        for env in self.envs:
            env.close()


def _serve(conn: Connection, cfg: GameConfig, lo: int, hi: int, path: str,
           fields: list[Field]) -> None:
    """A worker process: games ``lo`` to ``hi`` over the arena at ``path``, one pipe message
    per vector step; errors go back as one line. It ends when the learner closes the pipe."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the learner handles Ctrl-C and stops us
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    games = None
    try:
        arena = Arena.attach(path, fields)
        games = GameSlice(cfg, lo, hi, arena.arrays)
        conn.send(("ready", None))
        while True:
            cmd, arg = conn.recv()
            if cmd == "step":
                games.step(*arg)
            elif cmd == "reset":
                games.reset(arg)
            elif cmd == "close":
                break
            conn.send(("ok", None))
    except (EOFError, BrokenPipeError, KeyboardInterrupt):
        pass
    except BaseException as e:  # noqa: BLE001 - reported to the learner as one line
        try:
            conn.send(("error", one_line(e)))
        except (BrokenPipeError, OSError):
            pass
    finally:
        if games is not None:
            games.close()
