"""The narration-guided RL experiment: action spaces × rewards × seeds, one step budget per space.

Each run is ``sc2data rl train`` (its defaults: 16 games in worker processes, the learner on
every core, so one job at a time fills the machine; ``--jobs J`` runs J side by side, each
learner on its share of the cores: ``--threads`` cores // J unless ``--train-args`` sets it),
then ``sc2data rl evaluate`` on seeded episodes training never used (both start sides,
sampled and argmax); the reference agents are played once on the same episodes (``rl
baselines``) and every action space's runs are compared with ``rl compare`` (IQM,
stratified-bootstrap CIs, probability of improvement), into ``OUT/<space>-compare/``.
Everything is resumable: rerunning the same command resumes unfinished training runs (``rl
train`` resumes itself) and skips evaluations already written for the trained step count.
Narration runs wait until the MEM run (``--mem``) has finished training. Prints and writes
``OUT/summary.md`` (the table of BENCHMARKS.md) and one learning-curve PNG per action space.

An experiment longer than the machine's life (a grid of 1,000,000-decision runs over several
sittings, each on a fresh machine) keeps every finished run's record (``sc2data rl record``: no
model, ≈ 20 kB) in ``--records DIR`` (``DIR/<space>/<run>``, e.g. a folder of the repository):
a run recorded there for the budget and evaluation episodes asked is not trained again, and
the comparison and curves take the records where the runs are not on this machine. ``rl
compare`` groups records by their full settings and inputs (the MEM's digest), so a record
of another MEM or setting is a group apart, not a seed of this one.

    python benchmarks/rl_experiment.py --out /tmp/rl-exp --mem RUN \\
        --steps macro=16384 paper=8192 --seeds 0 1 2 --jobs 2 \\
        --eval-episodes macro=5 paper=2
    python benchmarks/rl_experiment.py --out /tmp/rl-exp-pot --mem RUN --rewards narration \\
        --train-args "--shaping potential" --steps paper=8192 --seeds 0 1 2
    python benchmarks/rl_experiment.py --out /tmp/rl-exp --summary      # the table alone
"""

from __future__ import annotations

import argparse
import csv
import json
import platform
import shlex
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

SC2DATA = [sys.executable, "-m", "sc2data.cli"]
REWARDS = ("sparse", "rules", "narration", "zero")


def sh(args: list[str], log: Path, check: bool = True) -> float:
    """Run one sc2data command (echoed, output appended to ``log``); its wall seconds. With
    ``check`` False a failure is reported (its last line) and the experiment goes on."""
    print("$ sc2data " + shlex.join(args), flush=True)
    t0 = time.perf_counter()
    with open(log, "a") as f:
        f.write("$ sc2data " + shlex.join(args) + "\n")
        f.flush()
        done = subprocess.run([*SC2DATA, *args], check=check, stdout=f, stderr=subprocess.STDOUT)
    if done.returncode:
        print(f"  failed: {log.read_text().strip().splitlines()[-1]}", flush=True)
    return time.perf_counter() - t0


def wait_for_mem(mem: Path) -> None:
    """Block until the MEM run's ``state.json`` says it finished training."""
    while True:
        try:
            if json.loads((mem / "state.json").read_text()).get("finished"):
                return
        except (OSError, ValueError):
            pass
        time.sleep(20)


