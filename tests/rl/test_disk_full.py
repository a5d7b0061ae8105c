"""A full disk at every write of ``sc2data rl train``, ``rl evaluate`` and ``rl plot``.

Each case runs the command in its own process on a small tmpfs (root only; skipped elsewhere)
that fills up the moment the command opens one named file to write (:mod:`tests.diskfill`: a
real ``ENOSPC`` from the kernel, nothing of sc2data patched): the lock and ``config.json`` at
start, a checkpoint's model, curve and state, the derived ``curve.json``, SB3's
``progress.csv``, ``eval.json`` and the plot's PNG. Each ends in one line saying the disk is full
and what to do, exit 2, no traceback and no ``*.partial*`` file; the previous checkpoint is
intact, and the same command, once there is space, resumes from it.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from sc2data.rl import arena, runs
from tests.cli import exit_code

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--rollout", "32", "--batch-size", "32", "--episode-steps", "25", "--checkpoint-every",
        "64", "--epochs", "1", "--threads", "1", "--no-progress"]
"""A run that checkpoints at 32 decisions (its end) and, resumed to 64, logs at 64 (SB3's first
dump of the session) and then checkpoints at 64."""


def _train(out: Path, steps: int, envs: int = 1) -> list[object]:
    return ["rl", "train", "--out", out, "--steps", steps, "--envs", envs, "--processes",
            envs if envs > 1 else 0, *TINY]


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run with one checkpoint (32 decisions), to resume on a disk that fills."""
    run = tmp_path_factory.mktemp("rl") / "run"
    assert exit_code(*_train(run, 32)) == 0
    return run


def _fails_when_filling_at(name: str, fs: Path, *args: object, nth: int = 1) -> None:
    """``sc2data ARGS`` in its own process, the disk filling at the ``nth`` write of ``name…``,
    fails in one line saying the disk is full and what to do; the disk is then freed."""
    p = subprocess.run([sys.executable, "-m", "tests.diskfill", name, str(nth),
                        str(fs / "ballast"), "--", *map(str, args)],
                       cwd=ROOT, capture_output=True, text=True, check=False, timeout=300)
    (fs / "ballast").unlink(missing_ok=True)
    assert p.returncode == 2, (p.returncode, p.stderr)
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sc2data: error: cannot write "), p.stderr
    assert "No space left on device; free some space, then rerun the same command" in lines[0]


def _whole(run: Path, timesteps: int, resumes: int) -> None:
    """``run`` holds one whole checkpoint of ``timesteps`` (model, curve and state agree), no
    partial file, and ``verify`` passes."""
    state = runs.read_state(run)
    assert state is not None and (state["timesteps"], state["resumes"]) == (timesteps, resumes)
    assert len(runs.read_curve(run)) == state["episodes"]
    assert not list(run.rglob("*.partial*"))
    assert exit_code("verify", run) == 0


@pytest.mark.parametrize("name", [runs.CONFIG, "progress.csv", runs.MODEL_PARTIAL,
                                  runs.CURVE_PARTIAL, runs.STATE_PARTIAL, runs.CURVE_JSON])
def test_a_resumed_train(base: Path, fs: Path, name: str) -> None:
    """At start (``config.json``), in SB3's log, and at each file of a checkpoint: the previous
    checkpoint stays whole (or, the disk filling at ``curve.json`` after the commit, the new
    one) and the rerun resumes from it."""
    run = shutil.copytree(base, fs / "run")
    _fails_when_filling_at(name, fs, *_train(run, 64))
    committed = name == runs.CURVE_JSON  # written once the checkpoint is whole
    _whole(run, 64 if committed else 32, 1 if committed else 0)
    assert exit_code(*_train(run, 64)) == 0
    _whole(run, 64, 1)


