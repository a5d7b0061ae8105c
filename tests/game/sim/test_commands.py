"""FunctionCall validation and available_actions, held against pysc2's own code."""

from __future__ import annotations

from typing import Any

import pytest

from sc2data._pysc2 import actions, features, sc2_env
from sc2data.game.env import interface_format
from sc2data.game.sim import mapdata as md
from sc2data.game.sim.commands import functions_for
from tests.game.sim.sim_helpers import (
    F,
    new_env,
    of_type,
    pixel,
    scvs,
    select,
    step,
    wait_until,
)

sc_pb = sc2_env.sc_pb


def pysc2_error(call: Any, available_abilities: tuple[tuple[int, bool], ...] = (),
                idle: int = 0) -> BaseException:
    """The exception pysc2's ``Features.transform_action`` raises for ``call``."""
    obs = sc_pb.Observation()
    obs.player_common.idle_worker_count = idle
    for ability_id, point in available_abilities:
        a = obs.abilities.add()
        a.ability_id = ability_id
        a.requires_point = point
    with pytest.raises(Exception) as err:
        features.Features(interface_format()).transform_action(obs, call)
    return err.value


@pytest.mark.parametrize("call", [
    actions.FunctionCall(42, [[0], [10, 10]]),      # Build_Barracks_screen, not available
    actions.FunctionCall(477, [[0]]),               # Train_Marine_quick, nothing selected
    actions.FunctionCall(9999, []),                 # not a function (pysc2: IndexError)
    actions.FunctionCall(2, [[0]]),                 # select_point, missing an argument
    actions.FunctionCall(2, [[0], [-1, 5]]),        # negative coordinate
    actions.FunctionCall(3, [[0], [1, 2, 3], [4, 5]]),  # a point with 3 values
], ids=["unavailable", "nothing-selected", "bad-id", "arg-count", "negative", "point-size"])
def test_refused_like_pysc2(call: Any) -> None:
    env, _ = new_env()
    want = pysc2_error(call)
    with pytest.raises(Exception) as err:
        env.step([call])
    assert type(err.value) is type(want)
    assert str(err.value) == str(want)
    assert env.game.loop == 0  # nothing happened


def test_large_coordinates_pass_like_pysc2() -> None:
    """pysc2 only rejects negative values; a click past the screen is sent to the game."""
    env, _ = new_env()
    obs = step(env, F.select_point("select", [70, 70])).observation
    assert obs["game_loop"][0] == 8
    assert obs["single_select"].shape == (0, 7)


def test_available_functions_follow_pysc2s_derivation() -> None:
    scv = {(F.Harvest_Gather_SCV_screen.ability_id, True),
           (F.Build_SupplyDepot_screen.ability_id, True), (F.Smart_screen.ability_id, True)}
    got = functions_for(frozenset(scv))
    assert got == {F.Harvest_Gather_screen.id, F.Build_SupplyDepot_screen.id,
                   F.Smart_screen.id, F.Smart_minimap.id}
    obs = sc_pb.Observation()
    for ability_id, point in scv:
        a = obs.abilities.add()
        a.ability_id = ability_id
        a.requires_point = point
    ref = set(features.Features(interface_format()).available_actions(obs)) - {0, 1, 2, 3, 4}
    assert ref == got


def test_command_cards() -> None:
    env, obs = new_env()
    assert sorted(obs["available_actions"]) == [0, 1, 2, 3, 4]
    obs = select(env, scvs(env)[0]).observation
    card = set(obs["available_actions"]) - {0, 1, 2, 3, 4}
    assert card <= {F.Harvest_Gather_screen.id, F.Harvest_Return_quick.id,
                    F.Build_SupplyDepot_screen.id, F.Smart_screen.id, F.Smart_minimap.id}
    assert {F.Harvest_Gather_screen.id, F.Build_SupplyDepot_screen.id} <= card
    assert F.Move_screen.id not in card and F.Attack_screen.id not in card
    obs = select(env, env.game.cc).observation
    assert set(obs["available_actions"]) == {0, 1, 2, 3, 4, F.build_queue.id,
                                             F.Train_SCV_quick.id, F.Rally_Workers_screen.id,
                                             F.Rally_Workers_minimap.id, F.Smart_screen.id,
                                             F.Smart_minimap.id}


def test_return_cargo_only_when_carrying() -> None:
    env, _ = new_env()
    u = scvs(env)[0]
    wait_until(env, lambda: u.cargo > 0, limit=60)
    obs = select(env, u).observation
    if u.cargo:
        assert F.Harvest_Return_quick.id in obs["available_actions"]
    wait_until(env, lambda: u.cargo == 0, limit=60)
    obs = select(env, u).observation
    if not u.cargo:
        assert F.Harvest_Return_quick.id not in obs["available_actions"]


def test_marine_card() -> None:
    env, _ = new_env()
    g = env.game
    m = g._create(md.MARINE, 1, 35.0, 25.0)
    g.army_count += 1
    obs = step(env).observation
    assert F.select_army.id in obs["available_actions"]
    obs = step(env, F.select_army("select")).observation
    card = set(obs["available_actions"]) - {0, 1, 2, 3, 4, 7}
    assert card == {F.Attack_screen.id, F.Attack_minimap.id, F.Move_screen.id,
                    F.Move_minimap.id, F.Patrol_screen.id, F.Patrol_minimap.id,
                    F.HoldPosition_quick.id, F.Stop_quick.id, F.Smart_screen.id,
                    F.Smart_minimap.id}
    step(env, F.Move_screen("now", pixel(38.0, 25.0)))
    obs = step(env).observation
    assert m.pos(env.game.loop)[0] > 35.0
    assert obs["single_select"][0].unit_type == md.MARINE


def test_gather_sends_an_idle_worker_to_mine() -> None:
    env, _ = new_env()
    g = env.game
    u = scvs(env)[0]
    g.order_idle(u, float(g.loop))
    obs = step(env).observation
    assert obs["player"].idle_worker_count == 1
    obs = step(env, F.select_idle_worker("select")).observation
    assert obs["single_select"][0].unit_type == md.SCV
    patch = of_type(env, md.MINERAL)[0]
    step(env, F.Harvest_Gather_screen("now", pixel(patch.x1, patch.y1)))
    assert "gathered" in [e.kind for e in env.events]
    obs = step(env).observation
    assert obs["player"].idle_worker_count == 0
    assert F.select_idle_worker.id not in obs["available_actions"]
