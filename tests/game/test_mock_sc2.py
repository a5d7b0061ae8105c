"""The ``--env sc2`` code path end to end without the game, through pysc2's mock SC2 env.

:class:`sc2data.testing.mock_sc2.MockSC2Env` (pysc2's ``SC2TestEnv``: the real specs, constant
dummy observations, 10-step episodes) is built with ``SC2Env``'s own arguments and injected where
the library takes an environment factory: every agent plays it, a ``--env sc2`` rollout is
written on it (one process and two), then verified and labelled with the CLI as a user runs
them, and a live MEM reward scores it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sc2data.testing.mock_sc2 import EPISODE_STEPS, make_mock_env, mock_env_factory
from tests.cli import run_cli

AGENTS = ("random", "reduced-random", "scripted")


def test_without_the_game_sc2_is_refused(monkeypatch: pytest.MonkeyPatch,
                                         tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                         ) -> None:
    from sc2data.game.env import make_env, sc2_available
    from sc2data.ground.errors import Sc2DataError

    monkeypatch.setenv("SC2PATH", str(tmp_path))
    assert not sc2_available()
    with pytest.raises(Sc2DataError, match="StarCraft II"):
        make_env("sc2")
    code, _, err = run_cli(["rollout", "--env", "sc2", "--episodes", "1", "--out",
                            str(tmp_path / "out")], capsys)
    assert code != 0 and "StarCraft II" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_the_mock_is_built_as_sc2env_is() -> None:
    from sc2data.game.env import sc2_env_kwargs

    env = make_mock_env(4, 7)
    assert env.action_spec() and env.observation_spec()
    assert sc2_env_kwargs(7, 4)["random_seed"] == 7 and sc2_env_kwargs(7, 4)["step_mul"] == 4


@pytest.mark.parametrize("agent_name", AGENTS)
def test_every_agent_plays_the_real_interface(agent_name: str) -> None:
    import sc2data

    env = mock_env_factory()(0)
    agent = sc2data.make_agent(agent_name, seed=0)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    agent.reset()
    timestep, steps = env.reset()[0], 0
    while not timestep.last():
        timestep = env.step([agent.step(timestep)])[0]  # an invalid call would raise here
        steps += 1
    assert steps == EPISODE_STEPS


def test_the_mock_checks_actions_as_sc2env_does() -> None:
    from sc2data._pysc2 import actions

    env = mock_env_factory()(0)
    env.reset()
    with pytest.raises(ValueError, match="not available"):
        env.step([actions.FUNCTIONS.Train_Marine_quick("now")])


def test_rollout_verify_label_and_a_live_reward(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    import sc2data
    from sc2data.data.rollout import RolloutConfig, rollout
    from tests.mem_helpers import tiny_pairset, train_tiny

    for agent_name in AGENTS:
        out = tmp_path / agent_name
        rollout(RolloutConfig(env="sc2", agent=agent_name, episodes=2, seed=0), out,
                progress=False, env_factory=mock_env_factory())
        ds = sc2data.open_dataset(out)
        assert len(ds) == 2 * EPISODE_STEPS and ds.settings["env"] == "sc2"
        acts = ds.actions(*ds.locate(0, len(ds)))  # the game's action masks are kept
        assert acts["available"][range(len(ds)), acts["function"]].all()
        code, out_text, err = run_cli(["verify", str(out)], capsys)
        assert code == 0 and "OK" in out_text, err
        code, out_text, err = run_cli(["label", str(out)], capsys)
        assert code == 0, err
        assert f"{2 * EPISODE_STEPS} stacks labelled" in out_text
    # Worker processes build the mock too: the factory pickles; same seed, same data.
    two = tmp_path / "two"
    rollout(RolloutConfig(env="sc2", agent="scripted", episodes=2, episodes_per_shard=1, seed=0),
            two, workers=2, progress=False, env_factory=mock_env_factory())
    assert len(sc2data.open_dataset(two)) == 2 * EPISODE_STEPS
    assert run_cli(["verify", str(two)], capsys)[0] == 0

    mem = sc2data.load_model(train_tiny(tiny_pairset(tmp_path / "pairs"), tmp_path / "run",
                                        epochs=1))
    env = mock_env_factory()(0)
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
