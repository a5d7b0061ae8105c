"""Import pysc2 4.0.0 on Python 3.11 with no manual step.

Two known breakages of the last released pysc2 (4.0.0) on Python 3.11 are handled here, once, and every other
module imports pysc2 through this one:

* ``s2clientprotocol`` ships old generated protobuf code. We pin ``protobuf<3.21``; if another
  package forced a newer protobuf, the pure-Python implementation still loads the old code, so we
  select it before protobuf is first imported.
* ``pysc2/lib/colors.py`` calls ``random.shuffle(x, fn)``; the second argument was removed in 3.11.
  We accept and ignore it for the duration of the first import (pysc2 seeds that shuffle with a
  constant, so its palettes stay deterministic either way).

``sc2_env`` (the real game's environment) is imported on first use: through its human renderer
it imports scikit-video and SciPy, 1.8 of the 2.2 s that importing pysc2 took (``python -X
importtime``), which every command paid on start-up though only ``--env sc2`` needs it. The
interface format and its dimensions are ``features``' own classes, which ``sc2_env`` re-exports.
"""

from __future__ import annotations

import os
import random
import sys
from collections.abc import Callable, MutableSequence
from typing import Any

from sc2data.vocab import MINIMAP_SIZE, SCREEN_SIZE

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
if "google.protobuf" not in sys.modules:
    os.environ.setdefault("PROTOCOL_BUFFERS_PYTHON_IMPLEMENTATION", "python")

_shuffle = random.shuffle


def _shuffle_compat(x: MutableSequence[Any], random_fn: Callable[[], float] | None = None) -> None:
    """``random.shuffle`` accepting pysc2's removed ``random`` argument (Fisher-Yates with it)."""
    if random_fn is None:
        _shuffle(x)
        return
    for i in reversed(range(1, len(x))):
        j = int(random_fn() * (i + 1))
        x[i], x[j] = x[j], x[i]


random.shuffle = _shuffle_compat  # type: ignore[assignment]
try:
    from pysc2.agents import base_agent  # noqa: E402
    from pysc2.env import environment  # noqa: E402
    from pysc2.lib import actions, buffs, colors, features, point, units  # noqa: E402
finally:
    random.shuffle = _shuffle

__all__ = ["actions", "base_agent", "buffs", "colors", "environment", "features",
           "interface_format", "point", "sc2_env", "units"]


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
