"""The gymnasium environments: spaces, env checker, masks, seeding, registration, vector envs."""

from __future__ import annotations

import hashlib

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sc2data.rl  # noqa: F401  (registers the ids)
from sc2data._pysc2 import actions, features, units
from sc2data.ground.errors import Sc2DataError
from sc2data.rl.envs import (
    MACROS,
    MAX_DECISION_STEPS,
    PAPER_FUNCTIONS,
    BuildMarinesGym,
    paper_call,
)
from sc2data.schema import Schema

LOOPS = 8 * 120
"""120 pysc2 steps per episode: enough for depots and a barracks, fast to play."""


@pytest.mark.parametrize("space", ["macro", "paper"])
def test_env_checker_passes(space: str) -> None:
    env = BuildMarinesGym(space, game_loops=LOOPS)
    check_env(env, skip_render_check=True)
    assert set(env.observation_space.spaces) == set(Schema.named("paper").keys())


def test_gymnasium_make_both_ids() -> None:
    for space, n in (("macro", len(MACROS)), ("paper", len(PAPER_FUNCTIONS))):
        env = gymnasium.make(f"sc2data/BuildMarines-{space}-v0", game_loops=LOOPS)
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        masks = env.unwrapped.action_masks()
        assert masks.shape == ((n,) if space == "macro" else (n + 128,))
        env.close()


def _random_masked(env: BuildMarinesGym, rng: np.random.Generator) -> object:
    m = env.action_masks()
    if env.kind == "macro":
        return int(rng.choice(np.flatnonzero(m)))
    f = int(rng.choice(np.flatnonzero(m[:len(PAPER_FUNCTIONS)])))
    return np.array([f, rng.integers(64), rng.integers(64)])


@pytest.mark.parametrize("space", ["macro", "paper"])
def test_masked_random_actions_never_send_an_invalid_call(space: str) -> None:
    """The simulator raises on any unavailable call, as pysc2 does: 300 masked random steps
    (with barracks built and marines queued on the macro space) must never hit one."""
    env = BuildMarinesGym(space, game_loops=8 * 2000)
    env.reset(seed=5)
    rng = np.random.default_rng(0)
    used: set[int] = set()
    for _ in range(300):
        action = _random_masked(env, rng)
        used.add(int(np.asarray(action).reshape(-1)[0]))
        _, _, terminated, _, info = env.step(action)
        assert not info["invalid"]
        assert 1 <= info["env_steps"] <= 62
        assert not terminated
    assert len(used) >= 5, used


def test_events_follow_the_pysc2_steps_of_a_decision() -> None:
    """``env.events`` holds one entry per pysc2 step of the decision (``frames[1:]``), and
    every SCV the game completed shows up there once: the SCV count rises by the completions."""
    env = BuildMarinesGym("macro", game_loops=8 * 1500)
    env.reset(seed=3)
    rng = np.random.default_rng(1)
    completed = 0
    for _ in range(200):
        env.step(_random_masked(env, rng))
        assert len(env.events) == len(env.frames) - 1
        completed += sum(e.kind == "completed" and e.unit_type == units.Terran.SCV
                         for step in env.events for e in step)
    workers = int(env.frames[-1]["player"][features.Player.food_workers])
    assert completed > 0 and workers == 12 + completed


def test_unmasked_invalid_action_plays_no_op() -> None:
    env = BuildMarinesGym("paper", game_loops=LOOPS)
    env.reset(seed=0)
    train_marine = PAPER_FUNCTIONS.index("Train_Marine_quick")
    assert not env.action_masks()[train_marine]
    _, _, _, _, info = env.step(np.array([train_marine, 0, 0]))
    assert info["invalid"] and info["env_steps"] == 1


def test_paper_calls_fill_every_argument() -> None:
    for i, name in enumerate(PAPER_FUNCTIONS):
        call = paper_call(i, 63, 0)
        assert actions.FUNCTIONS[call.function].name == name
        for arg in call.arguments:
            assert all(0 <= a < 64 for a in arg)


