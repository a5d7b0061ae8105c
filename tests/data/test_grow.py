"""A dataset grows: more episodes into a finished folder equal a fresh run's bytes; it never
shrinks."""

from __future__ import annotations

import hashlib
import json
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import pytest

import sc2data
from sc2data.data.audit import verify
from sc2data.data.dataset import DATASET_RECORD, INDEX, read_dataset_record
from sc2data.ground.errors import Sc2DataError
from tests.cli import assert_one_line_error, run_cli
from tests.synthetic_data import as_format, make_dataset

ROOT = Path(__file__).resolve().parents[2]


def sums(folder: Path) -> dict[str, str]:
    """sha256 of every file of a folder but its lock (which names the last writer's pid)."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())
            if p.name != ".lock"}


@pytest.mark.parametrize("small, large, workers, kept", [
    (2, 3, 1, 1),  # a full shard kept, a new one
    (1, 3, 2, 0),  # the partial shard rolled out again, a new one, by two workers
    (3, 5, 1, 1),  # a full shard kept, the partial one rolled out again, a new one
])
def test_a_grown_dataset_is_byte_for_byte_a_fresh_one(tmp_path: Path, small: int, large: int,
                                                      workers: int, kept: int) -> None:
    grown, fresh = tmp_path / "grown", tmp_path / "fresh"
    make_dataset(grown, episodes=small)  # 2 episodes per shard
    before = {p.name: p.stat().st_mtime_ns for p in grown.glob("shard-*.h5")}
    s = make_dataset(grown, episodes=large, workers=workers)
    assert (s.grew_from, s.episodes, s.shards_kept) == (small, large, kept)
    assert s.shards_written == -(-large // 2) - kept
    make_dataset(fresh, episodes=large)
    assert sums(grown) == sums(fresh) and verify(grown) == []
    assert sorted(sums(grown)) == [DATASET_RECORD, INDEX, *(f"shard-{i:05d}.h5" for i in
                                                     range(-(-large // 2)))]
    if kept:  # a full shard is not touched
        assert (grown / "shard-00000.h5").stat().st_mtime_ns == before["shard-00000.h5"]
    again = make_dataset(grown, episodes=large)  # finished: nothing to do
    assert (again.shards_written, again.grew_from) == (0, None) and sums(grown) == sums(fresh)


def _grow_killed(out: Path, episode: int) -> None:
    """Grow ``out`` to 5 episodes in another process, SIGKILLed as ``episode`` starts."""
    code = textwrap.dedent(f"""
        import os, signal
        from sc2data.data.rollout import episode_seeds, rollout
        from sc2data.testing.synthetic import pysc2_random_agent, synthetic_env_factory
        from tests.synthetic_data import STEPS, config

        doomed = episode_seeds(7, {episode})[1]

        def agent(seed):
            if seed == doomed:
                os.kill(os.getpid(), signal.SIGKILL)
            return pysc2_random_agent(seed)

        rollout(config(episodes=5), {str(out)!r}, progress=False,
                env_factory=synthetic_env_factory(STEPS), agent_factory=agent)
    """)
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                       check=False)
    assert p.returncode == -signal.SIGKILL, p.stderr


@pytest.mark.parametrize("episode", [1, 3])
def test_a_grow_killed_midway_finishes_to_the_same_bytes(tmp_path: Path, episode: int) -> None:
    """SIGKILL while the partial shard 0 is rolled out again (episode 1: the old shard is still
    there) or after it was replaced (episode 3); the same command then ends at a fresh run's
    bytes, and a smaller one is refused."""
    grown, fresh = tmp_path / "grown", tmp_path / "fresh"
    make_dataset(grown, episodes=1)
    _grow_killed(grown, episode)
    assert not (grown / INDEX).exists() and list(grown.glob("*.partial"))
    assert read_dataset_record(grown)["settings"]["episodes"] == 5
    with pytest.raises(Sc2DataError, match="holds 5 episodes \\(or is growing to them\\)"):
        make_dataset(grown, episodes=3)
    with pytest.raises(Sc2DataError, match="unfinished rollout"):
        sc2data.open_dataset(grown)
    make_dataset(grown, episodes=5)
    make_dataset(fresh, episodes=5)
    assert sums(grown) == sums(fresh) and verify(grown) == []


def test_shrinking_is_refused_and_changes_nothing(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "d"
    make_dataset(out, episodes=3)
    before = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in out.iterdir()}
    with pytest.raises(Sc2DataError, match="holds 3 episodes .* more than the 2 asked for; a "
                                           "dataset only grows"):
        make_dataset(out, episodes=2)
    code, _, err = run_cli(["rollout", "--out", out, "--episodes", "1"], capsys)
    assert_one_line_error(code, err, "holds 3 episodes", "only grows")
    assert {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in out.iterdir()} == before


def test_the_cli_grows_a_folder_with_its_own_settings(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """``sc2data rollout --out DATA --episodes N``: the settings not given are the folder's."""
    grown, fresh = tmp_path / "grown", tmp_path / "fresh"
    settings = ["--env", "sim", "--agent", "random", "--seed", "5", "--episodes-per-shard", "2",
                "--max-steps", "6", "--no-progress"]
    assert run_cli(["rollout", "--out", grown, "--episodes", "3", *settings], capsys)[0] == 0
    code, out, err = run_cli(["rollout", "--out", grown, "--episodes", "4", "--no-progress"],
                             capsys)
    assert code == 0, err
    assert "4 episodes, grown from 3, 24 stacks" in out and "(1 shard written, 1 kept)" in out
    assert run_cli(["rollout", "--out", fresh, "--episodes", "4", *settings], capsys)[0] == 0
    assert sums(grown) == sums(fresh)
    code, _, err = run_cli(["rollout", "--out", grown, "--episodes", "5", "--seed", "6"], capsys)
    assert_one_line_error(code, err, "other settings (differs in: seed)")


