"""Reward wrappers on hand-built frames: exact bonuses, game reward untouched, narration order."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from sc2data._pysc2 import features
from sc2data.ground.errors import Sc2DataError
from sc2data.rl.narration import Narration, load_narration
from sc2data.rl.rewards import NarrationShaping, RuleShaping, SparseReward, wrap_reward
from sc2data.rulebase import blank_frame, set_field
from sc2data.schema import Schema, StackBatch


def as_obs(frame: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A schema frame (``blank_frame``) as the pysc2 observation ``Schema.extract`` reads."""
    obs: dict[str, np.ndarray] = {
        "feature_screen": np.zeros((len(features.SCREEN_FEATURES), 64, 64), np.int32),
        "feature_minimap": np.zeros((len(features.MINIMAP_FEATURES), 64, 64), np.int32),
    }
    for key, value in frame.items():
        group, _, name = key.partition("/")
        if name:
            table = features.SCREEN_FEATURES if group == "screen" else features.MINIMAP_FEATURES
            obs[f"feature_{group}"][getattr(table, name).index] = value
        else:
            obs[key] = value.copy()
    return obs


def frame(**fields: int) -> dict[str, np.ndarray]:
    """A blank frame with ``vector__field=value`` set, e.g. ``player__minerals=50``."""
    f = blank_frame()
    set_field(f, "player", "food_workers", 12)
    for key, value in fields.items():
        vector, field = key.split("__")
        set_field(f, vector, field, value)
    return f


class ScriptedEnv(gym.Env):  # type: ignore[type-arg]
    """Plays given decisions: each a list of frames (after the previous decision's last) and a
    game reward; ``frames`` as ``BuildMarinesGym`` keeps them."""

    observation_space = spaces.Discrete(1)
    action_space = spaces.Discrete(1)

    def __init__(self, start: dict[str, np.ndarray],
                 decisions: Sequence[tuple[Sequence[dict[str, np.ndarray]], float]]) -> None:
        self.start, self.decisions = as_obs(start), list(decisions)
        self.frames: list[Any] = []

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[int, dict]:
        super().reset(seed=seed)
        self.i, self.frames = 0, [self.start]
        return 0, {"game_reward": 0.0}

    def step(self, action: Any) -> tuple[int, float, bool, bool, dict]:
        new, reward = self.decisions[self.i]
        self.i += 1
        self.frames = [self.frames[-1], *(as_obs(f) for f in new)]
        return 0, reward, self.i == len(self.decisions), False, {"game_reward": reward}

    def action_masks(self) -> np.ndarray:
        return np.ones(1, bool)


def test_sparse_is_the_game_reward() -> None:
    env = SparseReward(ScriptedEnv(frame(), [([frame()], 1.0), ([frame()], 0.0)]))
    env.reset()
    assert env.step(0)[1] == 1.0 and env.step(0)[4]["game_reward"] == 0.0


def test_rules_bonus_per_firing_over_every_stack_of_a_decision() -> None:
    idle2, idle1 = frame(player__idle_worker_count=2), frame(player__idle_worker_count=1)
    scv = frame(player__idle_worker_count=1, score_cumulative__total_value_units=50)
    env = RuleShaping(ScriptedEnv(idle2, [([idle1, idle1], 0.0), ([scv], 1.0)]), bonus=0.25)
    env.reset()
    _, r, _, _, info = env.step(0)  # collect_minerals fires on the first stack only
    assert r == pytest.approx(0.25) and info["shaping"] == pytest.approx(0.25)
    _, r, _, _, info = env.step(0)  # build_scv fires; the game's +1 is kept apart
    assert r == pytest.approx(1.25) and info["game_reward"] == 1.0


class FakeScorer:
    """A MEM stand-in: a stack matches command ``c`` when the current frame's minerals equal
    the command's number (distance 0), else distance 1."""

    schema = Schema.paper()
    codes = {"one": 1, "two": 2, "three": 3}

    def __init__(self) -> None:
        self.calls: list[str] = []

    def distance(self, stacks: StackBatch, text: str) -> np.ndarray:
        self.calls.append(text)
        minerals = stacks.vector("player", "minerals")[:, 1]
        return np.where(minerals == self.codes[text], 0.0, 1.0)


def m(n: int) -> dict[str, np.ndarray]:
    return frame(player__minerals=n)


def test_narration_rewards_commands_in_turn_and_loops() -> None:
    narration = Narration(("one", "two"), "test")
    decisions = [([m(2)], 0.0),          # "two" is not the current command: nothing
                 ([m(1), m(0), m(2)], 0.0),  # "one" then "two", in one decision: 2 bonuses
                 ([m(1)], 1.0),          # looped back to "one"
                 ([m(1)], 0.0)]          # now waiting for "two"
    env = NarrationShaping(ScriptedEnv(m(0), decisions), FakeScorer(), narration, bonus=0.5)
    _, info = env.reset()
    assert info["narration_index"] == 0
    got = [env.step(0) for _ in decisions]
    assert [g[1] for g in got] == [0.0, 1.0, 1.5, 0.0]
    assert [g[4]["narration_index"] for g in got] == [0, 0, 1, 1]
    assert [g[4]["game_reward"] for g in got] == [0.0, 0.0, 1.0, 0.0]
    env.reset()
    assert env.index == 0


