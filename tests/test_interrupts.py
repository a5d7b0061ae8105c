"""Ctrl-C at any moment — while the commands import, while a folder lock is awaited, twice in a
row while the first is handled — exits 130 with one line and no traceback, leaves nothing that
looks complete, and the same command run again gives a clean result.

The signal goes to a real ``sc2data`` process at moments the test observes from outside, without
hooks in the code: numpy mapped into the process (the commands are importing), the folder's lock
file open (the lock is awaited), a shard being written (the workers are playing). Linux only
(``/proc``).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from sc2data.data.audit import verify
from sc2data.ground.files import FolderLock
from tests.cli import exit_code

ROOT = Path(__file__).resolve().parents[1]
ROLLOUT = ["rollout", "--agent", "reduced-random", "--episodes", "2", "--episodes-per-shard", "1",
           "--max-steps", "60", "--seed", "5", "--no-progress"]
INTERRUPTED = "sc2data: interrupted; rerun the same command to resume"

pytestmark = pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs Linux /proc")


def _start(args: list[object], module: str = "sc2data.cli",
           env: dict[str, str] | None = None) -> subprocess.Popen[str]:
    """``python -m MODULE ARGS`` (``sc2data ARGS``) in its own session, with SIGINT handled as a
    terminal's foreground job has it (this test may itself run with SIGINT ignored, as a
    background job does)."""
    return subprocess.Popen([sys.executable, "-m", module, *map(str, args)], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True,
                            preexec_fn=lambda: signal.signal(  # noqa: PLW1509 - one signal() call
                                signal.SIGINT, signal.SIG_DFL))


def _wait_until(proc: subprocess.Popen[str], ready: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + 120
    while not ready():
        if proc.poll() is not None:
            pytest.fail(f"the command ended before {what}: {proc.communicate()[1]}")
        assert time.monotonic() < deadline, f"no {what} in time"
        time.sleep(0.002)


def _mapped(pid: int, library: str) -> Callable[[], bool]:
    def ready() -> bool:
        try:
            return library in Path(f"/proc/{pid}/maps").read_text()
        except OSError:
            return False
    return ready


def _has_open(pid: int, path: Path) -> Callable[[], bool]:
    def ready() -> bool:
        try:
            return any(os.readlink(f) == str(path) for f in Path(f"/proc/{pid}/fd").iterdir())
        except OSError:
            return False
    return ready


def _interrupted(proc: subprocess.Popen[str], *gaps: float) -> str:
    """SIGINT now, and once more after each gap (seconds); asserts exit 130, the one line and no
    traceback; returns stderr."""
    proc.send_signal(signal.SIGINT)
    for gap in gaps:
        time.sleep(gap)
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    return _ended_interrupted(proc)


def _ended_interrupted(proc: subprocess.Popen[str]) -> str:
    """Wait for ``proc``; asserts exit 130, the one line and no traceback; returns stderr."""
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines() == [INTERRUPTED], err
    return err


@pytest.mark.parametrize("gaps", [(), (0.01,)], ids=["once", "twice"])
def test_ctrl_c_while_the_commands_import(tmp_path: Path, gaps: tuple[float, ...]) -> None:
    out = tmp_path / "data"
    proc = _start([*ROLLOUT, "--out", out])
    _wait_until(proc, _mapped(proc.pid, "_multiarray_umath"), "numpy import")
    _interrupted(proc, *gaps)
    assert not out.exists()


def test_ctrl_c_while_the_folder_lock_is_awaited(tmp_path: Path) -> None:
    out = tmp_path / "data"
    out.mkdir()
    with FolderLock(out, "rollout"):
        proc = _start([*ROLLOUT, "--out", out])
        _wait_until(proc, _has_open(proc.pid, out / ".lock"), "lock wait")
        time.sleep(0.1)
        _interrupted(proc, 0.01)
    assert [p.name for p in out.iterdir()] == [".lock"]


@pytest.mark.parametrize("gap", [0.005, 0.05, 0.3])
def test_ctrl_c_twice_while_workers_play(tmp_path: Path, gap: float) -> None:
    """The second Ctrl-C lands while the first stops the workers, or later: still 130 and one
    line, and the same command finishes the dataset."""
    out = tmp_path / "data"
    proc = _start([*ROLLOUT, "--workers", "2", "--out", out])
    _wait_until(proc, lambda: any(out.glob("shard-*.partial")), "shard started")
    _interrupted(proc, gap)
    assert not (out / "index.parquet").exists()
    assert exit_code(*ROLLOUT, "--out", out) == 0
    assert verify(out) == []


INSIDE_A_STRING = """
import os, signal, threading

import sc2data.cli


def _run(argv):
    threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT)).start()
    exec("while True: pass")  # the Ctrl-C lands in code compiled from a string


sc2data.cli._run = _run
sc2data.cli.main()
"""


def test_ctrl_c_inside_code_compiled_from_a_string(tmp_path: Path) -> None:
    """A ``KeyboardInterrupt`` that passes through ``exec`` or ``eval`` of a string, as the
    methods dataclasses and namedtuples make do, leaves a flag in CPython that makes
    ``python -m`` end the process by SIGINT (status -2) after the command exited 130."""
    (tmp_path / "inside_a_string.py").write_text(INSIDE_A_STRING)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    _ended_interrupted(_start([], module="inside_a_string", env=env))  # it sends its own


RL_TRAIN = ["rl", "train", "--envs", "2", "--processes", "2", "--steps", "256", "--rollout", "32",
            "--batch-size", "32", "--episode-steps", "30", "--checkpoint-every", "64",
            "--no-progress"]


def _children(pid: int) -> list[int]:
    try:
        return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


@pytest.mark.parametrize("moment", ["import", "workers", "training"])
def test_ctrl_c_to_rl_train_and_its_workers(tmp_path: Path, moment: str) -> None:
    """Ctrl-C from a terminal reaches the learner and its worker processes alike (the whole
    process group): one line, exit 130, no worker traceback, no worker left; the rerun
    finishes the run."""
    out = tmp_path / "run"
    proc = _start([*RL_TRAIN, "--out", out])
    if moment == "import":
        _wait_until(proc, _mapped(proc.pid, "_multiarray_umath"), "numpy import")
    elif moment == "workers":
        _wait_until(proc, lambda: len(_children(proc.pid)) >= 2, "worker processes")
    else:
        _wait_until(proc, lambda: (out / "state.json").is_file(), "a first checkpoint")
    workers = _children(proc.pid)
    os.killpg(proc.pid, signal.SIGINT)
    _ended_interrupted(proc)
    deadline = time.monotonic() + 15
    while any(Path(f"/proc/{w}").exists() and "Z" not in
              Path(f"/proc/{w}/stat").read_text().split()[2] for w in workers):
        assert time.monotonic() < deadline, "a worker outlived its learner"
        time.sleep(0.05)
    assert exit_code(*RL_TRAIN, "--out", out) == 0
    assert (out / "state.json").is_file()
