"""build_barracks on hand-built frames: new barracks fire; walking, dying, finishing don't."""

from __future__ import annotations

import numpy as np

from sc2data._pysc2 import units
from sc2data.rulebase import SCREEN_PX_PER_UNIT as K
from sc2data.rulebase import blank_frame, paint_disk, stack
from sc2data.rules.build_barracks import BuildBarracks

UT = "screen/unit_type"
BARRACKS, DEPOT = int(units.Terran.Barracks), int(units.Terran.SupplyDepot)
MARINE, SCV = int(units.Terran.Marine), int(units.Terran.SCV)
BARRACKS_R, DEPOT_R, SMALL_R = 1.8125 * K, 1.125 * K, 0.375 * K
rule = BuildBarracks()


def fires(prev: dict, cur: dict) -> bool:
    return bool(rule(stack([(prev, cur)]))[0])


def with_barracks(center: tuple[float, float] = (35, 25)) -> dict:
    f = blank_frame()
    paint_disk(f, UT, center, BARRACKS_R, BARRACKS)
    return f


def test_new_barracks_fires() -> None:
    assert fires(blank_frame(), with_barracks())


def test_new_barracks_under_its_builder_and_at_the_edge_fires() -> None:
    prev = blank_frame()
    paint_disk(prev, UT, (35, 25), SMALL_R, SCV)
    cur = with_barracks()
    paint_disk(cur, UT, (35, 25), SMALL_R, SCV)
    assert fires(prev, cur)
    assert fires(blank_frame(), with_barracks((63.5, 25)))


def test_unchanged_cancelled_or_finished_does_not_fire() -> None:
    assert not fires(blank_frame(), blank_frame())
    assert not fires(with_barracks(), with_barracks())
    assert not fires(with_barracks(), blank_frame())


def test_marines_leaving_a_barracks_do_not_fire() -> None:
    prev = with_barracks()
    for dx in (-3, 0, 3):
        for dy in (-3, 0, 3):
            paint_disk(prev, UT, (35 + dx, 25 + dy), SMALL_R, MARINE)  # nine marines: 36 px
    assert not fires(prev, with_barracks())


def test_a_depot_is_not_a_barracks() -> None:
    cur = blank_frame()
    paint_disk(cur, UT, (35, 25), DEPOT_R, DEPOT)
    assert not fires(blank_frame(), cur)


def test_barracks_and_depot_in_one_stack() -> None:
    cur = with_barracks()
    paint_disk(cur, UT, (10, 10), DEPOT_R, DEPOT)
    assert fires(blank_frame(), cur)


def test_vectorised_over_a_batch() -> None:
    out = rule(stack([(blank_frame(), with_barracks()), (with_barracks(), with_barracks())]))
    assert out.dtype == np.bool_ and out.tolist() == [True, False]
