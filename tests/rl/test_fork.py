"""``sc2data rl fork``: a narration run continued with another MEM, as docs/mem-loop.md does."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, run_cli

TINY = ["--envs", "1", "--rollout", "32", "--batch-size", "32", "--episode-steps", "40",
        "--checkpoint-every", "64", "--no-progress"]


def test_a_fork_resumes_with_the_new_mem_and_refuses_what_it_cannot(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tests.mem_helpers import tiny_pairset, train_tiny

    pairs = tiny_pairset(tmp_path / "pairs")
    mem0 = train_tiny(pairs, tmp_path / "mem0", epochs=1)
    mem1 = train_tiny(pairs, tmp_path / "mem1", epochs=1, seed=1)
    run, fork = tmp_path / "run", tmp_path / "fork"
    code, _, err = run_cli(["rl", "train", "--out", run, "--reward", "narration", "--mem", mem0,
                            "--steps", "64", *TINY], capsys)
    assert code == 0, err
    code, _, err = run_cli(["rl", "fork", run, "--mem", mem1, "--out", fork], capsys)
    assert code == 0, err
    assert json.loads((fork / "config.json").read_text())["mem"] == str(mem1)
    assert json.loads((fork / "fork.json").read_text())["from_mem"] == str(mem0)
    code, out, err = run_cli(["rl", "train", "--out", fork, "--reward", "narration", "--mem",
                              mem1, "--steps", "128", *TINY], capsys)
    assert code == 0, err
    state = json.loads((fork / "state.json").read_text())
    assert state["timesteps"] == 128 and state["resumes"] == 1  # resumed, not started over
    assert json.loads((run / "state.json").read_text())["timesteps"] == 64  # untouched

    code, _, err = run_cli(["rl", "fork", run, "--mem", mem1, "--out", fork], capsys)
    assert_one_line_error(code, err, "exists; a fork goes into a new folder")
    code, _, err = run_cli(["rl", "fork", run, "--mem", tmp_path / "nope", "--out",
                            tmp_path / "f2"], capsys)
    assert code == 2 and not (tmp_path / "f2").exists(), err
    sparse = tmp_path / "sparse"
    code, _, err = run_cli(["rl", "train", "--out", sparse, "--steps", "64", *TINY], capsys)
    assert code == 0, err
    code, _, err = run_cli(["rl", "fork", sparse, "--mem", mem1, "--out", tmp_path / "f3"],
                           capsys)
    assert_one_line_error(code, err, "only a narration run has a MEM to replace")
    assert not (tmp_path / "f3").exists()


def test_a_fork_of_a_run_started_from_another_policy_keeps_that_start(
        mem_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The fork's inputs name the new MEM and keep the starting policy's digest, so the fork
    resumes (a start the fork forgot would read as another --init-policy)."""
    from tests.mem_helpers import tiny_pairset, train_tiny

    mem1 = train_tiny(tiny_pairset(tmp_path / "pairs"), tmp_path / "mem1", epochs=1, seed=1)
    start, run, fork = tmp_path / "start", tmp_path / "run", tmp_path / "fork"
    code, _, err = run_cli(["rl", "train", "--out", start, "--steps", "32", *TINY], capsys)
    assert code == 0, err
    narration = ["--reward", "narration", "--init-policy", start, *TINY]
    code, _, err = run_cli(["rl", "train", "--out", run, "--mem", mem_run, "--steps", "64",
                            *narration], capsys)
    assert code == 0, err
    digest = json.loads((run / "config.json").read_text())["inputs"]["init_policy_sha256"]
    code, _, err = run_cli(["rl", "fork", run, "--mem", mem1, "--out", fork], capsys)
    assert code == 0, err
    assert json.loads((fork / "config.json").read_text())["inputs"]["init_policy_sha256"] == digest
    code, _, err = run_cli(["rl", "train", "--out", fork, "--mem", mem1, "--steps", "128",
                            *narration], capsys)
    assert code == 0, err
    assert json.loads((fork / "state.json").read_text())["timesteps"] == 128
