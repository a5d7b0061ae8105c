"""The scorer's CPU fast path computes the training path's function: same distances, any batch."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sc2data import load_model  # noqa: E402
from sc2data._pysc2 import units  # noqa: E402
from sc2data.model.infer import _WORDS_FROM, FastStateEncoder, _cell_totals  # noqa: E402
from sc2data.model.mem import MEM, ModelConfig, conv_for, model_inputs, value_tables  # noqa: E402
from sc2data.model.scorer import MEMScorer  # noqa: E402
from sc2data.pairs.loader import PairSet  # noqa: E402
from sc2data.schema import Schema  # noqa: E402
from sc2data.testing.synthetic_pairs import stacks  # noqa: E402
from tests.mem_helpers import SMALL_SCHEMA, tiny_pairset, train_tiny  # noqa: E402

EVENTS = ["build_supply_depot", "build_barracks", "build_scv", "train_marine",
          "collect_minerals", None]
WORDS = ("build", "a", "supply", "depot")


def reference(model: MEM, arrays: dict[str, np.ndarray]) -> np.ndarray:
    """State embeddings through the training path: numpy packing, one-hot image, the towers."""
    with torch.no_grad():
        return model.state(model_inputs(model, arrays, torch.device("cpu"))).numpy()


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("infer")
    return train_tiny(tiny_pairset(tmp / "data"), tmp / "run", epochs=2)


def test_trained_model_gives_the_reference_distances_at_any_batch_size(run: Path) -> None:
    fast, slow = load_model(run), load_model(run, fast=False)
    assert fast.fast is not None and slow.fast is None
    with PairSet(fast.meta["config"]["data"]).packed("test") as packed:
        batch = packed.read(0, len(packed))
    texts = [c["text"] for c in fast.commands]
    n = len(batch)
    assert n > 9
    for size in (1, 2, 3, 7, n):  # batch 1 and odd sizes
        part = {k: v[:size] for k, v in batch.arrays.items()}
        per = [texts[i % len(texts)] for i in range(size)]
        np.testing.assert_allclose(fast.distance(part, per), slow.distance(part, per),
                                   atol=1e-5, rtol=0)
        np.testing.assert_allclose(fast.embed_states(part), reference(fast.model, part),
                                   atol=1e-5, rtol=0)
    np.testing.assert_allclose(fast.distances(batch, texts), slow.distances(batch, texts),
                               atol=1e-5, rtol=0)
    # the reference path through the scorer is the training path itself (to float rounding:
    # on 2 threads torch's inference mode takes other kernels than no_grad, 1e-7 apart)
    np.testing.assert_allclose(slow.embed_states(batch), reference(slow.model, batch.arrays),
                               atol=1e-6, rtol=0)


@pytest.mark.parametrize("mode", ["onehot", "embed"])
@pytest.mark.parametrize("pool", [1, 2, 4])
def test_same_function_on_the_paper_layers_with_constant_unseen_and_single_id_inputs(
        mode: str, pool: int) -> None:
    schema = Schema.paper()
    batch = stacks(schema, EVENTS, seed=1)
    conv = conv_for(pool, 24 if pool == 4 else 16)  # and a first convolution of other width
    cfg = ModelConfig(categorical=mode, pool=pool, conv=conv)  # type: ignore[arg-type]
    torch.manual_seed(0)
    model = MEM(schema, value_tables(schema, [batch], cfg.max_table),
                np.zeros((4, 5), np.float32), cfg).eval()
    enc = FastStateEncoder(model.state)
    arrays = {k: np.array(v) for k, v in batch.arrays.items()}
    variants = {"as drawn": arrays}
    odd = {k: v.copy() for k, v in arrays.items()}
    odd["screen/unit_type"][0, 1, :5, :7] = units.Terran.Reaper  # an id training never saw
    odd["screen/unit_hit_points"][:] = 45  # a scalar constant over the batch
    odd["screen/player_relative"][:] = 1  # one id in the whole batch
    variants["unseen, constant, single"] = odd
    variants["blank"] = {k: np.zeros_like(v) for k, v in arrays.items()}  # nothing varies
    same = {k: v.copy() for k, v in arrays.items()}  # one map's layers in every stack and frame
    for key in ("screen/height_map", "screen/visibility_map", "minimap/camera",
                "minimap/player_relative"):
        same[key][:] = arrays[key][2, 1]
    variants["the same maps everywhere"] = same
    variants["24 stacks"] = {k: np.concatenate([v] * 4) for k, v in arrays.items()}  # word-wide
    with torch.inference_mode():
        for name, a in [*variants.items(), *variants.items()]:  # twice: the second from cache
            for size in (1, 5, len(EVENTS), 4 * len(EVENTS)):
                part = {k: v[:size] for k, v in a.items()}
                np.testing.assert_allclose(enc(part).numpy(), reference(model, part),
                                           atol=1e-5, rtol=0, err_msg=f"{name}, batch {size}")
    assert all(g._cache for _, g in enc.groups)  # the constant layers were cached


@pytest.mark.parametrize("pool", [1, 2, 3, 4])
def test_cell_totals_sum_every_p_by_p_cell(pool: int) -> None:
    """Booleans, and integers whose cell sums need 8-bit, 16-bit or (past 65,535) no lanes."""
    rng = np.random.default_rng(pool)
    shape = (48, 2, 48, 48)  # enough pixels for the word-wide sums
    cases = [rng.random(shape) < 0.4, np.ones(shape, bool), np.zeros(shape, bool),
             rng.integers(0, 16, shape).astype(np.uint8), np.full(shape, 255, np.uint8),
             rng.integers(0, 4096, shape).astype(np.uint16),
             np.full(shape, 65535, np.uint16), rng.integers(0, 9, shape).astype(np.int32)]
    assert cases[0].size >= _WORDS_FROM
    for x in cases:
        out = np.full((48, 2, 48 // pool, 48 // pool), -1, np.float32)
        _cell_totals(x, pool, int(x.max()), out)
        want = x.astype(np.int64).reshape(48, 2, 48 // pool, pool, 48 // pool, pool).sum((3, 5))
        np.testing.assert_array_equal(out, want, err_msg=f"{x.dtype}, max {x.max()}")


def test_scalar_encoding_keeps_the_training_path() -> None:
    batch = stacks(SMALL_SCHEMA, EVENTS, seed=0)
    cfg = ModelConfig(categorical="scalar")
    model = MEM(SMALL_SCHEMA, value_tables(SMALL_SCHEMA, [batch], cfg.max_table),
                np.zeros((4, 5), np.float32), cfg).eval()
    scorer = MEMScorer(model, {"words": WORDS}, torch.device("cpu"))
    assert scorer.fast is None
    np.testing.assert_allclose(scorer.embed_states(batch), reference(model, batch.arrays),
                               atol=1e-6, rtol=0)  # inference mode on 2 threads: 1e-7 apart
