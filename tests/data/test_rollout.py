"""The rollout loop: seeding, worker-count independence, resume, refusal, crash safety."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pysc2.agents import base_agent

import sc2data
from sc2data._pysc2 import actions
from sc2data.cli import main
from sc2data.data.audit import verify
from sc2data.data.dataset import DATASET_RECORD, INDEX
from sc2data.data.rollout import RolloutConfig, episode_seeds, rollout
from sc2data.ground.errors import Sc2DataError
from sc2data.testing.synthetic import synthetic_env_factory
from tests.synthetic_data import config, make_dataset

ROOT = Path(__file__).resolve().parents[2]


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
    with pytest.raises(Sc2DataError, match=r"other settings \(differs in: "
                                           r"episodes_per_shard\)"):
        make_dataset(out, episodes=6, per_shard=3)  # more episodes alone would grow it
    with pytest.raises(Sc2DataError, match="seed"):
        make_dataset(out, seed=1)
    assert sorted((p.name, p.stat().st_mtime_ns) for p in out.iterdir()) == before


def test_a_run_killed_before_its_dataset_record_is_resumable(tmp_path: Path) -> None:
    """A folder holding only our lock and a half-written dataset record is ours, not foreign."""
    out = tmp_path / "out"
    out.mkdir()
    (out / ".lock").write_bytes(b"")
    (out / "dataset.json.partial").write_bytes(b"{")
    make_dataset(out, episodes=1)
    assert verify(out) == [] and not list(out.glob("*.partial"))


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


KILL_RUN = ["rollout", "--env", "sim", "--agent", "reduced-random", "--episodes", "6",
            "--episodes-per-shard", "1", "--max-steps", "900", "--seed", "11", "--no-progress"]
"""The command the kill test runs: the real simulator and agent, through the CLI."""


@pytest.mark.slow
def test_kill_9_then_rerun_equals_an_uninterrupted_run(tmp_path: Path) -> None:
    """``kill -9`` a two-worker ``sc2data rollout`` mid-run (its workers die with it); running the
    same command again finishes the job, and the data equals an uninterrupted run's."""
    out = tmp_path / "killed"
    sc2data_cli = Path(sys.executable).with_name("sc2data")
    proc = subprocess.Popen([sc2data_cli, *KILL_RUN, "--workers", "2", "--out", out], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not list(out.glob("shard-*.h5")) and proc.poll() is None:
        assert time.monotonic() < deadline, "the rollout wrote no shard in time"
        time.sleep(0.02)
    assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / INDEX).exists() and (out / DATASET_RECORD).exists()
    resumed = rollout(RolloutConfig(env="sim", agent="reduced-random", episodes=6,
                                    episodes_per_shard=1, max_steps=900, seed=11), out,
                      progress=False)  # the same settings, in this process, with one worker
    assert resumed.shards_kept >= 1 and resumed.shards_written >= 1
    assert verify(out) == []
    main([*KILL_RUN, "--out", str(tmp_path / "clean")])
    assert shas(out) == shas(tmp_path / "clean")
    a, b = sc2data.open_dataset(out), sc2data.open_dataset(tmp_path / "clean")
    e, t = np.repeat(np.arange(6), 3), np.tile([0, 450, 899], 6)
    for k, v in a.read(e, t).arrays.items():
        np.testing.assert_array_equal(v, b.read(e, t).arrays[k])