def _read(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def one_run(out: Path, space: str, reward: str, seed: int, steps: int, a: argparse.Namespace,
            mem_lock: threading.Lock, name: str | None = None,
            narration: Path | None = None) -> None:
    """Train and evaluate one run; its wall times go to ``RUN.times.json`` beside it."""
    name = name or f"{space}-{reward}-s{seed}"
    run = out / space / name
    run.parent.mkdir(parents=True, exist_ok=True)
    log = out / space / f"{name}.log"
    times_file = out / space / f"{name}.times.json"
    times: dict[str, float] = _read(times_file) or {}
    args = ["rl", "train", "--action-space", space, "--reward", reward, "--steps", str(steps),
            "--seed", str(seed), "--out", str(run), "--no-progress",
            *shlex.split(train_args(a.train_args, a.jobs))]
    if reward == "narration":
        with mem_lock:
            wait_for_mem(a.mem)
        args += ["--mem", str(a.mem)]
        if narration is not None:
            args += ["--narration", str(narration)]
    episodes = int(dict(s.split("=", 1) for s in a.eval_episodes)[space])
    kept = a.records / space / name if a.records is not None else None
    if kept is not None and recorded(kept, steps, episodes):
        print(f"recorded: {kept}", flush=True)
        return
    state = _read(run / "state.json") or {}
    if state.get("timesteps", 0) < steps:
        times["train_s"] = times.get("train_s", 0.0) + sh(args, log)
        times_file.write_text(json.dumps(times))
    trained = (_read(run / "state.json") or {}).get("timesteps")
    done = _read(run / "eval.json")
    if not (done and done.get("trained_timesteps") == trained and done.get("episodes") == episodes
            and "sampled" in done):
        times["eval_s"] = sh(["rl", "evaluate", str(run), "--episodes", str(episodes),
                              "--no-progress"], log)
        times_file.write_text(json.dumps(times))
    if kept is not None:
        sh(["rl", "record", str(run), "--out", str(kept)], log)


def recorded(kept: Path, steps: int, episodes: int) -> bool:
    """Whether ``kept`` is a run's record trained for ``steps`` and evaluated on ``episodes``
    (``rl compare`` checks it by content where it reads it)."""
    entry = _read(kept / "record.json") or {}
    done = _read(kept / "eval.json") or {}
    return entry.get("timesteps", 0) >= steps and done.get("episodes") == episodes and \
        done.get("trained_timesteps") == entry.get("timesteps")


def space_runs(out: Path, records: Path | None, space: str) -> list[str]:
    """The action space's runs on this machine, and the records of those that are not."""
    here = {p.name: p for p in (out / space).iterdir() if (p / "config.json").is_file()}
    kept = {} if records is None or not (records / space).is_dir() else {
        p.name: p for p in (records / space).iterdir() if (p / "record.json").is_file()}
    return sorted(str(p) for p in {**kept, **here}.values())


def train_args(given: str, jobs: int) -> str:
    """``--train-args`` with ``--threads`` added for runs side by side: each learner gets cores //
    jobs threads. On 2 cores two learners of 2 threads each took 1.6-1.9x the wall time of one
    thread each, their OpenMP threads spinning for a core the other holds (BENCHMARKS.md, "Runs
    side by side")."""
    if jobs <= 1 or any(arg.split("=", 1)[0] == "--threads" for arg in shlex.split(given)):
        return given
    from sc2data.rl.train import cores  # the cores `rl train` itself counts

    return f"{given} --threads {max(1, cores() // jobs)}".strip()


def macro_sites(train_args: str) -> str:
    """The ``--macro-sites`` the runs train with (``random`` unless ``--train-args`` names one):
    the reference agents must build where the runs' macros build."""
    args = shlex.split(train_args)
    for i, arg in enumerate(args):
        if arg.startswith("--macro-sites="):
            return arg.split("=", 1)[1]
        if arg == "--macro-sites" and i + 1 < len(args):
            return args[i + 1]
    return "random"


def _rows(path: Path) -> list[dict[str, str]]:
    try:
        with path.open(newline="") as f:
            return list(csv.DictReader(f))
    except (OSError, csv.Error):
        return []


def fmt(values: list[float]) -> str:
    return f"{np.mean(values):.1f} ± {np.std(values):.1f}" if values else "—"


def summary(out: Path, last: int = 10, records: Path | None = None) -> str:
    """The results table: per action space and reward, over seeds (the records of runs not on
    this machine with them; their training minutes are not kept)."""
    lines = ["| space | reward | runs | decisions | pysc2 steps | training episodes | "
             f"marines, first {last} episodes | marines, last {last} episodes | "
             "evaluate argmax | evaluate sampled | train min / run |",
             "| --- | --- | ---: | ---: | ---: | ---: | --- | --- | --- | --- | ---: |"]
    for space_dir in sorted(p for p in out.iterdir() if p.is_dir()):
        groups: dict[str, list[Path]] = {}
        for run in map(Path, space_runs(out, records, space_dir.name)):
            groups.setdefault(run.name.rsplit("-s", 1)[0].split("-", 1)[1], []).append(run)
        for reward, runs in groups.items():
            first, final, det, sto, mins, steps, env_steps, eps = [], [], [], [], [], [], [], []
            for run in runs:
                m = [float(r["marines"]) for r in _rows(run / "curve.csv")]
                first.append(float(np.mean(m[:last]))) if m else None
                final.append(float(np.mean(m[-last:]))) if m else None
                eps.append(len(m))
                st = _read(run / "state.json") or _read(run / "record.json") or {}
                steps.append(st.get("timesteps", 0))
                env_steps.append(st.get("env_steps", 0))
                e = _read(run / "eval.json") or {}
                if "sampled" in e:
                    det.append(e["argmax"]["mean"])
                    sto.append(e["sampled"]["mean"])
                t = _read(space_dir / f"{run.name}.times.json") or {}
                if "train_s" in t:
                    mins.append(t["train_s"] / 60)
            lines.append(
                f"| {space_dir.name} | {reward} | {len(runs)} | {int(np.median(steps)):,} | "
                f"{int(np.median(env_steps)):,} | {int(np.median(eps))} | {fmt(first)} | "
                f"{fmt(final)} | {fmt(det)} | {fmt(sto)} | "
                f"{np.median(mins) if mins else float('nan'):.1f} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/rl-exp"))
    ap.add_argument("--mem", type=Path, help="MEM run for the narration reward.")
    ap.add_argument("--steps", nargs="*", default=["macro=40960", "paper=20480"],
                    help="SPACE=DECISIONS per run, one per action space to run.")
    ap.add_argument("--rewards", nargs="*", default=["sparse", "rules", "narration"],
                    choices=REWARDS)
    ap.add_argument("--seeds", nargs="*", type=int, default=list(range(10)),
                    help="Training seeds (≥ 10 for a claim: Agarwal et al. 2021).")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--eval-episodes", nargs="*", default=["macro=10", "paper=10"],
                    help="SPACE=EPISODES of each evaluation (half with each start side; "
                         "sampled and argmax).")
    ap.add_argument("--train-args", default="", help="More `rl train` options for every run, "
                    "e.g. '--shaping potential' (one --out per setting: runs are named by "
                    "space, reward and seed).")
    ap.add_argument("--paraphrased", type=Path, help="Also one narration run (seed 0) per action "
                    "space with this narration file.")
    ap.add_argument("--records", type=Path, help="Keep each finished run's record (sc2data rl "
                    "record) in RECORDS/<space>/<run>; runs recorded there are not trained "
                    "again, and their records are compared beside this machine's runs.")
    ap.add_argument("--summary", action="store_true", help="Only print the table.")
    a = ap.parse_args()
    out: Path = a.out
    if not a.summary:
        budgets = dict(s.split("=", 1) for s in a.steps)
        if "narration" in a.rewards and a.mem is None:
            ap.error("the narration reward needs --mem")
        out.mkdir(parents=True, exist_ok=True)
        print(f"# {platform.node()} {platform.processor() or platform.machine()}, "
              f"{time.strftime('%Y-%m-%d %H:%M')}", flush=True)
        lock = threading.Lock()
        jobs: list[tuple[Any, ...]] = [
            (space, reward, seed, int(budget)) for seed in a.seeds
            for space, budget in budgets.items() for reward in a.rewards]
        # seed by seed: an experiment stopped early holds every reward on its first seeds
        with ThreadPoolExecutor(a.jobs) as pool:
            futures = [pool.submit(one_run, out, *job, a, lock) for job in jobs]
            if a.paraphrased is not None:
                futures += [pool.submit(one_run, out, space, "narration", 0, int(budget), a, lock,
                                        f"{space}-paraphrased-s0", a.paraphrased)
                            for space, budget in budgets.items()]
            for f in futures:
                f.result()
        episodes = dict(s.split("=", 1) for s in a.eval_episodes)
        sites = macro_sites(a.train_args)
        for space in budgets:
            runs = space_runs(out, a.records, space)
            ref = out / f"baselines-{episodes[space]}" if sites == "random" else \
                out / f"baselines-{episodes[space]}-{sites}"
            if not (ref / "baselines.json").is_file():
                sh(["rl", "baselines", "--out", str(ref), "--episodes", episodes[space],
                    "--macro-sites", sites, "--no-progress"], out / "baselines.log")
            sh(["rl", "plot", *runs, "--group", "--baselines", str(ref), "--out",
                str(out / f"curves-{space}.png")], out / "plot.log", check=False)
            sh(["rl", "compare", *runs, "--baselines", str(ref), "--out",
                str(out / f"{space}-compare")], out / "compare.log", check=False)
    table = summary(out, records=a.records)
    print(table)
    (out / "summary.md").write_text(table + "\n")


if __name__ == "__main__":
    main()
