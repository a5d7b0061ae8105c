"""collect_minerals on hand-built frames: an idle SCV back to work fires; deaths and idling
don't."""

from __future__ import annotations

from sc2data.rulebase import blank_frame, set_field, stack
from sc2data.rules.collect_minerals import CollectMinerals

rule = CollectMinerals()


def frame(idle: int, workers: int = 12, collected: int = 0) -> dict:
    f = blank_frame()
    set_field(f, "player", "idle_worker_count", idle)
    set_field(f, "player", "food_workers", workers)
    set_field(f, "score_cumulative", "collected_minerals", collected)
    return f


def answers(*pairs: tuple[dict, dict]) -> list[bool]:
    return rule(stack(list(pairs))).tolist()


def test_idle_scv_sent_to_mine_fires() -> None:
    assert answers((frame(2), frame(1))) == [True]


def test_idle_scv_sent_to_mine_while_an_scv_finishes_fires() -> None:
    assert answers((frame(1, workers=12), frame(0, workers=13))) == [True]


def test_idle_scv_dying_does_not_fire() -> None:
    assert answers((frame(1, workers=13), frame(0, workers=12))) == [False]


def test_ordinary_mining_does_not_fire() -> None:
    # Minerals delivered (what "collected_minerals rose" would catch) is not the command.
    assert answers((frame(0, collected=100), frame(0, collected=105))) == [False]


def test_scv_going_idle_or_nothing_does_not_fire() -> None:
    assert answers((frame(0), frame(1)), (frame(1), frame(1))) == [False, False]
