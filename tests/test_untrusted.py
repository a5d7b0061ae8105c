"""Files, records and plugins that are not what they seem: a lock path that is a link or someone
else's file, records nested too deep or holding ``Infinity``, a rules file that ends the process,
a rule that writes into its batch, and ``verify`` beside a command writing the folder. Each is one
line and a non-zero exit, nothing written, driven through the CLI as a user runs it
(``docs/reliability.md``)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, run_cli
from tests.mem_helpers import tiny_pairset
from tests.synthetic_data import make_dataset

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small rolled-out dataset, never labelled."""
    out = tmp_path_factory.mktemp("untrusted") / "data"
    make_dataset(out, episodes=2, per_shard=1)
    return out


@pytest.fixture
def data(dataset: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(dataset, tmp_path / "data"))


def _snapshot(folder: Path, *, results: bool = False) -> dict[str, bytes]:
    """Every regular file's bytes; ``results``: only what a command leaves as its result (not
    the lock's record, nor a resumable label run's parts), and no partial file may be there."""
    assert not results or not list(folder.rglob("*.partial"))
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.is_symlink() and not (results and (
                p.name == ".lock" or ".labels-parts" in p.parts))}


# -- the folder lock never follows a link ----------------------------------------------------------

def _link(lock: Path, victim: Path) -> None:
    lock.symlink_to(victim)


def _hard_link(lock: Path, victim: Path) -> None:
    os.link(victim, lock)


def _foreign(lock: Path, victim: Path) -> None:
    lock.write_text("my notes\n")


def _pipe(lock: Path, victim: Path) -> None:
    os.mkfifo(lock)


LOCKS: dict[str, tuple[Callable[[Path, Path], None], str]] = {
    "symlink": (_link, "is a symbolic link"),
    "hard-link": (_hard_link, "has 2 names"),
    "foreign-file": (_foreign, "holds something other than sc2data's lock record"),
    "fifo": (_pipe, "is a named pipe"),
}


@pytest.mark.parametrize("kind", LOCKS)
def test_label_never_writes_through_a_lock_that_is_not_its_own(
        data: Path, tmp_path: Path, kind: str, capsys: pytest.CaptureFixture[str]) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    make, needle = LOCKS[kind]
    (data / ".lock").unlink()  # the rollout's, replaced
    make(data / ".lock", victim)
    before = _snapshot(data)
    code, _, err = run_cli(["label", str(data), "--no-progress"], capsys)
    assert_one_line_error(code, err, f"{data / '.lock'} {needle}", "move it away or delete it")
    assert victim.read_text() == "precious\n"
    assert _snapshot(data) == before  # no labels, no parts
    (data / ".lock").unlink()  # what the message says to do; then the command works
    code, _, err = run_cli(["label", str(data), "--no-progress"], capsys)
    assert code == 0, err


