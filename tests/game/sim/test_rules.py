"""Game rules: costs, build times, supply, tech requirement, placement, queues."""

from __future__ import annotations

import pytest

from sc2data.game.sim import mapdata as md
from tests.game.sim.sim_helpers import (
    BARRACKS_SITE,
    DEPOT_SITE,
    F,
    build,
    new_env,
    of_type,
    pixel,
    scvs,
    select,
    step,
    wait,
    wait_until,
)


def test_train_scv_costs_50_and_takes_272_loops() -> None:
    env, _ = new_env()
    select(env, env.game.cc)
    obs = step(env, F.Train_SCV_quick("now")).observation
    queued_at = env.game.loop - 8
    assert obs["player"].minerals < 50 + 8  # 50 spent (a little mined meanwhile at most)
    assert env.game.spent == 50
    assert obs["player"].food_used == 13  # supply is taken when the SCV is queued …
    assert obs["player"].food_workers == 12  # … but the game counts only workers that exist
    assert obs["build_queue"].shape == (1, 7)
    n = len(scvs(env))
    ts = wait_until(env, lambda: len(scvs(env)) > n)
    assert env.game.loop - 8 < queued_at + 272 <= env.game.loop
    done = [e for e in env.events if e.kind == "completed" and e.unit_type == md.SCV]
    assert done and done[0].loop == queued_at + 272
    assert ts.observation["player"].food_workers == 13


def test_supply_depot_costs_100_and_completes_after_480_loops() -> None:
    env, _ = new_env()
    env.game.minerals = 1000
    build(env, F.Build_SupplyDepot_screen, *DEPOT_SITE)
    ts = wait_until(env, lambda: bool(of_type(env, md.DEPOT)), limit=100)
    depot = of_type(env, md.DEPOT)[0]
    placed = [e for e in env.events if e.kind == "placed"][0]
    assert placed.unit_type == md.DEPOT
    assert env.game.spent == 100
    assert ts.observation["player"].food_cap == 15  # not before it completes
    assert not depot.complete
    done_at = placed.loop + 480
    while env.game.loop < done_at - 8:
        ts = step(env)
        assert ts.observation["player"].food_cap == 15
    ts = wait_until(env, lambda: depot.complete, limit=3)
    assert [e.loop for e in env.events if e.kind == "completed"] == [done_at]
    assert ts.observation["player"].food_cap == 23


def test_barracks_needs_a_completed_depot() -> None:
    env, _ = new_env()
    env.game.minerals = 1000
    obs = select(env, scvs(env)[0]).observation
    assert F.Build_Barracks_screen.id not in obs["available_actions"]
    with pytest.raises(ValueError, match="Function 42/Build_Barracks_screen is currently not "
                                         "available"):
        env.step([F.Build_Barracks_screen("now", pixel(*BARRACKS_SITE))])
    step(env, F.Build_SupplyDepot_screen("now", pixel(*DEPOT_SITE)))
    wait_until(env, lambda: bool(of_type(env, md.DEPOT)), limit=100)
    obs = select(env, scvs(env)[1]).observation
    assert F.Build_Barracks_screen.id not in obs["available_actions"]  # depot still building
    wait_until(env, lambda: of_type(env, md.DEPOT)[0].complete, limit=70)
    obs = select(env, scvs(env)[1]).observation
    assert F.Build_Barracks_screen.id in obs["available_actions"]
    step(env, F.Build_Barracks_screen("now", pixel(*BARRACKS_SITE)))
    wait_until(env, lambda: bool(of_type(env, md.BARRACKS)), limit=100)
    placed = [e for e in env.events if e.kind == "placed"][0]
    rax = of_type(env, md.BARRACKS)[0]
    assert env.game.spent == 250
    wait_until(env, lambda: rax.complete, limit=140)
    assert [e.loop for e in env.events if e.kind == "completed"] == [placed.loop + 1040]


