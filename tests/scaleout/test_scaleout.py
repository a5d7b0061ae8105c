"""Rollout and label as Ray tasks (``sc2data.scaleout.driver``) on a local 2-CPU Ray instance:
the same data as a local run, workers killed mid-episode, hung and crashed instances, the retry
budget, resume, a full disk, the CLI joining a running cluster, and ``--ray`` without Ray
installed."""

from __future__ import annotations

import functools
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

import sc2data
from sc2data.data.audit import verify
from sc2data.data.dataset import INDEX
from sc2data.data.rollout import RolloutConfig, _make_agent, episode_seeds, rollout
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.files import sha256_file
from sc2data.labels.label import label_dataset
from sc2data.labels.store import LABELS_FILE, STACKS_FILE, SUMS_FILE
from sc2data.scaleout.driver import RayOptions, label_on_ray, rollout_on_ray
from tests.cli import assert_one_line_error, run_cli
from tests.conftest import leave_free

CONFIG = RolloutConfig(env="sim", agent="reduced-random", episodes=4, episodes_per_shard=1,
                       max_steps=40, seed=5)
"""The real simulator and agent; short episodes, one per shard."""
AGENT = functools.partial(_make_agent, CONFIG.agent)


@pytest.fixture(scope="module")
def ray_instance() -> Any:
    """One local Ray instance with 2 CPUs for the module; this module's fault-injecting agents
    travel to the workers by value (the workers cannot import ``tests``)."""
    ray = pytest.importorskip("ray")
    ray.init(address="local", num_cpus=2, include_dashboard=False, object_store_memory=100 << 20,
             log_to_driver=False, logging_level="WARNING")
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield ray
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    ray.shutdown()


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same settings rolled out locally, in this process."""
    out = tmp_path_factory.mktemp("local") / "data"
    rollout(CONFIG, out, progress=False)
    return out


def assert_same_data(folder: Path, reference: Path) -> None:
    """Byte-identical shards, and so frame for frame the same stacks, as the local run."""
    a, b = sc2data.open_dataset(folder), sc2data.open_dataset(reference)
    assert a.index.column("shard_sha256").to_pylist() == \
        b.index.column("shard_sha256").to_pylist()
    episodes = np.repeat(np.arange(CONFIG.episodes), CONFIG.max_steps)
    steps = np.tile(np.arange(CONFIG.max_steps), CONFIG.episodes)
    got, want = a.read(episodes, steps), b.read(episodes, steps)
    for key, value in want.arrays.items():
        np.testing.assert_array_equal(got.arrays[key], value, err_msg=key)
    assert not list(folder.glob("*.partial"))


@dataclass(frozen=True)
class Faulty:
    """An agent factory: the real agent, except in one episode where, at one step, it kills its
    worker process, hangs, loses its game (pysc2's ConnectionError) or raises a bug — as long as
    ``marker`` holds fewer than ``times`` lines (one is appended each time)."""

    episode: int
    fault: str
    marker: str
    times: int = 1
    at_step: int = 20

    def __call__(self, seed: int) -> Any:
        agent = AGENT(seed)
        if seed != episode_seeds(CONFIG.seed, self.episode)[1]:
            return agent
        return _FaultyAgent(agent, self)

    def fire(self) -> None:
        path = Path(self.marker)
        if path.exists() and len(path.read_text().splitlines()) >= self.times:
            return
        with path.open("a") as f:
            f.write(f"{os.getpid()}\n")
        if self.fault == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        elif self.fault == "hang":
            time.sleep(3600)
        elif self.fault == "crash":
            from pysc2.lib import protocol

            raise protocol.ConnectionError("Connection already closed. SC2 probably crashed.")
        raise RuntimeError("agent exploded")

    def fired(self) -> int:
        path = Path(self.marker)
        return len(path.read_text().splitlines()) if path.exists() else 0


class _FaultyAgent:
    def __init__(self, agent: Any, fault: Faulty) -> None:
        self.agent, self.fault, self.steps = agent, fault, 0

    def setup(self, *specs: Any) -> None:
        self.agent.setup(*specs)

    def reset(self) -> None:
        self.steps = 0
        self.agent.reset()

    def step(self, timestep: Any) -> Any:
        self.steps += 1
        if self.steps == self.fault.at_step:
            self.fault.fire()
        return self.agent.step(timestep)


@pytest.mark.slow
def test_a_worker_killed_mid_episode_is_retried_and_the_data_equals_a_local_run(
        ray_instance: Any, reference: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    fault = Faulty(episode=2, fault="kill", marker=str(tmp_path / "killed"))
    out = tmp_path / "data"
    summary, report = rollout_on_ray(CONFIG, out, RayOptions(timeout_s=60), progress=False,
                                     agent_factory=fault)
    assert fault.fired() == 1
    assert (summary.episodes, summary.steps, summary.shards_written) == (4, 160, 4)
    assert list(report.retried) == ["shard-00002.h5"]
    first, second = report.retried["shard-00002.h5"]
    assert "worker process died" in first and second.endswith(": done")
    assert report.lines()[0].startswith("ray: 4 tasks, 1 retried; peak RSS per task ")
    assert run_cli(["verify", out], capsys)[0] == 0
    assert_same_data(out, reference)


def test_a_dataset_grown_on_ray_equals_a_local_run(ray_instance: Any, tmp_path: Path) -> None:
    """2 → 4 episodes as Ray tasks, its partial shard rolled out again: a local 4-episode run's
    bytes, every file."""
    from dataclasses import replace

    from tests.data.test_grow import sums

    config = replace(CONFIG, episodes_per_shard=3)
    out = tmp_path / "ray"
    rollout_on_ray(replace(config, episodes=2), out, RayOptions(), progress=False)
    summary, _ = rollout_on_ray(config, out, RayOptions(), progress=False)
    assert (summary.grew_from, summary.shards_written, summary.shards_kept) == (2, 2, 0)
    rollout(config, tmp_path / "local", progress=False)
    assert sums(out) == sums(tmp_path / "local")


@pytest.mark.slow
def test_a_hung_task_is_cancelled_and_run_again(ray_instance: Any, reference: Path,
                                                tmp_path: Path) -> None:
    fault = Faulty(episode=1, fault="hang", marker=str(tmp_path / "hung"))
    out = tmp_path / "data"
    _, report = rollout_on_ray(CONFIG, out, RayOptions(timeout_s=10), progress=False,
                               agent_factory=fault)
    assert fault.fired() == 1
    tries = report.retried["shard-00001.h5"]
    assert "hung: no progress for 10 s, cancelled" in tries[0] and tries[-1].endswith(": done")
    # On a loaded machine a healthy attempt can also go 10 s without progress: it is cancelled
    # and run again like the hung one, and every retried task still ends done.
    for key, attempts in report.retried.items():
        assert all("no progress for 10 s, cancelled" in a for a in attempts[:-1]), (key, attempts)
        assert attempts[-1].endswith(": done"), (key, attempts)
    assert_same_data(out, reference)


@pytest.mark.slow
def test_a_crashed_game_is_retried_but_a_bug_fails_at_once(ray_instance: Any, reference: Path,
                                                           tmp_path: Path) -> None:
    crash = Faulty(episode=3, fault="crash", marker=str(tmp_path / "crashed"))
    _, report = rollout_on_ray(CONFIG, tmp_path / "crash", RayOptions(), progress=False,
                               agent_factory=crash)
    assert crash.fired() == 1
    first, _ = report.retried["shard-00003.h5"]
    assert "failed: ConnectionError: Connection already closed" in first
    assert_same_data(tmp_path / "crash", reference)

    bug = Faulty(episode=1, fault="bug", marker=str(tmp_path / "bug"), times=99)
    out = tmp_path / "bug-data"
    with pytest.raises(Sc2DataError, match=r"^rollout of shard-00001\.h5 failed: RuntimeError: "
                                           r"agent exploded$"):
        rollout_on_ray(CONFIG, out, RayOptions(), progress=False, agent_factory=bug)
    assert bug.fired() == 1  # not retried: a bug is not a fault of the machine
    assert not list(out.glob("*.partial")) and not (out / INDEX).exists()


@pytest.mark.slow
def test_past_the_retry_budget_the_run_fails_in_one_line_and_a_rerun_resumes(
        ray_instance: Any, reference: Path, tmp_path: Path) -> None:
    fault = Faulty(episode=1, fault="kill", marker=str(tmp_path / "killed"), times=99)
    out = tmp_path / "data"
    with pytest.raises(Sc2DataError) as caught:
        rollout_on_ray(CONFIG, out, RayOptions(retries=1, timeout_s=60), progress=False,
                       agent_factory=fault)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith("rollout of shard-00001.h5 failed after 2 attempt(s) (retries: 1)"
                              ": its worker process died")
    assert message.endswith("rerun the same command to resume")
    assert fault.fired() == 2
    assert not list(out.glob("*.partial")) and not (out / INDEX).exists()
    assert not (out / "shard-00001.h5").exists()
    # What a driver killed mid-run would leave: an attempt folder and a partial shard.
    (out / "shard-00001.h5.0123456789ab.partial").mkdir()
    (out / "shard-00001.h5.0123456789ab.partial" / "shard-00001.h5.partial").write_bytes(b"x")
    (out / "shard-00003.h5.partial").write_bytes(b"x")
    kept = len(list(out.glob("shard-*.h5")))
    resumed, report = rollout_on_ray(CONFIG, out, RayOptions(), progress=False)
    assert (resumed.shards_kept, resumed.shards_written) == (kept, 4 - kept)
    assert not report.retried
    assert_same_data(out, reference)


@pytest.mark.slow
def test_label_on_ray_equals_a_local_label(ray_instance: Any, reference: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    local, remote, cli_run = (Path(shutil.copytree(reference, tmp_path / n))
                              for n in ("local", "remote", "cli"))
    label_dataset(local, progress=False)
    summary, report = label_on_ray(remote, RayOptions(), progress=False)
    assert summary.stacks == 160 and report.tasks == 4 and not report.retried
    code, out, err = run_cli(["label", "--ray", cli_run, "--no-progress"], capsys)  # bare
    assert code == 0, err
    assert "ray: 4 tasks, none retried" in out
    want = pq.read_table(local / STACKS_FILE).replace_schema_metadata(None)
    for folder in (remote, cli_run):
        assert pq.read_table(folder / STACKS_FILE).replace_schema_metadata(None).equals(want)
        assert not (folder / ".labels-parts").exists()


@pytest.mark.slow
def test_the_cli_joins_a_running_cluster(ray_instance: Any, reference: Path,
                                         tmp_path: Path) -> None:
    """``sc2data rollout --ray HOST:PORT`` in a fresh process, as on a cluster's head node."""
    address = ray_instance.get_runtime_context().gcs_address
    out = tmp_path / "data"
    args = ["rollout", "--env", "sim", "--agent", CONFIG.agent, "--episodes", "4",
            "--episodes-per-shard", "1", "--max-steps", "40", "--seed", "5", "--no-progress",
            "--out", out, "--ray", address]
    done = subprocess.run([Path(sys.executable).with_name("sc2data"), *map(str, args)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert "4 episodes, 160 stacks" in done.stdout
    assert "ray: 4 tasks, none retried" in done.stdout
    assert_same_data(out, reference)


@pytest.mark.slow
def test_a_node_without_the_game_fails_the_run_at_once(ray_instance: Any, tmp_path: Path) -> None:
    """Joining a cluster, the driver's machine needs no SC2, but a node that lacks it stops the
    run at once with a line naming the node (no retry can fix that)."""
    from sc2data.game.env import sc2_available

    if sc2_available():
        pytest.skip("StarCraft II is installed here")
    out = tmp_path / "data"
    with pytest.raises(Sc2DataError, match=r"^rollout of shard-00000\.h5 failed: node \S+ has "
                                           r"no StarCraft II under .*; install it and set SC2PATH "
                                           r"on every node$"):
        rollout_on_ray(RolloutConfig(env="sc2", episodes=1), out, RayOptions(address="auto"),
                       progress=False)
    assert not list(out.glob("*.partial")) and not (out / INDEX).exists()


def test_without_ray_the_option_says_how_to_install_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now fails, as when absent
    for args in (["rollout", "--out", tmp_path / "out", "--ray"],
                 ["label", tmp_path / "out", "--ray", "auto"]):
        code, _, err = run_cli(args, capsys)
        assert_one_line_error(code, err, "sc2data: error: --ray needs the optional package "
                              "'ray'; install it with pip install 'sc2data[ray]'")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args, match", [
    (["--ray=somewhere"], "--ray takes local, auto, HOST:PORT or ray://HOST:PORT, not 'some"),
    (["--ray", "--ray-retries", "-1"], "ray-retries must be 0 or more, not -1"),
    (["--ray", "auto", "--ray-timeout", "0"], "ray-timeout must be positive"),
    (["--ray", "--workers", "0"], "workers must be at least 1"),
])
def test_bad_ray_options_fail_in_one_line(args: list[str], match: str, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("ray")
    code, _, err = run_cli(["rollout", "--out", tmp_path / "out", *args], capsys)
    assert_one_line_error(code, err, f"sc2data: error: {match}")
    assert not (tmp_path / "out").exists()


TINY_RECIPE = """
name = "tiny"
seed = 3

[rollout]
env = "sim"
agent = "reduced-random"
episodes = 3

[commands.build_scv]
text = "build an SCV"

[commands.collect_minerals]
text = "collect minerals"

[pairs]
states_per_command = 2
null_states = 6
"""


@pytest.mark.slow
def test_build_on_ray_equals_a_local_build(ray_instance: Any, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """``sc2data build --ray``: rollout and label as Ray tasks, the same data and pairs as a
    local build (episodes cut to 400 steps to keep the test short)."""
    recipe = tmp_path / "tiny.toml"
    recipe.write_text(TINY_RECIPE)
    from_recipe = RolloutConfig.from_recipe.__func__  # type: ignore[attr-defined]
    monkeypatch.setattr(RolloutConfig, "from_recipe", classmethod(
        lambda cls, r, **kw: from_recipe(cls, r, **kw, max_steps=400)))
    outs = {}
    for name, extra in (("local", []), ("ray", ["--ray"])):
        outs[name] = tmp_path / name
        code, out, err = run_cli(["build", recipe, "--out", outs[name], "--no-progress", *extra],
                                 capsys)
        assert code == 0, err
        assert "rollout: 3 episodes, 1,200 stacks (1 shard written, 0 kept)" in out
    assert out.count("ray: 1 tasks, none retried") == 2  # the rollout's shard, the label's unit
    local, remote = (pq.read_table(o / "pairs" / "pairs.parquet") for o in outs.values())
    assert remote.equals(local) and remote.num_rows == 2 * 2 * 2 + 6
    for name in (INDEX, STACKS_FILE):
        a, b = (pq.read_table(o / "rollout" / name).replace_schema_metadata(None)
                for o in outs.values())
        assert a.equals(b), name


@pytest.mark.parametrize("args, match", [
    (["--ray=somewhere"], "--ray takes local, auto, HOST:PORT or ray://HOST:PORT, not 'some"),
    (["--ray", "--ray-memory", "0"], "ray-memory must be at least 1 MB, not 0"),
    (["--ray", "--workers", "0"], "workers must be at least 1"),
    (["--workers", "0"], "workers must be at least 1"),
])
def test_bad_build_options_fail_in_one_line(args: list[str], match: str, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("ray")
    recipe = tmp_path / "tiny.toml"
    recipe.write_text(TINY_RECIPE)
    code, _, err = run_cli(["build", recipe, "--out", tmp_path / "out", *args], capsys)
    assert_one_line_error(code, err, f"sc2data: error: {match}")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_a_full_disk_fails_the_run_in_one_line_and_a_rerun_resumes(
        ray_instance: Any, reference: Path, fs: Path) -> None:
    """Ray tasks writing to a filesystem that fills part-way: one line naming the full disk,
    nothing that looks complete, and with space again the rerun gives the local run's bytes."""
    out = fs / "data"
    ballast = leave_free(fs, sum(p.stat().st_size for p in reference.glob("shard-*.h5")) // 2)
    with pytest.raises(Sc2DataError) as caught:
        rollout_on_ray(CONFIG, out, RayOptions(retries=1, timeout_s=60), progress=False)
    message = str(caught.value)
    assert "\n" not in message and "No space left on device" in message, message
    assert not (out / INDEX).exists() and not list(out.glob("*.partial"))
    for shard in out.glob("shard-*.h5"):
        assert sha256_file(shard) == sha256_file(reference / shard.name)
    ballast.unlink()
    rollout_on_ray(CONFIG, out, RayOptions(), progress=False)
    assert_same_data(out, reference)


@pytest.mark.slow
def test_a_full_disk_fails_a_label_in_one_line_and_a_rerun_resumes(
        ray_instance: Any, reference: Path, fs: Path, tmp_path: Path) -> None:
    """Label tasks writing their parts to a filesystem that fills part-way: one line, no label
    checksums, and with space again the rerun gives the local labels."""
    local = Path(shutil.copytree(reference, tmp_path / "local"))
    label_dataset(local, progress=False)
    data = Path(shutil.copytree(reference, fs / "data"))
    need = sum(p.stat().st_size for p in local.rglob("*") if p.is_file()) - \
        sum(p.stat().st_size for p in data.rglob("*") if p.is_file())
    ballast = leave_free(fs, need // 2)
    with pytest.raises(Sc2DataError) as caught:
        label_on_ray(data, RayOptions(retries=1, timeout_s=60), progress=False)
    message = str(caught.value)
    assert "\n" not in message and "No space left on device" in message, message
    assert not (data / SUMS_FILE).exists()
    ballast.unlink()
    label_on_ray(data, RayOptions(), progress=False)
    assert verify(data) == []
    for name in (LABELS_FILE, STACKS_FILE):
        a, b = (pq.read_table(d / name).replace_schema_metadata(None) for d in (local, data))
        assert a.equals(b), name
