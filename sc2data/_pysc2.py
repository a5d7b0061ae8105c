"""pysc2 for sc2data's modules: every one imports pysc2 through this one.

pysc2 4.0.0's two breakages on Python 3.11 are fixed by the import hook of
:mod:`sc2data.ground._pysc2_compat` (which ``import sc2data`` installs too, so that a user's own
``from pysc2.lib import features`` works after it); this module makes sure it is installed first.

``sc2_env`` (the real game's environment) is imported on first use: through its human renderer
it imports scikit-video and SciPy, 1.8 of the 2.2 s that importing pysc2 took (``python -X
importtime``), which every command paid on start-up though only ``--env sc2`` needs it. The
interface format and its dimensions are ``features``' own classes, which ``sc2_env`` re-exports.
"""

from __future__ import annotations

from typing import Any

from sc2data.ground._pysc2_compat import install
from sc2data.ground.vocab import MINIMAP_SIZE, SCREEN_SIZE

install()
from pysc2.agents import base_agent  # noqa: E402
from pysc2.env import environment  # noqa: E402
from pysc2.lib import actions, buffs, colors, features, point, units  # noqa: E402

__all__ = ["actions", "base_agent", "buffs", "colors", "environment", "features",
           "interface_format", "point", "sc2_env", "units"]  # noqa: F822  (sc2_env: lazy)


def __getattr__(name: str) -> Any:
    """``sc2_env``, imported the first time it is asked for (see the module docstring)."""
    if name != "sc2_env":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from pysc2.env import sc2_env

    globals()["sc2_env"] = sc2_env
    return sc2_env


def interface_format() -> features.AgentInterfaceFormat:
    """The agent interface the whole project uses: 64×64 feature screen and minimap (the simulator
    and the real game alike)."""
    return features.AgentInterfaceFormat(
        feature_dimensions=features.Dimensions(screen=SCREEN_SIZE, minimap=MINIMAP_SIZE))
