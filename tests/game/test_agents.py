"""Agents: registry, seeding, macro expansion into valid pysc2 calls, whole episodes on the sim."""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np
import pytest

from sc2data._pysc2 import actions, environment, features, units  # first: pysc2 on 3.11

from pysc2.agents import base_agent, random_agent  # isort: skip
from pysc2.env import mock_sc2_env  # isort: skip
from pysc2.lib import named_array  # isort: skip
from sc2data.game.agents import (
    AGENTS,
    MacroRulesAgent,
    ReducedRandomAgent,
    ScriptedAgent,
    far_spot,
    make_agent,
    play,
)
from sc2data.game.env import interface_format, make_env
from sc2data.game.screen import ScreenView
from sc2data.ground.errors import Sc2DataError

_F, _S, _P = actions.FUNCTIONS, features.SCREEN_FEATURES, features.Player
T = units.Terran


# --- a hand-drawn observation -------------------------------------------------------------

def _specs() -> tuple[Any, Any]:
    env = mock_sc2_env.SC2TestEnv(agent_interface_format=[interface_format()])
    return env.observation_spec()[0], env.action_spec()[0]


def _timestep(*, selected: int = 0, available: tuple[int, ...] = (0, 1, 2, 3, 4),
              minerals: int = 500, food: tuple[int, int] = (12, 15), idle: int = 0,
              queue: int = 0) -> Any:
    """A BuildMarines-like frame: CC, minerals to its left, SCVs, one Barracks, buildable ground."""
    screen = np.zeros((27, 64, 64), np.int32)
    ut, pr = screen[_S.unit_type.index], screen[_S.player_relative.index]
    screen[_S.buildable.index, :48, :] = 1
    ut[17:32, 16:31] = T.CommandCenter
    for y in (10, 16, 22, 28, 34):
        ut[y:y + 3, 4:10] = units.Neutral.MineralField
    for y, x in ((20, 11), (20, 14), (40, 40)):
        ut[y:y + 2, x:x + 2] = T.SCV
    ut[5:13, 50:58] = T.Barracks
    pr[ut != 0] = features.PlayerRelative.SELF
    pr[np.isin(ut, [units.Neutral.MineralField])] = features.PlayerRelative.NEUTRAL
    screen[_S.buildable.index][(ut != 0) & (ut != T.SCV)] = 0  # units stand on buildable ground
    if selected in (T.CommandCenter, T.Barracks):  # the one on screen is the selected one
        screen[_S.selected.index][ut == selected] = 1
    player = np.zeros(11, np.int32)
    player[[_P.player_id, _P.minerals, _P.food_used, _P.food_cap, _P.food_workers,
            _P.idle_worker_count]] = [1, minerals, food[0], food[1], 12, idle]
    one = np.array([[selected, 1, 45, 0, 0, 0, 0]], np.int32)
    obs = {"feature_screen": screen, "feature_minimap": np.zeros((11, 64, 64), np.int32),
           "player": player, "available_actions": np.array(available, np.int32),
           "single_select": one if selected else np.zeros((0, 7), np.int32),
           "multi_select": np.zeros((0, 7), np.int32),
           "build_queue": np.tile(np.array([[T.SCV, 1, 45, 0, 0, 0, 0]], np.int32), (queue, 1)),
           "score_cumulative": np.zeros(13, np.int32), "game_loop": np.zeros(1, np.int32)}
    return environment.TimeStep(environment.StepType.MID, 0.0, 1.0, named_array.NamedDict(obs))


# --- registry and seeding -----------------------------------------------------------------

def test_registry_makes_every_agent_as_a_pysc2_base_agent() -> None:
    assert set(AGENTS) == {"random", "reduced-random", "macro-rules", "scripted"}
    for name in AGENTS:
        assert isinstance(make_agent(name, seed=0), base_agent.BaseAgent)
    assert isinstance(make_agent("random", seed=0), random_agent.RandomAgent)


def test_unknown_agent_lists_the_choices() -> None:
    with pytest.raises(Sc2DataError, match="'zerg'; choose one of: random, reduced-random, scr"):
        make_agent("zerg", seed=0)


def test_random_agent_is_reproducible_and_leaves_the_global_rng_alone() -> None:
    obs_spec, act_spec = _specs()
    ts = _timestep(available=(0, 1, 2, 3, 4, 6, 7, 12, 42, 91))

    def calls(seed: int) -> list[Any]:
        agent = make_agent("random", seed=seed)
        agent.setup(obs_spec, act_spec)
        return [agent.step(ts) for _ in range(30)]

    np.random.seed(123)
    before = np.random.get_state()[1].copy()
    a, b, c = calls(7), calls(7), calls(8)
    assert np.array_equal(np.random.get_state()[1], before)
    assert a == b and a != c
    # Exactly what pysc2's own agent plays after numpy.random.seed(7).
    plain = random_agent.RandomAgent()
    plain.setup(obs_spec, act_spec)
    np.random.seed(7)
    assert [plain.step(ts) for _ in range(30)] == a
    assert all(int(call.function) in (0, 1, 2, 3, 4, 6, 7, 12, 42, 91) for call in a)


