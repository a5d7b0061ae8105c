"""``make_env``: one call for the embedded simulator or the real game, same pysc2 interface."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Literal

from sc2data import _pysc2
from sc2data._pysc2 import environment, interface_format
from sc2data.ground.errors import Sc2DataError
from sc2data.ground.vocab import BACKENDS, MAP_NAME, STEP_MUL

Backend = Literal["sim", "sc2"]

SC2_INSTALL_HINT = (
    "install StarCraft II (Linux package from Blizzard's s2client-proto page) and set SC2PATH to "
    "it, and put BuildMarines.SC2Map from pysc2's mini_games.zip under $SC2PATH/Maps/mini_games/; "
    "or use --env sim, the embedded simulator"
)


def sc2_path() -> Path:
    """Where pysc2 looks for StarCraft II on Linux (``SC2PATH``, else ``~/StarCraftII``)."""
    return Path(os.environ.get("SC2PATH", "~/StarCraftII")).expanduser()


def sc2_available() -> bool:
    """True where the SC2 binary and the BuildMarines map are both installed."""
    root = sc2_path()
    has_binary = any((root / "Versions").glob("Base*/SC2_x64"))
    maps = root / "Maps"
    has_map = (maps / "mini_games" / "BuildMarines.SC2Map").is_file() or \
        (maps / "BuildMarines.SC2Map").is_file()
    return has_binary and has_map


def sc2_env_kwargs(seed: int | None, step_mul: int = STEP_MUL) -> dict[str, Any]:
    """``SC2Env``'s arguments for BuildMarines: the map, one Terran agent, this project's
    interface format (also what :mod:`sc2data.testing.mock_sc2` builds its mock with)."""
    sc2_env = _pysc2.sc2_env
    return {"map_name": MAP_NAME, "players": [sc2_env.Agent(sc2_env.Race.terran)],
            "agent_interface_format": interface_format(), "step_mul": step_mul,
            "random_seed": seed}


def make_env(backend: str = "sim", *, seed: int | None = None, step_mul: int = STEP_MUL,
             **kwargs: Any) -> environment.Base:
    """A BuildMarines environment speaking pysc2's ``environment.Base`` interface.

    ``sim`` is the embedded simulator (default, no SC2 needed); ``sc2`` is pysc2's ``SC2Env`` on
    the real game. Extra keyword arguments go to the backend's constructor.
    """
    if backend == "sim":
        from sc2data.game.sim import BuildMarinesEnv

        return BuildMarinesEnv(seed=seed, step_mul=step_mul, **kwargs)
    if backend == "sc2":
        if not sc2_available():
            raise Sc2DataError(f"StarCraft II or the BuildMarines map was not found under "
                               f"{sc2_path()}; {SC2_INSTALL_HINT}")
        return _pysc2.sc2_env.SC2Env(**sc2_env_kwargs(seed, step_mul), **kwargs)
    raise Sc2DataError(f"unknown environment {backend!r}; choose one of: {', '.join(BACKENDS)}")
