"""`sc2data rl train` stopped by ``kill -9`` at a random moment, then rerun: a loop over seeds.

For each seed (a seeded schedule: ``random.Random(seed)`` draws the moment uniformly over an
uninterrupted run's duration, start-up included) and each ``--envs`` (1, and 2 in two worker
processes), the same command is started, killed with SIGKILL at that moment, and run again to
the end. What ``rl train`` promises across a resume (``sc2data/rl/train.py``: a resume seeds its
games anew, so the resumed part cannot equal an uninterrupted run) is checked exactly:

* after the kill, once a commit it cut is finished or undone (``runs.recover``, what the rerun
  does first), the run holds its last whole checkpoint or none: ``state.json``, ``model.zip``
  and ``curve.csv`` agree (``runs.read_state``), and that checkpoint's curve is the
  uninterrupted run's curve up to its decision count, row for row (the same seed trains the
  same until the first resume);
* after the rerun: trained to ``--steps``; the checkpoint agrees with itself and its settings;
  the rows the kill kept are still the curve's first rows; episodes numbered without a gap;
  ``resumes`` is 1 if the kill left a checkpoint short of ``--steps``, else 0 (a kill after
  the last checkpoint leaves a finished run, which the rerun leaves as it is);
  ``sc2data verify RUN`` passes;
* no ``*.partial*`` file in the run, no shared-memory file of the killed process, and no process
  of it left.

    .venv/bin/python benchmarks/rl_kill_anywhere.py --seeds 20

Prints one line per stop and a summary; exits 1 if any check failed.
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sc2data.rl import arena, runs  # noqa: E402

SETTINGS = ["--steps", "192", "--rollout", "32", "--batch-size", "32", "--episode-steps", "25",
            "--checkpoint-every", "32", "--threads", "1", "--no-progress"]


def command(out: Path, envs: int) -> list[str]:
    return [sys.executable, "-m", "sc2data.cli", "rl", "train", *SETTINGS, "--envs", str(envs),
            "--processes", str(envs if envs > 1 else 0), "--out", str(out)]


def finish(args: list[str]) -> float:
    """Run ``args`` to the end; its wall time."""
    t0 = time.monotonic()
    done = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=900)
    if done.returncode:
        raise AssertionError(f"exit {done.returncode}: {done.stderr.strip()[-500:]}")
    return time.monotonic() - t0


def kill_at(args: list[str], seconds: float) -> int | None:
    """Start ``args``, ``kill -9`` it after ``seconds``; its pid, or None if it ended first."""
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        proc.wait(timeout=seconds)
        return None
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate(timeout=60)
        return proc.pid


def left_behind(run: Path, pid: int | None) -> list[str]:
    """Partial files in the run, shared memory and processes of the killed ``pid``."""
    out = [str(p) for p in run.rglob("*.partial*")] if run.is_dir() else []
    if pid is not None:
        out += [str(p) for p in arena.folder().glob(f"{arena.PREFIX}{pid}-*")]
        time.sleep(0.5)  # workers end once the learner's pipe closes
        ps = subprocess.run(["ps", "-eo", "pid,ppid,args"], capture_output=True, text=True)
        out += [line for line in ps.stdout.splitlines()[1:]
                if str(run) in line and line.split()[0] != str(os.getpid())]
    return out


def check(run: Path, ref_rows: list[dict[str, float]], moment: float, pid: int | None,
          args: list[str]) -> str:
    """Stop-then-finish checks (the module docstring); a line on what was seen."""
    if run.is_dir():
        runs.recover(run)  # what the rerun does first: a commit the kill cut is finished or undone
    kept = runs.read_state(run) if (run / runs.STATE).is_file() else None
    kept_rows = runs.read_curve(run) if kept is not None else []
    if kept is not None:
        want = [r for r in ref_rows if r["timesteps"] <= kept["timesteps"]]
        assert kept_rows == want, "the kept checkpoint's curve is not the uninterrupted run's"
        assert kept["episodes"] == len(kept_rows)
    finish(args)
    state = runs.read_state(run)
    assert state is not None and state["timesteps"] >= 192, state
    resumed = kept is not None and kept["timesteps"] < 192  # else: already trained, kept as is
    assert state["resumes"] == int(resumed), (state, kept)
    rows = runs.read_curve(run)
    assert rows[:len(kept_rows)] == kept_rows, "the rerun changed the kept rows"
    assert [r["episode"] for r in rows] == list(range(1, len(rows) + 1)) == list(
        range(1, state["episodes"] + 1)), "episodes not numbered 1..N"
    assert all(r["timesteps"] <= state["timesteps"] for r in rows)
    assert not left_behind(run, pid), left_behind(run, pid)
    v = subprocess.run([sys.executable, "-m", "sc2data.cli", "verify", str(run)], cwd=ROOT,
                       capture_output=True, text=True)
    assert v.returncode == 0, v.stdout + v.stderr
    what = "no checkpoint" if kept is None else f"checkpoint at {kept['timesteps']} kept"
    return f"killed at {moment:5.2f} s: {what}; resumed to {state['timesteps']}, " \
           f"{state['episodes']} episodes, verify ok"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="Seeds 1..N.")
    ap.add_argument("--envs", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--only", type=int, nargs="+", help="These seeds alone (a replay).")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="rl-kill-"))
    refs = {}
    for envs in a.envs:
        ref = tmp / f"ref-{envs}"
        duration = finish(command(ref, envs))
        again = tmp / f"ref-{envs}-again"
        finish(command(again, envs))
        same = runs.read_curve(ref) == runs.read_curve(again)
        print(f"envs {envs}: uninterrupted run {duration:.1f} s; a second one gives the same "
              f"curve: {same}", flush=True)
        assert same, "training is not reproducible: the curve check below means nothing"
        refs[envs] = (runs.read_curve(ref), duration)
    failed = early = 0
    seeds = a.only or list(range(1, a.seeds + 1))
    for seed in seeds:
        for envs in a.envs:
            ref_rows, duration = refs[envs]
            moment = random.Random(f"{seed} {envs}").uniform(0.0, duration)
            run = tmp / f"s{seed}-e{envs}"
            args = command(run, envs)
            try:
                pid = kill_at(args, moment)
                if pid is None:
                    early += 1
                    line = f"finished before the kill at {moment:.2f} s"
                else:
                    line = check(run, ref_rows, moment, pid, args)
            except AssertionError as e:
                failed += 1
                line = f"FAILED at {moment:.2f} s: {e}"
            print(f"seed {seed:2d} envs {envs}: {line}", flush=True)
    stops = len(seeds) * len(a.envs) - early
    print(f"{stops - failed} of {stops} stops resumed to a consistent run; {early} runs "
          f"finished before their kill ({tmp})")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