def _trajectory(space: str, seed: int) -> str:
    env = BuildMarinesGym(space, game_loops=LOOPS)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    h = hashlib.sha256()
    for _ in range(60):
        obs, r, term, _, info = env.step(_random_masked(env, rng))
        for k in sorted(obs):
            h.update(obs[k].tobytes())
        h.update(repr((r, info["env_steps"])).encode())
        if term:
            break
    return h.hexdigest()


@pytest.mark.parametrize("space", ["macro", "paper"])
def test_same_seed_same_trajectory(space: str) -> None:
    assert _trajectory(space, 3) == _trajectory(space, 3)
    assert _trajectory(space, 3) != _trajectory(space, 4)


def test_episode_ends_when_the_timer_does() -> None:
    env = BuildMarinesGym("macro", game_loops=8 * 30)
    env.reset(seed=0)
    steps, terminated = 0, False
    while not terminated:
        _, _, terminated, truncated, info = env.step(MACROS.index("no_op"))
        steps += info["env_steps"]
        assert not truncated
    assert steps == 30 and info["game_loop"] == 240


def test_bad_settings_are_errors() -> None:
    with pytest.raises(Sc2DataError, match="unknown action space"):
        BuildMarinesGym("full")
    with pytest.raises(Sc2DataError, match="unknown layer set"):
        BuildMarinesGym("macro", layers="tiny")


def _first_allowed(mask: np.ndarray) -> int:
    """A choice that depends on the mask alone: the first macro allowed after ``no_op``'s turn
    (so that two envs asked in the same state answer alike)."""
    order = [MACROS.index(m) for m in ("gather", "build_barracks", "train_marine",
                                       "build_supply_depot", "train_scv", "no_op")]
    return next(a for a in order if mask[a])


def test_merged_waits_play_the_same_game_asking_only_when_there_is_a_choice() -> None:
    """``merge_waits``: the forced ``no_op`` steps after the supply ceiling join the decision
    before them; the game is played step for step as without them."""
    played = {}
    for merge in (False, True):
        env = BuildMarinesGym("macro", obs="compact", merge_waits=merge)
        env.reset(seed=5)
        decisions, steps, reward, frames, done = 0, 0, 0.0, [], False
        forced_ends = []
        while not done:
            _, r, done, _, info = env.step(_first_allowed(env.action_masks()))
            decisions += 1
            steps += info["env_steps"]
            reward += r
            frames += [int(f["game_loop"][0]) for f in env.frames[1:]]
            forced_ends.append(env.action_masks().sum() == 1 and not done
                               and info["env_steps"] < MAX_DECISION_STEPS)
        played[merge] = (decisions, steps, reward, info["marines"], frames, any(forced_ends))
        env.close()
    (d0, s0, r0, m0, f0, forced0), (d1, s1, r1, m1, f1, forced1) = played[False], played[True]
    assert (s1, r1, m1, f1) == (s0, r0, m0, f0) and s0 == 1800 and m0 > 0
    assert forced0 and not forced1, "unmerged decisions end where only no_op is allowed"
    assert d1 < 0.8 * d0, (d1, d0)


def test_merged_waits_change_nothing_in_the_paper_space() -> None:
    env = BuildMarinesGym("paper", game_loops=LOOPS, merge_waits=True)
    assert not env.merge_waits


