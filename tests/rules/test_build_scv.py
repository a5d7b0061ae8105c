"""build_scv on hand-built frames: an SCV finishing fires; queueing, marines, deaths don't."""

from __future__ import annotations

from sc2data.rulebase import blank_frame, set_field, stack
from sc2data.rules.build_scv import BuildScv

rule = BuildScv()


def frame(value: int, marines_made: int = 0, workers: int = 12, used: int = 12) -> dict:
    f = blank_frame()
    set_field(f, "score_cumulative", "total_value_units", value)
    set_field(f, "score_cumulative", "score", marines_made)
    set_field(f, "player", "food_workers", workers)
    set_field(f, "player", "food_used", used)
    return f


def answers(*pairs: tuple[dict, dict]) -> list[bool]:
    return rule(stack(list(pairs))).tolist()


def test_scv_completed_fires() -> None:
    assert answers((frame(600), frame(650))) == [True]


def test_two_scvs_or_an_scv_and_a_marine_in_one_stack_fire() -> None:
    assert answers((frame(600), frame(700)), (frame(600, 3), frame(700, 4))) == [True, True]


def test_marine_completed_is_not_an_scv() -> None:
    assert answers((frame(600, 3), frame(650, 4))) == [False]


def test_queued_scv_does_not_fire_until_it_exists() -> None:
    # Queueing takes supply (food_used); food_workers and the units' value rise at completion.
    assert answers((frame(600, used=12), frame(600, used=13))) == [False]
    assert answers((frame(600, used=13), frame(650, workers=13, used=13))) == [True]


def test_deaths_do_not_fire() -> None:
    # A unit dying lowers the living units' value (or leaves a cumulative value unchanged).
    assert answers((frame(650), frame(600)), (frame(650, 3), frame(650, 3))) == [False, False]


def test_scv_finished_while_a_unit_died_is_missed() -> None:
    # Documented limitation: with a value over living units the two cancel out.
    assert answers((frame(650), frame(650))) == [False]


def test_nothing_happening_does_not_fire() -> None:
    assert answers((frame(0), frame(0)), (frame(650, 9), frame(650, 9))) == [False, False]