def test_train_never_writes_through_a_linked_lock(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    pairs = tiny_pairset(tmp_path / "pairs")
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    run = tmp_path / "run"
    run.mkdir()
    (run / ".lock").symlink_to(victim)
    code, _, err = run_cli(["train", str(pairs), "--out", str(run), "--epochs", "1",
                            "--threads", "1", "--vocab-size", "2000", "--no-progress"], capsys)
    assert_one_line_error(code, err, f"{run / '.lock'} is a symbolic link")
    assert victim.read_text() == "precious\n"
    assert sorted(p.name for p in run.iterdir()) == [".lock"]


# -- plugins: a rules file cannot end the process, a rule cannot change its batch ---------------

EXITS = "import sys\nsys.exit(0)\n"
ONE_RULE = '''
import numpy as np
from sc2data.rulebase import rule


@rule(id="{id}", command="{id} text", requires=["player"])
def {id}(batch):
    return np.ones(len(batch), bool)
'''
WRITES = '''
import numpy as np
from sc2data.rulebase import rule


@rule(id="a_writer", command="writes", requires=["screen/unit_type"])
def a_writer(batch):
    if len(batch) > {min_size}:  # 5 and 1 are the load check's synthetic batches
        batch.layer("screen/unit_type")[:] = 0
    return np.zeros(len(batch), bool)
'''


@pytest.mark.parametrize("argv", [["rules", "list"], ["label", "{data}", "--overwrite",
                                                     "--no-progress"]])
def test_a_rules_file_that_calls_sys_exit_is_one_line(
        data: Path, tmp_path: Path, argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    rules = tmp_path / "rules"
    rules.mkdir()
    (rules / "exits.py").write_text(EXITS)
    before = _snapshot(data, results=True)
    code, out, err = run_cli([a.format(data=data) for a in argv] + ["--rules-dir", str(rules)],
                             capsys)
    assert_one_line_error(code, err, f"rule file {rules / 'exits.py'} called sys.exit(0) while "
                                     f"it was imported")
    assert out == ""
    assert _snapshot(data, results=True) == before


@pytest.mark.parametrize("min_size", [0, 5])
def test_a_rule_writing_into_its_batch_is_named(data: Path, tmp_path: Path, min_size: int,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Caught on the load check's batch (``min_size`` 0), or on the data (5)."""
    rules = tmp_path / "rules"
    rules.mkdir()
    (rules / "writer.py").write_text(WRITES.format(min_size=min_size))
    (rules / "zz_reader.py").write_text(ONE_RULE.format(id="zz_reader"))
    before = _snapshot(data, results=True)
    code, _, err = run_cli(["label", str(data), "--rules-dir", str(rules), "--no-progress"],
                           capsys)
    assert_one_line_error(code, err, "rule 'a_writer' from file", "wrote into the batch it was "
                          "given", "a synthetic batch" if min_size == 0 else "episode 0 step 0")
    assert _snapshot(data, results=True) == before


def test_rules_see_the_batch_as_read(dataset: Path) -> None:
    """Every rule, in every position, gets the stored arrays: a rule before it cannot change
    them (its view is read-only, and a new key or array it sets is its own)."""
    import numpy as np

    from sc2data.data.dataset import open_dataset
    from sc2data.labels.registry import call
    from sc2data.rulebase import rule

    seen: list[np.ndarray] = []

    @rule(id="swaps", command="swaps", requires=["screen/unit_type"])
    def swaps(batch):  # type: ignore[no-untyped-def]
        batch.arrays["screen/unit_type"] = np.zeros_like(batch.arrays["screen/unit_type"])
        return np.zeros(len(batch), bool)

    @rule(id="looks", command="looks", requires=["screen/unit_type"])
    def looks(batch):  # type: ignore[no-untyped-def]
        seen.append(np.array(batch.layer("screen/unit_type")))
        return np.zeros(len(batch), bool)

    batch = open_dataset(dataset)[0:8]
    stored = np.array(batch.layer("screen/unit_type"))
    assert stored.any()
    for r in (looks, swaps, looks):
        call(r, "test", batch)
    assert all(np.array_equal(s, stored) for s in seen) and len(seen) == 2


# -- verify beside a command writing the folder ---------------------------------------------------

def test_verify_beside_a_running_train_reports_the_write_not_damage(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``verify`` polled all through a real ``sc2data train`` (epochs committing under it) never
    reports a fault: while the train holds the folder, one line naming it; after, OK."""
    pairs = tiny_pairset(tmp_path / "pairs")
    run = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "sc2data.cli", "train", str(pairs), "--out", str(run),
         "--epochs", "4", "--threads", "1", "--vocab-size", "2000", "--no-progress"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    from sc2data.ground.files import writer

    seen: set[str] = set()
    try:
        deadline = time.monotonic() + 120
        while writer(run) is None and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        while proc.poll() is None:  # from before its first epoch to after its last
            code, out, err = run_cli(["verify", str(run)], capsys)
            if code == 0:  # between the lock's release and the process's end
                seen.add("ok")
                continue
            assert "FAULT" not in err and "damaged" not in err, err
            assert_one_line_error(code, err, f"{run} is being written by sc2data train "
                                             f"(pid {proc.pid}) now", "verify it when")
            seen.add("writing")
    finally:
        proc.wait(timeout=300)
    assert proc.returncode == 0, proc.stderr.read() if proc.stderr else ""
    assert "writing" in seen
    code, out, err = run_cli(["verify", str(run)], capsys)
    assert code == 0 and "OK (training run)" in out, err
    code, out, err = run_cli(["info", str(run)], capsys)
    assert code == 0 and "4 of 4 epochs" in out and not out.startswith("writing"), out


def test_verify_and_info_of_a_dataset_being_written(
        data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A dataset whose lock another process holds (as a rollout or label does)."""
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from pathlib import Path; "
         "from sc2data.ground.files import FolderLock; "
         "lock = FolderLock(Path(sys.argv[1]), 'label'); "
         "print('held', flush=True); time.sleep(60)", str(data)],
        cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        code, _, err = run_cli(["verify", str(data)], capsys)
        assert_one_line_error(code, err, f"is being written by sc2data label (pid {holder.pid})")
        code, out, err = run_cli(["info", str(data)], capsys)
        assert code == 0, err
        assert out.startswith(f"writing   sc2data label (pid {holder.pid}) is writing"), out
    finally:
        holder.kill()
        holder.wait()
    code, out, err = run_cli(["verify", str(data)], capsys)
    assert code == 0, err
