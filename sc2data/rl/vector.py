"""Many BuildMarines games stepped together: one batched call, arrays in shared memory.

:class:`BuildMarinesVecEnv` is a vector of ``n`` :class:`~sc2data.rl.envs.BuildMarinesGym`
games behind SB3's ``VecEnv`` interface (MaskablePPO trains on it unchanged; ``action_masks``
comes batched, read from memory, not asked of each game). The games are split over ``processes``
worker processes (0: all in this process), each stepping its share one after another and
writing observations, masks, the game's reward, the episode's end and the pysc2 frames of each
decision straight into preallocated arrays. Those arrays live in one shared-memory file
(:mod:`sc2data.rl.arena`) that every process maps: a vector step sends each worker one short
message and nothing else crosses a pipe (EnvPool, Sample Factory and PufferLib work so). What a
worker runs is in :mod:`sc2data.rl.games`, which loads neither torch nor stable-baselines3.

The reward is computed here, in the learner's process, once per vector step for all games
(:mod:`sc2data.rl.batched`): the narration reward scores every game's new two-frame stacks in one
MEM call, from the frames the workers already extracted; one MEM is loaded, not one per worker.
A contiguous part of the games can be stepped and waited for on its own (``step_async_rows``),
its reward scored at once or, with the parts waited for after it, in one call once they step
again (``score_waited``), so that the learner works for one part while another steps
(:mod:`sc2data.rl.pipeline`).

Semantics are those of SB3's ``DummyVecEnv`` over the same games: game ``i`` is reset with
``seed + i`` after :meth:`seed` (then continues its own stream), a game that ends is reset at
once and its last observation is ``info["terminal_observation"]``; the same seed and the same
``n`` give the same trajectories whatever ``processes`` is. Each game's ``info`` carries
``game_reward``, ``shaping``, ``env_steps``, ``invalid``, ``game_loop`` and ``marines`` as
:class:`~sc2data.rl.envs.BuildMarinesGym` and the reward wrappers give them.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import os
import signal
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from multiprocessing import resource_tracker
from multiprocessing.connection import Connection
from typing import Any

import gymnasium.vector as gym_vector
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from sc2data.ground.errors import Sc2DataError
from sc2data.rl.arena import Arena, Field
from sc2data.rl.games import GameConfig, GameSlice, _serve, layout

__all__ = ["BuildMarinesVecEnv", "BuildMarinesVectorEnv", "GameConfig", "GameSlice",
           "default_processes", "spans"]


def spans(n: int, k: int) -> list[tuple[int, int]]:
    """Games ``0..n`` in ``k`` contiguous parts as even as can be: how games are spread over
    worker processes, and over the groups of a pipelined rollout (:mod:`sc2data.rl.pipeline`)."""
    bounds = np.linspace(0, n, k + 1).round().astype(int)
    return [(int(lo), int(hi)) for lo, hi in zip(bounds[:-1], bounds[1:])]


def default_processes(n: int, spare: int = 0) -> int:
    """Worker processes for ``n`` games: none for one game, else one per core less ``spare``
    (cores left to the learner), at least one, at most ``n``."""
    if n <= 1:
        return 0
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(n, cores - spare))


def _stacked(parts: list[np.ndarray]) -> np.ndarray:
    """Parts' frames ``(games, slots, …)`` one after another, the slots of the part with the
    most (the others' extra slots zero: no decision of theirs reads them)."""
    if len(parts) == 1:
        return parts[0]
    slots = max(p.shape[1] for p in parts)
    out = np.zeros((sum(len(p) for p in parts), slots, *parts[0].shape[2:]), parts[0].dtype)
    row = 0
    for p in parts:
        out[row:row + len(p), :p.shape[1]] = p
        row += len(p)
    return out


@dataclass
class _Waited:
    """A part of the games waited for and not yet scored: what its reward and infos need."""

    lo: int
    hi: int
    game: np.ndarray
    done: np.ndarray
    frames: dict[str, np.ndarray] = field(default_factory=dict)
    n_frames: np.ndarray | None = None
    infos: list[dict[str, Any]] = field(default_factory=list)


class BuildMarinesVecEnv(VecEnv):
    """``n`` BuildMarines games as one SB3 ``VecEnv`` (see the module docstring).

    ``shaping`` (:mod:`sc2data.rl.batched`) adds its bonus to the game's reward and reads the
    frames of its schema; ``None`` is the game's sparse reward.

    Besides SB3's ``step_async``/``step_wait`` for every game, :meth:`step_async_rows` and
    :meth:`step_wait_rows` step a contiguous part of the games (waited for in the order sent),
    so that a learner can act for one part while another steps (:mod:`sc2data.rl.pipeline`).
    """

    def __init__(self, cfg: GameConfig, n: int, *, processes: int | None = None,
                 shaping: Any = None, reward_scale: float = 1.0) -> None:
        if n < 1:
            raise Sc2DataError("--envs must be at least 1")
        if shaping is not None and cfg.frames is None and shaping.schema is not None:
            cfg = dataclasses.replace(cfg, frames=shaping.schema)
        self.game_weight = float(getattr(shaping, "game_weight", 1.0))
        self.cfg, self.shaping = cfg, shaping
        self.reward_scale = float(reward_scale)
        """What the learner's reward is multiplied by (infos keep the game's and the bonus's
        own figures)."""
        # A MEM scoring the reward makes the learner's share of a step the larger one: it gets
        # a core of its own (2 cores: one worker, 1.13× two on paper narration, 1.08× on macro
        # narration; with no MEM two workers, 1.26× one on macro sparse; BENCHMARKS.md, "A
        # worker without torch, a core for the learner").
        spare = 1 if getattr(shaping, "scorer", None) is not None else 0
        k = default_processes(n, spare) if processes is None else int(processes)
        if k < 0:
            raise Sc2DataError("--processes must be 0 or more")
        self.processes = min(k, n)
        probe = cfg.make()
        fields = layout(cfg, n, probe)
        obs_space, act_space = probe.observation_space, probe.action_space
        self._conns: list[Connection] = []
        self._procs: list[Any] = []
        self._slices = spans(n, self.processes)
        self._inflight: list[tuple[int, int, list[int]]] = []
        """Parts sent to step and not yet waited for: their rows and the workers stepping them."""
        self._waited: list[_Waited] = []
        """Parts waited for and not yet scored (:meth:`step_wait_rows_unscored`)."""
        self._local: GameSlice | None = None
        self.arena = Arena.private(fields) if self.processes == 0 else Arena.create(fields)
        try:
            if self.processes == 0:
                probe.close()
                self._local = GameSlice(cfg, 0, n, self.arena.arrays)
            else:
                probe.close()
                self._start(cfg, n, fields)
        except BaseException:
            self.close()
            raise
        finally:
            self.arena.unlink()
        self.a = self.arena.arrays
        self.obs_keys = [k[4:] for k in self.a if k.startswith("obs/")]
        self.frame_arrays = {k[7:]: v for k, v in self.a.items() if k.startswith("frames/")}
        self._closed = False
        super().__init__(n, obs_space, act_space)

    # -- processes -------------------------------------------------------------------------------

    def _start(self, cfg: GameConfig, n: int, fields: list[Field]) -> None:
        ctx = mp.get_context("spawn")
        # Ctrl-C must reach the learner (which stops the workers) and never a worker (a
        # traceback each): the workers start with SIGINT blocked, a mask that survives exec,
        # and ignore it before unblocking (_serve). The learner's own mask is restored at
        # once, so a Ctrl-C that came meanwhile is delivered to it then. multiprocessing's
        # resource tracker is started first: starting it (in the first p.start()) unblocks
        # SIGINT on its way out, and the workers started after it would inherit that.
        # The mask is this thread's only: a Ctrl-C another thread of ours (torch's, tqdm's)
        # receives still interrupts this one, so it is deferred (a handler that notes it) until
        # every started worker has its start-up data, then raised again: interrupted mid-
        # p.start(), a worker would read a half-written pipe and print a traceback.
        resource_tracker.ensure_running()
        deferred: list[int] = []
        main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, lambda s, _: deferred.append(s)) if main else None
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            for lo, hi in self._slices:
                mine, theirs = ctx.Pipe()
                p = ctx.Process(target=_serve, args=(theirs, cfg, lo, hi,
                                                     self.arena.path, fields), daemon=True)
                p.start()
                theirs.close()
                self._conns.append(mine)
                self._procs.append(p)
        finally:
            if main:  # None: a handler not set from Python; Python's own stands in for it
                signal.signal(signal.SIGINT, signal.default_int_handler if previous is None
                              else previous)
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        if deferred:
            signal.raise_signal(signal.SIGINT)
        self._collect()

    def _send(self, cmd: str, args: Sequence[Any] | None = None,
              workers: Sequence[int] | None = None) -> None:
        if self._local is not None:
            if cmd == "reset":
                self._local.reset(args[0] if args else [None] * self.num_envs)
            return
        for j in range(len(self._conns)) if workers is None else workers:
            try:
                self._conns[j].send((cmd, None if args is None else args[j]))
            except (BrokenPipeError, ConnectionResetError):
                self._died(self._procs[j])

    def _died(self, p: Any) -> None:
        p.join(timeout=1)
        self.close()
        raise Sc2DataError(f"an environment process ended unexpectedly (exit code "
                           f"{p.exitcode}); rerun the same command to resume") from None

    def _collect(self, workers: Sequence[int] | None = None) -> None:
        for j in range(len(self._conns)) if workers is None else workers:
            conn, p = self._conns[j], self._procs[j]
            try:
                kind, msg = conn.recv()
            except (EOFError, ConnectionResetError):
                self._died(p)
            if kind == "error":
                self.close()
                raise Sc2DataError(f"environment process: {msg}")

    def _per_worker(self, values: Sequence[Any]) -> list[list[Any]]:
        if self._local is not None:
            return [list(values)]
        return [list(values[lo:hi]) for lo, hi in self._slices]

    # -- VecEnv ----------------------------------------------------------------------------------

    def reset(self) -> dict[str, np.ndarray]:
        if self._inflight:  # their replies would be read as the reset's
            raise RuntimeError("reset while games are stepping: wait for them first")
        if self._waited:
            raise RuntimeError("reset while games wait to be scored: score_waited() first")
        self._send("reset", self._per_worker(self._seeds))
        if self._local is None:
            self._collect()
        self._reset_seeds()
        if self.shaping is not None:
            self.shaping.reset(self.num_envs)
        self.reset_infos = [{"game_reward": 0.0, "env_steps": 0,
                             "game_loop": int(self.a["game_loop"][i]),
                             "marines": int(self.a["marines"][i])} for i in range(self.num_envs)]
        return self._obs()

    def step_async(self, actions: np.ndarray) -> None:
        self.step_async_rows(0, self.num_envs, actions)

    def step_wait(self) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, list[dict]]:
        return self.step_wait_rows(0, self.num_envs)

    def step_async_rows(self, lo: int, hi: int, actions: np.ndarray) -> None:
        """Start stepping games ``lo`` to ``hi`` with ``actions`` (one row per game)."""
        self.a["actions"][lo:hi] = np.asarray(actions).reshape(hi - lo, -1)
        workers = [j for j, (a, b) in enumerate(self._slices) if a < hi and lo < b]
        self._inflight.append((lo, hi, workers))
        self._send("step", [(lo, hi)] * len(self._slices), workers)

    def step_wait_rows(self, lo: int, hi: int
                       ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, list[dict]]:
        """Wait for games ``lo`` to ``hi`` (the oldest part sent) and give what ``step_wait``
        gives, for those games."""
        if self._waited:
            raise RuntimeError("games waited for and not yet scored: score_waited() first")
        obs, done = self._wait_rows(lo, hi, keep_frames=False)  # scored before they step again
        reward, _, infos = self.score_waited()
        return obs, reward, done, infos

    def step_wait_rows_unscored(self, lo: int, hi: int) -> tuple[dict[str, np.ndarray],
                                                                 np.ndarray]:
        """Wait for games ``lo`` to ``hi`` (the oldest part sent) and give their observations
        and episode ends; their reward waits for :meth:`score_waited`, which scores every part
        waited for since in one shaping call (one MEM call for the narration reward: two calls
        of 8 stacks cost 1.4× one of 16, BENCHMARKS.md). Their frames are copied meanwhile,
        so the part may step again before it is scored."""
        return self._wait_rows(lo, hi, keep_frames=True)

    def _wait_rows(self, lo: int, hi: int, keep_frames: bool
                   ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Wait for games ``lo`` to ``hi`` and set them aside for :meth:`score_waited`, their
        frames copied (``keep_frames``) or as views of the arrays the next step overwrites."""
        if not self._inflight or self._inflight[0][:2] != (lo, hi):
            raise RuntimeError(f"games {lo}-{hi} waited for out of the order they were sent in")
        if self._waited and self._waited[-1].hi != lo:
            raise RuntimeError(f"games {lo}-{hi} waited for before games "
                               f"{self._waited[-1].hi}-{lo} were scored")
        workers = self._inflight.pop(0)[2]
        if self._local is not None:
            self._local.step(lo, hi)
        else:
            self._collect(workers)
        a = self.a
        part = _Waited(lo, hi, game=a["game_reward"][lo:hi].copy(), done=a["done"][lo:hi].copy())
        if self.shaping is not None:
            part.n_frames = a["n_frames"][lo:hi].copy()
            used = int(part.n_frames.max())  # the slots a decision filled, not all of them
            part.frames = {k: v[lo:hi, :used].copy() if keep_frames else v[lo:hi, :used]
                           for k, v in self.frame_arrays.items()}
        for j, i in enumerate(range(lo, hi)):
            info = {"game_reward": float(part.game[j]), "env_steps": int(a["env_steps"][i]),
                    "invalid": bool(a["invalid"][i]), "game_loop": int(a["game_loop"][i]),
                    "marines": int(a["marines"][i])}
            if part.done[j]:
                info["terminal_observation"] = {k: a[f"final/{k}"][i].copy()
                                                for k in self.obs_keys}
            part.infos.append(info)
        self._waited.append(part)
        return self._obs(lo, hi), part.done.copy()

    def score_waited(self) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """The rewards, episode ends and infos of the games waited for since the last call
        (:meth:`step_wait_rows_unscored`), in order: one shaping call for them all."""
        parts, self._waited = self._waited, []
        if not parts:
            return np.zeros(0, np.float32), np.zeros(0, bool), []
        game = np.concatenate([p.game for p in parts])
        done = np.concatenate([p.done for p in parts])
        infos = [i for p in parts for i in p.infos]
        extra = np.zeros(len(game))
        extra_info: list[dict[str, Any]] = [{} for _ in infos]
        if self.shaping is not None:
            n_frames = np.concatenate([p.n_frames for p in parts])
            frames = {k: _stacked([p.frames[k] for p in parts]) for k in parts[0].frames}
            extra, extra_info = self.shaping(frames, n_frames, done, first=parts[0].lo)
            extra = extra + (self.game_weight - 1.0) * game  # a control may take the game's away
        for info, e, more in zip(infos, extra, extra_info):
            info["shaping"] = float(e)
            info.update(more)
        reward = (game + extra) * self.reward_scale
        return reward.astype(np.float32), done, infos

    def _obs(self, lo: int = 0, hi: int | None = None) -> dict[str, np.ndarray]:
        # Copies: SB3 keeps the last observation while the next step overwrites the arrays.
        return {k: self.a[f"obs/{k}"][lo:hi].copy() for k in self.obs_keys}

    def action_masks(self, lo: int = 0, hi: int | None = None) -> np.ndarray:
        """``(n, mask length)``: every game's mask (sb3-contrib's protocol, batched), or games
        ``lo`` to ``hi``'s."""
        return self.a["masks"][lo:hi].copy()

    def close(self) -> None:
        if getattr(self, "_closed", False):
            return
        self._closed = True
        for conn in self._conns:
            try:
                conn.send(("close", None))
            except (BrokenPipeError, OSError):
                pass
        for p in self._procs:
            p.join(timeout=5)
            if p.is_alive():
                p.kill()
                p.join()
        for conn in self._conns:
            conn.close()
        if self._local is not None:
            self._local.close()

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None,
                   **method_kwargs: Any) -> list[Any]:
        if method_name == "action_masks":
            masks = self.a["masks"]
            return [masks[i].copy() for i in self._get_indices(indices)]
        raise AttributeError(f"BuildMarinesVecEnv games have no method {method_name!r} "
                             f"reachable from the learner")

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        n = len(list(self._get_indices(indices)))
        if attr_name == "render_mode":
            return [None] * n
        if attr_name == "action_masks":
            return [self.action_masks] * n
        raise AttributeError(f"BuildMarinesVecEnv games have no attribute {attr_name!r} "
                             f"reachable from the learner")

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        raise AttributeError(f"BuildMarinesVecEnv cannot set {attr_name!r} on its games")

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(list(self._get_indices(indices)))

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass


