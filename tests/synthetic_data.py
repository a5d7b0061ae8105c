"""Small datasets for the storage and rollout tests, made through the real rollout code path."""

from __future__ import annotations

import json
from pathlib import Path

import h5py

from sc2data.data.chunks import Codec
from sc2data.data.dataset import DATASET_RECORD, write_dataset_record, write_index
from sc2data.data.rollout import RolloutConfig, RolloutSummary, index_rows, rollout
from sc2data.data.shards import MASKS
from sc2data.testing.synthetic import pysc2_random_agent, synthetic_env_factory

STEPS = 30
"""Steps per synthetic episode: 31 frames, so chunks (4 frames by default) straddle episodes."""


def config(episodes: int = 5, seed: int = 7, per_shard: int = 2,
           chunk_frames: int = Codec().chunk_frames, **kw: object) -> RolloutConfig:
    return RolloutConfig(env="sim", agent="random", episodes=episodes, seed=seed,
                         episodes_per_shard=per_shard, codec=Codec(chunk_frames=chunk_frames),
                         **kw)


def make_dataset(out: Path, workers: int = 1, steps: int = STEPS, **kw: object) -> RolloutSummary:
    """Roll pysc2's RandomAgent out on the synthetic env (pysc2's mock env, moving frames)."""
    return rollout(config(**kw), out, workers=workers, progress=False,
                   env_factory=synthetic_env_factory(steps), agent_factory=pysc2_random_agent)


def as_format(folder: Path, version: int) -> None:
    """Rewrite a dataset as an older sc2data wrote it: dataset and shard format ``version``,
    without action masks (before format 4) and with the episode count in each shard's settings
    (before format 3)."""
    record = json.loads((folder / DATASET_RECORD).read_text())
    shards = sorted(folder.glob("shard-*.h5"))
    for path in shards:
        with h5py.File(path, "r+") as f:
            f.attrs["format_version"] = version
            del f[MASKS]
            if version < 3:
                f.attrs["settings"] = json.dumps(record["settings"])
    write_dataset_record(folder, {**record, "format_version": version})
    write_index(folder, [row for path in shards for row in index_rows(path)])