def test_marine_takes_400_loops_and_scores() -> None:
    env, _ = new_env()
    g = env.game
    rax = g._create(md.BARRACKS, 1, *BARRACKS_SITE)
    g.minerals = 500
    step(env)  # draw it: clicks hit what the last observation showed
    select(env, rax)
    ts = step(env, F.Train_Marine_quick("now"))
    queued_at = env.game.loop - 8
    assert (ts.observation["player"].food_used, ts.observation["player"].food_army) == (13, 0)
    total = 0.0
    while not of_type(env, md.MARINE):
        ts = step(env)
        total += ts.reward
    assert total == 1 and ts.reward == 1
    assert [e.loop for e in env.events if e.kind == "completed"] == [queued_at + 400]
    assert ts.observation["score_cumulative"].score == 1
    assert ts.observation["player"].army_count == 1
    assert (ts.observation["player"].food_used, ts.observation["player"].food_army) == (13, 1)


def test_queue_holds_five() -> None:
    env, _ = new_env()
    env.game.minerals = 1000
    env.game.food_cap = 200
    select(env, env.game.cc)
    for _ in range(5):
        obs = step(env, F.Train_SCV_quick("now")).observation
        assert len(obs["action_result"]) == 0
    assert obs["build_queue"].shape == (5, 7)
    obs = step(env, F.Train_SCV_quick("now")).observation
    assert list(obs["action_result"]) == [7]  # QueueIsFull
    assert obs["build_queue"].shape == (5, 7)
    assert env.game.spent == 250


def test_supply_cap_blocks_queueing() -> None:
    env, _ = new_env()
    env.game.minerals = 1000
    select(env, env.game.cc)
    for _ in range(3):
        step(env, F.Train_SCV_quick("now"))
    obs = step(env, F.Train_SCV_quick("now")).observation
    assert list(obs["action_result"]) == [13]  # NotEnoughFood: 15/15
    assert obs["player"].food_used == 15
    assert env.game.spent == 150


def test_not_enough_minerals() -> None:
    env, _ = new_env()
    env.game.minerals = 40
    select(env, env.game.cc)
    obs = step(env, F.Train_SCV_quick("now")).observation
    assert list(obs["action_result"]) == [9]
    assert obs["build_queue"].shape == (0, 7)


def test_cancel_refunds() -> None:
    env, _ = new_env()
    env.game.minerals = 200
    select(env, env.game.cc)
    step(env, F.Train_SCV_quick("now"))
    obs = step(env, F.Train_SCV_quick("now")).observation
    before = obs["player"].minerals
    obs = step(env, F.build_queue(1)).observation
    assert obs["build_queue"].shape == (1, 7)
    assert obs["player"].minerals >= before + 50
    assert obs["player"].food_used == 13
    assert [e.kind for e in env.events] .count("cancelled") == 1


@pytest.mark.parametrize("site", [(23.0, 28.0), md.CC_POS, (40.0, 18.5), (30.0, 15.0)],
                         ids=["minerals", "command-center", "playable-edge", "off-playable"])
def test_placement_refused(site: tuple[float, float]) -> None:
    env, _ = new_env()
    env.game.minerals = 1000
    ts = build(env, F.Build_SupplyDepot_screen, *site)
    assert list(ts.observation["action_result"]) == [44]  # CantBuildLocationInvalid
    wait(env, 40)
    assert not of_type(env, md.DEPOT)
    assert env.game.spent == 0


def test_placement_refused_on_overlap() -> None:
    env, _ = new_env()
    env.game.minerals = 1000
    build(env, F.Build_SupplyDepot_screen, *DEPOT_SITE)
    wait_until(env, lambda: bool(of_type(env, md.DEPOT)), limit=100)
    select(env, scvs(env)[3])
    ts = step(env, F.Build_SupplyDepot_screen("now", pixel(DEPOT_SITE[0] + 1, DEPOT_SITE[1])))
    assert list(ts.observation["action_result"]) == [44]
    wait(env, 40)
    assert len(of_type(env, md.DEPOT)) == 1
    assert env.game.spent == 100


def test_builder_goes_idle_after_building() -> None:
    env, _ = new_env()
    env.game.minerals = 1000
    build(env, F.Build_SupplyDepot_screen, *DEPOT_SITE)
    builder = scvs(env)[0]
    assert builder not in env.game.idle_workers
    wait_until(env, lambda: bool(of_type(env, md.DEPOT)) and of_type(env, md.DEPOT)[0].complete,
               limit=200)
    obs = step(env).observation
    assert builder in env.game.idle_workers
    assert obs["player"].idle_worker_count == 1
    assert F.select_idle_worker.id in obs["available_actions"]