class BuildMarinesVectorEnv(gym_vector.VectorEnv):  # type: ignore[misc]
    """The same games behind gymnasium's vector API (``gymnasium.vector.VectorEnv``).

    ``reset(seed=s)`` seeds game i with ``s + i``; ``step`` returns batched observations,
    rewards, ``terminated`` (the game's timer) and ``truncated`` (always False), and ``infos`` as
    gymnasium batches them (each key an array, ``_key`` saying which games carry it). A game that
    ends is reset in the same step (``AutoresetMode.SAME_STEP``): its last observation is
    ``infos["final_obs"][i]``. ``action_masks()`` gives every game's mask.
    """

    metadata = {"autoreset_mode": gym_vector.AutoresetMode.SAME_STEP}

    def __init__(self, cfg: GameConfig, n: int, *, processes: int | None = None,
                 shaping: Any = None) -> None:
        self.vec = BuildMarinesVecEnv(cfg, n, processes=processes, shaping=shaping)
        self.num_envs = n
        probe = self.vec.observation_space
        self.single_observation_space = probe
        self.single_action_space = self.vec.action_space
        self.observation_space = gym_vector.utils.batch_space(probe, n)
        self.action_space = gym_vector.utils.batch_space(self.vec.action_space, n)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        if seed is not None:
            self.vec.seed(seed)
        obs = self.vec.reset()
        return obs, _batch_infos(self.vec.reset_infos)

    def step(self, actions: Any) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray,
                                          np.ndarray, dict[str, Any]]:
        obs, rewards, dones, infos = self.vec.step(np.asarray(actions))
        final = [i.pop("terminal_observation", None) for i in infos]
        batched = _batch_infos(infos)
        if any(f is not None for f in final):
            batched["final_obs"] = np.array(final, dtype=object)
            batched["_final_obs"] = np.array([f is not None for f in final])
        return obs, rewards, dones, np.zeros_like(dones), batched

    def action_masks(self) -> np.ndarray:
        return self.vec.action_masks()

    def close_extras(self, **kwargs: Any) -> None:
        self.vec.close()


def _batch_infos(infos: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Per-game info dicts as gymnasium's vector infos: one array per key, ``_key`` masks."""
    out: dict[str, Any] = {}
    for key in sorted({k for i in infos for k in i}):
        present = np.array([key in i for i in infos])
        values = [i.get(key, 0) for i in infos]
        out[key] = np.array(values)
        out[f"_{key}"] = present
    return out
