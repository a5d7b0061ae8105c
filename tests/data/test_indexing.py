"""Dataset and StackBatch indexing: positions, slices, positions arrays, masks, (episode, step)."""

from __future__ import annotations

import numpy as np
import pytest

import sc2data
from sc2data.data.rollout import RolloutConfig, rollout
from sc2data.testing.synthetic import synthetic_env_factory


@pytest.fixture(scope="module")
def ds(tmp_path_factory: pytest.TempPathFactory) -> sc2data.Dataset:
    out = tmp_path_factory.mktemp("idx") / "ds"
    rollout(RolloutConfig(episodes=3, max_steps=7, episodes_per_shard=2), out,
            env_factory=synthetic_env_factory(20), progress=False)
    return sc2data.open_dataset(out)


def loops(batch: sc2data.StackBatch) -> list[int]:
    return batch.vector("game_loop", "game_loop")[:, 1].tolist()


def test_global_positions(ds: sc2data.Dataset) -> None:
    assert len(ds) == 21
    every = ds.read(*ds.locate(0, 21))
    assert loops(ds[0]) == [8] and loops(ds[7]) == [8] and loops(ds[-1]) == [56]
    assert loops(ds[5:9]) == loops(every)[5:9]
    assert loops(ds[::5]) == loops(every)[::5]
    assert loops(ds[[20, 0, -2]]) == [loops(every)[i] for i in (20, 0, 19)]
    mask = np.zeros(21, bool)
    mask[[1, 8]] = True
    assert loops(ds[mask]) == [16, 16]
    assert len(list(ds)) == 21 and all(len(b) == 1 for b in ds)
    assert np.array_equal(ds[8].arrays["player"], ds.read([1], [1]).arrays["player"])


def test_episode_and_step(ds: sc2data.Dataset) -> None:
    assert loops(ds[2, 3]) == [32]
    assert loops(ds[2, 3:6]) == [32, 40, 48] and loops(ds[2, -1]) == [56]
    assert loops(ds[1, [0, 6]]) == [8, 56]
    with pytest.raises(IndexError):
        ds[1, 7]
    with pytest.raises(KeyError):
        ds[9, 0]
    with pytest.raises(IndexError):
        ds[21]
    with pytest.raises(TypeError):
        ds[1.5]  # type: ignore[index]


def test_batches_index_too_and_reprs_show_shapes(ds: sc2data.Dataset) -> None:
    batch = ds[0:6]
    assert loops(batch[1:3]) == [16, 24] and loops(batch[-1]) == [48]
    assert [loops(b) for b in batch] == [[8], [16], [24], [32], [40], [48]]
    assert "screen/unit_type: (6, 2, 64, 64) uint16" in repr(batch)
    assert "[" not in repr(batch).split("\n")[0] and "array" not in repr(batch)
    text = repr(ds)
    assert "stacks=21" in text and "(2, 64, 64)" in text and "array" not in text


def test_a_shard_from_another_dataset_is_refused_when_read(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """As ``label`` and ``verify`` refuse it: by its size as the index records it, and (a foreign
    shard whose size the index was made to record) by its header and episode table."""
    import shutil

    import pyarrow.parquet as pq

    from sc2data.data.dataset import INDEX, write_index
    from sc2data.ground.errors import Sc2DataError

    def make(out, seed):  # type: ignore[no-untyped-def]
        rollout(RolloutConfig(episodes=2, max_steps=7, episodes_per_shard=1, seed=seed), out,
                env_factory=synthetic_env_factory(20), progress=False)
        return out

    ours, theirs = make(tmp_path / "ours", 1), make(tmp_path / "theirs", 2)
    before = loops(sc2data.open_dataset(ours)[7:14])  # episode 1: shard-00001
    shutil.copyfile(theirs / "shard-00001.h5", ours / "shard-00001.h5")
    ds = sc2data.open_dataset(ours)
    assert len(ds[0:7]) == 7  # its own shards read on
    with pytest.raises(Sc2DataError, match=r"shard-00001.h5 is not this dataset's shard "
                                                   r"\(.* bytes, the index says .*\): damaged, "
                                                   r"replaced or copied from another dataset"):
        ds[7:14]
    rows = pq.read_table(ours / INDEX).to_pylist()
    size = (ours / "shard-00001.h5").stat().st_size
    write_index(ours, [{**r, "shard_bytes": size} if r["shard"] == "shard-00001.h5" else r
                       for r in rows])
    with pytest.raises(Sc2DataError, match=r"shard-00001.h5 is not this dataset's shard "
                                                   r"\(its settings differ"):
        sc2data.open_dataset(ours)[7:14]
    write_index(ours, rows)  # the control: the same shard, rolled out again, reads as before
    shutil.rmtree(theirs)
    make(theirs, 1)
    shutil.copyfile(theirs / "shard-00001.h5", ours / "shard-00001.h5")
    assert loops(sc2data.open_dataset(ours)[7:14]) == before
