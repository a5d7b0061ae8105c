"""Import pysc2 4.0.0 on Python 3.11 with no manual step.

Two known breakages of the last released pysc2 (4.0.0) on Python 3.11 are handled here, once, and every other
module imports pysc2 through this one:

* ``s2clientprotocol`` ships old generated protobuf code. We pin ``protobuf<3.21``; if another
  package forced a newer protobuf, the pure-Python implementation still loads the old code, so we
  select it before protobuf is first imported.
* ``pysc2/lib/colors.py`` calls ``random.shuffle(x, fn)``; the second argument was removed in 3.11.
  We accept and ignore it for the duration of the first import (pysc2 seeds that shuffle with a
  constant, so its palettes stay deterministic either way).
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
    from pysc2.env import environment, sc2_env  # noqa: E402
    from pysc2.lib import actions, buffs, colors, features, point, units  # noqa: E402
finally:
    random.shuffle = _shuffle

__all__ = ["actions", "base_agent", "buffs", "colors", "environment", "features",
           "interface_format", "point", "sc2_env", "units"]


def interface_format() -> sc2_env.AgentInterfaceFormat:
    """The agent interface the whole project uses: 64×64 feature screen and minimap (the simulator
    and the real game alike)."""
    return sc2_env.AgentInterfaceFormat(
        feature_dimensions=sc2_env.Dimensions(screen=SCREEN_SIZE, minimap=MINIMAP_SIZE))
