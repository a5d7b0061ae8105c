"""build_scv on hand-built frames: an SCV finishing fires; queueing, dying, nothing don't."""

from __future__ import annotations

from sc2data.rulebase import blank_frame, set_field, stack
from sc2data.rules.build_scv import BuildScv

rule = BuildScv()


def frame(workers: int, food_used: int | None = None) -> dict:
    f = blank_frame()
    set_field(f, "player", "food_workers", workers)
    set_field(f, "player", "food_used", workers if food_used is None else food_used)
    return f


def answers(*pairs: tuple[dict, dict]) -> list[bool]:
    return rule(stack(list(pairs))).tolist()


def test_scv_completed_fires() -> None:
    assert answers((frame(12), frame(13))) == [True]


def test_two_scvs_in_one_stack_fire_once() -> None:
    assert answers((frame(12), frame(14))) == [True]


def test_queued_scv_does_not_fire_until_it_exists() -> None:
    assert answers((frame(12), frame(12, food_used=13))) == [False]


def test_scv_dying_or_nothing_does_not_fire() -> None:
    assert answers((frame(13), frame(12)), (frame(12), frame(12))) == [False, False]


def test_scv_finished_while_another_died_is_missed() -> None:
    # Documented limitation: food_workers nets the two out.
    assert answers((frame(13), frame(13))) == [False]
