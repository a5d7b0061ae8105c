"""Policy observations: the compact encoding against the pysc2 layers it comes from, and the
simulator drawing only what is read."""

from __future__ import annotations

import numpy as np
import pytest

from sc2data._pysc2 import actions, features, units
from sc2data.game.sim import BuildMarinesEnv
from sc2data.ground.errors import Sc2DataError
from sc2data.rl.envs import PAPER_FUNCTIONS, BuildMarinesGym
from sc2data.rl.obs import UNIT_TYPES, ObsConfig, Observer

S = features.SCREEN_FEATURES


def _played(steps: int = 400) -> object:
    """An observation with SCVs mining, a depot and a barracks (the scripted agent's)."""
    from sc2data.game.agents import make_agent

    env = BuildMarinesEnv(seed=0)
    agent = make_agent("scripted", seed=0)
    agent.setup(env.observation_spec()[0], env.action_spec()[0])
    agent.reset()
    ts = env.reset()[0]
    for _ in range(steps):
        ts = env.step([agent.step(ts)])[0]
    return ts.observation


def test_compact_one_hot_follows_the_layers() -> None:
    obs = _played()
    ob = Observer(ObsConfig(kind="compact"))
    out = ob(obs)
    assert ob.space.contains(out)
    screen = np.asarray(obs["feature_screen"])
    unit_type = screen[S.unit_type.index]
    for c, u in enumerate(UNIT_TYPES):
        assert (out["screen"][c] == (unit_type == u)).all(), units.get_unit_type(u).name
    scv = UNIT_TYPES.index(units.Terran.SCV)
    marine = UNIT_TYPES.index(units.Terran.Marine)
    assert out["screen"][scv].any() and scv != marine  # two channels, not 0.0229 vs 0.0245
    rel = screen[S.player_relative.index]
    n = len(UNIT_TYPES)
    assert (out["screen"][n] == (rel == 1)).all() and (out["screen"][n + 1] == (rel == 3)).all()
    assert (out["screen"][n + 2] == (screen[S.selected.index] > 0)).all()
    assert (out["screen"][-2] == np.minimum(screen[S.build_progress.index], 255)).all()
    vec = out["vector"]
    player = np.asarray(obs["player"], dtype=np.float64)
    assert np.allclose(vec[:len(player)], np.log1p(player))
    available = set(np.asarray(obs["available_actions"]).tolist())
    flags = [int(actions.FUNCTIONS[f].id) in available for f in PAPER_FUNCTIONS]
    assert (vec[-len(PAPER_FUNCTIONS):] == flags).all()


def test_compact_32_sums_one_hot_cells_and_averages_scalars() -> None:
    obs = _played()
    full = Observer(ObsConfig(kind="compact"))(obs)["screen"].astype(np.int64)
    half = Observer(ObsConfig(kind="compact", size=32))
    out = half(obs)["screen"]
    assert out.shape == (len(half.screen_channels), 32, 32)
    cells = full.reshape(len(full), 32, 2, 32, 2).sum(axis=(2, 4))
    n_onehot = len(half.screen_channels) - 3
    assert (out[:n_onehot] == cells[:n_onehot]).all()
    assert (out[n_onehot:] == cells[n_onehot:] // 4).all()
    assert half.scales()["screen"][:n_onehot] == [4.0] * n_onehot


def test_minimap_channels_are_optional() -> None:
    obs = _played(10)
    without = Observer(ObsConfig(kind="compact"))
    with_map = Observer(ObsConfig(kind="compact", minimap=True))
    assert "minimap" not in without.space.spaces
    out = with_map(obs)
    assert out["minimap"].shape == (4, 64, 64) and out["minimap"][3].any()  # the camera box


def test_stored_observation_is_the_schema_extract() -> None:
    obs = _played(10)
    ob = Observer(ObsConfig(kind="stored"))
    out = ob(obs)
    assert set(out) == set(ob.schema.keys())
    assert all((out[k] == v).all() for k, v in ob.schema.extract(obs).items())


def test_bad_observation_settings_are_errors() -> None:
    with pytest.raises(Sc2DataError, match="unknown observation"):
        Observer(ObsConfig(kind="pixels"))
    with pytest.raises(Sc2DataError, match="--obs-size"):
        Observer(ObsConfig(kind="compact", size=48))


def test_the_simulator_draws_what_is_asked_exactly_and_nothing_else() -> None:
    """Layers asked for (and those the env's own masks read) equal a full drawing of the same
    game; every other layer is 0; the minimap is skipped when none of its layers is asked."""
    from sc2data.game.sim.observe import ENV_SCREEN

    asked = frozenset({"screen/unit_hit_points", "screen/unit_density"})
    full, part = BuildMarinesEnv(seed=3), BuildMarinesEnv(seed=3, layers=asked)
    a, b = full.reset()[0], part.reset()[0]
    for _ in range(40):
        a = full.step([actions.FUNCTIONS.no_op()])[0]
        b = part.step([actions.FUNCTIONS.no_op()])[0]
    sa = np.asarray(a.observation["feature_screen"])
    sb = np.asarray(b.observation["feature_screen"])
    drawn = {k.split("/")[1] for k in asked} | set(ENV_SCREEN) | {
        "height_map", "visibility_map", "pathable"}
    for f in S:
        if f.name in drawn:
            assert (sa[f.index] == sb[f.index]).all(), f.name
        else:
            assert not sb[f.index].any(), f.name
    assert sa[S.unit_density_aa.index].any()  # it was there to draw
    assert not np.asarray(b.observation["feature_minimap"]).any()


def test_gym_env_with_compact_obs_passes_the_env_checker() -> None:
    from gymnasium.utils.env_checker import check_env

    env = BuildMarinesGym("paper", obs="compact", game_loops=8 * 30)
    check_env(env, skip_render_check=True)


def test_macro_clock_features_by_hand() -> None:
    from sc2data.rl.obs import GAME_LOOPS, MACROS, MacroClock

    clock = MacroClock()
    assert np.all(clock.features(0) == 1.0)  # nothing acted: as long ago as an episode lasts
    clock.acted(1, 100)
    f = clock.features(100)
    assert f[1] == 0.0 and np.all(np.delete(f, 1) == 1.0) and len(f) == len(MACROS)
    assert clock.features(199)[1] == pytest.approx(np.log(100) / np.log(GAME_LOOPS + 1))
    assert clock.features(100 + 2 * GAME_LOOPS)[1] == 1.0  # capped
    clock.reset()
    assert np.all(clock.features(500) == 1.0)


def test_history_needs_the_clock_and_widens_the_vector() -> None:
    obs = _played(50)
    plain = Observer(ObsConfig("compact", size=32))
    timed = Observer(ObsConfig("compact", size=32, history=True))
    from sc2data.rl.obs import MACROS, MacroClock

    assert timed.space["vector"].shape[0] == plain.space["vector"].shape[0] + len(MACROS)
    with pytest.raises(ValueError, match="MacroClock"):
        timed(obs)
    a, b = plain(obs), timed(obs, clock=MacroClock())
    assert np.array_equal(b["vector"][:-len(MACROS)], a["vector"])
    assert np.array_equal(b["screen"], a["screen"])
