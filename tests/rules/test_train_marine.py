"""train_marine on hand-built frames: BuildMarines' score counts marines made, deaths aside."""

from __future__ import annotations

from sc2data.rulebase import blank_frame, set_field, stack
from sc2data.rules.train_marine import TrainMarine

rule = TrainMarine()


def frame(score: int, army: int) -> dict:
    f = blank_frame()
    set_field(f, "score_cumulative", "score", score)
    set_field(f, "player", "army_count", army)
    set_field(f, "player", "food_army", army)
    return f


def answers(*pairs: tuple[dict, dict]) -> list[bool]:
    return rule(stack(list(pairs))).tolist()


def test_marine_completed_fires() -> None:
    assert answers((frame(3, 3), frame(4, 4))) == [True]


def test_marine_completed_while_another_dies_fires() -> None:
    assert answers((frame(3, 3), frame(4, 3))) == [True]


def test_two_marines_in_one_stack_fire_once() -> None:
    assert answers((frame(3, 3), frame(5, 5))) == [True]


def test_marine_dying_or_nothing_does_not_fire() -> None:
    assert answers((frame(4, 4), frame(4, 3)), (frame(4, 4), frame(4, 4))) == [False, False]
