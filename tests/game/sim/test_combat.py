"""Marines: attacking own units (the way scripted agents stay under the supply cap), moving."""

from __future__ import annotations

import math

from sc2data.game.sim import mapdata as md
from tests.game.sim.sim_helpers import (
    F,
    new_env,
    of_type,
    pixel,
    select,
    step,
    wait_until,
)


def two_marines(gap: float = 3.0):  # type: ignore[no-untyped-def]
    env, _ = new_env()
    g = env.game
    a = g._create(md.MARINE, 1, 34.0, 25.0)
    b = g._create(md.MARINE, 1, 34.0 + gap, 25.0)
    g.army_count += 2
    g.food_army += 2
    step(env)
    return env, a, b


def test_marine_kills_a_marine_with_its_real_weapon() -> None:
    env, a, b = two_marines()
    select(env, a)
    step(env, F.Attack_screen("now", pixel(b.x1, b.y1)))
    start = env.game.loop - 8
    wait_until(env, lambda: not b.alive, limit=40)
    (died,) = [e for e in env.events if e.kind == "died"]
    shots = math.ceil(45 / md.MARINE_DAMAGE)  # 8 shots of 6 damage, 0 armour
    assert died.loop == math.ceil(start + (shots - 1) * md.MARINE_COOLDOWN)
    assert env.game.damage_dealt == shots * md.MARINE_DAMAGE
    obs = step(env).observation
    assert obs["player"].food_used == 12 + 1
    assert obs["score_cumulative"].score == 0  # killing is not scored
    assert a.order == 0  # idle again


def test_marine_walks_into_range() -> None:
    env, a, b = two_marines(gap=9.0)
    select(env, a)
    step(env, F.Attack_screen("now", pixel(b.x1, b.y1)))
    wait_until(env, lambda: not b.alive, limit=60)
    x, _ = a.pos(env.game.loop)
    assert x > 34.5  # it closed in to 5 + radii
    assert abs((b.x1 - x) - (md.MARINE_RANGE + 0.75)) < 0.2


def test_attack_on_ground_just_moves() -> None:
    env, a, b = two_marines()
    select(env, a)
    step(env, F.Attack_screen("now", pixel(30.0, 22.0)))
    wait_until(env, lambda: a.order == 0, limit=60)
    assert b.alive and math.hypot(a.x1 - 30.0, a.y1 - 22.0) < 0.5


def test_marines_can_kill_an_scv_and_structures_have_armour() -> None:
    env, a, _ = two_marines()
    g = env.game
    depot = g._create(md.DEPOT, 1, 36.0, 30.0)
    step(env)
    select(env, a)
    step(env, F.Attack_screen("now", pixel(36.0, 30.0)))
    step(env)
    for _ in range(5):
        step(env)
    assert depot.dmg > 0 and depot.dmg % 5 == 0  # 6 − 1 armour per shot
    assert of_type(env, md.DEPOT) == [depot]


def test_units_stay_in_the_playable_area() -> None:
    env, a, _ = two_marines()
    select(env, a)
    step(env, F.Move_screen("now", [40, 63]))  # south of the playable area's edge (y 19)
    wait_until(env, lambda: a.order == 0, limit=60)
    assert a.y1 == md.PLAYABLE[1] + md.UNIT_DATA[md.MARINE].radius
