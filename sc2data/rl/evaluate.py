"""Evaluate trained agents and reference agents on the same seeded episodes; draw learning curves.

The evaluation protocol: ``episodes`` (default 10) episodes, their seeds :func:`eval_seeds`
chosen so that the SCVs start on the west and on the east of the command centre in turn (the
simulator's seed picks the side), the same seeds for every run and every reference agent. A
trained run plays each episode twice: **sampled** (actions drawn from the policy, torch and numpy
seeded with the episode's seed, so a rerun gives the same figures) and **argmax** (the most likely
action). Both go to ``RUN/eval.json``::

    {"episodes": 10, "seeds": [...], "sides": ["west", "east", ...],
     "sampled": {"marines": [...], "mean": …, "std": …, "iqm": …},
     "argmax":  {"marines": [...], "mean": …, "std": …, "iqm": …},
     "actions": {"sampled": {"select_point": 0.31, …}, "argmax": {…}},
     "trained_timesteps": …, "trained_env_steps": …, "config": {…}, "protocol": 2}

``std`` is the sample standard deviation (ddof 1), ``iqm`` the interquartile mean over the
episodes; ``actions`` the share of decisions each function (paper space) or macro chose, with
``+masked`` for a choice the masks did not allow — what an argmax policy that makes no marine
plays instead. Scores are the game's own: marines made in the episode, whatever the training reward.

The ``2 × episodes`` episodes are independent (each seeds its own sampling), so they are spread
over ``processes`` worker processes (default: one per core, one thread each, with the simulator;
one with the real game) and give the same figures however they are spread.

Reference agents (:func:`baselines`, ``sc2data rl baselines --out DIR``) are played once on the
same seeds and stored in ``DIR/baselines.json``: the masked uniform policy of each action space
(uniform over the allowed functions, then over the screen; uniform over the feasible macros),
and the reduced-random, macro-rules and scripted agents of :mod:`sc2data.game.agents`.
"""

from __future__ import annotations

import functools
import io
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import writing
from sc2data.ground.formats import Shape, check_record, loads
from sc2data.ground.progress import bar
from sc2data.ground.vocab import STEP_MUL
from sc2data.rl.runs import CONFIG, EVAL, STATE, check_file_out, load_model, write_file
from sc2data.rl.train import (
    EVAL_SEED,
    STATE_SHAPE,
    _read_json,
    _write_json,
    default_shaping,
    game_loops,
    load_config,
    read_config,
    read_curve,
    require_rl,
)

PROTOCOL = 2
"""Version of ``eval.json``: 2 holds sampled and argmax play over seeds of both start sides."""

SIDES: tuple[str, ...] = ("west", "east")
"""Where the SCVs start, seen from the command centre, in the order :func:`eval_seeds` takes."""

SCORES_SHAPE: Shape = {"marines": [int], "mean": float, "std": float, "iqm": float}
"""Marines per episode and their summaries (:func:`scores`)."""
EVAL_SHAPE: Shape = {"episodes": int, "seeds": [int], "sides": [str], "sampled": SCORES_SHAPE,
                     "argmax": SCORES_SHAPE, "protocol": int,
                     "trained_timesteps?": (int, type(None)),
                     "actions?": {"*": {"*": float}}}
"""``eval.json``, as :func:`read_eval` checks it."""
BASELINES_SHAPE: Shape = {"episodes": int, "seeds": [int], "episode_steps": (int, type(None)),
                          "protocol": int, "macro_sites?": str,
                          "agents": {"*": {"space": str, **SCORES_SHAPE,
                                           "actions?": {"*": float}}}}
"""``baselines.json``, as :func:`read_baselines` checks it."""

REFERENCE_AGENTS: dict[str, str] = {
    "uniform-paper": "paper", "uniform-macro": "macro",
    "reduced-random": "macro", "macro-rules": "macro", "scripted": "macro"}
"""Reference agents and the action space each plays in (``macro-rules``: the scripted agent's
rules within the six macros, what that space allows; ``scripted`` places its buildings and kills
its own marines, which no macro does)."""

# -- the episodes -----------------------------------------------------------------------------

