"""sc2data: natural-language commands grounded in StarCraft II BuildMarines game states."""

from __future__ import annotations

from typing import Any

from sc2data.schema import Schema, StackBatch

__all__ = ["Dataset", "Schema", "StackBatch", "load_model", "open_dataset"]


def __getattr__(name: str) -> Any:
    """``open_dataset``, ``Dataset`` and ``load_model`` load their dependencies (h5py, pyarrow,
    torch) only when first used."""
    if name in ("Dataset", "open_dataset"):
        from sc2data.data import dataset

        return getattr(dataset, name)
    if name == "load_model":
        from sc2data.model.reward import load_model

        return load_model
    raise AttributeError(f"module 'sc2data' has no attribute {name!r}")
