"""A full disk: ``rollout``, ``label``, ``pair`` and ``train`` writing to a small filesystem that
runs out of space part-way give one line and a non-zero exit, leave nothing that looks complete,
and the same command, once there is space, finishes the job as if nothing had happened.

The filesystem is a real one (a tmpfs mounted for the test, so root only; skipped elsewhere),
filled with a ballast file to leave about half the space the command needs.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from sc2data.data.audit import verify
from sc2data.ground.files import sha256_file
from tests.cli import exit_code
from tests.conftest import leave_free

ROOT = Path(__file__).resolve().parents[1]
RECIPE = """name = "tiny"
seed = 0
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
states_per_command = 2
null_states = 6
mismatch = "uniform"
[split]
method = "episode"
train = 0.666667
val = 0.166667
test = 0.166666
"""
"""Two commands that fire within 200 steps: a dataset that pairs in seconds."""
ROLLOUT = ["rollout", "--episodes-per-shard", "1", "--max-steps", "200", "--no-progress"]
TRAIN = ["--epochs", "2", "--threads", "1", "--vocab-size", "2000", "--no-progress"]


def _bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


@pytest.fixture(scope="module")
def ref(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Each stage's output with space enough: data (rolled out, labelled), pairs and a run."""
    root = tmp_path_factory.mktemp("ref")
    (root / "tiny.toml").write_text(RECIPE)
    assert exit_code(*ROLLOUT, "--recipe", root / "tiny.toml", "--out", root / "data") == 0
    assert exit_code("label", root / "data", "--no-progress") == 0
    assert exit_code("pair", root / "tiny.toml", "--data", root / "data", "--out",
                     root / "pairs", "--no-progress") == 0
    assert exit_code("train", root / "pairs", "--out", root / "run", *TRAIN) == 0
    return root


def _fails_in_one_line(*args: object) -> None:
    """``sc2data ARGS`` in its own process (a crash shows as its exit status) fails in one line."""
    p = subprocess.run([sys.executable, "-m", "sc2data.cli", *map(str, args)], cwd=ROOT,
                       capture_output=True, text=True, check=False)
    assert p.returncode == 2, (p.returncode, p.stderr)
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sc2data: error: "), p.stderr
    assert "No space left on device" in lines[0], lines[0]


@pytest.mark.parametrize("workers", ["1", "2"])
def test_rollout(ref: Path, fs: Path, workers: str) -> None:
    """In one process, and in two worker processes (the parent reports the worker's error)."""
    args = [*ROLLOUT, "--recipe", ref / "tiny.toml", "--out", fs / "data", "--workers", workers]
    ballast = leave_free(fs, _bytes(ref / "data") // 2)
    _fails_in_one_line(*args)
    data = fs / "data"
    assert not (data / "index.parquet").exists() and not list(data.glob("*.partial"))
    kept = sorted(data.glob("shard-*.h5"))
    assert all(sha256_file(p) == sha256_file(ref / "data" / p.name) for p in kept)
    ballast.unlink()
    assert exit_code(*args) == 0
    assert verify(data) == []
    for p in (ref / "data").glob("shard-*.h5"):
        assert sha256_file(data / p.name) == sha256_file(p)


@pytest.mark.parametrize("workers", ["1", "2"])
def test_label(ref: Path, fs: Path, workers: str) -> None:
    """In one process, and in two worker processes (each writes its shards' label parts)."""
    data = fs / "data"
    shutil.copytree(ref / "data", data, ignore=shutil.ignore_patterns("*label*"))
    need = _bytes(ref / "data") - _bytes(data)
    ballast = leave_free(fs, need // 2)
    args = ["label", data, "--workers", workers, "--no-progress"]
    _fails_in_one_line(*args)
    assert not (data / "labels.sha256").exists()
    ballast.unlink()
    assert exit_code(*args) == 0
    assert verify(data) == []
    for name in ("labels.parquet", "stack_labels.parquet"):
        assert pq.read_table(data / name).equals(pq.read_table(ref / "data" / name))


def test_pair(ref: Path, fs: Path) -> None:
    args = ["pair", ref / "tiny.toml", "--data", ref / "data", "--out", fs / "pairs",
            "--no-progress"]
    ballast = leave_free(fs, _bytes(ref / "pairs") // 2)
    _fails_in_one_line(*args)
    assert sorted(p.name for p in fs.iterdir()) == ["ballast"]
    ballast.unlink()
    assert exit_code(*args) == 0
    for p in [ref / "pairs" / "pairs.parquet", *(ref / "pairs" / "packed").iterdir()]:
        assert sha256_file(fs / "pairs" / p.relative_to(ref / "pairs")) == sha256_file(p)


def test_train(ref: Path, fs: Path) -> None:
    args = ["train", ref / "pairs", "--out", fs / "run", *TRAIN]
    ballast = leave_free(fs, _bytes(ref / "run") // 2)
    _fails_in_one_line(*args)
    state = fs / "run" / "state.json"
    assert not state.exists() or not json.loads(state.read_text())["finished"]
    ballast.unlink()
    assert exit_code(*args) == 0
    assert exit_code("verify", fs / "run") == 0
