"""sc2data: natural-language commands grounded in StarCraft II BuildMarines game states."""

from __future__ import annotations

from sc2data.reward import load_model
from sc2data.schema import Schema, StackBatch

__all__ = ["Schema", "StackBatch", "load_model"]