def side_of(observation: Any) -> str:
    """``west`` or ``east``: where the SCVs stand relative to the command centre in a pysc2
    observation (screen x grows eastward)."""
    from sc2data._pysc2 import features, units

    unit_type = np.asarray(observation["feature_screen"][features.SCREEN_FEATURES.unit_type.index])
    scv = np.flatnonzero((unit_type == int(units.Terran.SCV)).any(axis=0))
    cc = np.flatnonzero((unit_type == int(units.Terran.CommandCenter)).any(axis=0))
    if not len(scv) or not len(cc):
        raise Sc2DataError("the first frame shows no SCV or no command centre: cannot tell the "
                           "start side")
    return "east" if scv.mean() > cc.mean() else "west"


@functools.lru_cache(maxsize=8)
def _seeds_and_sides(episodes: int) -> tuple[tuple[int, ...], tuple[str, ...]]:
    from sc2data.rl.envs import BuildMarinesGym

    env = BuildMarinesGym("macro", obs="compact", draw=("screen/unit_type",))
    seeds: list[int] = []
    sides: list[str] = []
    spare: dict[str, list[int]] = {s: [] for s in SIDES}
    seed = EVAL_SEED
    try:
        while len(seeds) < episodes:
            want = SIDES[len(seeds) % 2]
            if not spare[want]:
                env.reset(seed=seed)
                spare[side_of(env.frames[0])].append(seed)
                seed += 1
                continue
            seeds.append(spare[want].pop(0))
            sides.append(want)
    finally:
        env.close()
    return tuple(seeds), tuple(sides)


def eval_seeds(episodes: int) -> tuple[list[int], list[str]]:
    """The evaluation episodes' seeds and start sides: from :data:`~sc2data.rl.train.EVAL_SEED`
    on, the first seed of each side in turn (west, east, west, …), so that ``n`` episodes hold
    ``⌈n/2⌉`` west and ``⌊n/2⌋`` east starts, and the first ``n`` of a longer list are the same.
    The side is read from each seed's first frame on the simulator."""
    if episodes < 1:
        raise Sc2DataError("--episodes must be at least 1")
    seeds, sides = _seeds_and_sides(episodes)
    return list(seeds), list(sides)


def game_seed(seed: int) -> int:
    """The simulator's seed of the episode :class:`~sc2data.rl.envs.BuildMarinesGym` plays after
    ``reset(seed=seed)`` (its first draw), for agents that play the pysc2 env directly."""
    from gymnasium.utils import seeding

    return int(seeding.np_random(seed)[0].integers(2**31 - 1, size=2)[0])


def scores(marines: Sequence[int]) -> dict[str, Any]:
    """Marines per episode and their mean, sample std (0 for one episode) and IQM."""
    from scipy.stats import trim_mean

    m = np.asarray(marines, dtype=float)
    return {"marines": [int(x) for x in marines], "mean": float(m.mean()),
            "std": float(m.std(ddof=1)) if len(m) > 1 else 0.0,
            "iqm": float(trim_mean(m, 0.25))}


# -- playing ----------------------------------------------------------------------------------

def play(model: Any, env: Any, seed: int, deterministic: bool) -> Iterator[dict[str, Any]]:
    """One seeded episode of ``model``'s masked policy on ``env``: the info of each decision
    (``env.frames`` then holds that decision's pysc2 observations)."""
    obs, _ = env.reset(seed=seed)
    done = False
    while not done:
        action, _ = model.predict(obs, deterministic=deterministic,
                                  action_masks=env.action_masks())
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        yield info


