"""``load_model(RUN, threads=…)``: each call on that many torch threads, the process's own setting
given back after; None leaves torch's setting alone; anything else is a one-line error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sc2data import load_model  # noqa: E402
from sc2data.ground.errors import Sc2DataError  # noqa: E402
from sc2data.testing.synthetic_pairs import stacks  # noqa: E402
from tests.mem_helpers import SMALL_SCHEMA, tiny_pairset, train_tiny  # noqa: E402


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("threads")
    return train_tiny(tiny_pairset(tmp / "data"), tmp / "run", epochs=1)


def test_calls_run_on_the_scorers_threads_and_give_the_setting_back(
        run: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    batch = stacks(SMALL_SCHEMA, ["build_barracks", None], seed=0)
    before = torch.get_num_threads()
    seen: list[int] = []
    real_set = torch.set_num_threads
    monkeypatch.setattr(torch, "set_num_threads", lambda n: (seen.append(n), real_set(n))[1])
    try:
        real_set(3)
        one = load_model(run)
        assert one.threads == 1
        d1 = one.distance(batch, "build a barracks")
        assert torch.get_num_threads() == 3 and seen[:2] == [1, 3]  # set, then given back
        seen.clear()
        same = load_model(run, threads=None)
        assert same.threads is None
        d2 = same.distance(batch, "build a barracks")
        assert seen == [] and torch.get_num_threads() == 3  # torch's setting, untouched
        assert np.allclose(d1, d2, atol=1e-5)
    finally:
        real_set(before)


@pytest.mark.parametrize("threads", [0, -2, 1.5, True])
def test_a_bad_thread_count_is_one_line(run: Path, threads: object) -> None:
    with pytest.raises(Sc2DataError, match="threads must be a positive number"):
        load_model(run, threads=threads)  # type: ignore[arg-type]