@pytest.mark.slow
def test_ctrl_c_stops_cleanly_and_the_rerun_finishes(tmp_path: Path) -> None:
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) on a two-worker run:
    exit 130 with a one-line hint, no partial shard left, and the same command finishes."""
    out = tmp_path / "out"
    # Longer episodes than the kill test's: on a quiet machine short ones finish within moments
    # of the first partial appearing, and the signal would find the run already done.
    run = [a if a != "900" else "1500" for a in KILL_RUN]
    sc2data_cli = Path(sys.executable).with_name("sc2data")
    cmd = [sc2data_cli, *run, "--workers", "2", "--out", out]
    # A terminal's Ctrl-C reaches a process that handles SIGINT; where this test itself runs with
    # SIGINT ignored (a background job of a non-interactive shell), the child would inherit that.
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while not list(out.glob("shard-*.partial")) and proc.poll() is None:
        assert time.monotonic() < deadline, "the rollout started no shard in time"
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == ("sc2data: interrupted; rerun the same command to "
                                            "resume")
    assert "Traceback" not in err
    assert not list(out.glob("*.partial")) and not (out / INDEX).exists()
    main([*run, "--out", str(out)])  # the same command, with one worker
    assert verify(out) == []


def _small(out: Path) -> RolloutConfig:
    config = RolloutConfig(env="sim", agent="reduced-random", episodes=2, episodes_per_shard=1,
                           max_steps=12, seed=3)
    rollout(config, out, workers=1, progress=False)
    return config


def test_resume_refuses_a_shard_changed_since_the_index_recorded_it(tmp_path: Path) -> None:
    """A byte changed in a finished dataset's shard is not kept and re-hashed into the index."""
    from tests.data.test_storage import flip_byte_in_chunk

    out = tmp_path / "d"
    config = _small(out)
    index_before = (out / INDEX).read_bytes()
    flip_byte_in_chunk(out / "shard-00001.h5", "screen/unit_type", chunk=0)
    with pytest.raises(Sc2DataError, match=r"shard-00001.h5 does not match the sha256 "
                                           r"index.parquet recorded .*; delete it and rerun"):
        rollout(config, out, workers=1, progress=False)
    assert (out / INDEX).read_bytes() == index_before


def test_resume_refuses_a_shard_copied_over_another(tmp_path: Path) -> None:
    out = tmp_path / "d"
    config = _small(out)
    (out / "shard-00000.h5").replace(out / "shard-00001.h5")
    (out / INDEX).unlink()  # as if interrupted before the index was written
    with pytest.raises(Sc2DataError, match=r"holds episodes 0–1, not 1–2 \(a shard copied"):
        rollout(config, out, workers=1, progress=False)


def test_resume_checks_unindexed_shards_through_their_checksums(tmp_path: Path) -> None:
    """Shards of an interrupted run (no index yet) are read whole before they are kept."""
    from tests.data.test_storage import flip_byte_in_chunk

    out = tmp_path / "d"
    config = _small(out)
    (out / INDEX).unlink()
    flip_byte_in_chunk(out / "shard-00000.h5", "screen/unit_type", chunk=0)
    with pytest.raises(Sc2DataError, match=r"shard-00000.h5 is damaged \(.*unreadable chunk"):
        rollout(config, out, workers=1, progress=False)
    (out / "shard-00000.h5").unlink()  # the remedy the message gives
    rollout(config, out, workers=1, progress=False)
    assert verify(out) == []


def test_the_simulator_s_action_masks_are_kept_per_frame_and_reproducible(tmp_path: Path) -> None:
    """Each frame's ``available_actions`` is stored (shard format 4): the call taken at step t
    is always among frame t's, the masks change as the game does, and the same settings and
    seed give the same bytes whatever the worker count."""
    import h5py

    from sc2data.data.shards import MASK_BYTES, MASKS

    settings = dict(env="sim", agent="reduced-random", episodes=2, seed=3, episodes_per_shard=1,
                    max_steps=120)
    one = rollout(RolloutConfig(**settings), tmp_path / "one", workers=1, progress=False)
    rollout(RolloutConfig(**settings), tmp_path / "two", workers=2, progress=False)
    assert shas(tmp_path / "one") == shas(tmp_path / "two") and one.steps == 240
    with h5py.File(tmp_path / "one" / "shard-00000.h5", "r") as f:
        assert f[MASKS].shape == (121, MASK_BYTES) and f.attrs["format_version"] == 4
    ds = sc2data.open_dataset(tmp_path / "one")
    episodes, steps = ds.locate(0, len(ds))
    acts = ds.actions(episodes, steps)
    assert acts["available"].shape == (240, len(actions.FUNCTIONS))
    assert acts["available"][np.arange(240), acts["function"]].all()
    assert np.array_equal(acts["available"][1:120], acts["next_available"][:119])
    assert len({m.tobytes() for m in acts["available"]}) > 1
    assert acts["available"][:, 0].all()  # no_op, always available
    assert verify(tmp_path / "one") == []
