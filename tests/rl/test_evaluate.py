"""The evaluation protocol: seeds of both start sides, the same episodes for reference agents,
the masked uniform policy, and ``sc2data rl baselines``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sc2data.ground.errors import Sc2DataError
from sc2data.rl.envs import PAPER_FUNCTIONS, BuildMarinesGym
from sc2data.rl.evaluate import (
    REFERENCE_AGENTS,
    UniformPolicy,
    eval_seeds,
    game_seed,
    read_baselines,
    reference_summary,
    side_of,
)
from sc2data.rl.train import EVAL_SEED
from tests.cli import assert_one_line_error, run_cli


def test_evaluation_seeds_alternate_start_sides_and_extend() -> None:
    seeds, sides = eval_seeds(6)
    assert sides == ["west", "east"] * 3
    assert len(set(seeds)) == 6 and min(seeds) >= EVAL_SEED
    assert eval_seeds(3) == (seeds[:3], sides[:3])  # a shorter protocol is a prefix
    env = BuildMarinesGym("macro", obs="compact")
    try:
        for seed, side in zip(seeds, sides):  # the side as the episode's own first frame shows
            env.reset(seed=seed)
            assert side_of(env.frames[0]) == side
    finally:
        env.close()
    with pytest.raises(Sc2DataError, match="--episodes"):
        eval_seeds(0)


def test_agents_play_the_simulator_game_the_gym_env_plays() -> None:
    env = BuildMarinesGym("macro", obs="compact")
    try:
        for seed in eval_seeds(2)[0]:
            env.reset(seed=seed)
            assert env._env._seed == game_seed(seed)
    finally:
        env.close()


def test_uniform_policy_draws_only_what_the_masks_allow() -> None:
    n = len(PAPER_FUNCTIONS)
    policy = UniformPolicy([n, 64, 64])
    masks = np.zeros(n + 128, bool)
    masks[[2, 5]] = True
    masks[n + 10] = masks[n + 64 + 3] = masks[n + 64 + 60] = True
    policy.set_random_seed(0)
    drawn = [policy.predict(None, action_masks=masks)[0] for _ in range(200)]
    assert {int(a[0]) for a in drawn} == {2, 5} and {int(a[1]) for a in drawn} == {10}
    assert {int(a[2]) for a in drawn} == {3, 60}
    policy.set_random_seed(0)
    assert all((policy.predict(None, action_masks=masks)[0] == a).all() for a in drawn[:20])
    macro = UniformPolicy([6])
    only = np.array([False, True, False, False, True, False])
    assert {int(macro.predict(None, action_masks=only)[0]) for _ in range(100)} == {1, 4}


def test_baselines_play_every_reference_agent_on_the_evaluation_episodes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ref"
    args = ["rl", "baselines", "--out", out, "--episodes", "2", "--episode-steps", "30",
            "--no-progress"]
    code, text, err = run_cli(args, capsys)
    assert code == 0, err
    record = json.loads((out / "baselines.json").read_text())
    assert record["seeds"] == eval_seeds(2)[0] and record["episode_steps"] == 30
    assert record["macro_sites"] == "random" and "far sites" not in text
    assert set(record["agents"]) == set(REFERENCE_AGENTS)
    for name, agent in record["agents"].items():
        assert agent["space"] == REFERENCE_AGENTS[name] and len(agent["marines"]) == 2
        assert name in text
        # the uniform policies say what they chose, read against a trained policy's
        assert ("actions" in agent) == name.startswith("uniform-")
    paper = record["agents"]["uniform-paper"]["actions"]
    assert set(paper) <= set(PAPER_FUNCTIONS) and abs(sum(paper.values()) - 1) < 1e-3
    assert read_baselines(out)["agents"]["uniform-paper"]["actions"] == paper
    code, _, _ = run_cli(args, capsys)  # seeded: the same figures again
    assert json.loads((out / "baselines.json").read_text()) == record
    code, _, err = run_cli(["rl", "baselines", "--out", out, "--episodes", "0"], capsys)
    assert_one_line_error(code, err, "--episodes")
    code, _, err = run_cli(["rl", "baselines", "--out", out, "--macro-sites", "near"], capsys)
    assert_one_line_error(code, err, "unknown macro sites 'near'")
    far = reference_summary({**record, "macro_sites": "far"})
    assert [("far sites" in line) for line in far] == [
        name in ("uniform-macro", "reduced-random", "macro-rules") for name in record["agents"]]


class _Always:
    """A policy that always plays one action, allowed or not (to see ``+masked`` counted)."""

    def __init__(self, action: np.ndarray) -> None:
        self.action = action

    def set_random_seed(self, seed: int) -> None:
        pass

    def predict(self, obs: object, deterministic: bool = False,
                action_masks: np.ndarray | None = None) -> tuple[np.ndarray, None]:
        return self.action, None


def test_evaluation_counts_the_actions_each_mode_chose() -> None:
    from collections import Counter

    from sc2data.rl.evaluate import _episodes, action_shares

    env = BuildMarinesGym("paper", obs="compact", game_loops=200)
    try:
        seeds = eval_seeds(2)[0]
        counts: Counter[str] = Counter()
        _episodes(UniformPolicy(env.action_space.nvec), env, seeds, False, lambda: None, counts)
        assert set(counts) <= set(PAPER_FUNCTIONS) and len(counts) > 2  # the masks hold
        assert sum(counts.values()) == 2 * 25  # 200 game loops are 25 decisions
        shares = action_shares(counts)
        assert abs(sum(shares.values()) - 1) < 1e-3 and list(shares.values()) == sorted(
            shares.values(), reverse=True)
        train = PAPER_FUNCTIONS.index("Train_Marine_quick")  # never available at the start
        counts = Counter()
        _episodes(_Always(np.array([train, 0, 0])), env, seeds[:1], True, lambda: None, counts)
        assert counts == Counter({"Train_Marine_quick+masked": 25})
    finally:
        env.close()
