"""A rolled-out dataset as a torch Dataset, in a standard DataLoader with worker processes."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sc2data.data.dataset import open_dataset  # noqa: E402
from sc2data.data.torchdata import StackDataset  # noqa: E402
from sc2data.ground.errors import Sc2DataError  # noqa: E402
from tests.synthetic_data import make_dataset  # noqa: E402


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("stacks") / "data"
    make_dataset(out, episodes=3)
    return out


def test_a_dataloader_with_two_workers_sees_every_stack_once(data: Path) -> None:
    from torch.utils.data import DataLoader

    stacks = StackDataset(data)
    ds = open_dataset(data)
    assert len(stacks) == len(ds) and "stacks=" in repr(stacks)
    seen: list[tuple[int, int]] = []
    for batch in DataLoader(stacks, batch_size=16, shuffle=True, num_workers=2):
        assert batch["state"]["screen/unit_type"].dtype == torch.uint16
        assert batch["state"]["screen/unit_type"].shape[1:] == (2, 64, 64)
        assert batch["reward"].dtype == torch.float32
        episodes, steps = batch["episode"].numpy(), batch["step"].numpy()
        want = ds.read(episodes, steps).arrays
        acts = ds.actions(episodes, steps)
        for k, v in batch["state"].items():
            assert np.array_equal(v.numpy(), want[k]), k
        assert np.array_equal(batch["function"].numpy(), acts["function"])
        assert np.array_equal(batch["args"].numpy(), acts["args"])
        assert np.allclose(batch["reward"].numpy(), acts["reward"])
        assert batch["available"].dtype == torch.bool and batch["available"].shape[1] == 573
        assert np.array_equal(batch["available"].numpy(), acts["available"])
        assert np.array_equal(batch["next_available"].numpy(), acts["next_available"])
        seen += list(zip(episodes.tolist(), steps.tolist()))
    assert sorted(seen) == sorted(zip(*(a.tolist() for a in ds.locate(0, len(ds)))))


def test_items_by_position_and_a_subset_of_keys(data: Path) -> None:
    stacks = StackDataset(data, keys=["player", "screen/selected"])
    ds = open_dataset(data)
    item = stacks[-1]
    episode, step = ds.locate_positions([len(ds) - 1])
    assert (item["episode"], item["step"]) == (int(episode[0]), int(step[0]))
    assert set(item["state"]) == {"player", "screen/selected"}
    assert np.array_equal(item["state"]["player"], ds[len(ds) - 1].arrays["player"][0])
    again = pickle.loads(pickle.dumps(stacks))  # as a DataLoader worker gets it
    assert np.array_equal(again[3]["state"]["player"], stacks[3]["state"]["player"])
    with pytest.raises(IndexError):
        stacks[len(stacks)]
    with pytest.raises(Sc2DataError, match="'screen/nothing' is not stored"):
        StackDataset(data, keys=["screen/nothing"])
