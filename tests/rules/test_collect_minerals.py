"""collect_minerals on hand-built frames: an idle SCV sent to mine fires; deaths, idling, and
moments when a building was affordable (a build order looks the same) don't."""

from __future__ import annotations

from sc2data.rulebase import blank_frame, set_field, stack
from sc2data.rules.collect_minerals import CHEAPEST_BUILDING, CollectMinerals

rule = CollectMinerals()


def frame(idle: int, workers: int = 12, minerals: int = 40, collected: int = 0) -> dict:
    f = blank_frame()
    set_field(f, "player", "idle_worker_count", idle)
    set_field(f, "player", "food_workers", workers)
    set_field(f, "player", "minerals", minerals)
    set_field(f, "score_cumulative", "collected_minerals", collected)
    return f


def answers(*pairs: tuple[dict, dict]) -> list[bool]:
    return rule(stack(list(pairs))).tolist()


def test_idle_scv_sent_to_mine_fires() -> None:
    assert answers((frame(2), frame(1)), (frame(3), frame(0))) == [True, True]


def test_idle_scv_sent_to_mine_while_an_scv_finishes_or_minerals_arrive_fires() -> None:
    assert answers((frame(1, workers=12), frame(0, workers=13)),
                   (frame(1, minerals=95), frame(0, minerals=100))) == [True, True]


def test_idle_scv_dying_does_not_fire() -> None:
    assert answers((frame(1, workers=13), frame(0, workers=12))) == [False]


def test_abstains_when_a_building_was_affordable() -> None:
    # An idle SCV sent to build a depot leaves the idle count the same way; its cost is paid later.
    rich = CHEAPEST_BUILDING
    assert answers((frame(1, minerals=rich), frame(0, minerals=rich)),
                   (frame(1, minerals=rich - 1), frame(0, minerals=rich - 1))) == [False, True]


def test_ordinary_mining_does_not_fire() -> None:
    # Minerals delivered (what "collected_minerals rose" would catch) is not the command.
    assert answers((frame(0, collected=100), frame(0, collected=105))) == [False]


def test_scv_going_idle_or_nothing_does_not_fire() -> None:
    assert answers((frame(0), frame(1)), (frame(1), frame(1))) == [False, False]


def test_one_idle_scv_out_another_in_is_missed() -> None:
    # Documented limitation: the count stays level.
    assert answers((frame(1), frame(1))) == [False]
