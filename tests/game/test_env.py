"""make_env: the real game's construction path, unknown backends, and (with SC2) real steps."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sc2data.game.env import make_env
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.vocab import BACKENDS

SC2DATA = Path(sys.executable).with_name("sc2data")


def test_sc2_backend_without_the_game_says_what_to_install(tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SC2PATH", str(tmp_path))
    with pytest.raises(Sc2DataError) as e:
        make_env("sc2", seed=1)
    msg = str(e.value)
    assert str(tmp_path) in msg and "SC2PATH" in msg and "BuildMarines.SC2Map" in msg
    assert "--env sim" in msg and "\n" not in msg


def test_sc2_backend_needs_the_map_as_well_as_the_binary(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    binary = tmp_path / "Versions" / "Base12345" / "SC2_x64"
    binary.parent.mkdir(parents=True)
    binary.touch()
    monkeypatch.setenv("SC2PATH", str(tmp_path))
    with pytest.raises(Sc2DataError, match="BuildMarines"):
        make_env("sc2")


def test_unknown_backend_lists_the_choices() -> None:
    with pytest.raises(Sc2DataError) as e:
        make_env("starcraft3")
    assert "'starcraft3'" in str(e.value)
    assert all(b in str(e.value) for b in BACKENDS)


def _cli(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    import os

    return subprocess.run([str(SC2DATA), *args], capture_output=True, text=True, timeout=120,
                          env={**os.environ, **(env or {})})


def test_cli_without_sc2_prints_one_line_and_exits_2(tmp_path: Path) -> None:
    r = _cli("render", "--env", "sc2", "--steps", "1", "--out", str(tmp_path / "f.png"),
             env={"SC2PATH": str(tmp_path)})
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sc2data: error: StarCraft II"), r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "f.png").exists()


def test_cli_unknown_backend_prints_one_line_and_exits_2(tmp_path: Path) -> None:
    r = _cli("render", "--env", "starcraft3", "--out", str(tmp_path / "f.png"))
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "sc2data: error: unknown environment 'starcraft3'; choose one of: sim, sc2"]


@pytest.mark.sc2
def test_real_game_plays_a_few_steps_with_the_scripted_agent() -> None:
    from sc2data._pysc2 import features
    from sc2data.game.agents import make_agent, play

    env = make_env("sc2", seed=3)
    try:
        steps = list(play(env, make_agent("scripted", seed=3), 20))
    finally:
        env.close()
    assert len(steps) == 20 and steps[0].first()
    obs = steps[-1].observation
    assert obs["feature_screen"].shape == (27, 64, 64)
    assert obs["feature_minimap"].shape == (11, 64, 64)
    loops = [int(np.asarray(t.observation["game_loop"])[0]) for t in steps]
    assert np.all(np.diff(loops) == 8)
    start = steps[0].observation["player"]
    assert (start[features.Player.food_used], start[features.Player.food_cap]) == (12, 15)
