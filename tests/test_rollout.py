"""The rollout loop: seeding, worker-count independence, resume, refusal, crash safety."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import sc2data
from pysc2.agents import base_agent
from sc2data._pysc2 import actions
from sc2data.audit import verify
from sc2data.dataset import INDEX, MANIFEST
from sc2data.errors import Sc2DataError
from sc2data.rollout import RolloutConfig, episode_seeds, rollout
from sc2data.synthetic import synthetic_env_factory
from tests.synthetic_data import config, make_dataset

ROOT = Path(__file__).resolve().parents[1]


def shas(folder: Path) -> list[str]:
    return sc2data.open_dataset(folder).index.column("shard_sha256").to_pylist()


def test_episode_seeds_depend_on_seed_and_episode_only() -> None:
    assert episode_seeds(3, 5) == episode_seeds(3, 5)
    seeds = {episode_seeds(3, e) for e in range(1000)}
    assert len(seeds) == 1000
    assert episode_seeds(3, 5) != episode_seeds(4, 5)
    assert all(0 <= s < 2**31 for pair in seeds for s in pair)


def test_same_seed_same_bytes_whatever_the_worker_count(tmp_path: Path) -> None:
    one = make_dataset(tmp_path / "k1", workers=1)
    two = make_dataset(tmp_path / "k2", workers=2)
    assert (one.episodes, one.steps, one.shards_written) == (5, 150, 3)
    assert two.shards_written == 3
    assert shas(tmp_path / "k1") == shas(tmp_path / "k2")
    assert verify(tmp_path / "k1") == [] and verify(tmp_path / "k2") == []
    other = make_dataset(tmp_path / "s8", seed=8)
    assert shas(tmp_path / "s8") != shas(tmp_path / "k1") and other.episodes == 5


def test_rerun_resumes_and_keeps_complete_shards(tmp_path: Path) -> None:
    ref, out = tmp_path / "ref", tmp_path / "out"
    make_dataset(ref)
    make_dataset(out)
    (out / "shard-00001.h5").unlink()
    (out / INDEX).unlink()
    (out / "shard-00002.h5").rename(out / "shard-00002.h5.partial")
    again = make_dataset(out)
    assert (again.shards_written, again.shards_kept) == (2, 1)
    assert not list(out.glob("*.partial"))
    assert shas(out) == shas(ref) and verify(out) == []
    done = make_dataset(out)  # a finished dataset: nothing to do, the index is rewritten
    assert (done.shards_written, done.shards_kept) == (0, 3)


def test_other_settings_in_the_same_folder_are_refused(tmp_path: Path) -> None:
    out = tmp_path / "out"
    make_dataset(out)
    before = sorted((p.name, p.stat().st_mtime_ns) for p in out.iterdir())
    with pytest.raises(Sc2DataError, match=r"other settings \(differs in: episodes\)"):
        make_dataset(out, episodes=6)
    with pytest.raises(Sc2DataError, match="seed"):
        make_dataset(out, seed=1)
    assert sorted((p.name, p.stat().st_mtime_ns) for p in out.iterdir()) == before


def test_max_steps_cuts_episodes(tmp_path: Path) -> None:
    s = make_dataset(tmp_path / "out", episodes=2, max_steps=7)
    assert s.steps == 14
    ds = sc2data.open_dataset(tmp_path / "out")
    assert ds.n_steps.tolist() == [7, 7]


class _BrokenAgent(base_agent.BaseAgent):
    """Dies on its third step of an episode, as a buggy agent would."""

    def step(self, obs: object) -> object:
        super().step(obs)
        if self.steps == 3:
            raise RuntimeError("agent exploded")
        return actions.FUNCTIONS.no_op()


def _broken_agent(seed: int) -> object:
    return _BrokenAgent()


def test_a_failing_worker_fails_the_run_and_leaves_no_partial(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with pytest.raises(Sc2DataError, match="agent exploded"):
        rollout(config(), out, workers=2, progress=False, env_factory=synthetic_env_factory(5),
                agent_factory=_broken_agent)
    assert not list(out.glob("*.partial")) and not list(out.glob("shard-*"))


def test_bad_settings_are_refused_before_anything_is_written(tmp_path: Path) -> None:
    out = tmp_path / "out"
    for bad, match in ((RolloutConfig(episodes=0), "episodes must be at least 1"),
                       (RolloutConfig(episodes_per_shard=-1), "episodes-per-shard"),
                       (RolloutConfig(env="gym"), "unknown environment"),
                       (RolloutConfig(layers="most"), "unknown layer set"),
                       (RolloutConfig(seed=-1), "seed"),
                       (RolloutConfig(max_steps=0), "max-steps")):
        with pytest.raises(Sc2DataError, match=match):
            rollout(bad, out, progress=False)
    with pytest.raises(Sc2DataError, match="workers must be at least 1"):
        rollout(RolloutConfig(), out, workers=0, progress=False)
    assert not out.exists()


KILL_SCRIPT = textwrap.dedent("""
    import sys
    from tests.synthetic_data import make_dataset
    if __name__ == "__main__":
        make_dataset(sys.argv[1], workers=2, episodes=12, steps=60)
""")


def test_kill_9_then_rerun_equals_an_uninterrupted_run(tmp_path: Path) -> None:
    """SIGKILL the rollout (its workers die with it) mid-run; the rerun finishes the job."""
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-c", KILL_SCRIPT, str(out)], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not list(out.glob("shard-*.h5")) and proc.poll() is None:
        assert time.monotonic() < deadline, "the rollout wrote no shard in time"
        time.sleep(0.05)
    assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / INDEX).exists() and (out / MANIFEST).exists()
    resumed = make_dataset(out, episodes=12, steps=60)
    assert resumed.shards_kept >= 1 and resumed.shards_written >= 1
    assert verify(out) == []
    make_dataset(tmp_path / "clean", episodes=12, steps=60)
    assert shas(out) == shas(tmp_path / "clean")
    a, b = sc2data.open_dataset(out), sc2data.open_dataset(tmp_path / "clean")
    e, t = np.repeat(np.arange(12), 3), np.tile([0, 30, 59], 12)
    for k, v in a.read(e, t).arrays.items():
        np.testing.assert_array_equal(v, b.read(e, t).arrays[k])