class UniformPolicy:
    """The masked uniform policy: each dimension of the action drawn uniformly among the values
    its mask allows (for the paper space: a function, then x and y). ``predict`` follows
    MaskablePPO's, so :func:`play` plays it; ``set_random_seed`` seeds its generator."""

    def __init__(self, nvec: Sequence[int]) -> None:
        self.nvec = [int(n) for n in nvec]
        self.rng = np.random.default_rng(0)

    def set_random_seed(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def predict(self, obs: Any, deterministic: bool = False,
                action_masks: np.ndarray | None = None) -> tuple[np.ndarray, None]:
        masks = np.ones(sum(self.nvec), bool) if action_masks is None else action_masks
        parts = np.split(np.asarray(masks, bool), np.cumsum(self.nvec)[:-1])
        action = np.array([self.rng.choice(np.flatnonzero(p)) for p in parts])
        return (action if len(action) > 1 else action[0]), None


def _episodes(policy: Any, env: Any, seeds: Sequence[int], deterministic: bool,
              tick: Callable[[], None], actions: Counter[str] | None = None) -> list[int]:
    """Marines made in each seeded episode (the policy's sampling reseeded per episode);
    ``actions`` counts the functions (or macros) chosen, ``+masked`` marking those not allowed."""
    marines = []
    for seed in seeds:
        policy.set_random_seed(seed)
        info: dict[str, Any] = {}
        for info in play(policy, env, seed, deterministic):
            if actions is not None:
                actions[info["action"] + ("+masked" if info["invalid"] else "")] += 1
        marines.append(int(info["marines"]))
        tick()
    return marines


def action_shares(counts: Counter[str]) -> dict[str, float]:
    """Each action's share of the decisions, largest first."""
    total = sum(counts.values())
    return {name: round(n / total, 4) for name, n in counts.most_common()}


def evaluate(run: Path, episodes: int = 10, progress: bool | None = None,
             processes: int | None = None) -> dict[str, Any]:
    """Play the trained policy of ``run`` on the evaluation episodes, sampled then argmax, with
    the action masks, over ``processes`` worker processes (None: see the module docstring);
    writes and returns ``RUN/eval.json`` (see the module docstring)."""
    require_rl("sc2data rl evaluate")
    if episodes < 1:
        raise Sc2DataError("--episodes must be at least 1")
    if processes is not None and processes < 1:
        raise Sc2DataError(f"--processes must be at least 1, got {processes}")
    cfg = load_config(run)
    state = _read_json(run / STATE, STATE_SHAPE) if (run / STATE).is_file() else {}
    seeds, sides = eval_seeds(episodes)
    jobs = [(deterministic, seed) for deterministic in (False, True) for seed in seeds]
    if processes is None:
        from sc2data.rl.vector import default_processes

        processes = default_processes(len(jobs)) if cfg.backend == "sim" else 1
    with bar(len(jobs), desc="rl evaluate", unit="episode", show=progress) as b:
        played = _play_jobs(run, jobs, min(processes, len(jobs)), lambda: b.update(1))
    counts: dict[str, Counter[str]] = {"sampled": Counter(), "argmax": Counter()}
    marines: dict[str, list[int]] = {"sampled": [], "argmax": []}
    for (deterministic, _), (made, actions) in zip(jobs, played):
        mode = "argmax" if deterministic else "sampled"
        marines[mode].append(made)
        counts[mode].update(actions)
    result = {"episodes": episodes, "seeds": seeds, "sides": sides,
              "sampled": scores(marines["sampled"]), "argmax": scores(marines["argmax"]),
              "actions": {mode: action_shares(c) for mode, c in counts.items()},
              "trained_timesteps": state.get("timesteps"),
              "trained_env_steps": state.get("env_steps"), "config": cfg.identity(),
              "protocol": PROTOCOL}
    with writing(str(run / EVAL), "free some space, then rerun the same command"):
        _write_json(run / EVAL, result)
    return result


_PLAYER: tuple[str, Any, Any] | None = None
"""This process's (run, model, env) for evaluation episodes, loaded once by
:func:`_load_player`."""


def _load_player(run: str) -> None:
    """Load ``run``'s policy and a game for it into this process (once), torch on one
    thread."""
    global _PLAYER
    if _PLAYER is not None and _PLAYER[0] == run:
        return
    _close_player()
    import torch

    from sc2data.rl.envs import BuildMarinesGym

    torch.set_num_threads(1)
    cfg = load_config(Path(run))
    env = BuildMarinesGym(cfg.action_space, backend=cfg.backend, obs=cfg.obs_config(),
                          game_loops=game_loops(cfg), merge_waits=cfg.merge_waits,
                          sites=cfg.macro_sites)
    try:
        _PLAYER = (run, load_model(Path(run), env), env)
    except BaseException:
        env.close()
        raise


def _close_player() -> None:
    global _PLAYER
    if _PLAYER is not None:
        _PLAYER[2].close()
        _PLAYER = None


def _play_job(run: str, job: tuple[bool, int]) -> tuple[int, Counter[str]]:
    """One evaluation episode of ``run``'s policy (argmax or not, its seed): the marines made
    and the actions chosen. The player is loaded on a process's first job, not by a pool
    initializer, so that an error loading it reaches the caller as itself."""
    _load_player(run)
    assert _PLAYER is not None
    deterministic, seed = job
    actions: Counter[str] = Counter()
    (made,) = _episodes(_PLAYER[1], _PLAYER[2], [seed], deterministic, lambda: None, actions)
    return made, actions


def _play_jobs(run: Path, jobs: Sequence[tuple[bool, int]], processes: int,
               tick: Callable[[], None]) -> list[tuple[int, Counter[str]]]:
    """Every job's result, in order: in this process, or over ``processes`` worker processes
    (spawned, as the vector env's are; a worker's error is raised here)."""
    if processes <= 1:
        try:
            out = []
            for job in jobs:
                out.append(_play_job(str(run), job))
                tick()
            return out
        finally:
            _close_player()
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(processes, mp_context=mp.get_context("spawn")) as pool:
        futures = [pool.submit(_play_job, str(run), job) for job in jobs]
        try:
            results = []
            for f in futures:
                results.append(f.result())
                tick()
            return results
        except BaseException:
            for f in futures:
                f.cancel()
            raise


def read_eval(run: Path) -> dict[str, Any]:
    """``RUN/eval.json`` of this protocol, checked; a one-line error naming the command that
    writes it when it is missing, older, or stale (the model trained on since)."""
    path = run / EVAL
    redo = f"run sc2data rl evaluate {run}"
    try:
        record = loads(path.read_bytes())
    except OSError:
        raise Sc2DataError(f"{run} has no evaluation (eval.json); {redo}") from None
    except ValueError as e:
        raise Sc2DataError(f"cannot read {path}: {e}; {redo}") from None
    if not isinstance(record, dict) or record.get("protocol") != PROTOCOL:
        raise Sc2DataError(f"{path} is from an older evaluation protocol (no sampled and argmax "
                           f"play over both start sides); {redo}")
    check_record(record, EVAL_SHAPE, path, redo)
    if (run / STATE).is_file():
        trained = _read_json(run / STATE, STATE_SHAPE)["timesteps"]
        if record.get("trained_timesteps") != trained:
            raise Sc2DataError(f"{path} evaluated the model at {record.get('trained_timesteps')} "
                               f"decisions, it has trained {trained} since; {redo}")
    return record  # type: ignore[no-any-return]


def summary(result: dict[str, Any]) -> str:
    """Sampled and argmax marines per episode (mean ± sample std, IQM), then each mode's most
    chosen actions (what an argmax policy that makes nothing does instead)."""
    west = sum(s == "west" for s in result["sides"])
    where = (f"over {result['episodes']} episodes ({west} west, {result['episodes'] - west} east "
             f"starts; seeds {min(result['seeds'])}…{max(result['seeds'])})")
    lines = [f"{mode:>7}: marines per episode {result[mode]['mean']:.2f} ± "
             f"{result[mode]['std']:.2f} (IQM {result[mode]['iqm']:.2f}) {where}"
             for mode in ("sampled", "argmax")]
    for mode, shares in result.get("actions", {}).items():
        top = ", ".join(f"{name} {share:.0%}" for name, share in list(shares.items())[:4])
        lines.append(f"{mode:>7}: decisions {top}")
    return "\n".join(lines)


# -- reference agents -------------------------------------------------------------------------

def _agent_episodes(name: str, seeds: Sequence[int], episode_steps: int | None,
                    tick: Callable[[], None], sites: str = "random") -> list[int]:
    """Marines made by a pysc2 agent of :mod:`sc2data.game.agents` on the seeded episodes (the
    simulator seeded as :class:`~sc2data.rl.envs.BuildMarinesGym` seeds it; the agent with the
    episode's seed; the macro agents building on ``sites``)."""
    from sc2data.game.agents import make_agent
    from sc2data.game.agents import play as play_agent
    from sc2data.game.env import make_env

    kwargs = {"game_loops": episode_steps * STEP_MUL} if episode_steps else {}
    marines = []
    for seed in seeds:
        env = make_env("sim", seed=game_seed(seed), **kwargs)
        try:
            ts: Any = None
            for ts in play_agent(env, make_agent(name, seed=seed, sites=sites)):  # noqa: B007
                pass
            marines.append(int(np.asarray(ts.observation["score_cumulative"])[0]))
        finally:
            env.close()
        tick()
    return marines


def baselines(out: Path, episodes: int = 10, episode_steps: int | None = None,
              agents: Sequence[str] = tuple(REFERENCE_AGENTS),
              progress: bool | None = None, sites: str = "random") -> dict[str, Any]:
    """Play the reference agents on the evaluation episodes (simulator); writes and returns
    ``OUT/baselines.json``: per agent its action space and :func:`scores`, and for the uniform
    policies the share of each function (or macro) they chose, as ``eval.json``'s ``actions``;
    the macro-space agents build on ``sites`` (``rl train --macro-sites``)."""
    require_rl("sc2data rl baselines")
    from sc2data.game.agents import SITES

    if sites not in SITES:
        raise Sc2DataError(f"unknown macro sites {sites!r}; choose one of: {', '.join(SITES)}")
    unknown = [a for a in agents if a not in REFERENCE_AGENTS]
    if unknown:
        raise Sc2DataError(f"unknown reference agent {unknown[0]!r}; choose from: "
                           f"{', '.join(REFERENCE_AGENTS)}")
    if episode_steps is not None and episode_steps < 1:
        raise Sc2DataError("--episode-steps must be at least 1")
    if out.exists() and not out.is_dir():
        raise Sc2DataError(f"{out} is a file; --out takes a folder")
    seeds, sides = eval_seeds(episodes)
    from sc2data.rl.envs import BuildMarinesGym

    record: dict[str, Any] = {"episodes": episodes, "seeds": seeds, "sides": sides,
                              "episode_steps": episode_steps, "backend": "sim",
                              "protocol": PROTOCOL, "macro_sites": sites, "agents": {}}
    with bar(episodes * len(agents), desc="rl baselines", unit="episode", show=progress) as b:
        for name in agents:
            space = REFERENCE_AGENTS[name]
            if name.startswith("uniform-"):
                env = BuildMarinesGym(space, obs="compact", sites=sites,
                                      game_loops=episode_steps * STEP_MUL if episode_steps
                                      else None)
                chosen: Counter[str] = Counter()
                try:
                    nvec = getattr(env.action_space, "nvec", [getattr(env.action_space, "n", 0)])
                    marines = _episodes(UniformPolicy(nvec), env, seeds, False,
                                        lambda: b.update(1), chosen)
                finally:
                    env.close()
                record["agents"][name] = {"space": space, **scores(marines),
                                          "actions": action_shares(chosen)}
            else:
                marines = _agent_episodes(name, seeds, episode_steps, lambda: b.update(1),
                                          sites)
                record["agents"][name] = {"space": space, **scores(marines)}
    with writing(str(out / "baselines.json"), "free some space, then rerun the same command"):
        out.mkdir(parents=True, exist_ok=True)
        _write_json(out / "baselines.json", record)
    return record


def read_baselines(path: Path) -> dict[str, Any]:
    """A ``baselines.json`` (or the folder holding one), checked; one-line errors."""
    file = path / "baselines.json" if path.is_dir() else path
    redo = f"write one with sc2data rl baselines --out {path}"
    try:
        record = loads(file.read_bytes())
    except OSError:
        raise Sc2DataError(f"{file} does not exist; {redo}") from None
    except ValueError as e:
        raise Sc2DataError(f"cannot read {file}: {e}; {redo}") from None
    if not isinstance(record, dict) or record.get("protocol") != PROTOCOL:
        raise Sc2DataError(f"{file} is from an older evaluation protocol; {redo}")
    check_record(record, BASELINES_SHAPE, file, redo)
    return record  # type: ignore[no-any-return]


def reference_summary(record: dict[str, Any]) -> list[str]:
    """One line per reference agent: marines per episode, mean ± sample std and IQM."""
    sites = record.get("macro_sites", "random")
    lines = []
    for name, a in record["agents"].items():
        where = a["space"]
        if sites != "random" and name in ("uniform-macro", "reduced-random", "macro-rules"):
            where += f", {sites} sites"
        lines.append(f"{name} ({where}): marines per episode {a['mean']:.2f} ± {a['std']:.2f} "
                     f"(IQM {a['iqm']:.2f}) over {record['episodes']} episodes")
    return lines


# -- learning curves --------------------------------------------------------------------------

def _label(cfg: dict[str, Any]) -> str:
    """``space, reward`` of a run's config, its narration file's name where not the default,
    and its shaping where not the reward's default (:func:`~sc2data.rl.train.default_shaping`;
    a config without one was event-shaped)."""
    reward = str(cfg.get("reward"))
    label = f"{cfg.get('action_space')}, {reward}"
    label += f" ({Path(cfg['narration']).stem})" if cfg.get("narration") else ""
    shaping = cfg.get("shaping", "event")
    return label + (f", {shaping}" if shaping != default_shaping(reward) else "")


def seed_band(curves: Sequence[tuple[np.ndarray, np.ndarray]]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(x, mean, min, max)`` of several runs' ``(x, y)`` curves over the points all of them
    reached (episode by episode; x is the runs' mean there)."""
    n = min(len(x) for x, _ in curves)
    xs = np.mean([x[:n] for x, _ in curves], axis=0)
    ys = np.array([y[:n] for _, y in curves])
    return xs, ys.mean(axis=0), ys.min(axis=0), ys.max(axis=0)


def reference_lines(ax: Any, record: dict[str, Any], spaces: set[str]) -> None:
    """Dashed horizontal lines at the reference agents' mean (those of ``spaces``, and the
    reduced-random, macro-rules and scripted agents, which play macros by themselves)."""
    styles = {"uniform-paper": ":", "uniform-macro": ":", "reduced-random": "-.",
              "macro-rules": (0, (5, 1, 1, 1)), "scripted": "--"}
    for name, a in record["agents"].items():
        if name.startswith("uniform-") and a["space"] not in spaces:
            continue
        ax.axhline(a["mean"], color="0.35", lw=1, ls=styles.get(name, "--"),
                   label=f"{name}: {a['mean']:.1f} (evaluation mean)")


def plot(runs: Sequence[Path], out: Path, window: int = 10, group: bool = False,
         baselines_file: Path | None = None, say: Callable[[str], None] = lambda s: None
         ) -> Path:
    """Marines per training episode against pysc2 steps: one line (rolling mean of ``window``
    episodes) per run, or with ``group`` one per action space, reward and narration, the mean
    of its runs' rolling means over the episodes all of them reached, shaded from the lowest run
    to the highest. A run (group) with fewer episodes than ``window`` is drawn as its episodes'
    points (its runs' mean over the episodes all reached), marked so in the legend, and ``say``
    is told. ``baselines_file``: reference agents as horizontal lines."""
    check_file_out(out)
    curves = []
    for run in runs:
        if not (run / CONFIG).is_file():
            raise Sc2DataError(f"{run} is not an sc2data rl run (no config.json)")
        rows = read_curve(run)
        if not rows:
            raise Sc2DataError(f"{run} has no finished training episode to plot yet")
        curves.append((run, read_config(run), rows))
    if window < 1:
        raise Sc2DataError("--window must be at least 1")
    reference = read_baselines(baselines_file) if baselines_file is not None else None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    groups: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    short = False
    for run, cfg, rows in curves:
        x = np.array([r["env_steps"] for r in rows], dtype=float)
        y = np.array([r["marines"] for r in rows], dtype=float)
        if group:
            groups.setdefault(_label(cfg), []).append((x, y))
            continue
        name = f"{run.name} ({_label(cfg)})"
        if len(y) < window:
            short = True
            say(f"{run}: {len(y)} episodes, fewer than --window {window}: drawn as points")
            ax.plot(x, y, "o", ms=4, label=f"{name}: {len(y)} episodes, points")
            continue
        smooth = np.convolve(y, np.ones(window) / window, mode="valid")
        line, = ax.plot(x[window - 1:], smooth, label=name)
        ax.scatter(x, y, s=6, alpha=0.3, color=line.get_color())
    for label, members in groups.items():
        runs_word = "run" if len(members) == 1 else "runs"
        if min(len(y) for _, y in members) < window:
            short = True
            xs, mean, lo, hi = seed_band(members)
            say(f"{label}: {len(xs)} episodes reached by all its runs, fewer than --window "
                f"{window}: drawn as points")
            line, = ax.plot(xs, mean, "o", ms=4, label=f"{label}: mean of {len(members)} "
                                                      f"{runs_word}, {len(xs)} episodes, points")
        else:
            smoothed = [(x[window - 1:], np.convolve(y, np.ones(window) / window, mode="valid"))
                        for x, y in members]
            xs, mean, lo, hi = seed_band(smoothed)
            line, = ax.plot(xs, mean, label=f"{label}: mean of {len(members)} {runs_word}")
        if len(members) > 1:
            ax.fill_between(xs, lo, hi, alpha=0.15, color=line.get_color())
    if reference is not None:
        reference_lines(ax, reference, {str(c.get("action_space")) for _, c, _ in curves})
    ax.set_xlabel("pysc2 steps (all envs)")
    ax.set_ylabel(f"marines per episode\n(rolling mean of {window}"
                  + ("; points: fewer episodes)" if short else ")"))
    ax.set_title("BuildMarines, MaskablePPO: game score while training")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    write_file(out, buf.getvalue())
    return out