def test_history_records_when_each_macro_last_acted() -> None:
    """``history``: the vector ends with the clock's features; a macro acts when it sends its
    first call that is not a wait, and one that gave up waiting did not act."""
    from sc2data.rl.obs import GAME_LOOPS, ObsConfig

    env = BuildMarinesGym("macro", obs=ObsConfig("compact", size=32, history=True),
                          game_loops=LOOPS)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=3)
    assert np.all(obs["vector"][-len(MACROS):] == 1.0), "nothing has acted yet"
    depot = MACROS.index("build_supply_depot")
    obs, _, _, _, info = env.step(depot)  # 50 minerals at the start: waits, then builds
    acted_at = int(env._clock.last[depot])
    assert 0 < acted_at < info["game_loop"]
    since = info["game_loop"] - acted_at
    tail = obs["vector"][-len(MACROS):]
    assert tail[depot] == pytest.approx(np.log1p(since) / np.log1p(GAME_LOOPS))
    assert np.all(np.delete(tail, depot) == 1.0)
    env.step(MACROS.index("train_marine") if env.action_masks()[3] else MACROS.index("no_op"))
    assert env._clock.last[MACROS.index("train_marine")] == -1, "no barracks: it cannot act"
    env.reset(seed=3)
    assert np.all(env._clock.last == -1), "reset clears the clock"
    env._expander.PATIENCE = 1  # 50 minerals, a depot costs 100: one wait, then it gives up
    env.step(depot)
    assert env._clock.last[depot] == -1, "a macro that gave up waiting did not act"
    env.step(MACROS.index("no_op"))
    assert env._clock.last[MACROS.index("no_op")] >= 0, "no_op acts by waiting"


def test_history_in_the_paper_space_times_each_function() -> None:
    """Paper space: a function acts when its call is sent; an unavailable one is sent, and
    timed, as ``no_op``; the vector ends with one feature per function."""
    from sc2data.rl.obs import GAME_LOOPS, ObsConfig

    env = BuildMarinesGym("paper", obs=ObsConfig("compact", size=32, history=True,
                                                 action_space="paper"), game_loops=LOOPS)
    check_env(env, skip_render_check=True)
    n = len(PAPER_FUNCTIONS)
    obs, info = env.reset(seed=3)
    assert obs["vector"].shape[0] == env.observer.space["vector"].shape[0]
    assert np.all(obs["vector"][-n:] == 1.0), "nothing has acted yet"
    idle = PAPER_FUNCTIONS.index("select_idle_worker")
    marine = PAPER_FUNCTIONS.index("Train_Marine_quick")
    start = info["game_loop"]
    obs, _, _, _, info = env.step(np.array([marine, 0, 0]))  # no barracks: sent as no_op
    assert env._clock.last[marine] == -1
    assert env._clock.last[PAPER_FUNCTIONS.index("no_op")] == start
    env.step(np.array([PAPER_FUNCTIONS.index("select_rect"), 40, 40]))
    acted = info["game_loop"]
    obs, _, _, _, info = env.step(np.array([idle, 0, 0]))
    tail = obs["vector"][-n:]
    rect = PAPER_FUNCTIONS.index("select_rect")
    assert env._clock.last[rect] == acted
    assert tail[rect] == pytest.approx(np.log1p(info["game_loop"] - acted) / np.log1p(GAME_LOOPS))
    assert tail[marine] == 1.0
    env.reset(seed=3)
    assert np.all(env._clock.last == -1), "reset clears the clock"


def test_history_needs_the_compact_observation_of_its_space() -> None:
    from sc2data.rl.obs import ObsConfig

    with pytest.raises(Sc2DataError, match="--history needs --obs compact"):
        BuildMarinesGym("macro", obs=ObsConfig("stored", history=True))
    with pytest.raises(ValueError, match="paper-space env with history"):
        BuildMarinesGym("paper", obs=ObsConfig("compact", history=True))


def test_the_macro_rules_agent_chooses_the_envs_macros() -> None:
    """``env.view`` is what a macro agent reads: the macro-rules agent, asked at each decision
    which macro it would start (``choose``), plays the far-site macro env to its own level
    (119–123 marines on its own episodes), and only ever picks an allowed macro."""
    from sc2data.game.agents import MacroRulesAgent
    from sc2data.ground.vocab import STEP_MUL
    from sc2data.rl.obs import MACROS

    env = BuildMarinesGym("macro", obs="compact", merge_waits=True, sites="far")
    agent = MacroRulesAgent(0, sites="far")
    _, info = env.reset(seed=5)
    done = False
    try:
        while not done:
            agent.view, agent.steps = env.view, info["game_loop"] // STEP_MUL
            action = MACROS.index(agent.choose())
            assert env.action_masks()[action]
            _, _, done, _, info = env.step(action)
    finally:
        env.close()
    assert info["marines"] >= 100
