"""``sc2data rollout``: agents play BuildMarines and their 2-frame stacks stream into shards.

Shard ``i`` holds episodes ``[i·E, (i+1)·E)`` and episode ``e`` is seeded from ``(seed, e)``
alone, so the data never depends on the number of workers. K worker processes each write whole
shards as ``*.h5.partial`` and rename them when complete and fsynced
(:mod:`sc2data.ground.workers`); the parent shows one progress bar fed by the workers, and writes
``index.parquet`` last.
Rerunning the same command after an interruption (Ctrl-C, ``kill -9``) deletes stale partials,
keeps the complete shards and finishes the rest; other settings in the same folder are refused.

A dataset grows: more ``episodes`` with the same other settings adds the missing episodes (the
last shard of the smaller run, if partial, is rolled out again from its episodes' seeds), and the
folder ends byte for byte as a fresh run of that many episodes would leave it, since no shard
records the episode count. Fewer episodes than the folder holds are refused: a dataset only
grows.
"""

from __future__ import annotations

import contextlib
import functools
import os
import random
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from sc2data._pysc2 import base_agent, environment
from sc2data.data.audit import check_shard
from sc2data.data.chunks import Codec
from sc2data.data.dataset import (
    DATASET_RECORD,
    INDEX,
    keep_freed_memory,
    read_dataset_record,
    read_index,
    shard_name,
    shard_settings,
    write_dataset_record,
    write_index,
)
from sc2data.data.shards import Shard, ShardWriter
from sc2data.game import env as envs
from sc2data.ground.errors import Sc2DataError, reason
from sc2data.ground.files import LOCK, PARTIAL, FolderLock, publish, sha256_file, writing
from sc2data.ground.formats import DATASET
from sc2data.ground.progress import Bar
from sc2data.ground.progress import bar as progress_bar
from sc2data.ground.provenance import versions
from sc2data.ground.recipe import MAX_EPISODES, Recipe, RolloutSpec
from sc2data.ground.resume import differences, refusal
from sc2data.ground.vocab import BACKENDS, EPISODE_STEPS, LAYER_SETS, MAP_NAME
from sc2data.ground.workers import run_parallel
from sc2data.schema import Schema

EnvFactory = Callable[[int], environment.Base]
"""``seed -> environment.Base`` (a pysc2 environment) for one episode."""
AgentFactory = Callable[[int], base_agent.BaseAgent]
"""``seed -> pysc2 BaseAgent`` for one episode."""
ShardRunner = Callable[["RolloutConfig", Path, list[int], EnvFactory, AgentFactory, Bar],
                      dict[int, list[dict[str, Any]]]]
"""Writes the shards ``todo`` elsewhere than in local worker processes (Ray tasks:
``sc2data.scaleout.driver.RayShards``):
``runner(config, out, todo, env_factory, agent_factory, bar)``,
each shard through :func:`write_shard`, feeding the progress ``bar``; returns what
:func:`write_shard` returned, by shard."""
_SETTINGS_ORDER = ("env", "agent", "episodes", "seed", "layers", "episodes_per_shard", "max_steps",
                   "step_mul", "recipe", "codec")
"""Key order of the settings JSON in ``dataset.json`` and every shard (kept so bytes stay equal)."""
_OPTIONAL_SETTINGS = ("agent_sha256",)
"""Settings recorded only when set, after the others: data made without them keeps its bytes."""


