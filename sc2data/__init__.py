"""sc2data: natural-language commands grounded in StarCraft II BuildMarines game states."""

from __future__ import annotations

from typing import Any

from sc2data.schema import Schema, StackBatch

__all__ = ["Dataset", "Schema", "StackBatch", "open_dataset"]


def __getattr__(name: str) -> Any:
    """``open_dataset`` and ``Dataset`` load h5py and pyarrow only when first used."""
    if name in ("Dataset", "open_dataset"):
        from sc2data import dataset

        return getattr(dataset, name)
    raise AttributeError(f"module 'sc2data' has no attribute {name!r}")