# --- macro expansion ----------------------------------------------------------------------

def test_screen_view_reads_units_selection_and_free_ground() -> None:
    v = ScreenView(_timestep(selected=T.SCV))
    assert v.selected_type() == T.SCV
    assert len(v.blobs(v.own(T.SCV))) == 3 and len(v.blobs(v.minerals())) == 5
    x, y = v.centre_pixel(v.own(T.CommandCenter))
    assert v.unit_type[y, x] == T.CommandCenter and abs(x - 23) <= 1 and abs(y - 24) <= 1
    depot, rax = v.placements(2), v.placements(3)
    assert depot.any() and rax.any() and not (rax & ~depot).any()
    ys, xs = np.nonzero(rax)
    for y, x in zip(ys, xs, strict=True):  # a 3×3 building (8 px) centred there touches nothing
        assert np.isin(v.unit_type[max(0, y - 4):y + 5, max(0, x - 4):x + 5], [0, T.SCV]).all()
        assert v.buildable[max(0, y - 4):y + 5, max(0, x - 4):x + 5].all()
    assert depot[40, 40], "SCVs are pushed aside, so they do not block a depot"
    assert not depot[24, 23] and not depot[12, 8] and not depot[9, 54]


def _macro_calls(agent: ReducedRandomAgent, macro: str, frames: list[Any]) -> list[Any]:
    agent.setup(*_specs())
    agent.MACROS = (macro,)
    return [agent.step(ts) for ts in frames]


def test_train_scv_selects_the_command_center_then_trains() -> None:
    agent = ReducedRandomAgent(seed=1)
    first, second = _macro_calls(agent, "train_scv", [
        _timestep(), _timestep(selected=T.CommandCenter, available=(0, 1, 2, 3, 4, 490))])
    assert first.function == _F.select_point.id and first.arguments[0] == [0]
    x, y = first.arguments[1]
    assert agent.view is not None and _timestep().observation["feature_screen"][
        _S.unit_type.index][y, x] == T.CommandCenter
    assert second == _F.Train_SCV_quick("now")


def test_build_depot_picks_an_scv_then_a_free_buildable_spot() -> None:
    agent = ReducedRandomAgent(seed=2)
    frames = [_timestep(), _timestep(selected=T.SCV, available=(0, 1, 2, 3, 4, 91, 42, 264))]
    select, build = _macro_calls(agent, "build_supply_depot", frames)
    ut = frames[0].observation["feature_screen"][_S.unit_type.index]
    assert select.function == _F.select_point.id and ut[select.arguments[1][1],
                                                        select.arguments[1][0]] == T.SCV
    assert build.function == _F.Build_SupplyDepot_screen.id
    x, y = build.arguments[1]
    assert ScreenView(frames[1]).placements(2)[y, x]


def test_idle_workers_are_selected_and_sent_to_minerals() -> None:
    agent = ReducedRandomAgent(seed=3)
    select, gather = _macro_calls(agent, "gather", [
        _timestep(idle=2, available=(0, 1, 2, 3, 4, 6)),
        _timestep(selected=T.SCV, idle=2, available=(0, 1, 2, 3, 4, 264))])
    assert select == _F.select_idle_worker("select_all")
    x, y = gather.arguments[1]
    assert gather.function == _F.Harvest_Gather_screen.id
    assert _timestep().observation["feature_screen"][_S.unit_type.index][y, x] == \
        units.Neutral.MineralField


def test_an_unavailable_command_falls_back_to_no_op_and_drops_the_macro() -> None:
    agent = ReducedRandomAgent(seed=4)
    # The CC is selected but Train_SCV_quick is not offered (e.g. a cut-down card): no_op.
    calls = _macro_calls(agent, "train_scv", [_timestep(selected=T.CommandCenter)] * 2)
    assert calls == [_F.no_op(), _F.no_op()]


def test_scripted_agent_queues_scvs_until_the_queue_is_full() -> None:
    agent = ScriptedAgent(seed=0)
    agent.setup(*_specs())
    cc = dict(selected=T.CommandCenter, available=(0, 1, 2, 3, 4, 490), minerals=120,
              food=(12, 23))
    first = agent.step(_timestep(**cc))
    assert first == _F.Train_SCV_quick("now")
    assert agent.step(_timestep(queue=1, **cc)) == _F.Train_SCV_quick("now")
    assert agent.step(_timestep(queue=2, **cc)) != _F.Train_SCV_quick("now")


# --- whole episodes on the embedded simulator ---------------------------------------------

