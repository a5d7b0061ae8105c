"""``sc2data build`` grows its data when the pair stage finds too few states, within bounds."""

from __future__ import annotations

import re
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from sc2data.build import GROW_LIMIT, GROW_ROUNDS, grow_to
from sc2data.data.dataset import open_dataset
from sc2data.pairs.draw import NotEnoughStates
from tests.cli import assert_one_line_error, run_cli

RECIPE = """
name = "grows"
seed = 0

[rollout]
env = "sim"
agent = "reduced-random"
episodes = 1
layers = "paper"

[commands.build_scv]
text = "build an SCV"

[commands.{second}]
text = "{text}"

[pairs]
states_per_command = 40
null_states = 100

[split]
method = "random"
train = 0.6
val = 0.2
test = 0.2
"""


def test_build_grows_the_data_until_the_pairs_can_be_drawn(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """One episode holds fewer collect_minerals states than the recipe asks for: build grows the
    data to what the shortage asks for, says so, and pairs; a rerun keeps the grown data."""
    recipe = tmp_path / "r.toml"
    recipe.write_text(RECIPE.format(second="collect_minerals", text="collect minerals"))
    code, out, err = run_cli(["build", recipe, "--out", tmp_path / "b", "--workers", "1",
                              "--no-progress"], capsys)
    assert code == 0, err
    grow = re.search(r"pair: too few labelled states for the recipe: .*collect_minerals \d+ of "
                     r"40 the recipe asks for.* \(in 1 episode\); growing the data to (\d+) "
                     r"episodes", out)
    assert grow, out
    episodes = int(grow[1])
    assert f"rollout: {episodes} episodes, grown from 1" in out
    assert len(open_dataset(tmp_path / "b" / "rollout").episode_ids) == episodes
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == ["pairs", "rollout"]  # no lock
    kinds = pq.read_table(tmp_path / "b" / "pairs" / "pairs.parquet")["kind"].to_pylist()
    assert (kinds.count("matched"), kinds.count("null")) == (80, 100)
    code, out, err = run_cli(["build", recipe, "--out", tmp_path / "b", "--no-progress"], capsys)
    assert code == 0, err
    assert f"keeping the {episodes} episodes an earlier build grew the data to" in out
    assert "0 shards written, 1 kept" in out and "growing" not in out


def test_a_command_that_never_fires_ends_the_build_in_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rules = tmp_path / "rules"
    rules.mkdir()
    (rules / "never.py").write_text(
        "import numpy as np\nfrom sc2data.rulebase import rule\n"
        "@rule(id='build_factory', command='build a factory', requires=['screen/unit_type'])\n"
        "def f(batch):\n    return np.zeros(len(batch), bool)\n")
    recipe = tmp_path / "r.toml"
    recipe.write_text(RECIPE.format(second="build_factory", text="build a factory"))
    code, _, err = run_cli(["build", recipe, "--out", tmp_path / "b", "--rules-dir", rules,
                            "--workers", "1", "--no-progress"], capsys)
    assert_one_line_error(code, err, "build_factory 0 of 40 the recipe asks for (in 1 episode); "
                                     "build_factory never fires in the data; check the agent")
    assert len(open_dataset(tmp_path / "b" / "rollout").episode_ids) == 1  # not grown


def _short(episodes: int | None) -> NotEnoughStates:
    return NotEnoughStates("too few", "roll out more", episodes)


def test_growing_is_bounded() -> None:
    assert grow_to(_short(30), 20, 20, 0) == 30
    assert grow_to(_short(20), 20, 20, 1) == 21  # always more than the data has
    assert grow_to(_short(GROW_LIMIT * 20), 150, 20, GROW_ROUNDS - 1) == GROW_LIMIT * 20
    with pytest.raises(NotEnoughStates, match="^too few; it needs about 201 episodes, .* at "
                                              "most 10× the recipe's 20 episodes .*; set "
                                              r"\[rollout\] episodes = 201 in the recipe"):
        grow_to(_short(GROW_LIMIT * 20 + 1), 20, 20, 0)
    with pytest.raises(NotEnoughStates, match="at most 3 times"):
        grow_to(_short(60), 50, 20, GROW_ROUNDS)
    with pytest.raises(NotEnoughStates, match="^too few; roll out more$"):
        grow_to(_short(None), 20, 20, 0)
