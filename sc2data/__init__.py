"""sc2data: natural-language commands grounded in StarCraft II BuildMarines game states.

The public API, all loaded on first use so that ``import sc2data`` itself imports nothing heavy
(pysc2, h5py, pyarrow and torch come with the names that need them):

* ``make_env("sim" | "sc2", seed=…)`` — a BuildMarines pysc2 ``environment.Base``;
* ``make_agent(name, seed=…)`` — a pysc2 ``BaseAgent`` (``random``, ``reduced-random``,
  ``scripted``);
* ``Stacker(schema)`` — live observations into two-frame stacks;
* ``open_dataset(DIR)`` / ``Dataset`` — the stacks of a rollout folder;
* ``load_model(RUN)`` — a trained MEM as a batched reward signal (one torch thread a call by
  default: ``threads=``);
* ``Schema``, ``StackBatch`` — the state schema and a batch of stacks.

It also installs the import hook that makes pysc2 4.0.0 importable on Python 3.11
(:mod:`sc2data.ground._pysc2_compat`), so ``from pysc2.lib import features`` works after it, in
your code as in ours.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from sc2data.ground._pysc2_compat import install as _install_pysc2_fix

if TYPE_CHECKING:
    from sc2data.data.dataset import Dataset, open_dataset  # noqa: F401
    from sc2data.game.agents import make_agent  # noqa: F401
    from sc2data.game.env import make_env  # noqa: F401
    from sc2data.ground.stacker import Stacker  # noqa: F401
    from sc2data.model.scorer import load_model  # noqa: F401
    from sc2data.schema import Schema, StackBatch  # noqa: F401

_WHERE = {
    "Dataset": "sc2data.data.dataset",
    "open_dataset": "sc2data.data.dataset",
    "make_agent": "sc2data.game.agents",
    "make_env": "sc2data.game.env",
    "load_model": "sc2data.model.scorer",
    "Schema": "sc2data.schema",
    "StackBatch": "sc2data.schema",
    "Stacker": "sc2data.ground.stacker",
}
"""Each public name and the module it lives in."""

_install_pysc2_fix()

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    """Import a public name's module the first time the name is used."""
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'sc2data' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
