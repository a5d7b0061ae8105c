"""Feature layers drawn by their pysc2 meaning (blob sizes as measured on real 64×64
observations)."""

from __future__ import annotations

import numpy as np
import pytest

from sc2data._pysc2 import features
from sc2data.game.sim import mapdata as md
from sc2data.game.sim.observe import DiskStamp, stamp
from tests.game.sim.sim_helpers import (
    DEPOT_SITE,
    F,
    build,
    new_env,
    of_type,
    scvs,
    select,
    step,
    wait_until,
)

S = features.SCREEN_FEATURES
M = features.MINIMAP_FEATURES


def layer(obs: dict, name: str) -> np.ndarray:
    return np.asarray(obs["feature_screen"][getattr(S, name).index])


def test_blob_sizes_match_the_real_game() -> None:
    _, obs = new_env()
    ut = layer(obs, "unit_type")
    assert 165 <= (ut == md.CC).sum() <= 178  # 5×5 base ≈ 15×15 px, 168–177 px measured
    ys, xs = np.nonzero(ut == md.CC)
    assert 14 <= xs.max() - xs.min() + 1 <= 16
    cx, cy = md.world_to_screen(*md.CC_POS)
    assert abs(xs.mean() - cx) < 1 and abs(ys.mean() - cy) < 1  # CC near (23.7, 24.0) px
    minerals = (ut == md.MINERAL).sum()
    assert 8 * 20 <= minerals <= 8 * 32  # ≈29–32 px each, partly covered by workers
    assert 12 * 2 <= (ut == md.SCV).sum() <= 12 * 5


def test_3x3_building_is_about_10x10() -> None:
    n, flat, disk, _ = stamp(np.array([30.3]), np.array([20.7]),
                             md.UNIT_DATA[md.BARRACKS].radius * md.PX_PER_UNIT, 64)
    assert 70 <= disk.sum() <= 80  # 73–80 px measured
    small = DiskStamp(0.375 * md.PX_PER_UNIT, 64)
    fd, _, cov = small(np.array([[10.0], [10.0]]))  # centred on a pixel corner
    assert (fd < 4096).sum() == 4  # a 2×2 square
    assert cov.sum() == pytest.approx(np.pi, abs=0.3)


def test_unit_layers_at_the_start() -> None:
    _, obs = new_env()
    pr = layer(obs, "player_relative")
    pid = layer(obs, "player_id")
    ut = layer(obs, "unit_type")
    assert set(np.unique(pr)) == {0, 1, 3}
    assert (pr[ut == md.MINERAL] == features.PlayerRelative.NEUTRAL).all()
    assert (pid[ut == md.MINERAL] == 16).all() and (pid[ut == md.CC] == 1).all()
    hp = layer(obs, "unit_hit_points")
    assert (hp[ut == md.CC] == 1500).all() and (hp[ut == md.SCV] == 45).all()
    assert (hp[ut == md.MINERAL] == 0).all()
    assert (layer(obs, "unit_hit_points_ratio")[ut == md.CC] == 255).all()
    assert layer(obs, "selected").sum() == 0
    assert layer(obs, "build_progress").sum() == 0
    density = layer(obs, "unit_density")
    assert (density[ut > 0] >= 1).all() and (density[ut == 0] == 0).all()
    aa = layer(obs, "unit_density_aa")
    cc_only = (ut == md.CC) & (density == 1)
    assert aa.max() <= 255 and np.median(aa[cc_only]) == 16 and aa[cc_only].min() >= 5
    assert aa[ut == 0].max() < 16  # anti-aliased edges just outside the disks
    for name in ("creep", "power", "unit_energy", "unit_shields", "effects", "buffs"):
        assert layer(obs, name).sum() == 0, name


def test_terrain_layers() -> None:
    _, obs = new_env()
    pathable, buildable = layer(obs, "pathable"), layer(obs, "buildable")
    ut = layer(obs, "unit_type")
    assert pathable[10, 40] == 1 and buildable[10, 40] == 1
    assert (pathable[50:] == 0).all()  # rows below y_px 48 lie south of the playable area
    assert pathable[24, 24] == 0  # under the CC
    assert (layer(obs, "visibility_map")[:48] == 2).all()
    hm = layer(obs, "height_map")
    assert len(np.unique(hm[:47])) == 1 and hm[10, 10] > 0
    assert (pathable[ut == md.CC] == 0).mean() > 0.8  # the disk overhangs the 5×5 footprint


def test_minimap() -> None:
    _, obs = new_env()
    mm = obs["feature_minimap"]
    cam = np.asarray(mm.camera)
    ys, xs = np.nonzero(cam)
    assert xs.min() == 21 and xs.max() == 44  # 20.94 … 44.94 world x
    assert ys.min() == 27 and ys.max() == 50  # 64 − 37 … 64 − 13
    ut = np.asarray(mm.unit_type)
    ys, xs = np.nonzero(ut == md.CC)
    assert abs(xs.mean() + 0.5 - md.CC_POS[0]) < 1
    assert abs(ys.mean() + 0.5 - (64 - md.CC_POS[1])) < 1
    assert (ut == md.SCV).sum() >= 6
    assert (np.asarray(mm.player_relative)[ut == md.MINERAL] == 3).all()


def test_build_progress_rises() -> None:
    env, _ = new_env()
    env.game.minerals = 500
    build(env, F.Build_SupplyDepot_screen, *DEPOT_SITE)
    wait_until(env, lambda: bool(of_type(env, md.DEPOT)), limit=100)
    ts = step(env)
    bp = layer(ts.observation, "build_progress")
    ut = layer(ts.observation, "unit_type")
    first = bp[ut == md.DEPOT].max()
    assert 0 < first < 20
    for _ in range(20):
        ts = step(env)
    later = layer(ts.observation, "build_progress")[layer(ts.observation, "unit_type") == md.DEPOT]
    assert later.max() > first
    obs = select(env, of_type(env, md.DEPOT)[0]).observation
    assert 0 < obs["single_select"][0].build_progress < 100


def test_selected_layer_follows_selection() -> None:
    env, _ = new_env()
    obs = select(env, env.game.cc).observation
    sel = layer(obs, "selected")
    assert (layer(obs, "unit_type")[sel == 1] == md.CC).all() and sel.sum() > 150
    assert np.asarray(obs["feature_minimap"].selected).sum() > 10


def test_units_move_on_screen() -> None:
    env, obs = new_env()
    before = layer(obs, "unit_type") == md.SCV
    obs = step(env).observation
    after = layer(obs, "unit_type") == md.SCV
    assert (before != after).any()
    assert all(u.alive for u in scvs(env))


def test_minimap_shows_new_structures_and_marines() -> None:
    env, _ = new_env()
    g = env.game
    g._create(md.BARRACKS, 1, 38.5, 30.5)
    m = g._create(md.MARINE, 1, 40.0, 22.0)
    obs = step(env).observation
    ut = np.asarray(obs["feature_minimap"].unit_type)
    assert (ut == md.BARRACKS).sum() >= 9
    assert ut[int(64 - m.y1), int(m.x1)] == md.MARINE