def test_a_format_2_dataset_is_read_and_verified_but_not_grown(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "old"
    make_dataset(out, episodes=3)
    stacks = sc2data.open_dataset(out)[0:40].arrays
    as_format(out, 2)
    assert verify(out) == []
    for k, v in sc2data.open_dataset(out)[0:40].arrays.items():
        assert (v == stacks[k]).all()
    with h5py.File(out / "shard-00001.h5", "r+") as f:  # a shard that lost its count is caught
        f.attrs["settings"] = json.dumps({**json.loads(f.attrs["settings"]), "episodes": 9})
    assert verify(out)[0] == "shard-00001.h5: settings differ from dataset.json"
    code, _, err = run_cli(["rollout", "--out", out, "--episodes", "4"], capsys)
    assert_one_line_error(code, err, "has dataset format 2, which this sc2data reads and "
                                     "verifies but does not add to (it writes format 4)")


def test_a_format_3_dataset_reads_without_masks_and_is_not_grown(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Written before action masks were kept: its stacks and actions read as before, it
    verifies, it has no masks, and a rollout into it is refused in one line (a grow would mix
    shards with and without masks)."""
    out = tmp_path / "old"
    make_dataset(out, episodes=3)
    with sc2data.open_dataset(out) as new:
        stacks, acts = new[0:40].arrays, new.actions([0] * 5, range(5))
        assert new.has_masks and acts["available"].shape == (5, 573)
    as_format(out, 3)
    old = sc2data.open_dataset(out)
    assert verify(out) == [] and not old.has_masks
    for k, v in old[0:40].arrays.items():
        assert (v == stacks[k]).all()
    got = old.actions([0] * 5, range(5))
    assert sorted(got) == ["args", "function", "reward"]
    assert all((got[k] == acts[k]).all() for k in got)
    code, _, err = run_cli(["rollout", "--out", out, "--episodes", "4"], capsys)
    assert_one_line_error(code, err, "has dataset format 3, which this sc2data reads and "
                                     "verifies but does not add to (it writes format 4)",
                          "roll out into a new --out")
    code, out_text, err = run_cli(["info", out], capsys)
    assert code == 0, err
    assert "action masks none (written before format 4)" in out_text
