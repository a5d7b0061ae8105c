"""``sc2data rollout | info | verify`` as a user runs them: exit codes, one-line errors, no
debris left behind."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import pytest

from sc2data.data.dataset import INDEX
from sc2data.schema import Schema
from tests.cli import assert_one_line_error, run_cli
from tests.data.test_storage import flip_byte_in_chunk
from tests.synthetic_data import make_dataset


def cli(args: list[object], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """Run ``sc2data ARGS``; (exit code, stdout, stderr)."""
    return run_cli([str(a) for a in args], capsys)




@pytest.fixture(scope="module")
def good(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "data"
    make_dataset(out, episodes=3)
    return out


@pytest.fixture()
def copy(good: Path, tmp_path: Path) -> Path:
    """A private copy of the good dataset, to damage."""
    return Path(shutil.copytree(good, tmp_path / "data"))


@pytest.mark.parametrize("args, match", [
    (["--agent", "clever"], "unknown agent 'clever'"),
    (["--env", "gym"], "unknown environment 'gym'"),
    (["--episodes", "0"], "episodes must be at least 1, not 0"),
    (["--episodes", "-3"], "episodes must be at least 1, not -3"),
    (["--workers", "0"], "workers must be at least 1"),
    (["--episodes-per-shard", "0"], "episodes-per-shard must be at least 1"),
    (["--layers", "some"], "unknown layer set 'some'"),
    (["--max-steps", "-1"], "max-steps must be at least 1"),
    (["--episodes", "many"], "Invalid value for '--episodes'"),
])
def test_bad_options_fail_in_one_line_and_write_nothing(
        args: list[str], match: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    code, _, err = cli(["rollout", "--out", out, *args], capsys)
    assert_one_line_error(code, err, match)
    assert not out.exists()


def test_unwritable_output_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, _, err = cli(["rollout", "--out", blocker / "out"], capsys)
    assert_one_line_error(code, err, "cannot write to output folder")
    code, _, err = cli(["rollout", "--out", blocker], capsys)
    assert_one_line_error(code, err, "exists and is not a folder")
    assert blocker.read_text() == "x"


def test_foreign_output_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    code, _, err = cli(["rollout", "--out", tmp_path], capsys)
    assert_one_line_error(code, err, "is not empty and is not an sc2data dataset")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_recipe_settings_cannot_be_overridden(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    recipe = Path(__file__).resolve().parents[2] / "manifests" / "smoke.toml"
    code, _, err = cli(["rollout", "--out", tmp_path / "o", "--recipe", recipe,
                        "--episodes", "3"], capsys)
    assert_one_line_error(code, err, "--episodes conflicts with --recipe")
    code, _, err = cli(["rollout", "--out", tmp_path / "o", "--recipe", tmp_path / "no.toml"],
                       capsys)
    assert_one_line_error(code, err, "cannot read recipe")
    assert not (tmp_path / "o").exists()


def test_info_reports_the_dataset(good: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = cli(["info", good], capsys)
    assert code == 0
    assert "episodes  3   stacks 90   frames 93   shards 2" in out
    assert "B/frame" in out and "screen/unit_type" in out and "uint16" in out
    assert "shard-00001.h5" in out
    for layer in Schema.paper().layers:
        assert layer.key in out


def test_verify_passes_a_good_dataset(good: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = cli(["verify", good], capsys)
    assert (code, err) == (0, "") and ": OK (dataset" in out


def test_verify_catches_a_flipped_byte(copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    flip_byte_in_chunk(copy / "shard-00001.h5", "screen/player_relative")
    code, _, err = cli(["verify", copy], capsys)
    assert code == 1
    assert "shard-00001.h5:frames/screen_uint8: unreadable chunk" in err
    assert "shard-00001.h5: sha256" in err
    assert "shard-00000" not in err


def test_older_schema_version(copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A shard written under another schema version: verify, info and a resume all refuse it."""
    with h5py.File(copy / "shard-00000.h5", "r+") as f:
        f.attrs["schema"] = json.dumps({**Schema.paper().to_dict(), "version": 0})
    code, _, err = cli(["verify", copy], capsys)
    assert code == 1 and "schema version 0 is not the supported version" in err
    code, _, err = cli(["info", copy], capsys)
    assert_one_line_error(code, err, "schema version 0")
    code, _, err = cli(["rollout", "--out", copy, "--env", "sim", "--agent", "random",
                        "--episodes", "3", "--seed", "7", "--episodes-per-shard", "2"], capsys)
    assert_one_line_error(code, err, "shard-00000.h5: schema version 0")