def test_structure_hp_rises_while_built() -> None:
    env, _ = new_env()
    env.game.minerals = 1000
    build(env, F.Build_SupplyDepot_screen, *DEPOT_SITE)
    wait_until(env, lambda: bool(of_type(env, md.DEPOT)), limit=100)
    depot = of_type(env, md.DEPOT)[0]
    hp0 = depot.hp(env.game.loop)
    assert 40 <= hp0 <= 60  # 10% of 400, plus a step's progress
    wait(env, 30)
    assert depot.hp(env.game.loop) > hp0


def test_construction_pauses_without_its_scv_and_resumes() -> None:
    env, _ = new_env()
    env.game.minerals = 1000
    build(env, F.Build_SupplyDepot_screen, *DEPOT_SITE)
    builder = scvs(env)[0]
    wait_until(env, lambda: bool(of_type(env, md.DEPOT)), limit=100)
    depot = of_type(env, md.DEPOT)[0]
    wait(env, 5)
    patch = of_type(env, md.MINERAL)[0]
    step(env, F.Harvest_Gather_screen("now", pixel(patch.x1, patch.y1)))  # builder still selected
    p = depot.progress(env.game.loop)
    wait(env, 10)
    assert depot.progress(env.game.loop) == p  # paused
    select(env, scvs(env)[5])
    step(env, F.Smart_screen("now", pixel(depot.x1, depot.y1)))
    wait(env, 20)
    assert depot.progress(env.game.loop) > p
    assert depot.builder is scvs(env)[5] and depot.builder is not builder


def test_a_field_runs_out() -> None:
    env, _ = new_env()
    g = env.game
    patch = g.patches[0]
    patch.minerals = 5
    wait_until(env, lambda: not patch.alive, limit=100)
    assert any(e.kind == "died" and e.unit_type == md.MINERAL for e in env.events)
    wait(env, 30)
    assert all(u.patch is not patch for u in scvs(env))
    assert len(g.idle_workers) == 0


def test_several_actions_in_one_step() -> None:
    env, _ = new_env()
    env.game.minerals = 100
    (ts,) = env.step([[F.select_point("select", pixel(*md.CC_POS)), F.no_op()]])
    assert ts.observation["single_select"][0].unit_type == md.CC


def test_player_counts_units_in_production_only_in_food_used() -> None:
    """The game's meaning: ``food_used`` includes units in production; ``food_workers``,
    ``food_army``, ``army_count`` and ``idle_worker_count`` count only units that exist."""
    env, _ = new_env()
    g = env.game
    rax = g._create(md.BARRACKS, 1, *BARRACKS_SITE)
    g.minerals = 1000
    step(env)
    select(env, g.cc)
    step(env, F.Train_SCV_quick("now"))
    select(env, rax)
    p = step(env, F.Train_Marine_quick("now")).observation["player"]
    assert (p.food_used, p.food_workers, p.food_army, p.army_count) == (14, 12, 0, 0)
    p = wait_until(env, lambda: len(scvs(env)) == 13).observation["player"]
    assert (p.food_used, p.food_workers, p.food_army) == (14, 13, 0)
    p = wait_until(env, lambda: bool(of_type(env, md.MARINE))).observation["player"]
    assert (p.food_used, p.food_workers, p.food_army, p.army_count) == (14, 13, 1, 1)


def test_losing_a_producer_frees_the_supply_of_its_queue() -> None:
    env, _ = new_env()
    g = env.game
    rax = g._create(md.BARRACKS, 1, *BARRACKS_SITE)
    g.minerals = 1000
    step(env)
    select(env, rax)
    step(env, F.Train_Marine_quick("now"))
    p = step(env, F.Train_Marine_quick("now")).observation["player"]
    assert (p.food_used, p.food_army) == (14, 0)
    g._kill(rax, float(g.loop))
    p = step(env).observation["player"]
    assert (p.food_used, p.food_workers, p.food_army) == (12, 12, 0)