@dataclass(frozen=True)
class RolloutConfig(RolloutSpec):
    """Everything that decides a rollout's data (the number of workers does not): the recipe's
    rollout section plus the run's own settings."""

    seed: int = 0
    """Root seed; episode ``e`` is seeded from ``SeedSequence(seed, spawn_key=(e,))``."""
    episodes_per_shard: int = 8
    """Episodes per shard file: bounds a shard to ~8 × 1,801 frames (≈15 MB at 1 KB/frame)."""
    max_steps: int | None = None
    """Cut episodes after this many steps (None: play to the end, 1,800 steps on BuildMarines)."""
    recipe: str | None = None
    """The recipe (``manifests/*.toml``) these settings came from, if any."""
    codec: Codec = field(default_factory=Codec)
    """Chunking and compression of frame datasets."""
    agent_sha256: str | None = None
    """The sha256 of what the agent loads (a ``policy:RUN`` agent's ``model.zip``): which
    checkpoint made the data. Filled in by :func:`rollout`; a dataset grows only with the same."""

    def validate(self) -> None:
        """Raise :class:`Sc2DataError` on settings no rollout can run with."""
        if self.env not in BACKENDS:
            raise Sc2DataError(f"unknown environment {self.env!r}; choose one of: "
                               f"{', '.join(BACKENDS)}")
        if self.layers not in LAYER_SETS:
            raise Sc2DataError(f"unknown layer set {self.layers!r}; choose one of: "
                               f"{', '.join(LAYER_SETS)}")
        if self.episodes > MAX_EPISODES:
            raise Sc2DataError(f"episodes must be at most {MAX_EPISODES:,}, not "
                               f"{self.episodes:,}")
        for name in ("episodes", "episodes_per_shard"):
            if getattr(self, name) < 1:
                raise Sc2DataError(f"{name.replace('_', '-')} must be at least 1, "
                                   f"not {getattr(self, name)}")
        if self.step_mul < 1:
            raise Sc2DataError(f"step-mul must be at least 1, not {self.step_mul}")
        if self.max_steps is not None and self.max_steps < 1:
            raise Sc2DataError(f"max-steps must be at least 1, not {self.max_steps}")
        if not 0 <= self.seed < 2**63:
            raise Sc2DataError(f"seed must be a non-negative integer, not {self.seed}")
        if not (1 <= self.codec.chunk_frames <= 1024 and 1 <= self.codec.level <= 22):
            raise Sc2DataError(f"bad codec settings {self.codec}")

    @classmethod
    def from_recipe(cls, recipe: Recipe, **overrides: Any) -> RolloutConfig:
        """The rollout settings of a parsed recipe (:func:`sc2data.ground.recipe.load`) of one
        source; a recipe of several says in one line how to roll each out."""
        if recipe.sources:
            each = "; ".join(f"sc2data rollout --agent {s.rollout.agent} --episodes "
                             f"{s.rollout.episodes} --seed {recipe.seed} --out DIR/{s.name}"
                             for s in recipe.sources)
            raise Sc2DataError(f"recipe {recipe.name!r} draws from {len(recipe.sources)} "
                               f"datasets; roll each out ({each}), label each (sc2data label "
                               f"DIR/NAME), then sc2data pair RECIPE --data DIR")
        spec = {f.name: getattr(recipe.rollout, f.name) for f in fields(RolloutSpec)}
        return cls(**{**spec, "seed": recipe.seed, "recipe": recipe.name, **overrides})

    @classmethod
    def from_settings(cls, settings: dict[str, Any]) -> RolloutConfig:
        """The config whose :meth:`settings` are ``settings`` (a ``dataset.json``'s)."""
        try:
            return cls(**{**{k: settings[k] for k in _SETTINGS_ORDER},
                          **{k: settings[k] for k in _OPTIONAL_SETTINGS if k in settings},
                          "codec": Codec.from_dict(settings["codec"])})
        except (KeyError, TypeError, ValueError) as e:
            raise Sc2DataError(f"unreadable rollout settings ({e!r})") from None

    @property
    def schema(self) -> Schema:
        return Schema.named(self.layers)

    @property
    def n_shards(self) -> int:
        return -(-self.episodes // self.episodes_per_shard)

    def shard_episodes(self, i: int) -> range:
        e = self.episodes_per_shard
        return range(i * e, min((i + 1) * e, self.episodes))

    def settings(self) -> dict[str, Any]:
        """JSON form, recorded in ``dataset.json`` and in every shard."""
        d = asdict(self)
        d["codec"] = self.codec.to_dict()
        return {**{k: d[k] for k in _SETTINGS_ORDER},
                **{k: d[k] for k in _OPTIONAL_SETTINGS if d[k] is not None}}


def episode_seeds(seed: int, episode: int) -> tuple[int, int]:
    """(environment seed, agent seed) of an episode, from the root seed and its index only."""
    s = np.random.SeedSequence(seed, spawn_key=(episode,)).generate_state(2, np.uint32)
    return int(s[0] >> 1), int(s[1] >> 1)  # 31-bit: what SC2's random_seed accepts


def default_env_factory(config: RolloutConfig) -> EnvFactory:
    return functools.partial(_make_env, config.env, config.step_mul)


def _make_env(backend: str, step_mul: int, seed: int) -> environment.Base:
    return envs.make_env(backend, seed=seed, step_mul=step_mul)


def _make_agent(name: str, seed: int) -> base_agent.BaseAgent:
    from sc2data.game.agents import make_agent

    return make_agent(name, seed=seed)


def default_agent_factory(config: RolloutConfig) -> AgentFactory:
    return functools.partial(_make_agent, config.agent)


def resolve_agent(config: RolloutConfig) -> tuple[RolloutConfig, AgentFactory]:
    """``config`` with the sha256 of what its agent loads, and the agent's factory; one line for
    an unknown agent, or for a checkpoint other than the one the config records (a policy
    trained on since its data was rolled out: that data's agent no longer exists)."""
    from sc2data.game.agents import AGENTS
    from sc2data.game.agents import resolve_agent as resolve

    spec = resolve(config.agent)
    if config.agent_sha256 not in (None, spec.sha256):
        raise Sc2DataError(f"agent {config.agent} is not the one that made this data: its "
                           f"checkpoint's sha256 is {str(spec.sha256)[:12]}…, the data records "
                           f"{config.agent_sha256[:12]}…; roll the new policy out into another "
                           f"--out")
    factory = default_agent_factory(config) if config.agent in AGENTS else spec.factory
    return replace(config, agent_sha256=spec.sha256), factory


# -- one shard ----------------------------------------------------------------------------------
def play_episode(env: environment.Base, agent: base_agent.BaseAgent, writer: ShardWriter,
                 max_steps: int | None, report: Callable[[int], None]) -> int:
    """Play one episode into ``writer``: frame 0, then (action, frame t+1, reward) per step."""
    timestep = env.reset()[0]
    agent.reset()
    writer.add_observation(timestep.observation)
    steps = unreported = 0
    while not timestep.last() and (max_steps is None or steps < max_steps):
        call = agent.step(timestep)
        timestep = env.step([call])[0]
        writer.add_observation(timestep.observation)
        writer.add_step(int(call.function), call.arguments, timestep.reward)
        steps += 1
        unreported += 1
        if unreported == 200:
            report(unreported)
            unreported = 0
    report(unreported)
    return steps


def shard_attrs(config: RolloutConfig, i: int) -> dict[str, Any]:
    span = config.shard_episodes(i)
    return {"settings": shard_settings(config.settings()), "versions": versions(),
            "backend": config.env, "map": MAP_NAME, "agent": config.agent, "seed": config.seed,
            "layers": config.layers, "recipe": config.recipe or "",
            "episode_start": span.start, "episode_stop": span.stop}


def index_rows(path: Path, name: str | None = None) -> list[dict[str, Any]]:
    """Index rows of a complete shard (listed as ``name``, default its file name): its episode
    table plus the file's sha256 and size."""
    shard = Shard(path)
    try:
        table = shard.episodes
    finally:
        shard.close()
    digest, size = sha256_file(path), path.stat().st_size
    return [{"shard": name or path.name, **{c: (float(v[j]) if c == "reward" else int(v[j]))
                                    for c, v in table.items()},
             "shard_sha256": digest, "shard_bytes": size} for j in range(len(table["episode"]))]


def write_shard(config: RolloutConfig, out: Path, env_factory: EnvFactory,
                agent_factory: AgentFactory, i: int, report: Callable[[int], None]
                ) -> list[dict[str, Any]]:
    """Play shard ``i``'s episodes into ``shard-i.h5.partial``, then give it its final name.

    Returns the shard's index rows (hashed here, so that K workers hash in parallel)."""
    final = out / shard_name(i)
    partial = final.with_name(final.name + PARTIAL)
    keep_freed_memory()  # each step allocates ~620 KB of observation arrays: keep them warm
    writer = ShardWriter(partial, config.schema, config.codec, shard_attrs(config, i))
    try:
        for episode in config.shard_episodes(i):
            env_seed, agent_seed = episode_seeds(config.seed, episode)
            # Agents that draw from the global generators (pysc2's RandomAgent) are seeded too.
            random.seed(agent_seed)
            np.random.seed(agent_seed)
            env = env_factory(env_seed)
            try:
                agent = agent_factory(agent_seed)
                agent.setup(env.observation_spec()[0], env.action_spec()[0])
                writer.begin_episode(episode, env_seed, agent_seed)
                play_episode(env, agent, writer, config.max_steps, report)
                writer.end_episode()
            finally:
                env.close()
        writer.close()
    except BaseException:
        writer.abort()
        partial.unlink(missing_ok=True)
        raise
    rows = index_rows(partial, final.name)
    publish(partial, final)
    return rows


# -- the folder ---------------------------------------------------------------------------------
def dataset_record_for(config: RolloutConfig) -> dict[str, Any]:
    return {**DATASET.header(),
            "settings": config.settings(), "schema": config.schema.to_dict(),
            "versions": versions(), "map": MAP_NAME, "n_shards": config.n_shards}


def folder_config(out: Path) -> RolloutConfig | None:
    """The settings of the dataset in ``out``, if it holds a readable one: what a rollout into it
    takes for the settings it is not given."""
    try:
        return RolloutConfig.from_settings(read_dataset_record(out)["settings"])
    except (Sc2DataError, KeyError, TypeError):
        return None


def check_folder(config: RolloutConfig, out: Path) -> None:
    """Refuse a file, a foreign folder, a dataset of an older format or made with other
    settings, or fewer episodes than the folder holds (or is growing to)."""
    if out.exists() and not out.is_dir():
        raise Sc2DataError(f"output {out} exists and is not a folder; choose another --out")
    if out.is_dir() and (out / DATASET_RECORD).exists():
        old = read_dataset_record(out)
        if old["format_version"] != DATASET.version:
            raise Sc2DataError(f"{out} has dataset format {old['format_version']}, which this "
                               f"sc2data reads and verifies but does not add to (it writes "
                               f"format {DATASET.version}); roll out into a new --out")
        settings = old.get("settings", {})
        unresolved = ("agent_sha256",) if config.agent_sha256 is None else ()  # not yet known
        diff = differences(settings, config.settings(), ignore=("episodes", *unresolved))
        if diff:
            raise refusal(out, "a dataset made", diff, "use another --out or delete it")
        if settings.get("episodes", 0) > config.episodes:
            raise Sc2DataError(f"{out} holds {settings['episodes']} episodes (or is growing to "
                               f"them), more than the {config.episodes} asked for; a dataset "
                               f"only grows: ask for {settings['episodes']} or more, or use "
                               f"another --out")
    elif out.is_dir() and any(p.name != LOCK and not p.name.endswith(PARTIAL)
                              for p in out.iterdir()):  # our own debris is not foreign
        raise Sc2DataError(f"output folder {out} is not empty and is not an sc2data dataset; "
                           f"choose an empty or new folder")


def create_folder(out: Path) -> None:
    """Make ``out`` (and its parents) and prove it writable; undo on failure."""
    made = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / f".write-test{PARTIAL}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        if made and out.is_dir():
            with contextlib.suppress(OSError):
                out.rmdir()
        raise Sc2DataError(f"cannot write to output folder {out}: {reason(e)}") from None


def prepare_folder(config: RolloutConfig, out: Path) -> tuple[list[int], int | None]:
    """Check the complete shards, then write the dataset record (if new or growing) and drop stale
    partials; return the shards to write and, when a finished dataset grows, its episodes.

    Everything is checked before anything changes, so a refusal leaves the folder as it was. A
    grow removes the index first: until the new one is written the folder is an unfinished
    rollout, which the same command finishes, to the same bytes, after any interruption.
    """
    check_folder(config, out)  # again, under the lock
    had = read_dataset_record(out)["settings"]["episodes"] if (out / DATASET_RECORD).exists() \
        else None
    recorded = _recorded_hashes(out)
    todo = [i for i in range(config.n_shards) if not (out / shard_name(i)).exists() or
            not check_kept(config, out / shard_name(i), i, recorded.get(shard_name(i)))]
    grew = had is not None and had < config.episodes and (out / INDEX).exists()
    if had != config.episodes:
        (out / INDEX).unlink(missing_ok=True)
        write_dataset_record(out, dataset_record_for(config))
    for stale in out.glob(f"*{PARTIAL}"):
        if stale.is_dir():  # an attempt folder of a Ray task (sc2data.scaleout.driver)
            shutil.rmtree(stale)
        else:
            stale.unlink()
    return todo, had if grew else None


def _recorded_hashes(out: Path) -> dict[str, str]:
    """Each shard's sha256 as the index recorded it when the shard was written (none before the
    first run finished)."""
    if not (out / INDEX).is_file():
        return {}
    index = read_index(out)
    return dict(zip(index.column("shard").to_pylist(), index.column("shard_sha256").to_pylist()))


def check_kept(config: RolloutConfig, path: Path, i: int, recorded_sha256: str | None) -> bool:
    """Whether a resumed rollout keeps complete shard ``path``: True for shard ``i`` as this
    rollout writes it (its episodes, these settings, and the bytes the index recorded or, for a
    shard the index does not list yet, intact throughout: every chunk read through its
    checksum); False for shard ``i`` of a smaller dataset (the same first episode, fewer of
    them), which a grow rolls out again; an error for anything else. Never the other way round:
    what is on disk is not taken as the new truth."""
    def refuse(why: str) -> Sc2DataError:
        return Sc2DataError(f"{path} {why}; delete it and rerun to roll it out again")

    try:
        shard = Shard(path)
    except Sc2DataError as e:
        raise refuse(f"is not a complete shard ({e})") from None
    try:
        attrs = {k: shard.attrs.get(k) for k in ("settings", "episode_start", "episode_stop")}
    finally:
        shard.close()
    span = config.shard_episodes(i)
    if attrs["settings"] != shard_settings(config.settings()):
        raise refuse("was written with other settings")
    if attrs["episode_start"] == span.start and span.start < attrs["episode_stop"] < span.stop:
        return False  # outgrown
    if (attrs["episode_start"], attrs["episode_stop"]) != (span.start, span.stop):
        raise refuse(f"holds episodes {attrs['episode_start']}–{attrs['episode_stop']}, not "
                     f"{span.start}–{span.stop} (a shard copied over another?)")
    if recorded_sha256 is not None:
        if sha256_file(path) != recorded_sha256:
            raise refuse(f"does not match the sha256 {INDEX} recorded when it was written "
                         f"(damaged or replaced)")
        return True
    faults = check_shard(path, dataset_record_for(config))
    if faults:
        raise refuse(f"is damaged ({faults[0]})")
    return True


def _fail_fast(config: RolloutConfig, env_factory: EnvFactory,
               agent_factory: AgentFactory) -> None:
    """Make an agent (and a simulator) once here, so that a broken setup fails before any
    worker starts; the real game is not launched for this (its check is ``sc2_available``)."""
    try:
        agent_factory(0)
        if config.env == "sim":
            env_factory(0).close()
    except ImportError as e:
        raise Sc2DataError(f"this sc2data install is incomplete ({e})") from None


@dataclass(frozen=True)
class RolloutSummary:
    """What a rollout call did."""

    out: Path
    shards_written: int
    shards_kept: int
    episodes: int
    steps: int
    seconds: float
    grew_from: int | None = None
    """The episodes of the finished dataset this call grew (None: it did not grow one)."""


def rollout(config: RolloutConfig, out: str | os.PathLike[str], workers: int = 1,
            progress: bool | None = None, env_factory: EnvFactory | None = None,
            agent_factory: AgentFactory | None = None,
            runner: ShardRunner | None = None) -> RolloutSummary:
    """Roll out ``config`` into folder ``out`` with ``workers`` processes; resumable.

    ``env_factory``/``agent_factory`` replace the defaults (``make_env(config.env, seed=…)``,
    ``make_agent(config.agent, seed=…)``); they must be picklable for ``workers > 1``.
    ``runner`` writes the shards instead of local processes (``sc2data.scaleout.driver``).
    """
    out = Path(out)
    config.validate()
    if workers < 1:
        raise Sc2DataError(f"workers must be at least 1, not {workers}")
    if agent_factory is None:  # an unknown name (or a changed checkpoint) fails before writing
        config, agent_factory = resolve_agent(config)
    check_folder(config, out)
    if env_factory is None:
        if config.env == "sc2" and not envs.sc2_available():
            envs.make_env("sc2")  # raises the one-line install hint
        env_factory = default_env_factory(config)
    started = time.perf_counter()
    made = not out.exists()
    create_folder(out)
    try:
        _fail_fast(config, env_factory, agent_factory)
    except BaseException:
        if made:
            shutil.rmtree(out, ignore_errors=True)
        raise
    with FolderLock(out, "rollout") as lock, writing(f"the dataset {out}", "free some space, "
                                                    "then rerun the same command to resume"):
        todo, grew_from = prepare_folder(config, out)
        lock.share()
        per_episode = config.max_steps or EPISODE_STEPS
        total = sum(len(config.shard_episodes(i)) for i in todo) * per_episode
        with progress_bar(total, desc="rollout", unit="step", show=progress) as bar:
            job = functools.partial(write_shard, config, out, env_factory, agent_factory)
            if runner is not None:
                written = runner(config, out, todo, env_factory, agent_factory, bar)
            elif workers == 1 or len(todo) <= 1:
                written = {i: job(i, bar.update) for i in todo}
            else:
                written = run_parallel(job, todo, workers, out, bar.update, shard_name)
            bar.total = bar.n
            bar.refresh()
        rows = [row for i in range(config.n_shards)
                for row in written.get(i) or index_rows(out / shard_name(i))]
        write_index(out, rows)
    return RolloutSummary(out, len(todo), config.n_shards - len(todo), len(rows),
                          sum(r["n_steps"] for r in rows), time.perf_counter() - started,
                          grew_from)
