"""The simulator's specs and observations against pysc2's own, for our interface format."""

from __future__ import annotations

import numpy as np
import pytest

from sc2data._pysc2 import actions, features
from sc2data.game.env import interface_format, make_env
from sc2data.game.sim import BuildMarinesEnv
from tests.game.sim.sim_helpers import F, new_env, step

named_array = features.named_array
NAMED = {"feature_screen", "feature_minimap", "player", "score_cumulative",
         "score_by_category", "score_by_vital"}


def pysc2_spec() -> dict:
    return features.Features(interface_format()).observation_spec()


def check_obs(obs: dict, spec: dict) -> None:
    assert set(obs) == set(spec) | {"map_name"}, set(obs) ^ set(spec)
    for key, shape in spec.items():
        value = obs[key]
        if key == "map_name":
            assert value == "BuildMarines"
            continue
        assert isinstance(value, np.ndarray), key
        assert value.dtype == np.int32, (key, value.dtype)
        assert value.ndim == len(shape), (key, value.shape, shape)
        for got, want in zip(value.shape, shape):
            assert want == 0 or got == want, (key, value.shape, shape)
    for key in NAMED:
        assert isinstance(obs[key], named_array.NamedNumpyArray), key


def test_observation_spec_is_pysc2s() -> None:
    env = BuildMarinesEnv(seed=0)
    (spec,) = env.observation_spec()
    assert dict(spec) == dict(pysc2_spec())
    assert spec["feature_screen"] == (27, 64, 64)
    assert spec["feature_minimap"] == (11, 64, 64)


def test_action_spec_is_pysc2s() -> None:
    (spec,) = BuildMarinesEnv(seed=0).action_spec()
    ref = features.Features(interface_format()).action_spec()
    assert [f.id for f in spec.functions] == [f.id for f in ref.functions]
    assert [(t.name, t.sizes) for t in spec.types] == [(t.name, t.sizes) for t in ref.types]
    assert spec.types.screen.sizes == (64, 64)


def test_every_observation_matches_the_spec() -> None:
    spec = pysc2_spec()
    env, obs = new_env(seed=3)
    check_obs(obs, spec)
    rng = np.random.default_rng(3)
    (aspec,) = env.action_spec()
    for _ in range(300):
        fid = int(rng.choice(obs["available_actions"]))
        args = [[int(rng.integers(0, s)) for s in a.sizes] for a in aspec.functions[fid].args]
        obs = env.step([actions.FunctionCall(fid, args)])[0].observation
        check_obs(obs, spec)


def test_named_access_like_pysc2() -> None:
    _, obs = new_env()
    assert obs["player"].minerals == 50
    assert obs["player"].food_cap == 15
    assert obs["feature_screen"].unit_type.shape == (64, 64)
    assert obs.feature_minimap.camera.sum() > 0
    assert obs["score_cumulative"].score == 0


def test_selection_arrays_are_named_rows() -> None:
    env, obs = new_env()
    obs = step(env, F.select_army("select") if 7 in obs["available_actions"]
               else F.select_idle_worker("select") if 6 in obs["available_actions"]
               else F.select_rect("select", [0, 0], [63, 63])).observation
    multi = obs["multi_select"]
    assert multi.shape == (12, 7)
    assert isinstance(multi, named_array.NamedNumpyArray)
    assert (multi[:, features.UnitLayer.unit_type] == 45).all()
    assert multi[0].health == 45


def test_make_env_builds_the_simulator() -> None:
    env = make_env("sim", seed=1, step_mul=8)
    assert isinstance(env, BuildMarinesEnv)
    env.close()


def test_bad_step_mul() -> None:
    with pytest.raises(ValueError):
        BuildMarinesEnv(seed=0, step_mul=0)