@pytest.mark.parametrize("name", [".lock", runs.CONFIG, runs.MODEL_PARTIAL])
def test_a_new_train(fs: Path, name: str) -> None:
    """A new run that cannot write its lock, its settings or its first checkpoint leaves
    nothing: the rerun starts it afresh."""
    _fails_when_filling_at(name, fs, *_train(fs / "run", 32))
    assert not (fs / "run").exists()
    assert exit_code(*_train(fs / "run", 32)) == 0
    _whole(fs / "run", 32, 0)


def test_two_envs_in_worker_processes(fs: Path) -> None:
    """The second checkpoint of a run whose games step in two worker processes: the first is
    kept, no worker's shared memory is left, and the rerun resumes."""
    before = set(arena.folder().glob(f"{arena.PREFIX}*"))
    run = fs / "run"
    args = _train(run, 128, envs=2)
    _fails_when_filling_at(runs.MODEL_PARTIAL, fs, *args, nth=2)
    _whole(run, 64, 0)
    assert not _leaked(before)
    assert exit_code(*args) == 0
    _whole(run, 128, 1)


def _leaked(before: set[Path]) -> set[Path]:
    """Shared-memory files made since ``before`` whose creator no longer runs: another test's
    or another run's live file (the instant between its creation and its unlinking) is not a
    leak, and the suite runs RL tests side by side."""
    now = set(arena.folder().glob(f"{arena.PREFIX}*")) - before
    return {p for p in now if not arena._alive(int(p.name[len(arena.PREFIX):].split("-")[0]))}


def test_tensorboard_events(base: Path, fs: Path) -> None:
    pytest.importorskip("tensorboard")
    run = shutil.copytree(base, fs / "run")
    args = [*_train(run, 64), "--tensorboard"]
    _fails_when_filling_at("events.out.tfevents", fs, *args)
    _whole(run, 32, 0)
    assert exit_code(*args) == 0
    _whole(run, 64, 1)


def test_evaluate_and_compare(base: Path, fs: Path) -> None:
    run = shutil.copytree(base, fs / "run")
    args = ["rl", "evaluate", run, "--episodes", "1", "--no-progress"]
    _fails_when_filling_at("eval.json", fs, *args)
    assert not (run / "eval.json").exists() and not list(run.rglob("*.partial*"))
    assert exit_code(*args) == 0 and (run / "eval.json").is_file()
    args = ["rl", "compare", run, "--out", fs / "cmp", "--reps", "50"]
    _fails_when_filling_at("compare.png", fs, *args)
    assert not list(fs.rglob("*.partial*"))
    assert exit_code(*args) == 0 and (fs / "cmp" / "compare.png").is_file()


def test_baselines(fs: Path) -> None:
    args = ["rl", "baselines", "--out", fs / "ref", "--episodes", "1", "--episode-steps", "5",
            "--no-progress"]
    _fails_when_filling_at("baselines.json", fs, *args)
    assert not list((fs / "ref").iterdir())
    assert exit_code(*args) == 0 and (fs / "ref" / "baselines.json").is_file()


def test_plot(base: Path, fs: Path) -> None:
    args = ["rl", "plot", base, "--out", fs / "plots" / "curve.png"]
    _fails_when_filling_at("curve.png", fs, *args)
    assert not list((fs / "plots").iterdir())
    assert exit_code(*args) == 0 and (fs / "plots" / "curve.png").is_file()


def test_full_shared_memory_is_one_line(fs: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The games' shared memory on a full ``/dev/shm`` (here, the full tmpfs in its place) is
    refused when it is made: a sparse file there mapped, and the first write into it killed
    the process with SIGBUS."""
    import numpy as np

    from sc2data.ground.errors import Sc2DataError
    from tests.diskfill import fill

    monkeypatch.setattr(arena, "folder", lambda: fs)
    fill(fs / "ballast")
    with pytest.raises(Sc2DataError, match=r"shared memory \(400,000 bytes\) in .*No space left "
                                           r"on device; free space there, or run with "
                                           r"--processes 0"):
        arena.Arena.create([arena.Field("x", (1000, 100), np.dtype(np.float32))])
    assert [p.name for p in fs.iterdir()] == ["ballast"]
