"""The project's vocabulary: the names and numbers every stage shares, defined once.

Plain constants with no imports, so any module (the recipe parser, the simulator, the CLI) can use
them without pulling in pysc2, h5py or torch.
"""

from __future__ import annotations

SCREEN_SIZE = 64
MINIMAP_SIZE = 64
"""Feature screen and minimap resolution in pixels (the paper's 64×64)."""

MAP_NAME = "BuildMarines"
"""The pysc2 mini-game every environment plays."""

STEP_MUL = 8
"""Game loops per agent step: pysc2's default and the paper's."""

EPISODE_STEPS = 1800
"""Agent steps in one BuildMarines episode: the map's 900 game-second timer × 16 loops /
step_mul 8."""

BACKENDS: tuple[str, ...] = ("sim", "sc2")
"""Environment backends: ``sim`` the embedded simulator (default), ``sc2`` the real game."""

LAYER_SETS: tuple[str, ...] = ("paper", "full")
"""Layer-set presets of :class:`sc2data.schema.Schema`: the paper's 13 + 7 layers, or all
27 + 11."""

SPLITS: tuple[str, ...] = ("train", "val", "test")
"""Pair-set splits, in the order quotas are apportioned and files are listed."""

SPLIT_METHODS: tuple[str, ...] = ("episode", "random")
"""How pairs are split: by episode (default, honest) or at random (the paper's)."""

MISMATCH_METHODS: tuple[str, ...] = ("uniform", "confusable")
"""How a mismatched command is drawn for a state: uniformly among the commands not satisfied,
or (``confusable``) a share of them among the commands a recipe lists as confused with the
state's own (``[pairs.confusable]``)."""
