"""Selection by point, rectangle, idle worker, army, control group and multi-panel."""

from __future__ import annotations

import numpy as np

from sc2data._pysc2 import features
from sc2data.game.sim import mapdata as md
from tests.game.sim.sim_helpers import (
    F,
    new_env,
    of_type,
    pixel,
    scvs,
    select,
    step,
    unit_pixel,
)


def test_select_point_on_an_scv() -> None:
    env, _ = new_env()
    u = scvs(env)[0]
    obs = select(env, u).observation
    assert obs["single_select"].shape == (1, 7)
    row = obs["single_select"][0]
    assert row.unit_type == md.SCV
    assert row.player_relative == features.PlayerRelative.SELF
    assert row.health == 45
    assert obs["multi_select"].shape == (0, 7)
    screen = obs["feature_screen"]
    assert (screen.selected == 1).sum() >= 1
    assert set(np.unique(np.asarray(screen.unit_type)[np.asarray(screen.selected) == 1])) == \
        {md.SCV}


def test_select_point_on_ground_clears() -> None:
    env, _ = new_env()
    select(env, env.game.cc)
    obs = step(env, F.select_point("select", pixel(40.0, 22.0))).observation
    assert obs["single_select"].shape == (0, 7)
    assert np.asarray(obs["feature_screen"].selected).sum() == 0


def test_select_point_on_cc_shows_production() -> None:
    env, _ = new_env()
    env.game.minerals = 100
    obs = select(env, env.game.cc).observation
    assert obs["single_select"][0].unit_type == md.CC
    assert F.build_queue.id in obs["available_actions"]
    obs = step(env, F.Train_SCV_quick("now")).observation
    assert obs["build_queue"].shape == (1, 7)
    assert obs["build_queue"][0].unit_type == md.SCV
    assert 0 < obs["build_queue"][0].build_progress < 10
    assert obs["production_queue"].shape == (1, 2)


def test_select_rect_over_scvs() -> None:
    env, obs = new_env()
    ys, xs = np.nonzero(np.asarray(obs["feature_screen"].unit_type) == md.SCV)
    obs = step(env, F.select_rect("select", [int(xs.min()), int(ys.min())],
                                  [int(xs.max()), int(ys.max())])).observation
    multi = obs["multi_select"]
    assert multi.shape[0] >= 2
    assert (multi[:, features.UnitLayer.unit_type] == md.SCV).all()
    assert obs["single_select"].shape == (0, 7)
    assert F.select_unit.id in obs["available_actions"]


def test_select_rect_prefers_units_over_structures() -> None:
    env, _ = new_env()
    obs = step(env, F.select_rect("select", [0, 0], [63, 63])).observation
    types = set(obs["multi_select"][:, 0])
    assert types == {md.SCV}
    obs = step(env, F.select_rect("select", pixel(29.0, 29.0), pixel(30.0, 28.0))).observation
    assert obs["single_select"][0].unit_type == md.CC


def test_select_point_toggle_and_all_type() -> None:
    env, _ = new_env()
    a, b = scvs(env)[:2]
    select(env, a)
    obs = step(env, F.select_point("toggle", unit_pixel(env, b))).observation
    assert obs["multi_select"].shape == (2, 7)
    obs = step(env, F.select_point("toggle", unit_pixel(env, b))).observation
    assert obs["single_select"].shape == (1, 7)
    obs = step(env, F.select_point("select_all_type", unit_pixel(env, a))).observation
    assert obs["multi_select"].shape == (12, 7)


def test_select_idle_worker() -> None:
    env, _ = new_env()
    g = env.game
    for u in scvs(env)[:3]:
        g.order_idle(u, float(g.loop))
    obs = step(env).observation
    assert obs["player"].idle_worker_count == 3
    obs = step(env, F.select_idle_worker("select")).observation
    assert obs["single_select"][0].unit_type == md.SCV
    first = g.selection[0]
    obs = step(env, F.select_idle_worker("select")).observation
    assert g.selection[0] is not first  # cycles through the idle workers
    obs = step(env, F.select_idle_worker("select_all")).observation
    assert obs["multi_select"].shape == (3, 7)


def test_select_army() -> None:
    env, obs = new_env()
    assert F.select_army.id not in obs["available_actions"]
    g = env.game
    for i in range(3):
        g._create(md.MARINE, 1, 35.0 + i, 25.0)
        g.army_count += 1
    obs = step(env).observation
    assert obs["player"].army_count == 3
    obs = step(env, F.select_army("select")).observation
    assert obs["multi_select"].shape == (3, 7)
    assert (obs["multi_select"][:, 0] == md.MARINE).all()


def test_select_unit_from_multi_panel() -> None:
    env, _ = new_env()
    step(env, F.select_rect("select", [0, 0], [63, 63]))
    obs = step(env, F.select_unit("select", 2)).observation
    assert obs["single_select"].shape == (1, 7)
    step(env, F.select_rect("select", [0, 0], [63, 63]))
    obs = step(env, F.select_unit("deselect", 0)).observation
    assert obs["multi_select"].shape == (11, 7)


def test_control_groups() -> None:
    env, _ = new_env()
    select(env, env.game.cc)
    obs = step(env, F.select_control_group("set", 1)).observation
    assert list(obs["control_groups"][1]) == [md.CC, 1]
    step(env, F.select_point("select", unit_pixel(env, scvs(env)[0])))
    obs = step(env, F.select_control_group("recall", 1)).observation
    assert obs["single_select"][0].unit_type == md.CC


def test_selected_structure_layers() -> None:
    env, _ = new_env()
    obs = select(env, of_type(env, md.MINERAL)[0]).observation
    assert obs["single_select"][0].unit_type == md.MINERAL
    assert obs["single_select"][0].player_relative == features.PlayerRelative.NEUTRAL
    assert sorted(obs["available_actions"]) == [0, 1, 2, 3, 4]
