"""The Rule API's helpers: counting, hand-built stacks, synthetic batches, the decorator."""

from __future__ import annotations

import numpy as np
import pytest

from sc2data.rulebase import (
    RULE_ID,
    FunctionRule,
    Rule,
    appeared_pixels,
    blank_frame,
    change,
    count_true,
    fell,
    is_schema_key,
    paint_disk,
    pixel_count,
    rose,
    rule,
    schema_for,
    set_field,
    stack,
    synthetic_batch,
)
from sc2data.schema import MissingLayerError, Schema, StackBatch


def test_rose_fell_change() -> None:
    pair = np.array([[1, 2], [2, 2], [3, 1]], np.int32)
    assert rose(pair).tolist() == [True, False, False]
    assert fell(pair).tolist() == [False, False, True]
    assert change(pair).tolist() == [1, 0, -2]


@pytest.mark.parametrize("shape", [(5, 64, 64), (3, 7, 9), (0, 8, 8), (4, 2, 64, 64)])
def test_count_true_matches_numpy(shape: tuple[int, ...]) -> None:
    mask = np.random.default_rng(0).random(shape) < 0.3
    expected = mask.reshape(shape[0], int(np.prod(shape[1:]))).sum(axis=1)
    assert count_true(mask).tolist() == expected.tolist()
    view = np.random.default_rng(1).random((4, 2, 64, 64)) < 0.5
    assert count_true(view[:, 1]).tolist() == view[:, 1].reshape(4, -1).sum(axis=1).tolist()


def test_pixel_count_and_appeared_pixels() -> None:
    prev, cur = blank_frame(), blank_frame()
    prev["screen/unit_type"][0:2, 0:2] = 48   # a marine...
    prev["screen/unit_type"][0:5, 0:5][2:, 2:] = 19
    cur["screen/unit_type"][0:5, 0:5] = 19     # ...left; a depot grew over empty ground
    batch = stack([(prev, cur), (cur, prev)])
    layer = batch.layer("screen/unit_type")
    assert pixel_count(layer, [19]).tolist() == [[9, 25], [25, 9]]
    assert pixel_count(layer, [19, 48]).tolist() == [[13, 25], [25, 13]]
    assert appeared_pixels(batch, "screen/unit_type", [19]).tolist() == [25 - 9 - 4, 0]
    assert appeared_pixels(batch, "screen/unit_type", [48]).tolist() == [0, 0]


def test_appeared_pixels_matches_the_dense_definition() -> None:
    rng = np.random.default_rng(7)
    plane = rng.choice(np.array([0, 0, 0, 19, 21, 45, 47, 48], np.uint16), (9, 2, 64, 64))
    batch = StackBatch({"screen/unit_type": plane}, Schema.from_names(["unit_type"], []))
    for values in ([19, 47], [21], [45, 48, 19]):
        dense = (np.isin(plane[:, 1], values) & (plane[:, 0] == 0)).reshape(9, -1).sum(axis=1)
        assert appeared_pixels(batch, "screen/unit_type", values).tolist() == dense.tolist()
    other = StackBatch({"screen/unit_type": plane[::-1].copy()}, batch.schema)
    dense = (np.isin(plane[::-1, 1], [21]) & (plane[::-1, 0] == 0)).reshape(9, -1).sum(axis=1)
    assert appeared_pixels(other, "screen/unit_type", [21]).tolist() == dense.tolist()


def test_paint_disk_sizes_match_the_real_game() -> None:
    k = 64 / 24
    sizes = {r: paint_disk(blank_frame(), "screen/unit_type", (20, 20), r * k, 1)
             for r in (0.375, 1.125, 1.8125)}
    assert sizes[0.375] == 4 and 28 <= sizes[1.125] <= 32 and 69 <= sizes[1.8125] <= 80


def test_is_schema_key() -> None:
    for good in ("screen/unit_type", "minimap/camera", "screen/build_progress", "player",
                 "score_cumulative", "game_loop"):
        assert is_schema_key(good), good
    for bad in ("screen/nope", "unit_type", "hud/unit_type", "player/minerals", ""):
        assert not is_schema_key(bad), bad


def test_stack_builds_previous_then_current() -> None:
    a, b = blank_frame(), blank_frame()
    set_field(a, "player", "minerals", 50)
    set_field(b, "player", "minerals", 75)
    batch = stack([(a, b), (b, a)])
    assert len(batch) == 2
    assert batch.vector("player", "minerals").tolist() == [[50, 75], [75, 50]]
    assert batch.layer("screen/unit_type").shape == (2, 2, 64, 64)
    assert batch.schema == Schema.paper()


def test_synthetic_batch_holds_exactly_the_required_keys() -> None:
    batch = synthetic_batch(["screen/unit_type", "player"], size=3)
    assert set(batch.arrays) == {"screen/unit_type", "player"}
    assert batch.layer("screen/unit_type").max() < 1962
    with pytest.raises(MissingLayerError):
        batch.layer("screen/selected")
    with pytest.raises(MissingLayerError):
        batch.vector("score_cumulative", "score")
    assert schema_for(["minimap/camera", "player"]).minimap[0].name == "camera"


def test_rule_decorator_and_subclass() -> None:
    @rule(id="gain_minerals", command="gain minerals", requires=["player"], version=2)
    def gain_minerals(batch):  # type: ignore[no-untyped-def]
        """Minerals went up."""
        return rose(batch.vector("player", "minerals"))

    assert isinstance(gain_minerals, FunctionRule) and isinstance(gain_minerals, Rule)
    assert (gain_minerals.id, gain_minerals.version, gain_minerals.requires) == \
        ("gain_minerals", 2, ("player",))
    assert gain_minerals.__doc__ == "Minerals went up."
    a, b = blank_frame(), blank_frame()
    set_field(b, "player", "minerals", 5)
    assert gain_minerals(stack([(a, b), (b, a)])).tolist() == [True, False]
    assert "gain_minerals v2" in repr(gain_minerals)

    class Nothing(Rule):
        id, command, requires = "nothing", "do nothing", ("player",)

    with pytest.raises(NotImplementedError):
        Nothing()(stack([(a, b)]))


def test_rule_id_format() -> None:
    assert all(RULE_ID.match(i) for i in ("build_scv", "a", "x2_y3"))
    assert not any(RULE_ID.match(i) for i in ("Build", "2x", "a__b", "a_", "_a", "a-b", "a b"))


def test_readme_write_your_own_rule_examples_run() -> None:
    """The Python blocks of README's "Write your own rule", run in order, as a reader would."""
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    section = readme.split("## Write your own rule", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert len(blocks) == 2
    namespace: dict = {"__name__": "readme_example"}
    for block in blocks:
        exec(compile(block, "README.md", "exec"), namespace)  # noqa: S102
    from sc2data.labels.registry import validate

    validate(namespace["FinishSupplyDepot"](), "README.md")
