"""Episodes: TimeStep semantics, length, reward, determinism and the events record."""

from __future__ import annotations

import numpy as np

from sc2data._pysc2 import actions, environment
from sc2data.game.sim import EVENT_KINDS, BuildMarinesEnv, Event
from sc2data.game.sim import mapdata as md
from tests.game.sim.sim_helpers import (
    BARRACKS_SITE,
    F,
    new_env,
    of_type,
    select,
    step,
    wait_until,
)

FIRST, MID, LAST = environment.StepType.FIRST, environment.StepType.MID, environment.StepType.LAST


def random_calls(env: BuildMarinesEnv, obs: dict, rng: np.random.Generator) -> actions.FunctionCall:
    (spec,) = env.action_spec()
    fid = int(rng.choice(obs["available_actions"])) if rng.random() < 0.5 else 0
    args = [[int(rng.integers(0, s)) for s in a.sizes] for a in spec.functions[fid].args]
    return actions.FunctionCall(fid, args)


def test_timesteps_like_sc2env() -> None:
    env = BuildMarinesEnv(seed=0)
    (ts,) = env.reset()
    assert ts.step_type == FIRST and ts.reward == 0 and ts.discount == 0
    assert ts.observation["game_loop"][0] == 0
    (ts,) = env.step([F.no_op()])
    assert ts.step_type == MID and ts.discount == 1
    assert ts.observation["game_loop"][0] == 8


def test_full_episode_ends_with_last_and_reward_is_marines() -> None:
    env = BuildMarinesEnv(seed=5)
    g = env.game
    rax = g._create(md.BARRACKS, 1, *BARRACKS_SITE)
    (ts,) = env.reset()
    step(env)
    select(env, rax)
    total, steps = 0.0, 2
    while ts.step_type != LAST:
        call = F.Train_Marine_quick("now") if (
            F.Train_Marine_quick.id in ts.observation["available_actions"]
            and ts.observation["player"].minerals >= 50 and steps % 10 == 0) else F.no_op()
        (ts,) = env.step([call])
        total += ts.reward
        steps += 1
    assert steps == 1800
    assert ts.discount == 0
    assert ts.observation["game_loop"][0] == 14_400
    made = len([e for e in g.events if e.kind == "completed" and e.unit_type == md.MARINE])
    assert total == ts.observation["score_cumulative"].score == g.score > 0
    assert made <= g.score
    (ts,) = env.step([F.no_op()])  # stepping after LAST starts a new episode
    assert ts.step_type == FIRST and ts.observation["game_loop"][0] == 0


def test_step_mul_is_a_parameter() -> None:
    env = BuildMarinesEnv(seed=0, step_mul=16)
    env.reset()
    n = 0
    while True:
        (ts,) = env.step([F.no_op()])
        n += 1
        if ts.step_type == LAST:
            break
    assert n == 900
    (ts,) = env.step([F.no_op()])
    (ts,) = env.step([F.no_op()], step_mul=4)
    assert ts.observation["game_loop"][0] == 4


def run(seed: int, steps: int) -> list[dict]:
    env, obs = new_env(seed=seed)
    rng = np.random.default_rng(seed)
    out = [obs]
    for _ in range(steps):
        (ts,) = env.step([random_calls(env, out[-1], rng)])
        out.append(ts.observation)
    return out


def test_same_seed_same_observations() -> None:
    a, b = run(7, 400), run(7, 400)
    for oa, ob in zip(a, b):
        assert oa.keys() == ob.keys()
        for k in oa:
            if k != "map_name":
                np.testing.assert_array_equal(np.asarray(oa[k]), np.asarray(ob[k]), err_msg=k)


def test_seed_chooses_the_start_side() -> None:
    sides = set()
    for seed in range(8):
        env, _ = new_env(seed=seed)
        sides.add(min(u.x0 for u in env.game.units.values() if u.utype == md.SCV) > md.CC_POS[0])
    assert sides == {True, False}


def test_events_record() -> None:
    env, _ = new_env()
    g = env.game
    g.minerals = 1000
    assert env.events == []
    select(env, g.cc)
    step(env, F.Train_SCV_quick("now"))
    (queued,) = [e for e in env.events if e.kind == "queued"]
    assert queued == Event(g.loop - 8, "queued", md.SCV, g.cc.tag)
    step(env, F.build_queue(0))
    assert [e.kind for e in env.events if e.kind != "returned"] == ["cancelled"]
    step(env, F.Train_SCV_quick("now"))
    wait_until(env, lambda: any(e.kind == "completed" for e in env.events), limit=40)
    assert any(e.unit_type == md.SCV for e in env.events if e.kind == "completed")
    kinds = {e.kind for e in g.events} | {"returned"}
    assert kinds <= set(EVENT_KINDS)
    assert all(g.loop - 8 < e.loop <= g.loop for e in env.events)
    ret = [e for e in env.events if e.kind == "returned"]
    assert all(e.unit_type == md.SCV for e in ret)


def test_events_placed_died() -> None:
    env, _ = new_env()
    g = env.game
    a = g._create(md.MARINE, 1, 35.0, 25.0)
    b = g._create(md.MARINE, 1, 37.0, 25.0)
    g.army_count += 2
    g.food_army += 2
    step(env)
    select(env, a)
    step(env, F.Attack_screen("now", [int(x) for x in md.world_to_screen(37.0, 25.0)]))
    ts = wait_until(env, lambda: not b.alive, limit=40)
    died = [e for e in env.events if e.kind == "died"]
    assert died == [Event(died[0].loop, "died", md.MARINE, b.tag)]
    assert ts.observation["player"].food_army == 1
    assert ts.observation["player"].army_count == 1
    assert of_type(env, md.MARINE) == [a]
