"""A real ``sc2data build`` and ``sc2data train``, stopped at a seeded random moment of their run
(``kill -9`` or Ctrl-C), then run again to the end: the result equals an uninterrupted
run's, byte for byte (shards, labels, pair set) or tensor for tensor (checkpoint, metrics).

The moments are drawn uniformly over the uninterrupted run's own duration, start-up included, so
over the runs of the suite they land in every stage — importing, rolling out, labelling, drawing
and packing pairs, an epoch, its commit. Whatever moment a signal lands on, the assertions must
hold; the seed and moment are printed so a failure can be replayed. Linux only (signals).
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RECIPE = """
name = "killed"
seed = 3

[rollout]
env = "sim"
agent = "reduced-random"
episodes = 3
layers = "paper"

[commands.build_scv]
text = "build an SCV"

[commands.collect_minerals]
text = "collect minerals"

[pairs]
states_per_command = 30
null_states = 60

[split]
method = "random"
train = 0.6
val = 0.2
test = 0.2
"""
TRAIN = ["--epochs", "2", "--vocab-size", "2000", "--threads", "1", "--batch-size", "16"]
SIGNALS = (signal.SIGKILL, signal.SIGINT)
"""What stops a run: ``kill -9`` or Ctrl-C, drawn with the moment."""

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(sys.platform != "linux", reason="needs Linux signals")]


SEED = int(os.environ.get("SC2DATA_KILL_SEED", time.time_ns() % 2**32))
"""Seed of the moments: set ``SC2DATA_KILL_SEED`` to replay a run's draws (printed on failure)."""


def _sc2data(*args: object) -> list[str]:
    return [sys.executable, "-m", "sc2data.cli", *map(str, args)]


def _cli(*args: object) -> list[str]:
    """A long-running command, without progress lines."""
    return _sc2data(*args, "--no-progress")


def _run(args: list[str]) -> float:
    """Run to the end; its wall time."""
    t0 = time.monotonic()
    done = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return time.monotonic() - t0


def _stop_at(args: list[str], seconds: float, sig: int) -> bool:
    """Start ``args`` and send ``sig`` after ``seconds``; a Ctrl-C must end in exit 130 and one
    line, a kill in the kill. False when the run finished before the signal."""
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,  # SIGINT as a terminal job has it
                            preexec_fn=lambda: signal.signal(  # noqa: PLW1509 - one signal() call
                                signal.SIGINT, signal.SIG_DFL))
    time.sleep(seconds)
    if proc.poll() is None:
        proc.send_signal(sig)
    _, err = proc.communicate(timeout=300)
    if proc.returncode == 0:
        return False
    assert "Traceback" not in err, err
    if sig == signal.SIGINT:
        assert proc.returncode == 130, err
        assert err.strip().splitlines()[-1] == \
            "sc2data: interrupted; rerun the same command to resume", err
    else:
        assert proc.returncode == -signal.SIGKILL, err
    return True


def _stopped_then_finished(args: list[str], duration: float, rng: random.Random) -> None:
    """Stop ``args`` once at a drawn moment by a drawn signal, then run it to the end."""
    moment, sig = rng.uniform(0.0, duration), rng.choice(SIGNALS)
    print(f"SC2DATA_KILL_SEED={SEED}: stopping {args[3]} at {moment:.2f} s of {duration:.2f} s "
          f"({'kill -9' if sig == signal.SIGKILL else 'Ctrl-C'})")
    if _stop_at(args, moment, sig):
        _run(args)
    else:
        print("it finished before the signal")


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _build_content(out: Path) -> dict[str, str]:
    """Every file whose bytes a build's result is: shards, packed splits, pairs; the labels'
    content (their files also record when they were made)."""
    import pyarrow.parquet as pq

    files = {str(p.relative_to(out)): _sha(p) for p in sorted(out.rglob("*.h5"))}
    files["pairs.parquet"] = _sha(out / "pairs" / "pairs.parquet")
    for name in ("labels.parquet", "stack_labels.parquet"):
        table = pq.read_table(out / "rollout" / name)
        files[name] = hashlib.sha256(str(table.to_pydict()).encode()).hexdigest()
    return files


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, float, float]:
    """An uninterrupted build and training run, and how long each took."""
    root = tmp_path_factory.mktemp("kill-ref")
    recipe = root / "recipe.toml"
    recipe.write_text(RECIPE)
    build_s = _run(_cli("build", recipe, "--out", root / "build", "--workers", "1"))
    train_s = _run(_cli("train", root / "build" / "pairs", "--out", root / "run", *TRAIN))
    return recipe, root, build_s, train_s


def test_build_stopped_anywhere_finishes_to_the_same_bytes(
        reference: tuple[Path, Path, float, float], tmp_path: Path) -> None:
    recipe, root, build_s, _ = reference
    args = _cli("build", recipe, "--out", tmp_path / "build", "--workers", "1")
    _stopped_then_finished(args, build_s, random.Random(f"build {SEED}"))
    assert _build_content(tmp_path / "build") == _build_content(root / "build")
    done = subprocess.run(_sc2data("verify", tmp_path / "build" / "pairs"), cwd=ROOT,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_train_stopped_anywhere_finishes_to_the_same_model(
        reference: tuple[Path, Path, float, float], tmp_path: Path) -> None:
    import torch

    _, root, _, train_s = reference
    args = _cli("train", root / "build" / "pairs", "--out", tmp_path / "run", *TRAIN)
    _stopped_then_finished(args, train_s, random.Random(f"train {SEED}"))
    keep = ("epoch", "train_loss", "train_acc", "val_loss", "val_acc", "l2", "best")
    rows = [[{k: r[k] for k in keep} for r in map(json.loads, (run / "metrics.jsonl").open())]
            for run in (root / "run", tmp_path / "run")]
    assert rows[0] == rows[1]
    a, b = (torch.load(run / "best.pt", weights_only=True)["state_dict"]
            for run in (root / "run", tmp_path / "run"))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert json.loads((tmp_path / "run" / "state.json").read_text())["finished"] is True
    done = subprocess.run(_sc2data("verify", tmp_path / "run"), cwd=ROOT, capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr


RL = ["rl", "train", "--steps", "192", "--rollout", "32", "--batch-size", "32",
      "--episode-steps", "25", "--checkpoint-every", "64"]


@pytest.mark.parametrize("envs", [1, 2])
def test_rl_train_stopped_anywhere_resumes_to_a_run_that_agrees_with_itself(
        tmp_path: Path, envs: int) -> None:
    """An RL run cannot equal an uninterrupted one (a resume seeds its games anew), but after a
    stop anywhere and the rerun, its model, curve and state agree with each other (the sha256
    the last checkpoint recorded) and with its settings, it trained for its --steps, and it
    evaluates."""
    from sc2data.rl import runs

    ref = tmp_path / "ref"
    args = [*RL, "--envs", envs, "--processes", envs]
    duration = _run(_cli(*args, "--out", ref))
    out = tmp_path / "run"
    _stopped_then_finished(_cli(*args, "--out", out), duration, random.Random(f"rl {envs} {SEED}"))
    state = runs.read_state(out)  # raises unless model.zip and curve.csv are the recorded ones
    assert state is not None and state["timesteps"] >= 192
    rows = runs.read_curve(out)
    assert all(r["timesteps"] <= state["timesteps"] for r in rows)
    assert len(rows) == state["episodes"] and [r["episode"] for r in rows] == list(
        range(1, len(rows) + 1))
    assert not list(out.glob("*.partial*"))
    done = subprocess.run(_sc2data("rl", "evaluate", out, "--episodes", "1", "--no-progress"),
                          cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
