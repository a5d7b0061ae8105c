"""Files, records and plugins that are not what they seem: a lock path that is a link or someone
else's file, records nested too deep or holding ``Infinity``, a rules file that ends the process,
a rule that writes into its batch, and ``verify`` beside a command writing the folder. Each is one
line and a non-zero exit, nothing written, driven through the CLI as a user runs it
(``docs/reliability.md``)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, run_cli
from tests.mem_helpers import tiny_pairset, train_tiny
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


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.is_symlink()}


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
