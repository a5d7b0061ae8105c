"""Shared helpers of the model / train / evaluate tests: tiny pair sets, tiny runs, the CLI."""

from __future__ import annotations

from pathlib import Path

from sc2data.schema import Schema

SMALL_SCHEMA = Schema.from_names(["unit_type", "player_relative", "unit_hit_points"],
                                 ["player_relative", "camera"])
"""A few layers: fast to train on, and enough to tell every synthetic event apart."""


def tiny_pairset(path: Path, schema: Schema | None = None, **kw: object) -> Path:
    from sc2data.testing.synthetic_pairs import write_pairset

    args = dict(states_per_command=24, null_states=40, episodes=12, seed=0)
    args.update(kw)
    return write_pairset(path, schema=schema or SMALL_SCHEMA, **args)  # type: ignore[arg-type]


def train_tiny(data: Path, out: Path, epochs: int = 2, **kw: object) -> Path:
    from sc2data.model.train import TrainConfig, train

    args: dict[str, object] = dict(threads=1, progress=False, vocab_size=2000)
    args.update(kw)
    return train(TrainConfig(data=str(data), out=str(out), epochs=epochs, **args))  # type: ignore




