"""``--agent policy:RUN``: a trained ``sc2data rl`` policy as a seeded rollout agent."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sc2data.ground.files import sha256_file
from tests.cli import assert_one_line_error, run_cli

TINY = ["--steps", "64", "--envs", "1", "--rollout", "32", "--batch-size", "32",
        "--episode-steps", "40", "--checkpoint-every", "64", "--no-progress"]


@pytest.fixture(scope="module", params=["macro", "paper"])
def run(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny trained run of each action space."""
    from tests.cli import exit_code

    out = tmp_path_factory.mktemp("rl") / request.param
    assert exit_code("rl", "train", "--out", out, "--action-space", request.param, *TINY) == 0
    return out


def calls(run: Path, seed: int, steps: int = 120) -> list[str]:
    """The calls of ``policy:RUN`` with ``seed`` over ``steps`` steps of simulator game 0."""
    import sc2data.rl  # noqa: F401  registers the policy agent kind
    from sc2data.game.agents import make_agent
    from sc2data.game.env import make_env

    env = make_env("sim", seed=0)
    agent = make_agent(f"policy:{run}", seed=seed)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    agent.reset()
    try:
        out, ts = [], env.reset()[0]
        for _ in range(steps):
            call = agent.step(ts)
            out.append(str(call))
            ts = env.step([call])[0]
        return out
    finally:
        env.close()


def test_a_policy_agent_is_deterministic_per_seed(run: Path) -> None:
    a = calls(run, seed=3)
    assert a == calls(run, seed=3)
    assert a != calls(run, seed=4)  # sampled: another seed, another episode
    assert len(set(a)) > 3


def test_policy_rollout_records_its_run_verifies_and_repeats(
        run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    if run.name != "macro":
        pytest.skip("the dataset's provenance does not depend on the action space")
    args = ["rollout", "--agent", f"policy:{run}", "--episodes", "3", "--episodes-per-shard",
            "2", "--max-steps", "60", "--seed", "5", "--no-progress"]
    code, out, err = run_cli([*args, "--out", tmp_path / "a", "--workers", "2"], capsys)
    assert code == 0, err
    settings = json.loads((tmp_path / "a" / "dataset.json").read_text())["settings"]
    assert settings["agent"] == f"policy:{run}"
    assert settings["agent_sha256"] == sha256_file(run / "model.zip")
    code, out, err = run_cli(["verify", tmp_path / "a"], capsys)
    assert code == 0, err
    # Another folder, one worker: the same bytes (the workers do not change the data).
    code, out, err = run_cli([*args, "--out", tmp_path / "b", "--workers", "1"], capsys)
    assert code == 0, err
    for shard in sorted((tmp_path / "a").glob("shard-*.h5")):
        assert sha256_file(shard) == sha256_file(tmp_path / "b" / shard.name)
    # The run trains on: its checkpoint is not the one that made the data, so it cannot grow it.
    code, _, err = run_cli(["rl", "train", "--out", run, "--action-space", run.name,
                            "--steps", "128", *TINY[2:]], capsys)
    assert code == 0, err
    code, _, err = run_cli(["rollout", "--out", tmp_path / "a", "--episodes", "4"], capsys)
    assert_one_line_error(code, err, "is not the one that made this data")
    assert not (tmp_path / "a" / "shard-00002.h5").exists()


def test_a_bad_policy_is_one_line_before_anything_is_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["rollout", "--agent", f"policy:{tmp_path / 'nope'}", "--out",
                            tmp_path / "d", "--no-progress"], capsys)
    assert_one_line_error(code, err, "is not a trained sc2data rl run")
    assert not (tmp_path / "d").exists()
    code, _, err = run_cli(["rollout", "--agent", "policy:", "--out", tmp_path / "d"], capsys)
    assert_one_line_error(code, err, "names no policy")


@pytest.mark.parametrize("space", ["macro", "paper"])
def test_a_policy_agent_keeps_the_clock_its_run_saw(tmp_path: Path, space: str) -> None:
    """A run trained with ``--history`` sees, as a rollout agent, the time since each macro
    (paper space: each function) acted, kept by the agent as the env keeps it."""
    from tests.cli import exit_code

    run = tmp_path / "timed"
    assert exit_code("rl", "train", "--out", run, "--action-space", space, "--history",
                     *TINY) == 0
    import sc2data.rl  # noqa: F401
    from sc2data.game.agents import make_agent
    from sc2data.game.env import make_env
    from sc2data.rl.obs import history_actions

    n = len(history_actions(space))
    seen: list[np.ndarray] = []
    env = make_env("sim", seed=0)
    agent = make_agent(f"policy:{run}", seed=1)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    agent.reset()
    decide = agent._decide
    agent._decide = lambda obs, mask: (  # type: ignore[method-assign]
        seen.append(agent.observer(obs.observation, clock=agent.clock)["vector"][-n:].copy())
        or decide(obs, mask))
    try:
        ts = env.reset()[0]
        for _ in range(200):
            ts = env.step([agent.step(ts)])[0]
    finally:
        env.close()
    assert np.all(seen[0] == 1.0), "the first decision: nothing has acted"
    assert any(np.any(v < 1.0) for v in seen[1:]), "later decisions see what acted"
    assert (agent.clock.last >= 0).sum() >= 2
    assert calls(run, seed=1, steps=150) == calls(run, seed=1, steps=150)
