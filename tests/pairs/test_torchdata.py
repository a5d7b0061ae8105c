"""A pair set as a torch Dataset in a standard DataLoader with worker processes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sc2data.pairs.loader import PairSet  # noqa: E402
from sc2data.pairs.torchdata import PairDataset, block_order  # noqa: E402
from tests.mem_helpers import tiny_pairset  # noqa: E402


def test_a_dataloader_with_two_workers_sees_every_pair_once(tmp_path: Path) -> None:
    from torch.utils.data import DataLoader

    path = tiny_pairset(tmp_path / "pairs")
    ds = PairDataset(path, "val")
    pairs = PairSet(path).pairs("val")
    seen: list[int] = []
    for batch in DataLoader(ds, batch_size=8, sampler=block_order(ds), num_workers=2):
        assert batch["state"]["screen/unit_type"].dtype == torch.uint16
        assert batch["state"]["player"].shape[1:] == (2, 11)
        assert batch["target"].dtype == torch.float32
        for j, i in enumerate(batch["pair"].tolist()):
            assert batch["command"][j] == pairs.command[i]
            assert batch["kind"][j] == pairs.kind[i]
            assert float(batch["target"][j]) == pairs.target[i]
            assert ds.commands[int(batch["command_index"][j])] == pairs.command_id[i]
        seen += batch["pair"].tolist()
    assert sorted(seen) == list(range(len(ds)))
    packed = PairSet(path).packed("val")
    row = int(pairs.state[3])
    assert np.array_equal(ds[3]["state"]["player"], packed.read(row, row + 1).arrays["player"][0])
    assert "pairs=" in repr(ds)


def test_a_pair_set_changed_after_opening_is_rechecked_before_a_read(tmp_path: Path) -> None:
    """Replaced by another pair set (as a rebuild renames one into place): an error, not new
    states paired with the commands read before; the same bytes again (touched, copied): read
    on, the same items."""
    import os
    import pickle
    import shutil

    from sc2data.ground.errors import Sc2DataError

    path = tiny_pairset(tmp_path / "pairs")
    other = tiny_pairset(tmp_path / "other", seed=1)
    ds = PairDataset(path, "train")
    first = ds[0]
    copy = pickle.loads(pickle.dumps(ds))  # as a DataLoader worker gets it
    os.utime(path / "packed" / "train.h5")  # touched, same bytes
    shutil.copyfile(path / "pairs.parquet", tmp_path / "p")
    os.replace(tmp_path / "p", path / "pairs.parquet")  # another inode, same bytes
    again = ds[0]
    assert all(np.array_equal(again["state"][k], first["state"][k]) for k in first["state"])
    assert again["command"] == first["command"]
    path.rename(tmp_path / "old")
    other.rename(path)  # the folder replaced
    for d in (ds, copy):
        with pytest.raises(Sc2DataError, match=r"changed or is gone since this PairDataset "
                                               r"checked it .*make a new PairDataset"):
            d[0]
    shutil.rmtree(path)
    with pytest.raises(Sc2DataError, match="changed or is gone"):
        ds[1]
    assert PairDataset(tmp_path / "old", "train")[0]["command"] == first["command"]