def _episode(name: str, seed: int, agent: Any = None) -> tuple[list[Any], Counter[Any]]:
    """Every TimeStep of one full episode, and the simulator's event counts by (kind, unit).

    Also checks that every call the agent made was available in the observation it answered.
    """
    env = make_env("sim", seed=seed)
    agent = agent or make_agent(name, seed=seed)
    original = agent.step

    def step(ts: Any) -> Any:
        call = original(ts)
        assert int(call.function) in set(np.asarray(ts.observation["available_actions"]).tolist())
        return call

    agent.step = step  # type: ignore[method-assign]
    frames, events = [], Counter()
    try:
        for ts in play(env, agent):
            frames.append(ts)
            events.update((e.kind, e.unit_type) for e in env.events)
    finally:
        env.close()
    assert frames[-1].last() and len(frames) == 1801
    return frames, events


def test_pysc2_random_agent_finishes_an_episode() -> None:
    frames, _ = _episode("random", seed=5)
    assert sum(f.reward for f in frames) == frames[-1].observation["score_cumulative"][0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_reduced_random_agent_builds_scvs_depots_barracks_and_marines(seed: int) -> None:
    frames, events = _episode("reduced-random", seed)
    built = {u.name: events["completed", u] for u in (T.SCV, T.SupplyDepot, T.Barracks, T.Marine)}
    assert all(n > 0 for n in built.values()), built
    last = frames[-1].observation
    assert last["score_cumulative"][0] == built["Marine"]
    assert last["player"][_P.food_cap] == 15 + 8 * built["SupplyDepot"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scripted_agent_builds_60_to_160_marines(seed: int) -> None:
    frames, events = _episode("scripted", seed)
    marines = int(frames[-1].observation["score_cumulative"][0])
    assert 60 <= marines <= 160, marines
    assert sum(f.reward for f in frames) == marines == events["completed", T.Marine]
    assert events["completed", T.Barracks] >= 4


def test_scripted_agent_kills_its_own_marines_at_its_supply_ceiling() -> None:
    frames, events = _episode("scripted", 4, ScriptedAgent(4, max_supply=60))
    caps = [int(f.observation["player"][_P.food_cap]) for f in frames]
    assert max(caps) < 60 + 8
    assert events["died", T.Marine] > 10
    assert int(frames[-1].observation["score_cumulative"][0]) >= 60


def test_macro_rules_agent_sends_idle_workers_first_then_a_depot_when_supply_runs_low() -> None:
    agent = MacroRulesAgent(0)
    agent.reset()
    call = agent.step(_timestep(idle=2, food=(14, 15), available=(0, 1, 2, 3, 4, 6)))
    assert call.function == _F.select_idle_worker.id  # the gather macro
    agent = MacroRulesAgent(0)
    agent.reset()
    ts = _timestep(food=(14, 15), available=(0, 1, 2, 3, 4))
    call = agent.step(ts)
    x, y = call.arguments[1]
    assert call.function == _F.select_point.id
    assert ScreenView(ts).own(T.SCV)[y, x], "a depot starts by selecting an SCV, not the CC"
    ts = _timestep(food=(12, 23), available=(0, 1, 2, 3, 4))  # 11 free: an SCV instead
    agent = MacroRulesAgent(0)
    agent.reset()
    call = agent.step(ts)
    assert call.function == _F.select_point.id and ScreenView(ts).own(T.CommandCenter)[
        call.arguments[1][1], call.arguments[1][0]]


def test_macro_rules_agent_fills_its_supply_ceiling_without_killing_a_marine() -> None:
    frames, events = _episode("macro-rules", 0)
    last = frames[-1].observation["player"]
    marines = int(frames[-1].observation["score_cumulative"][0])
    assert events["died", T.Marine] == 0 and 1 <= events["completed", T.Barracks] <= 5
    # the buildings that fit on the screen cap its supply: it ends supply-blocked below 200
    assert last[_P.food_used] == last[_P.food_cap] < 200
    assert marines == events["completed", T.Marine] >= 60, marines


@pytest.mark.parametrize("sites", ["random", "far"])
def test_macros_build_on_the_sites_asked_for(sites: str) -> None:
    agent = ReducedRandomAgent(0, sites=sites)
    agent.view = ScreenView(_timestep(available=(0, 1, 2, 3, 4, 91)))
    macro = agent.macro("build_supply_depot")
    assert next(macro).function == _F.select_point.id  # an SCV first
    agent.view = ScreenView(_timestep(selected=T.SCV, available=(0, 1, 2, 3, 4, 91)))
    build = next(macro)
    far = far_spot(agent.view, 2)
    assert build.function == _F.Build_SupplyDepot_screen.id
    assert (tuple(build.arguments[1]) == far) == (sites == "far"), (build.arguments[1], far)
    with pytest.raises(Sc2DataError, match="unknown sites 'near'"):
        ReducedRandomAgent(0, sites="near")


def test_far_sites_raise_the_macro_rules_supply_ceiling() -> None:
    """On far sites more depots fit: the same rules end with a higher supply cap."""
    caps = {}
    for sites in ("random", "far"):
        frames, events = _episode("macro-rules", 0, MacroRulesAgent(0, sites=sites))
        caps[sites] = int(frames[-1].observation["player"][_P.food_cap])
        assert events["died", T.Marine] == 0
    assert caps["far"] >= caps["random"] + 16, caps