def test_narration_threshold_and_patience() -> None:
    narration = Narration(("one", "two", "three"), "test")
    decisions = [([m(0)], 0.0), ([m(0)], 0.0), ([m(2)], 0.0)]
    env = NarrationShaping(ScriptedEnv(m(0), decisions), FakeScorer(), narration, patience=2)
    env.reset()
    rewards = [env.step(0)[1] for _ in decisions]
    assert rewards == [0.0, 0.0, 1.0]  # "one" skipped after 2 decisions, then "two" matched
    strict = NarrationShaping(ScriptedEnv(m(0), [([m(1)], 0.0)]), FakeScorer(), narration,
                              threshold=0.0)
    strict.reset()
    assert strict.step(0)[1] == 0.0  # distance 0 is not below a threshold of 0


def test_unknown_reward_and_missing_mem() -> None:
    env = ScriptedEnv(m(0), [])
    with pytest.raises(Sc2DataError, match="unknown reward"):
        wrap_reward(env, "dense")
    with pytest.raises(Sc2DataError, match="needs a MEM"):
        wrap_reward(env, "narration")


def test_narration_files(tmp_path: Any) -> None:
    default = load_narration()
    assert default.commands[0] == "build an SCV" and len(default) >= 4
    text = tmp_path / "n.txt"
    text.write_text("# a comment\n\nbuild an SCV\n  train a marine  \n")
    assert load_narration(text).commands == ("build an SCV", "train a marine")
    for name, body, needle in (("e.txt", "# nothing\n\n", "no command"),
                               ("e.toml", "commands = []\n", "no command"),
                               ("k.toml", "command = ['x']\n", "unknown key"),
                               ("t.toml", "commands = [1]\n", "non-empty strings"),
                               ("b.toml", "commands = [\n", "not valid TOML")):
        (tmp_path / name).write_text(body)
        with pytest.raises(Sc2DataError, match=needle):
            load_narration(tmp_path / name)
    with pytest.raises(Sc2DataError, match="does not exist"):
        load_narration(tmp_path / "absent.toml")


# -- potential-based shaping ------------------------------------------------------------------

def built(units: int, structures: int = 400, marines: int = 0, idle: int = 0
          ) -> dict[str, np.ndarray]:
    """A frame of a player with ``units``/``structures`` minerals' worth built, ``marines``
    made and ``idle`` idle workers."""
    return frame(score_cumulative__total_value_units=units,
                 score_cumulative__total_value_structures=structures,
                 score_cumulative__score=marines, player__idle_worker_count=idle)


def discounted(rewards: Sequence[float], gamma: float) -> float:
    return sum(gamma ** t * r for t, r in enumerate(rewards))


def test_rules_potential_is_what_was_built_and_telescopes() -> None:
    # Φ = bonus · ((units + structures − 1,000) / 50 + marines): 0 at the start (a CC and 12
    # SCVs), 1 with an SCV more, 4 with a barracks placed, 6 with a marine (value and score).
    start = built(600)
    decisions = [([built(650)], 0.0), ([built(650, 550)], 0.0), ([built(700, 550, 1)], 1.0)]
    env = RuleShaping(ScriptedEnv(start, decisions), bonus=0.5, shaping="potential", gamma=0.9)
    env.reset()
    got = [env.step(0) for _ in decisions]
    shaping = [g[4]["shaping"] for g in got]
    assert shaping == pytest.approx([0.9 * 0.5 - 0.0, 0.9 * 2.0 - 0.5, 0.0 - 2.0])
    assert [g[1] for g in got] == pytest.approx([s + g for s, g in zip(shaping, (0, 0, 1))])
    # The episode's discounted shaping is -Φ(s_0) = 0 whatever was built: nothing to farm.
    assert discounted(shaping, 0.9) == pytest.approx(0.0)


def test_a_rules_loop_pays_as_an_event_and_not_as_a_potential() -> None:
    # Sending an idle worker back to mine, again and again: collect_minerals fires each time.
    loop = [([built(650, idle=1)], 0.0), ([built(650, idle=0)], 0.0)] * 3
    event = RuleShaping(ScriptedEnv(built(650, idle=1), loop), bonus=0.5)
    event.reset()
    assert sum(event.step(0)[4]["shaping"] for _ in loop) == pytest.approx(1.5)
    potential = RuleShaping(ScriptedEnv(built(650, idle=1), loop), bonus=0.5,
                            shaping="potential", gamma=1.0)
    potential.reset()
    # Φ = 0.5 throughout (one SCV more than the start): nothing until the end takes it back.
    assert [potential.step(0)[4]["shaping"] for _ in loop] == [0.0] * 5 + [-0.5]


def test_narration_potential_counts_commands_matched_this_episode() -> None:
    narration = Narration(("one", "two"), "test")
    decisions = [([m(1)], 0.0), ([m(0)], 0.0), ([m(2), m(1)], 0.0), ([m(0)], 0.0)]
    env = NarrationShaping(ScriptedEnv(m(0), decisions), FakeScorer(), narration, bonus=1.0,
                           shaping="potential", gamma=0.5)
    env.reset()
    shaping = [env.step(0)[4]["shaping"] for _ in decisions]
    # Φ: 0 → 1 → 1 → 3 (two matches in one decision) → 0 at the end
    assert shaping == pytest.approx([0.5 * 1 - 0, 0.5 * 1 - 1, 0.5 * 3 - 1, 0.0 - 3])
    assert discounted(shaping, 0.5) == pytest.approx(0.0)
    env.reset()
    assert env.matched == 0 and env.step(0)[4]["shaping"] == pytest.approx(0.5)


def test_unknown_shaping_is_an_error() -> None:
    with pytest.raises(Sc2DataError, match="unknown shaping"):
        wrap_reward(ScriptedEnv(m(0), []), "rules", shaping="difference")
    with pytest.raises(Sc2DataError, match="gamma"):
        RuleShaping(ScriptedEnv(m(0), []), shaping="potential", gamma=1.5)
