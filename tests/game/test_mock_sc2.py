"""The ``--env sc2`` code path end to end without the game, through pysc2's mock SC2 env.

``SC2DATA_MOCK_SC2=1`` makes ``make_env("sc2")`` build :class:`sc2data.game.mock_sc2.MockSC2Env`
(pysc2's ``SC2TestEnv``: the real specs, constant dummy observations, 10-step episodes) and
``sc2_available`` say yes. Every agent plays it, and rollout, verify, label and a live MEM
reward run on it as a user runs them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sc2data.game.env import MOCK_ENV_VAR
from sc2data.game.mock_sc2 import EPISODE_STEPS
from tests.cli import run_cli

AGENTS = ("random", "reduced-random", "scripted")


@pytest.fixture
def mock_sc2(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(MOCK_ENV_VAR, "1")


def test_without_the_variable_sc2_is_refused(monkeypatch: pytest.MonkeyPatch,
                                             tmp_path: Path) -> None:
    from sc2data.game.env import make_env, sc2_available
    from sc2data.ground.errors import Sc2DataError

    monkeypatch.delenv(MOCK_ENV_VAR, raising=False)
    monkeypatch.setenv("SC2PATH", str(tmp_path))
    assert not sc2_available()
    with pytest.raises(Sc2DataError, match="StarCraft II"):
        make_env("sc2")


@pytest.mark.parametrize("agent_name", AGENTS)
def test_every_agent_plays_the_real_interface(mock_sc2: None, agent_name: str) -> None:
    import sc2data
    from sc2data.game.mock_sc2 import MockSC2Env

    env = sc2data.make_env("sc2", seed=0)
    assert isinstance(env, MockSC2Env)
    agent = sc2data.make_agent(agent_name, seed=0)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    agent.reset()
    timestep, steps = env.reset()[0], 0
    while not timestep.last():
        timestep = env.step([agent.step(timestep)])[0]  # an invalid call would raise here
        steps += 1
    assert steps == EPISODE_STEPS


def test_the_mock_checks_actions_as_sc2env_does(mock_sc2: None) -> None:
    import sc2data
    from sc2data._pysc2 import actions

    env = sc2data.make_env("sc2", seed=0)
    env.reset()
    with pytest.raises(ValueError, match="not available"):
        env.step([actions.FUNCTIONS.Train_Marine_quick("now")])


def test_rollout_verify_label_and_a_live_reward(mock_sc2: None, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    import sc2data
    from tests.mem_helpers import tiny_pairset, train_tiny

    for agent_name in AGENTS:
        out = tmp_path / agent_name
        code, _, err = run_cli(["rollout", "--env", "sc2", "--agent", agent_name, "--episodes",
                                "2", "--workers", "1", "--seed", "0", "--out", str(out)], capsys)
        assert code == 0, err
        ds = sc2data.open_dataset(out)
        assert len(ds) == 2 * EPISODE_STEPS and ds.settings["env"] == "sc2"
        acts = ds.actions(*ds.locate(0, len(ds)))  # the game's action masks are kept
        assert acts["available"][range(len(ds)), acts["function"]].all()
        code, out_text, err = run_cli(["verify", str(out)], capsys)
        assert code == 0 and "OK" in out_text, err
        code, out_text, err = run_cli(["label", str(out)], capsys)
        assert code == 0, err
        assert f"{2 * EPISODE_STEPS} stacks labelled" in out_text
    # Worker processes inherit the variable.
    code, _, err = run_cli(["rollout", "--env", "sc2", "--agent", "scripted", "--episodes", "2",
                            "--episodes-per-shard", "1", "--workers", "2", "--seed", "0",
                            "--out", str(tmp_path / "two")], capsys)
    assert code == 0, err

    mem = sc2data.load_model(train_tiny(tiny_pairset(tmp_path / "pairs"), tmp_path / "run",
                                        epochs=1))
    env = sc2data.make_env("sc2", seed=0)
    agent = sc2data.make_agent("reduced-random", seed=0)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    agent.reset()
    stacker = sc2data.Stacker(mem.schema)
    timestep = env.reset()[0]
    distances = [mem.distance(stacker.push(timestep), "train a marine")]
    while not timestep.last():
        timestep = env.step([agent.step(timestep)])[0]
        distances.append(mem.distance(stacker.push(timestep), "train a marine"))
    d = np.concatenate(distances)
    assert d.shape == (EPISODE_STEPS + 1,) and np.isfinite(d).all()
