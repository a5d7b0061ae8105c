"""Shard format, chunk codec and dataset reading, on synthetic BuildMarines-like frames."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import hdf5plugin
import numpy as np
import pytest

import sc2data
from sc2data._pysc2 import actions
from sc2data.data.chunks import ChecksumError, Codec, fletcher32
from sc2data.data.dataset import Dataset
from sc2data.data.rollout import episode_seeds
from sc2data.data.shards import (
    ARG_WIDTH,
    CHUNK_INDEX,
    FrameSource,
    Shard,
    ShardWriter,
    chunk_table,
    flatten_args,
    function_call,
)
from sc2data.ground.errors import Sc2DataError
from sc2data.schema import Schema, StackBatch
from sc2data.testing.synthetic import synthetic_episode
from tests.synthetic_data import STEPS, make_dataset

SCHEMA = Schema.paper()


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """5 episodes of 30 steps in 3 shards (2, 2, 1 episodes), the default chunking."""
    out = tmp_path_factory.mktemp("ds") / "data"
    make_dataset(out)
    return out


def truth(episode: int, seed: int = 7) -> dict[str, np.ndarray]:
    """The frames an episode must hold: the synthetic scene the env was seeded with."""
    return synthetic_episode(SCHEMA, STEPS, episode_seeds(seed, episode)[0])


def write_shard(path: Path, lengths: tuple[int, ...] = (5, 9), chunk_frames: int = 4) -> list:
    """A shard of synthetic episodes; returns their frames and steps."""
    writer = ShardWriter(path, SCHEMA, Codec(1, chunk_frames), {"seed": 1})
    episodes = []
    for e, n in enumerate(lengths):
        frames = synthetic_episode(SCHEMA, n, seed=e)
        calls = [actions.FUNCTIONS.select_rect("add", [e, t % 64], [3, 4]) if t % 2 else
                 actions.FUNCTIONS.no_op() for t in range(n)]
        writer.begin_episode(e, 10 + e, 20 + e)
        writer.add_frame({k: v[0] for k, v in frames.items()})
        for t, call in enumerate(calls):
            writer.add_frame({k: v[t + 1] for k, v in frames.items()})
            writer.add_step(int(call.function), call.arguments, float(t % 3 == 0))
        writer.end_episode()
        episodes.append((frames, calls))
    writer.close()
    return episodes


# -- chunk codec --------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [7, 8, 4096, 40001])
def test_fletcher32_matches_hdf5(tmp_path: Path, n: int) -> None:
    """Our vectorised fletcher32 equals the checksum HDF5 itself stored, odd lengths included."""
    data = np.random.default_rng(n).integers(0, 256, 3 * n, dtype=np.uint8)
    with h5py.File(tmp_path / "f.h5", "w") as f:
        f.create_dataset("x", data=data, chunks=(n,), fletcher32=True)
        f.create_dataset("z", data=data, chunks=(n,), fletcher32=True, **hdf5plugin.Zstd())
    with h5py.File(tmp_path / "f.h5", "r") as f:
        raws = [f[k].id.read_direct_chunk((i * n,))[1] for k in "xz" for i in range(3)]
    stored = [int.from_bytes(r[-4:], "little") for r in raws]
    assert fletcher32([r[:-4] for r in raws]).tolist() == stored


def test_fletcher32_sees_a_flipped_bit() -> None:
    payload = bytes(range(256)) * 5
    flipped = bytearray(payload)
    flipped[100] ^= 0x04
    a, b = fletcher32([payload, bytes(flipped)])
    assert a != b


# -- shard files --------------------------------------------------------------------------------
def test_shard_roundtrip(tmp_path: Path) -> None:
    """Frames (through HDF5's own filters), steps, actions and the episode table read back."""
    path = tmp_path / "s.h5"
    episodes = write_shard(path)
    shard = Shard(path)
    try:
        assert shard.schema == SCHEMA and shard.attrs["seed"] == 1
        assert shard.episodes["n_steps"].tolist() == [5, 9]
        assert shard.episodes["frame_start"].tolist() == [0, 6]
        assert shard.episodes["agent_seed"].tolist() == [20, 21]
        steps = shard.steps()
        for (frames, calls), f0, s0 in zip(episodes, (0, 6), (0, 5)):
            for k, v in frames.items():
                b = SCHEMA.block_of(k)
                np.testing.assert_array_equal(
                    shard.file[f"frames/{b.name}"][f0:f0 + len(v), b.part(k)], v)
            for t, call in enumerate(calls):
                got = function_call(steps["function"][s0 + t], steps["args"][s0 + t])
                assert got == call
        assert steps["args"].shape == (14, ARG_WIDTH)
        assert steps["reward"][:5].tolist() == [1, 0, 0, 1, 0]
    finally:
        shard.close()


def test_fast_path_equals_hdf5_path(tmp_path: Path) -> None:
    path = tmp_path / "s.h5"
    write_shard(path, lengths=(6, 6))
    shard = Shard(path)
    try:
        for block in SCHEMA.blocks():
            fast = shard.frames(block.name)
            slow = FrameSource(shard.file[f"frames/{block.name}"], None, block.name)
            ids = np.arange(-(-14 // 4))
            assert fast.fast and not slow.fast
            assert fast.read_chunks(ids) == slow.read_chunks(ids)
    finally:
        shard.close()


def test_shard_bytes_depend_only_on_content(tmp_path: Path) -> None:
    write_shard(tmp_path / "a.h5")
    write_shard(tmp_path / "b.h5")
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()


def flip_byte_in_chunk(path: Path, key: str, chunk: int = 1) -> None:
    """Damage one byte in the middle of a stored frame chunk of the block holding ``key``."""
    with h5py.File(path, "r") as f:
        ds = f[f"frames/{SCHEMA.block_of(key).name}"]
        info = ds.id.get_chunk_info_by_coord((chunk * ds.chunks[0],) + (0,) * (ds.ndim - 1))
    with open(path, "r+b") as f:
        f.seek(info.byte_offset + info.size // 2)
        b = f.read(1)
        f.seek(-1, 1)
        f.write(bytes([b[0] ^ 0x10]))


def test_flipped_byte_is_caught_by_both_paths(tmp_path: Path) -> None:
    path = tmp_path / "s.h5"
    write_shard(path)
    flip_byte_in_chunk(path, "screen/unit_type")
    shard = Shard(path)
    try:
        with pytest.raises(ChecksumError, match="checksum"):
            shard.frames("screen_uint16").read_chunks(np.array([1]))
        with pytest.raises(OSError):
            shard.file["frames/screen_uint16"][4:8]
        shard.frames("screen_uint16").read_chunks(np.array([0, 2]))  # the others are fine
    finally:
        shard.close()


def test_reading_a_damaged_chunk_raises(dataset: Path, tmp_path: Path) -> None:
    """open_dataset's reads verify checksums too: the damaged chunk fails, the others read."""
    import shutil

    copy = Path(shutil.copytree(dataset, tmp_path / "d"))
    flip_byte_in_chunk(copy / "shard-00000.h5", "screen/unit_hit_points", chunk=1)
    ds = sc2data.open_dataset(copy, cache_bytes=0)
    c = Codec().chunk_frames
    with pytest.raises(ChecksumError, match=r"shard-00000.h5:frames/screen_uint16: fletcher32"):
        ds.read([0], [c])
    with pytest.raises(Sc2DataError):
        ds.read([0], [c + 1], keys=["screen/unit_hit_points"])
    ds.read([0], [c], keys=["screen/player_id", "minimap/camera", "player"])  # other blocks
    ds.read([0, 1], [0, 5])


def test_the_stored_chunk_index_is_hdf5s(tmp_path: Path) -> None:
    """Each shard stores its frame datasets' chunk index (what HDF5's says); readers use it,
    and shards without one (written before it existed) read the same through HDF5's."""
    path = tmp_path / "s.h5"
    write_shard(path, lengths=(6, 9))
    shard = Shard(path)
    try:
        index = shard.chunk_index()
        names = [b.name for b in SCHEMA.blocks()]
        assert list(index) == names
        for name in names:
            np.testing.assert_array_equal(index[name], chunk_table(shard.file[f"frames/{name}"]))
        ids = np.arange(-(-17 // 4))
        stored = {n: shard.frames(n).read_chunks(ids) for n in names}
    finally:
        shard.close()
    with h5py.File(path, "r+") as f:
        del f[CHUNK_INDEX]
    shard = Shard(path)
    try:
        assert shard.chunk_index() == {}
        assert {n: shard.frames(n).read_chunks(ids) for n in names} == stored
    finally:
        shard.close()


def test_a_wrong_chunk_index_is_caught(dataset: Path, tmp_path: Path) -> None:
    import shutil

    from sc2data.data.audit import verify

    copy = Path(shutil.copytree(dataset, tmp_path / "d"))
    with h5py.File(copy / "shard-00001.h5", "r+") as f:
        index = f[CHUNK_INDEX][()]
        index[2, 1, 0] += 8  # chunk 1 of the minimap layers: 8 bytes off
        f[CHUNK_INDEX][...] = index
    faults = verify(copy)
    assert "shard-00001.h5:chunk_index: disagrees with HDF5's chunk index of " \
        "frames/minimap_uint8" in faults
    ds = sc2data.open_dataset(copy, cache_bytes=0)
    with pytest.raises(ChecksumError, match="shard-00001.h5:frames/minimap_uint8"):
        ds.read([2], [Codec().chunk_frames])


def test_shard_of_another_schema_version_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.h5"
    write_shard(path)
    with h5py.File(path, "r+") as f:
        f.attrs["schema"] = json.dumps({**SCHEMA.to_dict(), "version": 0})
    with pytest.raises(Sc2DataError, match="schema version 0"):
        Shard(path)


def test_shard_of_an_older_format_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.h5"
    write_shard(path)
    with h5py.File(path, "r+") as f:
        f.attrs["format_version"] = 1
    with pytest.raises(Sc2DataError, match="has shard format 1, not 4; regenerate it"):
        Shard(path)


def test_truncated_and_foreign_files_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.h5"
    write_shard(path)
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    with pytest.raises(Sc2DataError, match="truncated or not an sc2data shard"):
        Shard(path)
    path.write_bytes(b"this is not HDF5\n" * 100)
    with pytest.raises(Sc2DataError, match="not a readable HDF5 file"):
        Shard(path)
    with h5py.File(path, "w") as f:
        f["x"] = np.zeros(3)
    with pytest.raises(Sc2DataError, match="not an sc2data shard"):
        Shard(path)


def test_add_observation_equals_add_frame_of_extract(tmp_path: Path) -> None:
    """The writer's vectorised observation path stores what Schema.extract gives, and refuses
    the same out-of-range values."""
    from sc2data.testing.synthetic import _Scene, render

    scene = _Scene(3)
    for schema in (SCHEMA, Schema.full()):
        paths = []
        for mode in ("frame", "obs"):
            path = tmp_path / f"{mode}.h5"
            w = ShardWriter(path, schema, Codec(1, 4), {})
            w.begin_episode(0, 0, 0)
            for t in range(0, 60, 10):
                obs = {**render(scene, t), "available_actions": np.array([0, 1, 2, 3 + t])}
                if mode == "frame":
                    w.add_frame(schema.extract(obs), obs["available_actions"])
                else:
                    w.add_observation(obs)
                if t:
                    w.add_step(0, [], 0.0)
            w.end_episode()
            w.close()
            paths.append(path)
        assert paths[0].read_bytes() == paths[1].read_bytes()
    obs = {**render(scene, 0), "available_actions": np.array([0])}
    obs["feature_screen"][SCHEMA.screen[6].index, 0, 0] = 70000  # unit_type beyond uint16
    w = ShardWriter(tmp_path / "bad.h5", SCHEMA, Codec(1, 4), {})
    w.begin_episode(7, 0, 0)
    with pytest.raises(Sc2DataError, match=r"frame 0 of episode 7: screen/unit_type holds values "
                                           r"outside \[0, 65536\) \(min 0, max 70000\)"):
        w.add_observation(obs)
    with pytest.raises(ValueError, match="screen/unit_type holds values outside"):
        SCHEMA.extract(obs)
    obs = {**render(scene, 0), "available_actions": np.array([0])}
    obs["feature_minimap"][SCHEMA.minimap[3].index, 5, 5] = -1  # camera: negative
    with pytest.raises(ValueError, match="minimap/camera holds values outside"):
        w.add_observation(obs)
    w.abort()


def test_counts_past_the_nominal_scale_are_kept(tmp_path: Path) -> None:
    """pysc2 declares unit_density's scale as 16 but does not clip: 20 units on a pixel is a
    real value, and it fits the layer's uint8, so it is stored, not refused."""
    from sc2data.testing.synthetic import _Scene, render

    obs = {**render(_Scene(3), 0), "available_actions": np.array([0])}
    density = next(l for l in SCHEMA.screen if l.name == "unit_density")
    obs["feature_screen"][density.index, 4, 4] = 20
    assert SCHEMA.extract(obs)[density.key][4, 4] == 20
    w = ShardWriter(tmp_path / "dense.h5", SCHEMA, Codec(1, 4), {})
    w.begin_episode(0, 0, 0)
    w.add_observation(obs)
    w.abort()


def test_flatten_args_pads_and_rejects_too_many() -> None:
    assert flatten_args(0, []).tolist() == [-1] * ARG_WIDTH
    assert flatten_args(3, [[1], [2, 3], [4, 5]]).tolist() == [1, 2, 3, 4, 5]
    with pytest.raises(ValueError):
        flatten_args(3, [[1], [2, 3], [4, 5], [6]])


# -- reading a dataset --------------------------------------------------------------------------
def test_open_dataset_tables(dataset: Path) -> None:
    ds = sc2data.open_dataset(dataset)
    assert isinstance(ds, Dataset)
    assert ds.episode_ids.tolist() == [0, 1, 2, 3, 4]
    assert ds.n_steps.tolist() == [STEPS] * 5 and len(ds) == 5 * STEPS
    assert ds.shard_names == ["shard-00000.h5", "shard-00001.h5", "shard-00002.h5"]
    assert ds.settings["episodes"] == 5 and ds.schema == SCHEMA
    assert "stacks=150" in repr(ds)


def test_read_random_stacks_equals_the_frames_played(dataset: Path) -> None:
    """Random (episode, step) pairs across shards and chunk edges give the env's frames."""
    ds = sc2data.open_dataset(dataset)
    rng = np.random.default_rng(0)
    episodes = rng.integers(0, 5, 200)
    steps = rng.integers(0, STEPS, 200)
    steps[:5] = [0, STEPS - 1, 3, 4, 7]  # episode edges and chunk edges
    batch = ds.read(episodes, steps)
    assert isinstance(batch, StackBatch) and len(batch) == 200
    frames = {e: truth(e) for e in range(5)}
    for i, (e, t) in enumerate(zip(episodes, steps)):
        for k in SCHEMA.keys():
            np.testing.assert_array_equal(batch.arrays[k][i, 0], frames[e][k][t])
            np.testing.assert_array_equal(batch.arrays[k][i, 1], frames[e][k][t + 1])


def test_stack_and_key_subsets(dataset: Path) -> None:
    ds = sc2data.open_dataset(dataset)
    one = ds.stack(3, 11)
    assert len(one) == 1 and one.layer("screen/unit_type").shape == (1, 2, 64, 64)
    assert one.layer("screen/unit_hit_points").dtype == np.uint16
    sub = ds.read([3], [11], keys=["player", "minimap/camera"])
    assert set(sub.arrays) == {"player", "minimap/camera"}
    np.testing.assert_array_equal(sub.arrays["player"], one.arrays["player"])
    assert sub.vector("player", "minerals").shape == (1, 2)
    with pytest.raises(KeyError, match="not stored"):
        ds.read([0], [0], keys=["screen/effects"])


def test_iter_batches_visits_every_stack_in_order(dataset: Path) -> None:
    ds = sc2data.open_dataset(dataset, cache_bytes=0)
    seen_e, seen_t, firsts = [], [], []
    for episodes, steps, batch in ds.iter_batches(batch_size=64, keys=["game_loop"]):
        assert len(batch) == len(episodes) <= 64
        seen_e += episodes.tolist()
        seen_t += steps.tolist()
        firsts.append(batch.arrays["game_loop"])
    assert seen_e == [e for e in range(5) for _ in range(STEPS)]
    assert seen_t == list(range(STEPS)) * 5
    loops = np.concatenate(firsts)[:, :, 0]
    assert (loops[:, 1] - loops[:, 0] == 8).all()  # (previous, current) of one episode


def test_locate_positions_follows_iteration_order(dataset: Path) -> None:
    ds = sc2data.open_dataset(dataset)
    e, t = ds.locate_positions([0, STEPS - 1, STEPS, 4 * STEPS + 2])
    assert e.tolist() == [0, 0, 1, 4] and t.tolist() == [0, STEPS - 1, 0, 2]
    assert [a.tolist() for a in ds.locate(STEPS - 1, STEPS + 1)] == [[0, 1], [STEPS - 1, 0]]
    with pytest.raises(IndexError):
        ds.locate_positions([len(ds)])


def test_cache_does_not_change_results(dataset: Path) -> None:
    cached, uncached = sc2data.open_dataset(dataset), sc2data.open_dataset(dataset, cache_bytes=0)
    e, t = np.array([1, 1, 4, 0, 1]), np.array([5, 6, 29, 0, 5])
    for _ in range(2):
        a, b = cached.read(e, t), uncached.read(e, t)
        for k in SCHEMA.keys():
            np.testing.assert_array_equal(a.arrays[k], b.arrays[k])


def test_a_sequential_read_takes_the_shared_chunk_from_the_cache(
        dataset: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Consecutive batches share a chunk at their boundary: with the cache it is decoded once,
    and the cached (read-only) chunk gives the same stacks."""
    from sc2data.data.chunks import ChunkDecoder

    decoded: list[int] = []
    real = ChunkDecoder.decode_into

    def counting(self: ChunkDecoder, raws: list, *a: object) -> None:
        decoded.append(len(raws))
        real(self, raws, *a)

    monkeypatch.setattr(ChunkDecoder, "decode_into", counting)
    c = Codec().chunk_frames
    counts = {}
    for cache in (128 << 20, 0):
        decoded.clear()
        ds = sc2data.open_dataset(dataset, cache_bytes=cache)
        first = ds.read([0] * c, np.arange(c))  # frames 0..c: chunks 0 and 1 of each block
        second = ds.read([0] * c, np.arange(c, 2 * c))  # frames c..2c: chunks 1 and 2
        counts[cache] = list(decoded)
        np.testing.assert_array_equal(second.arrays["screen/unit_type"][0, 0],
                                      first.arrays["screen/unit_type"][-1, 1])
        ds.close()
    blocks = len(SCHEMA.blocks())
    assert counts[0] == [2 * blocks, 2 * blocks]
    assert counts[128 << 20] == [2 * blocks, blocks]


def test_a_dataset_record_without_a_codec_is_refused(dataset: Path, tmp_path: Path) -> None:
    import shutil

    copy = Path(shutil.copytree(dataset, tmp_path / "d"))
    record = json.loads((copy / "dataset.json").read_text())
    del record["settings"]["codec"]
    (copy / "dataset.json").write_text(json.dumps(record))
    with pytest.raises(Sc2DataError, match="dataset.json: no valid codec in its settings"):
        sc2data.open_dataset(copy)


def test_bad_requests(dataset: Path) -> None:
    ds = sc2data.open_dataset(dataset)
    with pytest.raises(KeyError, match="episode 9"):
        ds.stack(9, 0)
    with pytest.raises(IndexError, match="outside episode 2"):
        ds.stack(2, STEPS)
    with pytest.raises(IndexError):
        ds.stack(2, -1)
    with pytest.raises(ValueError):
        ds.read([0, 1], [0])
    with pytest.raises(ValueError):
        next(ds.iter_batches(0))


def test_actions_are_the_agents_calls(dataset: Path) -> None:
    ds = sc2data.open_dataset(dataset)
    acts = ds.actions([0, 4, 4], [0, 0, STEPS - 1])
    assert acts["function"].shape == (3,) and acts["args"].shape == (3, ARG_WIDTH)
    for f, a in zip(acts["function"], acts["args"]):
        call = function_call(f, a)
        assert len(call.arguments) == len(actions.FUNCTIONS[int(f)].args)


def test_open_dataset_refuses_non_datasets(tmp_path: Path) -> None:
    with pytest.raises(Sc2DataError, match="not an sc2data dataset"):
        sc2data.open_dataset(tmp_path)
    with pytest.raises(Sc2DataError, match="not a folder"):
        sc2data.open_dataset(tmp_path / "nope")
