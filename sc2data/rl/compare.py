"""Compare groups of runs as the field reports them (Agarwal et al. 2021, ``rliable``).

A *group* is the runs that differ only by the settings that pick their random draws
(:data:`DRAWS`: ``--seed``, and ``--env-groups``, which orders the same decisions' draws
otherwise, :mod:`sc2data.rl.pipeline`): the same action space, reward, narration file, shaping
and every other setting of ``config.json``. A run's *final score* is its mean
marines per evaluation episode (``RUN/eval.json``, :mod:`sc2data.rl.evaluate`), sampled play
and argmax play apart. Per group, over its runs:

* the **IQM** (interquartile mean: the mean of the middle 50 % of runs, ``scipy``'s
  ``trim_mean(·, 0.25)``, which trims ``⌊n/4⌋`` runs from each end) of the final scores, with a
  95 % **stratified bootstrap** confidence interval (percentile method; one task, so the
  bootstrap resamples runs; each group's draws seeded by its own scores, so the same runs get
  the same interval in every comparison);
* the **probability of improvement** of one group over another, P(X > Y): the chance that a run
  of X scores above a run of Y, ties counting one half (the Mann–Whitney U over
  ``n_x · n_y``), with its bootstrap CI (runs of each group resampled independently);
* **sample-efficiency curves**: at ``points`` numbers of decisions from the first where every
  game of every run has ended a training episode to the earliest last episode of all runs, each
  run's score — over its games, the mean marines of each game's last ``window`` episodes ended
  by then — and the IQM of those over the group's runs with its CI band. Every game counts
  alike: a mean over the run's last episodes, whichever game played them, would begin with the
  episodes that end first, which in the macro space are the shortest and poorest (a game's
  marines rise with its decisions). For each pair of groups compared, the first of those
  points where X's IQM curve reaches Y's last value (``reach``: how many decisions X needs for
  what Y ends with, read on the training curves of both, so both are sampled play on training
  episodes);
* **performance profiles** (rliable's score distributions): the fraction of the group's runs
  whose final sampled score exceeds τ, for :data:`PROFILE_POINTS` values of τ from 0 to the
  best run's score, with a 95 % bootstrap band — the whole spread of runs, where the IQM
  gives its middle.

Reference agents (``sc2data rl baselines``) are drawn as horizontal lines and listed beside:
their evaluation episodes must be the runs' (the same seeds and episode length).
All runs must be of one action space: scores of the two spaces are not one experiment.
"""

from __future__ import annotations

import io
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import MissingDependencyError, Sc2DataError
from sc2data.ground.files import write_atomic, writing

MODES: tuple[str, ...] = ("sampled", "argmax")
CONFIDENCE = 0.95
PROFILE_POINTS = 101
"""Thresholds τ of a performance profile."""


@dataclass(frozen=True)
class RunScores:
    """What one run brings to a comparison."""

    run: Path
    config: dict[str, Any]
    final: dict[str, float]
    """Mean marines per evaluation episode, by play mode (:data:`MODES`)."""
    seeds: tuple[int, ...]
    decisions: int
    curve: tuple[np.ndarray, np.ndarray, np.ndarray]
    """Training episodes: decisions (all envs) when each ended, marines made, the game
    (``env``) that played it."""
    games: int
    """Games the run stepped together (``--envs``)."""


def require_rliable() -> None:
    """A one-line error naming the extra unless ``rliable`` is installed."""
    try:
        import rliable  # noqa: F401
    except ImportError:
        raise MissingDependencyError("rliable", "rl", "sc2data rl compare") from None


# -- statistics on score tables ---------------------------------------------------------------

def iqm(scores: np.ndarray) -> float:
    """Interquartile mean of a (runs, tasks) table (rliable's ``aggregate_iqm``)."""
    from rliable import metrics

    return float(metrics.aggregate_iqm(np.asarray(scores, dtype=float)))


def improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y) of two (runs, tasks) tables, averaged over tasks (rliable's
    ``probability_of_improvement``)."""
    from rliable import metrics

    return float(metrics.probability_of_improvement(np.asarray(x, dtype=float),
                                                    np.asarray(y, dtype=float)))


def _bootstrap(score_dict: dict[str, Any], func: Callable[..., np.ndarray], reps: int,
               seed: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """``rly.get_interval_estimates`` (percentile intervals of rliable's stratified bootstrap),
    each entry drawn from a stream of its own, seeded by ``seed`` and the entry's scores
    (:func:`stream_seed`): the same runs get the same interval in every comparison, whatever
    other groups stand beside them (one stream for all made a group's interval depend on the
    groups drawn before it). rliable draws from numpy's global generator whatever generator it
    is handed, so that is seeded per entry here and restored after. An entry is a table, or a
    tuple of tables resampled independently."""
    from rliable import library as rly

    point: dict[str, np.ndarray] = {}
    interval: dict[str, np.ndarray] = {}
    saved = np.random.get_state()
    try:
        for key, scores in score_dict.items():
            tables = scores if isinstance(scores, tuple) else (scores,)
            np.random.seed(stream_seed(seed, *tables))
            p, i = rly.get_interval_estimates({key: scores}, func, reps=reps,
                                              confidence_interval_size=CONFIDENCE)
            point[key], interval[key] = p[key], i[key]
    finally:
        np.random.set_state(saved)
    return point, interval


def stream_seed(seed: int, *tables: np.ndarray) -> int:
    """A 32-bit seed from ``seed`` and the scores' values and shapes (crc32), so that a
    bootstrap's draws follow from what it resamples, not from its place in a comparison."""
    import zlib

    crc = zlib.crc32(int(seed).to_bytes(8, "little", signed=True))
    for t in tables:
        a = np.ascontiguousarray(t, dtype=np.float64)
        crc = zlib.crc32(repr(a.shape).encode() + a.tobytes(), crc)
    return crc


def iqm_intervals(tables: dict[str, np.ndarray], reps: int = 2000, seed: int = 0
                  ) -> dict[str, tuple[float, float, float]]:
    """Per name, ``(IQM, CI low, CI high)`` of a (runs, tasks) table."""
    point, interval = _bootstrap(tables, lambda s: np.array([iqm(s)]), reps, seed)
    return {k: (float(point[k][0]), float(interval[k][0, 0]), float(interval[k][1, 0]))
            for k in tables}


def improvement_intervals(pairs: dict[str, tuple[np.ndarray, np.ndarray]], reps: int = 2000,
                          seed: int = 0) -> dict[str, tuple[float, float, float]]:
    """Per name, ``(P(X > Y), CI low, CI high)`` of a pair of (runs, tasks) tables."""
    point, interval = _bootstrap(pairs, lambda x, y: np.array([improvement(x, y)]), reps, seed)
    return {k: (float(point[k][0]), float(interval[k][0, 0]), float(interval[k][1, 0]))
            for k in pairs}


def curve_intervals(tables: dict[str, np.ndarray], reps: int = 2000, seed: int = 0
                    ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Per name, the IQM at each point of a (runs, tasks, points) table, and its (2, points)
    CI band."""
    return _bootstrap(tables, lambda s: np.array([iqm(s[..., k]) for k in range(s.shape[-1])]),
                      reps, seed)


def profile_intervals(tables: dict[str, np.ndarray], taus: np.ndarray, reps: int = 2000,
                      seed: int = 0) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Per name, the fraction of a (runs, tasks) table's scores above each τ of ``taus``
    (rliable's ``score_distributions``), and its (2, len(taus)) CI band."""
    from rliable import library as rly

    return _bootstrap(tables, lambda s: np.asarray(rly.score_distributions(s, taus)), reps, seed)


def reach(decisions: Sequence[int], curve: Sequence[float], target: float) -> int | None:
    """The first number of decisions at which ``curve`` is at least ``target`` (None: never)."""
    for x, v in zip(decisions, curve):
        if v >= target:
            return int(x)
    return None


def curve_scores(curve: tuple[np.ndarray, np.ndarray, np.ndarray], games: int,
                 at: np.ndarray, window: int) -> np.ndarray:
    """A run's score at each number of decisions in ``at``: over its ``games`` games, the mean
    of each game's marines over its last ``window`` training episodes ended by then (NaN until
    every game has ended one)."""
    per_game = _by_game(curve, games)
    out = np.full(len(at), np.nan)
    for i, x in enumerate(at):
        means = []
        for e, m in per_game:
            n = int(np.searchsorted(e, x, side="right"))
            if not n:
                break
            means.append(float(np.mean(m[max(0, n - window):n])))
        else:
            out[i] = float(np.mean(means))
    return out


def every_game_ended(curve: tuple[np.ndarray, np.ndarray, np.ndarray], games: int
                     ) -> float | None:
    """The decisions by which every one of the run's ``games`` games had ended a training
    episode (None: one never did)."""
    firsts = [e for e, _ in _by_game(curve, games)]
    return None if any(not len(f) for f in firsts) else max(float(f[0]) for f in firsts)


def _by_game(curve: tuple[np.ndarray, np.ndarray, np.ndarray], games: int
             ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each game's episodes of a curve: (decisions when each ended, marines), in order."""
    ends, marines, played = curve
    return [(ends[played == g], marines[played == g]) for g in range(games)]


# -- runs -------------------------------------------------------------------------------------

def load_run(run: Path) -> RunScores:
    """A run's (or its record's, :mod:`sc2data.rl.record`) settings, evaluation and training
    curve; one-line errors for a folder that is not a trained run or has no current
    evaluation."""
    from sc2data.rl.evaluate import read_eval
    from sc2data.rl.train import load_config, read_config, read_curve

    load_config(run, records=True)  # a trained run (or its record) of settings sc2data runs
    config = read_config(run)
    ev = read_eval(run)
    rows = read_curve(run)
    curve = (np.array([r["timesteps"] for r in rows], dtype=float),
             np.array([r["marines"] for r in rows], dtype=float),
             np.array([r["env"] for r in rows], dtype=int))
    return RunScores(run, config, {m: float(ev[m]["mean"]) for m in MODES},
                     tuple(int(s) for s in ev["seeds"]), int(ev.get("trained_timesteps") or 0),
                     curve, int(config.get("envs") or 1))


DRAWS: tuple[str, ...] = ("seed", "env_groups")
"""Settings that choose a run's random draws, not what it learns: runs that differ only by them
are samples of one group."""


def group_runs(runs: Sequence[RunScores]) -> dict[str, list[RunScores]]:
    """Runs by group (every setting but :data:`DRAWS`), named ``space, reward (narration)[,
    potential]`` and, where that name is shared by several groups, ``[k=v, …]`` of the settings
    that tell those apart."""
    from sc2data.rl.evaluate import _label

    keyed: dict[tuple[tuple[str, str], ...], list[RunScores]] = {}
    for r in runs:
        key = tuple(sorted((k, repr(v)) for k, v in r.config.items() if k not in DRAWS))
        keyed.setdefault(key, []).append(r)
    by_label: dict[str, list[list[RunScores]]] = {}
    for members in keyed.values():
        by_label.setdefault(_label(members[0].config), []).append(members)
    groups: dict[str, list[RunScores]] = {}
    for label, clash in by_label.items():
        configs = [_flat(m[0].config) for m in clash]
        varying = sorted(k for k in set().union(*configs) if k not in DRAWS
                         and len({repr(c.get(k)) for c in configs}) > 1)
        for members, flat in zip(clash, configs):
            extra = ", ".join(f"{k}={_short(flat.get(k))}" for k in varying)
            groups[label + (f" [{extra}]" if extra else "")] = members
    return groups


def final_tables(groups: dict[str, list[RunScores]], mode: str) -> dict[str, np.ndarray]:
    """Per group, its runs' final scores in ``mode`` as a (runs, 1 task) table."""
    return {g: np.array([[r.final[mode]] for r in members]) for g, members in groups.items()}


def _flat(config: dict[str, Any]) -> dict[str, Any]:
    """A run's settings with nested ones (``inputs``: the digests of what the reward reads)
    under dotted keys, so a label names only the entries that differ."""
    out: dict[str, Any] = {}
    for k, v in config.items():
        if isinstance(v, dict):
            out.update({f"{k}.{kk}": vv for kk, vv in v.items()})
        else:
            out[k] = v
    return out


def _short(value: Any) -> Any:
    """A sha256 digest cut to its first 12 hex digits (as git shows a commit); else as is."""
    if isinstance(value, str) and len(value) == 64 and all(c in "0123456789abcdef" for c in value):
        return value[:12]
    return value


def check_comparable(runs: Sequence[RunScores]) -> None:
    """One-line errors for runs that are not one experiment: two action spaces, other
    evaluation episodes, other episode lengths or backends, a run given twice."""
    seen: set[Path] = set()
    for r in runs:
        if r.run.resolve() in seen:
            raise Sc2DataError(f"{r.run} is given twice")
        seen.add(r.run.resolve())
    first = runs[0]
    for r in runs[1:]:
        for key, what in (("action_space", "action spaces"), ("episode_steps", "episode lengths"),
                          ("backend", "backends")):
            if r.config.get(key) != first.config.get(key):
                raise Sc2DataError(
                    f"runs of different {what} compared: {first.run} ({first.config.get(key)}) "
                    f"and {r.run} ({r.config.get(key)}); compare one at a time")
        if r.seeds != first.seeds:
            raise Sc2DataError(f"{r.run} and {first.run} were evaluated on other episodes "
                               f"({len(r.seeds)} and {len(first.seeds)}); rerun sc2data rl "
                               f"evaluate on both with the same --episodes")


# -- the comparison ---------------------------------------------------------------------------

def compare(runs: Sequence[Path], out: Path | None = None, *, baselines: Path | None = None,
            against: str | None = None, reps: int = 2000, points: int = 20, window: int = 1,
            seed: int = 0) -> dict[str, Any]:
    """Compare the groups the runs form (see the module docstring). Writes ``OUT/compare.json``
    and ``OUT/compare.png`` (sample-efficiency curves and final IQMs) when ``out`` is given;
    returns the record. ``against``: the probability of improvement of every group over this
    one only (default: every pair)."""
    require_rliable()
    if not runs:
        raise Sc2DataError("give at least one run folder")
    for name, value, least in (("--reps", reps, 1), ("--points", points, 2),
                               ("--window", window, 1)):
        if value < least:
            raise Sc2DataError(f"{name} must be at least {least}")
    if out is not None and out.exists() and not out.is_dir():
        raise Sc2DataError(f"{out} is a file; --out takes a folder")
    loaded = [load_run(Path(r)) for r in runs]
    check_comparable(loaded)
    groups = group_runs(loaded)
    if against is not None and against not in groups:
        raise Sc2DataError(f"unknown group {against!r}; the runs form: "
                           f"{'; '.join(repr(g) for g in groups)}")
    reference = _reference(baselines, loaded[0]) if baselines is not None else None

    record: dict[str, Any] = {"action_space": loaded[0].config.get("action_space"),
                              "episodes": len(loaded[0].seeds), "reps": reps,
                              "confidence": CONFIDENCE, "groups": {}, "improvement": []}
    for mode in MODES:
        tables = final_tables(groups, mode)
        for g, (point, lo, hi) in iqm_intervals(tables, reps, seed).items():
            entry = record["groups"].setdefault(g, {
                "runs": [str(r.run) for r in groups[g]],
                "seeds": [r.config.get("seed") for r in groups[g]],
                "decisions": [r.decisions for r in groups[g]]})
            entry[mode] = {"scores": [float(s) for s in tables[g][:, 0]], "iqm": point,
                           "ci": [lo, hi]}
    names = list(groups)
    pairs = [(x, against) for x in names if x != against] if against is not None else \
        [(x, y) for i, x in enumerate(names) for y in names[i + 1:]]
    if pairs:
        tables = final_tables(groups, "sampled")
        found = improvement_intervals({f"{x} > {y}": (tables[x], tables[y]) for x, y in pairs},
                                      reps, seed)
        record["improvement"] = [{"x": x, "y": y, "mode": "sampled", "p": found[f"{x} > {y}"][0],
                                  "ci": list(found[f"{x} > {y}"][1:])} for x, y in pairs]
    record["curves"] = _curves(groups, points, window, reps, seed)
    if record["curves"]:
        c = record["curves"]
        record["reach"] = [{"x": x, "y": y, "target": c["groups"][y]["iqm"][-1],
                            "decisions": reach(c["decisions"], c["groups"][x]["iqm"],
                                               c["groups"][y]["iqm"][-1]),
                            "of": c["decisions"][-1]} for x, y in pairs]
    record["profiles"] = _profiles(groups, reps, seed)
    if reference is not None:
        record["reference"] = {k: {"space": v["space"], "mean": v["mean"], "std": v["std"],
                                   "iqm": v["iqm"]} for k, v in reference["agents"].items()}
    if out is not None:
        from sc2data.rl.train import _write_json

        with writing(str(out), "free some space, then rerun the same command"):
            out.mkdir(parents=True, exist_ok=True)
            _write_json(out / "compare.json", record)
            write_atomic(out / "compare.png", _figure(record, window))
    return record


def _reference(path: Path, run: RunScores) -> dict[str, Any]:
    """The reference agents' record, checked to be on the runs' evaluation episodes."""
    from sc2data.rl.evaluate import read_baselines

    record = read_baselines(path)
    if tuple(record["seeds"]) != run.seeds or record["episode_steps"] != \
            run.config.get("episode_steps"):
        raise Sc2DataError(
            f"{path}: the reference agents played other episodes ({record['episodes']} of "
            f"{record['episode_steps'] or 1800} steps) than the runs ({len(run.seeds)} of "
            f"{run.config.get('episode_steps') or 1800}); rerun sc2data rl baselines --out "
            f"{path} --episodes {len(run.seeds)}"
            + (f" --episode-steps {run.config['episode_steps']}"
               if run.config.get("episode_steps") else ""))
    return record


def _curves(groups: dict[str, list[RunScores]], points: int, window: int, reps: int,
            seed: int) -> dict[str, Any]:
    """Sample-efficiency curves (see the module docstring); empty where the runs' training
    episodes do not overlap."""
    all_runs = [r for members in groups.values() for r in members]
    starts = [every_game_ended(r.curve, r.games) for r in all_runs]
    if any(s is None for s in starts):
        return {}
    lo = max(s for s in starts if s is not None)
    hi = min(float(r.curve[0][-1]) for r in all_runs)
    if hi < lo:
        return {}
    at = np.unique(np.linspace(lo, hi, points).round())
    tables = {g: np.array([[curve_scores(r.curve, r.games, at, window)] for r in members])
              for g, members in groups.items()}
    point, interval = curve_intervals(tables, reps, seed)
    return {"decisions": [int(x) for x in at], "window": window, "per": "game",
            "groups": {g: {"iqm": [float(v) for v in point[g]],
                           "lo": [float(v) for v in interval[g][0]],
                           "hi": [float(v) for v in interval[g][1]]} for g in groups}}


def _profiles(groups: dict[str, list[RunScores]], reps: int, seed: int) -> dict[str, Any]:
    """Performance profiles of the final sampled scores (see the module docstring)."""
    tables = final_tables(groups, "sampled")
    top = max(float(t.max()) for t in tables.values())
    taus = np.linspace(0.0, max(top, 1.0), PROFILE_POINTS)
    point, interval = profile_intervals(tables, taus, reps, seed)
    return {"mode": "sampled", "tau": [float(t) for t in taus],
            "groups": {g: {"fraction": [float(v) for v in point[g]],
                           "lo": [float(v) for v in interval[g][0]],
                           "hi": [float(v) for v in interval[g][1]]} for g in groups}}


def above(record: dict[str, Any], threshold: float) -> dict[str, tuple[int, int]]:
    """Per group, (runs whose final sampled score exceeds ``threshold``, runs)."""
    return {g: (sum(s > threshold for s in e["sampled"]["scores"]), len(e["sampled"]["scores"]))
            for g, e in record["groups"].items()}


def _figure(record: dict[str, Any], window: int) -> bytes:
    """Sample-efficiency curves with CI bands (left), final IQMs with CIs (middle) and the
    performance profiles (right), the reference agents as lines in all three."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from rliable import plot_utils

    fig, (left, right, prof) = plt.subplots(1, 3, figsize=(15, 4.2),
                                            gridspec_kw={"width_ratios": [3, 2, 2]})
    names = list(record["groups"])
    colors = {g: f"C{i}" for i, g in enumerate(names)}
    curves = record.get("curves") or {}
    if curves:
        point = {g: np.array(c["iqm"]) for g, c in curves["groups"].items()}
        band = {g: np.array([c["lo"], c["hi"]]) for g, c in curves["groups"].items()}
        plot_utils.plot_sample_efficiency_curve(
            np.array(curves["decisions"]), point, band, algorithms=names, colors=colors,
            xlabel="decisions (all envs)",
            ylabel=f"marines per episode, IQM over runs\n(each game's last ≤ {window} "
                   "episodes)", ax=left,
            labelsize="medium", ticklabelsize="small")
    else:
        left.text(0.5, 0.5, "no training episodes common to all runs", ha="center",
                  transform=left.transAxes)
    for i, g in enumerate(names):
        for j, mode in enumerate(MODES):
            e = record["groups"][g][mode]
            y = i + (0.15 if j else -0.15)
            right.errorbar(e["iqm"], y, xerr=[[e["iqm"] - e["ci"][0]], [e["ci"][1] - e["iqm"]]],
                           fmt="o" if mode == "sampled" else "s", color=colors[g],
                           mfc=colors[g] if mode == "sampled" else "white", capsize=3)
    right.set_yticks(range(len(names)), [
        textwrap.fill(f"{g} ({len(record['groups'][g]['runs'])})", 34) for g in names],
        fontsize=7)
    right.set_xlabel("final marines per episode: IQM, 95 % CI\n(● sampled, □ argmax)",
                     fontsize=8)
    right.grid(alpha=0.3, axis="x")
    for name, ref in (record.get("reference") or {}).items():
        if name.startswith("uniform-") and ref["space"] != record["action_space"]:
            continue
        for draw in (left.axhline, right.axvline):
            draw(ref["mean"], color="0.4", lw=1, ls=":" if name.startswith("uniform") else "--")
        left.annotate(f"{name} {ref['mean']:.1f}", (0.99, ref["mean"]),
                      xycoords=("axes fraction", "data"), fontsize=7, color="0.3", va="bottom",
                      ha="right")
    right.set_ylim(-0.6, len(names) - 0.4)
    profiles = record.get("profiles") or {}
    if profiles:
        taus = np.array(profiles["tau"])
        for g in names:
            c = profiles["groups"][g]
            prof.plot(taus, c["fraction"], color=colors[g], lw=1.5, drawstyle="steps-post")
            prof.fill_between(taus, c["lo"], c["hi"], color=colors[g], alpha=0.15, step="post")
        for name, ref in (record.get("reference") or {}).items():
            if not (name.startswith("uniform-") and ref["space"] != record["action_space"]):
                prof.axvline(ref["mean"], color="0.4", lw=1,
                             ls=":" if name.startswith("uniform") else "--")
        prof.set_xlabel("final marines per episode τ (sampled)", fontsize=8)
        prof.set_ylabel("fraction of runs with score > τ", fontsize=8)
        prof.set_ylim(-0.02, 1.02)
        prof.grid(alpha=0.3)
    handles = [plt.Line2D([], [], color=colors[g], label=textwrap.fill(g, 48)) for g in names]
    left.legend(handles=handles, fontsize=7, loc="best")
    fig.suptitle(f"BuildMarines, {record['action_space']} space: {record['episodes']} "
                 f"evaluation episodes a run, {record['reps']} bootstrap resamples", fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    return buf.getvalue()


def summary(record: dict[str, Any]) -> list[str]:
    """The comparison as lines: each group's IQMs, the probabilities of improvement, the
    reference agents."""
    lines = []
    for g, e in record["groups"].items():
        n = len(e["runs"])
        lines.append(f"{g}: {n} run{'s' if n != 1 else ''}, " + "; ".join(
            f"{mode} IQM {e[mode]['iqm']:.2f} [{e[mode]['ci'][0]:.2f}, {e[mode]['ci'][1]:.2f}]"
            for mode in MODES) + f" (decisions {min(e['decisions']):,}"
            + (f"–{max(e['decisions']):,})" if max(e["decisions"]) != min(e["decisions"]) else ")"))
    for r in record.get("reach", []):
        lines.append(f"{r['x']} reaches {r['y']}'s last training IQM ({r['target']:.2f}) "
                     + (f"at {r['decisions']:,} of {r['of']:,} decisions "
                        f"({r['decisions'] / r['of']:.2f})" if r["decisions"] is not None
                        else f"nowhere in {r['of']:,} decisions"))
    uniform = next((ref for name, ref in (record.get("reference") or {}).items()
                    if name.startswith("uniform-") and ref["space"] == record["action_space"]),
                   None)
    if uniform is not None:
        lines.append(f"runs above the masked uniform policy ({uniform['mean']:.2f}), sampled: "
                     + "; ".join(f"{g} {k} of {n}"
                                 for g, (k, n) in above(record, uniform["mean"]).items()))
    for p in record["improvement"]:
        lines.append(f"P({p['x']} > {p['y']}) = {p['p']:.2f} [{p['ci'][0]:.2f}, {p['ci'][1]:.2f}]"
                     f" ({p['mode']})")
    for name, ref in (record.get("reference") or {}).items():
        lines.append(f"reference {name} ({ref['space']}): {ref['mean']:.2f} ± {ref['std']:.2f} "
                     f"marines per episode (IQM {ref['iqm']:.2f})")
    return lines