def test_folder_of_an_older_format(copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A folder written before frames were stored in blocks (dataset and shard format 1):
    every command refuses it in one line, naming the format (verify: as its fault), and a rerun
    changes nothing."""
    record = json.loads((copy / "dataset.json").read_text())
    (copy / "dataset.json").write_text(json.dumps({**record, "format_version": 1}))
    before = {p.name: p.read_bytes() for p in copy.iterdir()}
    for args in (["info", copy],
                 ["rollout", "--out", copy, "--env", "sim", "--agent", "random", "--episodes",
                  "3", "--seed", "7", "--episodes-per-shard", "2"]):
        code, _, err = cli(args, capsys)
        assert_one_line_error(code, err, "has dataset format 1, not 4; regenerate it")
    code, _, err = cli(["verify", copy], capsys)
    assert code == 1 and err.startswith("FAULT ") and "has dataset format 1, not 4" in err
    assert {p.name: p.read_bytes() for p in copy.iterdir()} == before
    (copy / "dataset.json").write_text(json.dumps(record))
    with h5py.File(copy / "shard-00001.h5", "r+") as f:
        f.attrs["format_version"] = 1
    code, _, err = cli(["info", copy], capsys)
    assert_one_line_error(code, err, "shard-00001.h5 has shard format 1, not 4; regenerate it")
    code, _, err = cli(["verify", copy], capsys)
    assert code == 1 and "shard-00001.h5 has shard format 1, not 4" in err


def test_truncated_and_non_hdf5_shards(copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = (copy / "shard-00000.h5").read_bytes()
    (copy / "shard-00000.h5").write_bytes(data[:len(data) // 3])
    (copy / "shard-00001.h5").write_text("not a shard\n")
    code, _, err = cli(["verify", copy], capsys)
    assert code == 1
    assert "shard-00000.h5 is not a readable HDF5 file" in err
    assert "shard-00001.h5 is not a readable HDF5 file" in err
    assert "2 fault(s)" in err.splitlines()[-1] or "fault(s)" in err


def test_verify_index_faults(copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (copy / "shard-00001.h5").unlink()
    (copy / "shard-00009.h5.partial").write_bytes(b"")
    code, _, err = cli(["verify", copy], capsys)
    assert code == 1
    assert "shard-00001.h5: listed in index.parquet but missing" in err
    assert "shard-00009.h5.partial: a partial file" in err
    (copy / INDEX).unlink()
    code, _, err = cli(["verify", copy], capsys)
    assert code == 1 and err.startswith("FAULT ") and "unfinished rollout" in err


def test_verify_and_info_on_non_datasets(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    for command in ("verify", "info"):
        code, _, err = cli([command, tmp_path], capsys)
        assert_one_line_error(code, err, "not a dataset (sc2data rollout), pair set")
        code, _, err = cli([command, tmp_path / "absent"], capsys)
        assert_one_line_error(code, err, "is not a folder sc2data writes")


def test_rollout_stores_exactly_what_the_simulator_played(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The default path (embedded sim, reduced-random agent) end to end: the stored stacks,
    actions and rewards equal a direct replay of the same seeds."""
    import numpy as np

    from sc2data.data.rollout import episode_seeds
    from sc2data.data.shards import function_call
    from sc2data.game.agents import make_agent
    from sc2data.game.env import make_env

    out = tmp_path / "sim"
    code, stdout, err = cli(["rollout", "--out", out, "--episodes", "2", "--max-steps", "120",
                             "--seed", "5", "--no-progress"], capsys)
    assert code == 0, err
    assert "2 episodes, 240 stacks" in stdout
    assert cli(["verify", out], capsys)[0] == 0
    import sc2data

    ds = sc2data.open_dataset(out)
    assert ds.settings["agent"] == "reduced-random" and ds.settings["env"] == "sim"
    schema = Schema.paper()
    for episode in (0, 1):
        env_seed, agent_seed = episode_seeds(5, episode)
        np.random.seed(agent_seed)
        env, agent = make_env("sim", seed=env_seed), make_agent("reduced-random", seed=agent_seed)
        agent.setup(env.observation_spec()[0], env.action_spec()[0])
        agent.reset()
        ts = env.reset()[0]
        frames, calls, rewards = [schema.extract(ts.observation)], [], []
        for _ in range(120):
            call = agent.step(ts)
            ts = env.step([call])[0]
            frames.append(schema.extract(ts.observation))
            calls.append(call)
            rewards.append(ts.reward)
        stored = ds.read([episode] * 120, range(120))
        for k in schema.keys():
            np.testing.assert_array_equal(stored.arrays[k][:, 0], [f[k] for f in frames[:-1]])
            np.testing.assert_array_equal(stored.arrays[k][:, 1], [f[k] for f in frames[1:]])
        acts = ds.actions([episode] * 120, range(120))
        assert [function_call(f, a) for f, a in zip(acts["function"], acts["args"])] == calls
        assert acts["reward"].tolist() == rewards
        env.close()


def test_verify_checks_the_action_masks(copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A format 4 shard's masks: a bit past pysc2's function table, or none at all, is a fault."""
    with h5py.File(copy / "shard-00000.h5", "r+") as f:
        masks = f["available_actions"]
        row = masks[0]
        row[-1] |= 0x80  # function 575: pysc2 has 573
        masks[0] = row
    with h5py.File(copy / "shard-00001.h5", "r+") as f:
        del f["available_actions"]
    code, _, err = cli(["verify", copy], capsys)
    assert code == 1
    assert "shard-00000.h5:available_actions: bits set beyond pysc2's function table" in err
    assert "shard-00001.h5:available_actions: missing" in err
